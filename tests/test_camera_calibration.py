"""lerobot_rnd.camera_calibration: projection, resizing, 180-degree turns, EE-mounted cameras, JSON, validation.

References are independent of the code under test: OpenCV's projectPoints and hand-derived pixel maps.
"""

import json

import numpy as np
import pytest
import torch

from lerobot_rnd.camera_calibration import CameraCalibration
from tests.helpers import points_in_front, random_pose, simple_camera


def test_projection_matches_opencv():
    cv2 = pytest.importorskip("cv2")
    rng = np.random.default_rng(0)
    cam = CameraCalibration(
        "c", [[300, 0, 100.5], [0, 310, 80.25], [0, 0, 1]], (160, 200), T_world_cam=random_pose(rng)
    )
    T_cam_world = np.linalg.inv(cam.T_world_cam)
    pts_cam = np.concatenate([rng.uniform(-0.3, 0.3, (50, 2)), rng.uniform(0.5, 2.0, (50, 1))], 1)
    pts_world = pts_cam @ cam.T_world_cam[:3, :3].T + cam.T_world_cam[:3, 3]
    rvec, _ = cv2.Rodrigues(T_cam_world[:3, :3])
    ref, _ = cv2.projectPoints(pts_world, rvec, T_cam_world[:3, 3], cam.K, None)
    uv, z = cam.project(torch.tensor(pts_world))
    np.testing.assert_allclose(uv.numpy(), ref[:, 0], atol=1e-6)
    np.testing.assert_allclose(z.numpy(), pts_cam[:, 2], atol=1e-9)


def test_resized_maps_pixel_coordinates():
    """Resizing by s maps continuous pixel coordinates u -> (u + 0.5) s - 0.5 (pixel-centre convention)."""
    rng = np.random.default_rng(1)
    cam = simple_camera(H=96, W=128)
    pts = points_in_front(cam, rng)
    uv, _ = cam.project(torch.tensor(pts))
    for H2, W2 in [(48, 64), (192, 256), (96, 64)]:
        c2 = cam.resized(H2, W2)
        assert c2.image_size == (H2, W2)
        uv2, _ = c2.project(torch.tensor(pts))
        sx, sy = W2 / 128, H2 / 96
        np.testing.assert_allclose(uv2[:, 0].numpy(), (uv[:, 0].numpy() + 0.5) * sx - 0.5, atol=1e-9)
        np.testing.assert_allclose(uv2[:, 1].numpy(), (uv[:, 1].numpy() + 0.5) * sy - 0.5, atol=1e-9)
    back = cam.resized(192, 256).resized(96, 128)
    np.testing.assert_allclose(back.K, cam.K, atol=1e-12)


def test_rotated_180_mirrors_pixels():
    rng = np.random.default_rng(2)
    cam = simple_camera(H=96, W=128)
    pts = points_in_front(cam, rng)
    uv, _ = cam.project(torch.tensor(pts))
    uvf, _ = cam.rotated_180().project(torch.tensor(pts))
    np.testing.assert_allclose(uvf[:, 0].numpy(), 127 - uv[:, 0].numpy(), atol=1e-9)
    np.testing.assert_allclose(uvf[:, 1].numpy(), 95 - uv[:, 1].numpy(), atol=1e-9)


def test_camera_pose_for_ee_poses():
    rng = np.random.default_rng(3)
    T_we = torch.tensor(np.stack([random_pose(rng) for _ in range(5)]))
    static = simple_camera()
    out = static.T_world_cam_at(T_we)
    assert out.shape == (5, 4, 4)
    np.testing.assert_allclose(out.numpy(), np.broadcast_to(static.T_world_cam, (5, 4, 4)), atol=1e-12)
    mounted = simple_camera(static=False)
    out = mounted.T_world_cam_at(T_we)
    for i in range(5):
        np.testing.assert_allclose(out[i].numpy(), T_we[i].numpy() @ mounted.T_ee_cam, atol=1e-12)
    track = simple_camera(static=False, ee_follow_rotation=False)
    out = track.T_world_cam_at(T_we)
    for i in range(5):  # orientation fixed in the world, position follows the EE
        np.testing.assert_allclose(out[i, :3, :3].numpy(), track.T_ee_cam[:3, :3], atol=1e-12)
        np.testing.assert_allclose(
            out[i, :3, 3].numpy(), T_we[i, :3, 3].numpy() + track.T_ee_cam[:3, 3], atol=1e-12
        )
    with pytest.raises(ValueError, match="T_world_ee"):
        mounted.T_world_cam_at(None)


def test_calibration_json_round_trip():
    for cam in (simple_camera(), simple_camera(static=False, ee_follow_rotation=False)):
        d = json.loads(json.dumps(cam.to_dict()))
        back = CameraCalibration.from_dict(d)
        np.testing.assert_array_equal(back.K, cam.K)
        assert back.image_size == cam.image_size and back.ee_follow_rotation == cam.ee_follow_rotation
        for a in ("T_world_cam", "T_ee_cam"):
            assert (getattr(back, a) is None) == (getattr(cam, a) is None)
            if getattr(cam, a) is not None:
                np.testing.assert_array_equal(getattr(back, a), getattr(cam, a))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"K": np.eye(4)}, "K must have shape"),
        ({"K": [[-1, 0, 1], [0, 1, 1], [0, 0, 1]]}, "positive focal"),
        ({"K": [[1, 0, 1], [0, 1, 1], [0, 1, 1]]}, r"\[0, 0, 1\]"),
        ({"image_size": (0, 10)}, "image_size"),
        ({"T_world_cam": np.diag([2.0, 1, 1, 1])}, "non-orthonormal"),
        ({"T_world_cam": np.diag([-1.0, 1, 1, 1])}, "reflection"),
        ({"T_world_cam": None}, "exactly one"),
        ({"T_ee_cam": np.eye(4)}, "exactly one"),
    ],
)
def test_calibration_validation(kwargs, match):
    base = {"name": "c", "K": np.eye(3), "image_size": (4, 4), "T_world_cam": np.eye(4)}
    base.update(kwargs)
    with pytest.raises(ValueError, match=match):
        CameraCalibration(**base)
