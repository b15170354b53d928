"""The simulators' embodiment presets (MuJoCo and MetaWorld, no rendering needed).

References: MuJoCo's camera conventions (fovy -> focal length, image centre), the gripper's mirror symmetry.
"""

import json
import math

import numpy as np
import pytest

pytest.importorskip("metaworld")
pytest.importorskip("mujoco")

from lerobot_rnd.embodiment import EMBODIMENT_PRESETS, Embodiment, load_embodiment  # noqa: E402
from lerobot_rnd.sim.metaworld_env import metaworld_sawyer_embodiment  # noqa: E402


def test_metaworld_preset():
    emb = metaworld_sawyer_embodiment()
    assert set(emb.cameras) == {"observation.images.corner2", "observation.images.behindGripper"}
    corner2, behind = (
        emb.cameras["observation.images.corner2"],
        emb.cameras["observation.images.behindGripper"],
    )
    assert corner2.is_static and not behind.is_static and behind.ee_follow_rotation is False
    # MuJoCo intrinsics: fovy 60 degrees -> fy = 64 / tan(30 deg); centre (W-1)/2
    assert corner2.K[1, 1] == pytest.approx(64 / math.tan(math.radians(30)))
    assert corner2.K[0, 2] == pytest.approx(63.5) and corner2.K[1, 2] == pytest.approx(63.5)
    for name in ("full", "fingers"):
        assert emb.meshes[name].num_faces <= 2000
    assert 1000 <= emb.meshes["full"].num_faces
    # the fingers open along the hand's y axis: the fingers mesh is symmetric about y = 0
    fy = emb.meshes["fingers"].vertices[:, 1]
    assert fy.min() == pytest.approx(-fy.max(), abs=1e-4)
    back = Embodiment.from_dict(json.loads(json.dumps(emb.to_dict())))
    assert back.to_dict() == json.loads(json.dumps(emb.to_dict()))
    flipped = metaworld_sawyer_embodiment(flipped=True)
    np.testing.assert_allclose(
        flipped.cameras["observation.images.corner2"].T_world_cam[:3, :2],
        -corner2.T_world_cam[:3, :2],
        atol=1e-12,
    )
    assert set(EMBODIMENT_PRESETS) >= {"metaworld_sawyer", "metaworld_sawyer_lerobot"}
    lr = load_embodiment("metaworld_sawyer_lerobot")
    assert list(lr.cameras) == ["observation.image"] and lr.cameras["observation.image"].image_size == (
        480,
        480,
    )
    assert lr.ee_pose_dict()["rotation"] == "fixed"
