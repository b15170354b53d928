"""lerobot_rnd.ee_pose_source: EE poses and gripper states read from state vectors in every format.

References are independent of the code under test: scipy's Rotation.
"""

import json

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from lerobot_rnd.ee_pose_source import EEPoseReader, EEPoseSource


@pytest.mark.parametrize("fmt", ["quat_wxyz", "quat_xyzw", "rotvec", "rot6d", "euler_xyz", "matrix", "none"])
def test_ee_pose_source_formats(fmt):
    rng = np.random.default_rng(4)
    R = Rotation.random(6, random_state=rng)
    pos = rng.uniform(-1, 1, (6, 3))
    mats = R.as_matrix()
    rot = {
        "quat_wxyz": np.roll(R.as_quat(), 1, axis=1),
        "quat_xyzw": R.as_quat(),
        "rotvec": R.as_rotvec(),
        "rot6d": np.concatenate([mats[:, :, 0], mats[:, :, 1]], 1),
        "euler_xyz": R.as_euler("xyz"),
        "matrix": mats.reshape(6, 9),
        "none": np.zeros((6, 0)),
    }[fmt]
    state = torch.tensor(np.concatenate([pos, [[0.5]] * 6, rot], 1))
    n = rot.shape[1]
    fixed = Rotation.from_euler("y", 90, degrees=True)
    src = EEPoseSource(
        format=fmt, position_indices=[0, 1, 2], rotation_indices=list(range(4, 4 + n)) if n else None,
        fixed_rotation=fixed.as_matrix() if fmt == "none" else None, gripper_index=3,
    )  # fmt: skip
    T = src.ee_pose(state).numpy()
    ref_R = np.broadcast_to(fixed.as_matrix(), (6, 3, 3)) if fmt == "none" else mats
    np.testing.assert_allclose(T[:, :3, :3], ref_R, atol=1e-6)
    np.testing.assert_allclose(T[:, :3, 3], pos, atol=1e-12)
    np.testing.assert_allclose(T[:, 3], np.broadcast_to([0, 0, 0, 1], (6, 4)))
    np.testing.assert_allclose(src.gripper(state).numpy(), 0.5)
    back = EEPoseSource.from_dict(json.loads(json.dumps(src.to_dict())))
    np.testing.assert_allclose(back.ee_pose(state).numpy(), T, atol=1e-12)


def test_ee_pose_source_validation():
    with pytest.raises(ValueError, match="format"):
        EEPoseSource(format="quaternion", position_indices=[0, 1, 2])
    with pytest.raises(ValueError, match="4 rotation_indices"):
        EEPoseSource(format="quat_wxyz", position_indices=[0, 1, 2], rotation_indices=[3, 4, 5])
    with pytest.raises(ValueError, match="urdf_path"):  # "needs urdf (the URDF's text) or urdf_path, ..."
        EEPoseSource(format="joints")
    src = EEPoseSource(format="rotvec", position_indices=[0, 1, 2], rotation_indices=[3, 4, 5])
    with pytest.raises(ValueError, match="reads index 5"):
        src.ee_pose(torch.zeros(2, 4))


def test_ee_pose_reader_maps_the_gripper_to_plus_minus_one_and_checks_the_state_size():
    src = EEPoseSource(
        format="none", position_indices=[0, 1, 2], gripper_index=3, gripper_open_value=0.08,
        gripper_closed_value=0.0,
    )  # fmt: skip
    reader = EEPoseReader(src.to_dict(), state_dim=4)
    state = torch.tensor([[0.1, 0.2, 0.3, 0.08], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.04]])
    torch.testing.assert_close(reader.gripper(state), torch.tensor([-1.0, 1.0, 0.0]))  # open -1, closed +1
    torch.testing.assert_close(reader.pose(state)[0, :3, 3], torch.tensor([0.1, 0.2, 0.3]))
    no_gripper = EEPoseReader({"format": "none", "position_indices": [0, 1, 2]}, state_dim=3)
    torch.testing.assert_close(no_gripper.gripper(state[:, :3]), -torch.ones(3))
    with pytest.raises(ValueError, match="does not match this dataset"):
        EEPoseReader(src.to_dict(), state_dim=3)
    with pytest.raises(ValueError, match="ee_pose is empty"):
        EEPoseReader({}, state_dim=4)
