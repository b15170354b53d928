"""An interrupted `lerobot-train` run resumed with `--resume=true` ends where an uninterrupted run ends.

Reference: the same command run without interruption (same seed, same data); the resumed run must reach the
same weights (float tolerance on CPU) and log the same losses after the resume point. The interrupted run is
simulated by a run with fewer --steps, so the learning rate is constant here (a cosine schedule depends on
--steps; on a real resume LeRobot rebuilds it from the same --steps and restores its position).
"""

import os
import re
import subprocess
import sys
from pathlib import Path

import torch
from safetensors.torch import load_file

from tests.helpers import tiny_policy_flags

#: the toy dataset has 48 frames: batch 8 gives 6 steps per epoch, and the run is cut at an epoch boundary
BATCH, CUT, TOTAL = 8, 6, 12


def _train(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    cmd = [str(Path(sys.executable).parent / "lerobot-train"), *args]
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_LEROBOT_HOME": str(cwd / "hf")}
    result = subprocess.run(cmd, check=False, capture_output=True, text=True, timeout=900, env=env, cwd=cwd)
    assert result.returncode == 0, result.stderr[-4000:]
    return result


def _losses(result: subprocess.CompletedProcess) -> dict[int, float]:
    text = result.stdout + result.stderr
    return {int(s): float(v) for s, v in re.findall(r"step:(\d+) .*?loss:([0-9.]+)", text)}


def test_resume_reproduces_the_uninterrupted_run(toy_dataset_root, tmp_path):
    def flags(out: Path, steps: int) -> list[str]:
        return [
            "--policy.type=rnd", "--policy.device=cpu", "--policy.push_to_hub=false",
            "--dataset.repo_id=local/toy_reach", f"--dataset.root={toy_dataset_root}", f"--output_dir={out}",
            f"--steps={steps}", f"--save_freq={CUT}", f"--batch_size={BATCH}", "--num_workers=0", "--log_freq=1",
            "--eval_freq=0", "--wandb.enable=false", "--seed=7",
            # AdamW at a constant learning rate (the policy's preset is cosine over --steps)
            "--use_policy_training_preset=false", "--optimizer.type=adamw", "--optimizer.lr=1e-3",
            "--scheduler.type=diffuser", "--scheduler.name=constant",
            *tiny_policy_flags(),
        ]  # fmt: skip

    whole = _train(tmp_path, *flags(tmp_path / "whole", TOTAL))
    _train(tmp_path, *flags(tmp_path / "cut", CUT))
    cut_ckpt = tmp_path / "cut" / "checkpoints" / "last" / "pretrained_model"
    resumed = _train(
        tmp_path, f"--config_path={cut_ckpt / 'train_config.json'}", "--resume=true", f"--steps={TOTAL}"
    )

    want = load_file(
        tmp_path / "whole" / "checkpoints" / f"{TOTAL:06d}" / "pretrained_model" / "model.safetensors"
    )
    got = load_file(
        tmp_path / "cut" / "checkpoints" / f"{TOTAL:06d}" / "pretrained_model" / "model.safetensors"
    )
    assert set(got) == set(want)
    moved = load_file(
        tmp_path / "cut" / "checkpoints" / f"{CUT:06d}" / "pretrained_model" / "model.safetensors"
    )
    assert any(not torch.equal(moved[k], want[k]) for k in want)  # training after the cut changed the weights
    for key in want:
        torch.testing.assert_close(got[key], want[key], rtol=1e-5, atol=1e-6, msg=key)

    whole_losses, resumed_losses = _losses(whole), _losses(resumed)
    after_cut = range(CUT + 1, TOTAL + 1)
    assert all(s in resumed_losses for s in after_cut), sorted(resumed_losses)
    assert [resumed_losses[s] for s in after_cut] == [whole_losses[s] for s in after_cut]
