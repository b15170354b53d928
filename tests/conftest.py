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
    from lerobot_rnd.testing import record_toy_dataset

    return record_toy_dataset(tmp_path_factory.mktemp("toy") / "toy_reach")

