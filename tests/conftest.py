import os

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
os.environ.setdefault("HF_HUB_OFFLINE", "1")

import pytest  # noqa: E402
import torch  # noqa: E402

torch.set_num_threads(max(1, min(2, os.cpu_count() or 1)))


@pytest.fixture(scope="session")
def toy_dataset_root(tmp_path_factory):
    """A 3-episode synthetic reaching dataset (64x64 front + wrist cameras) with its embodiment JSON."""
    from tests.toy_data import record_toy_dataset

    return record_toy_dataset(tmp_path_factory.mktemp("toy") / "toy_reach")


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
