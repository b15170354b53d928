"""`lerobot-train --policy.type=rnd` in two CPU processes (torchrun; LeRobot's Accelerator then trains with
DDP over gloo, as `accelerate launch --multi_gpu` would on GPUs).

Each process estimates the statistics, renders and solves its SVDs on its own; DDP averages the gradients.
The saved checkpoint must load and predict. Marked slow (two training processes); CI runs it explicitly
(.ci/run), and docs/FAILURES.md gives the command.
"""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from tests.helpers import tiny_policy_flags


@pytest.mark.slow
def test_two_process_training_runs_and_its_checkpoint_loads(toy_dataset_root, tmp_path):
    out = tmp_path / "train"
    bin_dir = Path(sys.executable).parent
    cmd = [
        str(bin_dir / "torchrun"), "--standalone", "--nproc_per_node=2", str(bin_dir / "lerobot-train"),
        "--policy.type=rnd", "--policy.device=cpu", "--policy.push_to_hub=false",
        "--dataset.repo_id=local/toy_reach", f"--dataset.root={toy_dataset_root}", f"--output_dir={out}",
        "--steps=4", "--save_freq=4", "--batch_size=2", "--num_workers=0", "--log_freq=1", "--eval_freq=0",
        "--wandb.enable=false", *tiny_policy_flags(),
    ]  # fmt: skip
    env = {
        **os.environ,
        "HF_HUB_OFFLINE": "1",
        "HF_LEROBOT_HOME": str(tmp_path / "hf"),
        "OMP_NUM_THREADS": "1",
    }
    result = subprocess.run(
        cmd, check=False, capture_output=True, text=True, timeout=900, env=env, cwd=tmp_path
    )
    log = result.stdout + result.stderr
    assert result.returncode == 0, log[-4000:]
    assert re.search(r"Effective batch size: 2 x 2 = 4", log), log[-2000:]

    from lerobot_rnd.modeling_rnd import RnDPolicy

    policy = RnDPolicy.from_pretrained(out / "checkpoints" / "last" / "pretrained_model")
    obs = {
        "observation.images.front": torch.rand(1, 3, 64, 64),
        "observation.images.wrist": torch.rand(1, 3, 64, 64),
        "observation.state": torch.tensor([[0.0, 0.0, 0.2, 1.0]]),
    }
    actions = policy.predict_action_chunk(obs)
    assert actions.shape == (1, policy.config.chunk_size, 4) and torch.isfinite(actions).all()
