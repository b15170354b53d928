"""Sampling under `torch.inference_mode()` and training in the same process (issue 36).

LeRobot's rollout calls `select_action` under `torch.inference_mode()`; `lerobot-train --eval_freq` then goes
on training in the same process, where a batch may have a size first seen during evaluation (the last, partial
batch of an epoch). No tensor cached in one mode may be updated in place, or saved for backward, in the other.
The references are the same calls made in a fresh object or under the other mode.
"""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import trimesh

from lerobot_rnd.action_adapters import JointPositionAdapter
from lerobot_rnd.rendering import MeshBatch, Rasterizer
from tests.helpers import make_policy, six_joint_urdf, tiny_policy_flags, training_batch


def _meshes() -> MeshBatch:
    box = trimesh.creation.box(extents=[0.08, 0.03, 0.05])
    return MeshBatch.from_meshes([(box.vertices, box.faces, None)])


def _poses(n: int) -> tuple[torch.Tensor, torch.Tensor]:
    T = torch.eye(4).repeat(n, 1, 1)
    T[:, :3, 3] = torch.tensor([0.0, 0.0, 0.5]) + 0.02 * torch.randn(n, 3, generator=torch.Generator().manual_seed(n))
    K = torch.tensor([[60.0, 0.0, 31.5], [0.0, 60.0, 23.5], [0.0, 0.0, 1.0]])
    return T, K


@pytest.mark.parametrize("dynamic", [True, False])
def test_rasterizer_built_and_used_under_inference_mode_then_outside_it(dynamic):
    n = 3
    T, K = _poses(n)
    with torch.inference_mode():
        rast = Rasterizer(_meshes(), (48, 64))
        first = rast(torch.zeros(n, dtype=torch.long), T, K, dynamic=dynamic)
        first = {k: getattr(first, k).clone() for k in ("rgb", "mask", "points_cam")}
    again = rast(torch.zeros(n, dtype=torch.long), T, K, dynamic=dynamic)  # same sizes, outside inference mode
    fresh = Rasterizer(_meshes(), (48, 64))(torch.zeros(n, dtype=torch.long), T, K, dynamic=dynamic)
    assert first["mask"].any()
    for key, value in first.items():
        assert torch.equal(getattr(again, key), value), key
        assert torch.equal(getattr(fresh, key), value), key
    with torch.inference_mode():  # and back again: the buffers made outside serve inference mode too
        back = rast(torch.zeros(n, dtype=torch.long), T, K, dynamic=dynamic)
        assert torch.equal(back.mask, first["mask"])


@pytest.mark.parametrize("overrides", [{}, {"gripper_patches": 2}], ids=["all_patches", "gripper_patches"])
def test_policy_samples_under_inference_mode_then_trains_and_predicts_outside_it(toy_dataset_root, overrides):
    torch.manual_seed(0)
    policy, _ = make_policy(toy_dataset_root, **overrides)
    for b in (1, 3):
        batch = training_batch(toy_dataset_root, policy.config, n=b)
        current = {k: v[:, -1] for k, v in batch.items() if k.startswith("observation.")}
        history = {k: v for k, v in batch.items() if k.startswith("observation.")}
        noise = torch.randn(b, policy.config.chunk_size, 6, generator=torch.Generator().manual_seed(b))
        with torch.inference_mode():  # as LeRobot's rollout
            policy.reset()
            policy.select_action(current)
            in_mode = policy.predict_action_chunk(dict(history), noise=noise).clone()
        policy.train()
        loss, _ = policy.forward(batch)  # the same batch size, so the same render sizes, outside inference mode
        loss.backward()
        assert torch.isfinite(loss)
        assert all(p.grad is not None for p in policy.get_optim_params() if p.requires_grad)
        policy.zero_grad()
        outside = policy.predict_action_chunk(dict(history), noise=noise)
        torch.testing.assert_close(outside, in_mode)


def test_joint_adapter_chain_first_built_under_inference_mode_serves_autograd():
    adapter = JointPositionAdapter(urdf=six_joint_urdf(), ee_link="tool", gripper=False)
    q = torch.tensor([[0.1, 0.4, -0.3, 0.2, 0.5, -0.1]])
    with torch.inference_mode():
        T_ref = adapter.forward_kinematics(q).clone()  # builds the float32 chain under inference mode
    q_grad = q.clone().requires_grad_(True)
    T = adapter.forward_kinematics(q_grad)
    T[..., :3, 3].sum().backward()
    torch.testing.assert_close(T.detach(), T_ref)
    assert q_grad.grad is not None and torch.isfinite(q_grad.grad).all() and q_grad.grad.abs().sum() > 0


# ------------------------------------------------------------------------------------------------------------
# LeRobot's policy contract (its tests/policies/test_policies.py, adapted to `rnd` and a recorded MetaWorld
# dataset): factory, processors, a training step, save/load, and a rollout under inference mode followed by
# training with the rollout's batch size.


@pytest.fixture(scope="module")
def metaworld_dataset(tmp_path_factory) -> Path:
    """One scripted reach-v3 demo at 64x64 (52 frames), recorded by the plugin's recorder."""
    root = tmp_path_factory.mktemp("mw") / "mw_reach_1"
    cmd = [str(Path(sys.executable).parent / "lerobot-rnd-record"), "--task", "reach-v3", "--episodes", "1",
           "--image-size", "64", "--root", str(root), "--repo-id", "local/mw_reach_1"]
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env={**os.environ, "HF_HUB_OFFLINE": "1"})
    assert out.returncode == 0, out.stderr[-3000:]
    return root


def test_lerobot_policy_contract_with_a_rollout_under_inference_mode(metaworld_dataset, tmp_path):
    from lerobot.configs.types import FeatureType
    from lerobot.datasets.factory import resolve_delta_timestamps
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata
    from lerobot.datasets.utils import dataset_to_policy_features
    from lerobot.envs.configs import EnvConfig
    from lerobot.envs.factory import make_env, make_env_pre_post_processors
    from lerobot.policies.factory import get_policy_class, make_policy, make_pre_post_processors
    from lerobot.processor import PolicyProcessorPipeline
    from lerobot.scripts.lerobot_eval import rollout

    import lerobot_policy_rnd  # noqa: F401  (what LeRobot's plugin discovery imports)
    from lerobot_rnd.configuration_rnd import RnDConfig
    from tests.helpers import TINY_POLICY_KWARGS

    meta = LeRobotDatasetMetadata("local/mw_reach_1", root=metaworld_dataset)
    cfg = RnDConfig(**TINY_POLICY_KWARGS)
    features = dataset_to_policy_features(meta.features)
    cfg.output_features = {k: f for k, f in features.items() if f.type is FeatureType.ACTION}
    cfg.input_features = {k: f for k, f in features.items() if k not in cfg.output_features}

    # Factory and processors.
    assert get_policy_class("rnd").__name__ == "RnDPolicy"
    torch.manual_seed(0)
    policy = make_policy(cfg, ds_meta=meta)
    pre, post = make_pre_post_processors(cfg, dataset_stats=meta.stats)

    # Training step on a preprocessed dataloader batch.
    dataset = LeRobotDataset("local/mw_reach_1", root=metaworld_dataset,
                             delta_timestamps=resolve_delta_timestamps(cfg, meta))
    loader = torch.utils.data.DataLoader(dataset, batch_size=2, shuffle=True,
                                         generator=torch.Generator().manual_seed(0))
    optimizer = torch.optim.AdamW(policy.get_optim_params(), lr=1e-4)

    def train_step(batch):
        policy.train()
        loss, info = policy.forward(pre(batch))
        loss.backward()
        optimizer.step()
        optimizer.zero_grad()
        assert torch.isfinite(loss) and {"image_loss", "action_loss", "gripper_loss"} <= set(info)

    train_step(next(iter(loader)))

    # A rollout as lerobot-eval runs it (under inference mode), one env: batch size 1.
    env_cfg = EnvConfig.get_choice_class("rnd_mw")(task="reach-v3", episode_length=6, observation_height=64,
                                                   observation_width=64)
    envs = make_env(env_cfg, n_envs=1)
    env = next(iter(next(iter(envs.values())).values()))
    env_pre, env_post = make_env_pre_post_processors(env_cfg, cfg)
    policy.reset()
    try:
        info = rollout(env, policy, env_pre, env_post, pre, post, seeds=[1000])
    finally:
        env.close()
    assert info["action"].shape == (1, 6, 4)
    assert torch.isfinite(info["action"]).all()

    # Training again with the rollout's batch size (1), as the last, partial batch of an epoch can be.
    train_step({k: v[:1] if isinstance(v, torch.Tensor) else v[:1] for k, v in next(iter(loader)).items()})

    # Save and load: the same weights, buffers and config, and the same actions for the same noise.
    policy.save_pretrained(tmp_path / "ckpt")
    pre.save_pretrained(tmp_path / "ckpt")
    post.save_pretrained(tmp_path / "ckpt")
    reloaded = get_policy_class("rnd").from_pretrained(tmp_path / "ckpt")
    for name, value in policy.state_dict().items():
        assert torch.equal(value, reloaded.state_dict()[name]), name
    pre2 = PolicyProcessorPipeline.from_pretrained(tmp_path / "ckpt", "policy_preprocessor.json")
    assert [type(s).__name__ for s in pre2.steps] == [type(s).__name__ for s in pre.steps]
    sample = {k: v[None] if isinstance(v, torch.Tensor) else v for k, v in dataset[0].items()}
    obs = {k: v for k, v in pre(copy.deepcopy(sample)).items() if k.startswith("observation.")}
    noise = torch.randn(1, cfg.chunk_size, 6, generator=torch.Generator().manual_seed(3))
    with torch.inference_mode():
        a = policy.predict_action_chunk(dict(obs), noise=noise)
        b = reloaded.predict_action_chunk(dict(obs), noise=noise)
    assert torch.equal(a, b)


@pytest.mark.slow
def test_lerobot_train_with_evaluation_every_step_and_a_partial_last_batch(metaworld_dataset, tmp_path):
    """Step 1 trains on 51 frames, evaluation renders one env's batch under inference mode, step 2 trains on the
    epoch's last frame: a batch of 1, the size evaluation rendered first (it crashed before issue 36's fix)."""
    total = json.loads((metaworld_dataset / "meta" / "info.json").read_text())["total_frames"]
    assert total > 2
    out = tmp_path / "train"
    cmd = [
        str(Path(sys.executable).parent / "lerobot-train"),
        "--policy.type=rnd", "--policy.device=cpu", "--policy.push_to_hub=false",
        "--dataset.repo_id=local/mw_reach_1", f"--dataset.root={metaworld_dataset}",
        f"--output_dir={out}", "--steps=2", "--save_freq=2", f"--batch_size={total - 1}", "--num_workers=0",
        "--log_freq=1", "--eval_freq=1", "--wandb.enable=false",
        "--env.type=rnd_mw", "--env.task=reach-v3", "--env.episode_length=4",
        "--env.observation_height=64", "--env.observation_width=64",
        "--eval.n_episodes=1", "--eval.batch_size=1", "--eval.use_async_envs=false",
        *tiny_policy_flags(),
    ]
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_LEROBOT_HOME": str(tmp_path / "hf")}
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=env, cwd=tmp_path)
    assert res.returncode == 0, (res.stdout[-2000:], res.stderr[-4000:])
    log = res.stdout + res.stderr
    assert "Eval policy at step 1" in log and "Eval policy at step 2" in log
    for step in (1, 2):
        assert (out / "eval" / f"videos_step_{step:06d}").is_dir(), step
    assert (out / "checkpoints" / "000002" / "pretrained_model" / "model.safetensors").is_file()
