"""Utilities shared by the test modules: tiny policy configs, policy and batch builders, the GL probe and the
backward-compatibility procedures. Test modules import from here, never from each other."""

from __future__ import annotations

from pathlib import Path

import torch

REPO_ROOT = Path(__file__).resolve().parents[1]
FIXTURES = Path(__file__).resolve().parent / "fixtures"

TINY_POLICY_KWARGS = dict(
    device="cpu",
    dim_model=64,
    n_layers=2,
    n_heads=4,
    patch_size=16,
    image_size=(64, 64),
    chunk_size=4,
    n_action_steps=2,
    num_train_timesteps=20,
    stats_num_samples=32,
)


def tiny_policy_flags() -> list[str]:
    """`TINY_POLICY_KWARGS` as lerobot-train flags."""
    return [
        "--policy.dim_model=64",
        "--policy.n_layers=2",
        "--policy.n_heads=4",
        "--policy.image_size=[64,64]",
        "--policy.chunk_size=4",
        "--policy.n_action_steps=2",
        "--policy.num_train_timesteps=20",
        "--policy.stats_num_samples=32",
    ]


def make_policy(root, **overrides):
    """An `RnDPolicy` (TINY_POLICY_KWARGS + overrides) on the toy dataset at `root` -> (policy, meta)."""
    from lerobot.configs.types import FeatureType
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
    from lerobot.datasets.utils import dataset_to_policy_features

    from lerobot_rnd.configuration_rnd import RnDConfig
    from lerobot_rnd.modeling_rnd import RnDPolicy

    meta = LeRobotDatasetMetadata("local/toy_reach", root=root)
    features = dataset_to_policy_features(meta.features)
    cfg = RnDConfig(**{**TINY_POLICY_KWARGS, **overrides})
    cfg.output_features = {k: f for k, f in features.items() if f.type is FeatureType.ACTION}
    cfg.input_features = {k: f for k, f in features.items() if k not in cfg.output_features}
    return RnDPolicy(cfg, dataset_meta=meta), meta


def dataset_items(root, cfg, indices=None) -> dict[str, torch.Tensor]:
    """The toy dataset's training samples for `cfg`'s history / horizon, stacked: {key: (N, ...)}.

    `indices`: which frames (default all)."""
    from lerobot.datasets.factory import resolve_delta_timestamps
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata

    meta = LeRobotDatasetMetadata("local/toy_reach", root=root)
    ds = LeRobotDataset("local/toy_reach", root=root, delta_timestamps=resolve_delta_timestamps(cfg, meta))
    items = [ds[i] for i in (range(len(ds)) if indices is None else indices)]
    keys = [k for k in items[0] if isinstance(items[0][k], torch.Tensor)]
    return {k: torch.stack([it[k] for it in items]) for k in keys}


def training_batch(root, cfg, n=4) -> dict[str, torch.Tensor]:
    """`n` evenly spaced training samples of the toy dataset."""
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata

    total = LeRobotDatasetMetadata("local/toy_reach", root=root).total_frames
    return dataset_items(root, cfg, list(range(0, total, max(1, total // n)))[:n])


def gl_available() -> bool:
    """Whether MuJoCo can render offscreen here (MUJOCO_GL=egl / osmesa on a headless machine)."""
    try:
        import mujoco
    except ImportError:
        return False
    try:
        m = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom size='1'/></worldbody></mujoco>")
        r = mujoco.Renderer(m, 8, 8)
        r.render()
        r.close()
        return True
    except Exception:  # noqa: BLE001
        return False


# --------------------------------------------------------------------------------------------------
# Backward compatibility: a checkpoint and training losses recorded before the issue-10 refactor
# (tests/fixtures/make_backward_compat_fixtures.py), checked by tests/test_backward_compat.py.
# --------------------------------------------------------------------------------------------------
FIXTURE_CHECKPOINT = FIXTURES / "rnd_tiny_checkpoint"
FIXTURE_EXPECTED_ACTIONS = FIXTURES / "rnd_tiny_expected_actions.safetensors"
FIXTURE_TRAINING_LOSSES = FIXTURES / "rnd_tiny_training_losses.json"
#: frozen (not derived from TINY_POLICY_KWARGS): the recorded fixtures depend on it
FIXTURE_POLICY_KWARGS = dict(
    device="cpu",
    variant="AI",
    dim_model=32,
    n_layers=1,
    n_heads=2,
    patch_size=16,
    image_size=(64, 64),
    chunk_size=4,
    n_action_steps=2,
    num_train_timesteps=20,
    stats_num_samples=32,
)
LOSS_STEPS = 20


def fixture_inference_inputs() -> dict[str, torch.Tensor]:
    """Fixed observations with history (B=2, H=2; 32x32 images, which the policy resizes) and DDIM noise
    (B, chunk_size=4, 6) for the fixture policy."""
    g = torch.Generator().manual_seed(10)
    return {
        "observation.images.front": torch.rand(2, 2, 3, 32, 32, generator=g),
        "observation.images.wrist": torch.rand(2, 2, 3, 32, 32, generator=g),
        "observation.state": torch.tensor([[0.02, -0.01, 0.2, 1.0], [0.03, 0.0, 0.19, 1.0]])[None]
        .expand(2, 2, 4)
        .clone(),
        "noise": torch.randn(2, 4, 6, generator=g),
    }


def record_training_losses(root, steps: int = LOSS_STEPS) -> list[dict[str, float]]:
    """Train the fixture-size R&D-AI from scratch on the toy dataset at `root` for `steps` AdamW steps at
    fixed seeds; returns per step {"loss", "image_loss", "action_loss", "gripper_loss"}."""
    torch.manual_seed(0)
    policy, _ = make_policy(root, **FIXTURE_POLICY_KWARGS)
    data = dataset_items(root, policy.config)
    n = next(iter(data.values())).shape[0]
    optimizer = torch.optim.AdamW(policy.get_optim_params(), lr=1e-3, weight_decay=0.0)
    order = torch.Generator().manual_seed(0)
    torch.manual_seed(1)  # diffusion steps and noise drawn inside the loss
    policy.train()
    losses = []
    for _ in range(steps):
        idx = torch.randint(0, n, (4,), generator=order)
        loss, info = policy.forward({k: v[idx] for k, v in data.items()})
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append({"loss": loss.item(), **info})
    return losses
