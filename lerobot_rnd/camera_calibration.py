"""Camera calibration of R&D: OpenCV pinhole intrinsics, image size and extrinsics.

A :class:`CameraCalibration` is static (``T_world_cam``) or mounted on the end effector (``T_ee_cam``;
with ``ee_follow_rotation=False`` for a camera that follows the EE position but keeps a fixed world
orientation, like MuJoCo's ``mode="track"`` cameras). ``K`` has pixel centres at integer coordinates (see
docs/DESIGN.md). :func:`camera_from_mujoco` reads one from a MuJoCo model exactly as ``mujoco.Renderer``
draws it. The JSON layout is in docs/CALIBRATION.md.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from lerobot_rnd.arrays import as_matrix, as_rigid_transform, invert_pose, make_pose, mujoco_pose, tolist


@dataclass
class CameraCalibration:
    """Pinhole camera: OpenCV ``K`` (pixel centres at integer coordinates), size and extrinsics.

    Exactly one of ``T_world_cam`` (static camera) and ``T_ee_cam`` (camera mounted on the end
    effector) is set. ``T_ee_cam`` maps camera-frame points into the EE frame; with
    ``ee_follow_rotation=False`` it is instead expressed in a frame at the EE origin with world-aligned
    axes (the camera follows the EE position only; MuJoCo ``mode="track"``):
    ``T_world_cam = [I | p_world_ee] @ T_ee_cam``.
    """

    name: str
    K: Any
    image_size: tuple[int, int]
    T_world_cam: Any | None = None
    T_ee_cam: Any | None = None
    ee_follow_rotation: bool = True

    def __post_init__(self) -> None:
        if not isinstance(self.name, str):
            raise TypeError(f"camera name must be a string, got {self.name!r}")
        self.K = as_matrix(self.K, (3, 3), f"camera '{self.name}': K")
        K = self.K
        if not (K[0, 0] > 0 and K[1, 1] > 0):
            raise ValueError(
                f"camera '{self.name}': K must have positive focal lengths, got fx={K[0, 0]}, fy={K[1, 1]}"
            )
        if abs(K[1, 0]) > 1e-9 or not np.allclose(K[2], [0.0, 0.0, 1.0], atol=1e-9):
            raise ValueError(
                f"camera '{self.name}': K must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}"
            )
        try:
            H, W = (int(v) for v in self.image_size)
        except (TypeError, ValueError) as e:
            raise ValueError(
                f"camera '{self.name}': image_size must be (H, W), got {self.image_size!r}"
            ) from e
        if len(tuple(self.image_size)) != 2 or H <= 0 or W <= 0:
            raise ValueError(
                f"camera '{self.name}': image_size must be two positive ints (H, W), got {self.image_size!r}"
            )
        self.image_size = (H, W)
        if (self.T_world_cam is None) == (self.T_ee_cam is None):
            raise ValueError(
                f"camera '{self.name}': set exactly one of T_world_cam (static camera) and T_ee_cam "
                "(camera mounted on the end effector)"
            )
        for attr in ("T_world_cam", "T_ee_cam"):
            val = getattr(self, attr)
            if val is not None:
                setattr(self, attr, as_rigid_transform(val, f"camera '{self.name}': {attr}"))
        self.ee_follow_rotation = bool(self.ee_follow_rotation)

    # ------------------------------------------------------------------ properties
    @property
    def is_static(self) -> bool:
        return self.T_world_cam is not None

    @property
    def height(self) -> int:
        return self.image_size[0]

    @property
    def width(self) -> int:
        return self.image_size[1]

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "name": self.name,
            "K": tolist(self.K),
            "image_size": [int(self.image_size[0]), int(self.image_size[1])],
        }
        if self.T_world_cam is not None:
            d["T_world_cam"] = tolist(self.T_world_cam)
        else:
            d["T_ee_cam"] = tolist(self.T_ee_cam)
            d["ee_follow_rotation"] = self.ee_follow_rotation
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> CameraCalibration:
        unknown = set(d) - {"name", "K", "image_size", "T_world_cam", "T_ee_cam", "ee_follow_rotation"}
        if unknown:
            raise ValueError(f"camera calibration: unknown keys {sorted(unknown)}")
        for req in ("K", "image_size"):
            if req not in d:
                raise ValueError(f"camera calibration {d.get('name', '?')!r}: missing '{req}'")
        return cls(
            name=d.get("name", ""),
            K=d["K"],
            image_size=tuple(d["image_size"]),
            T_world_cam=d.get("T_world_cam"),
            T_ee_cam=d.get("T_ee_cam"),
            ee_follow_rotation=d.get("ee_follow_rotation", True),
        )

    # ------------------------------------------------------------------ transforms of the calibration
    def resized(self, height: int, width: int) -> CameraCalibration:
        """Calibration for the image resized to (height, width) (pixel-centre convention)."""
        H, W = self.image_size
        sx, sy = width / W, height / H
        K = self.K.copy()
        K[0, 0] *= sx
        K[0, 1] *= sx
        K[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
        K[1, 1] *= sy
        K[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
        return CameraCalibration(
            self.name, K, (height, width), self.T_world_cam, self.T_ee_cam, self.ee_follow_rotation
        )

    def rotated_180(self) -> CameraCalibration:
        """Calibration for the image turned by 180 degrees (flipped in both axes, ``np.flip(img, (0, 1))``).

        Pixel (u, v) moves to (W-1-u, H-1-v): the camera frame turns 180 degrees about its optical
        axis (x, y -> -x, -y) and the principal point is mirrored.
        """
        H, W = self.image_size
        K = self.K.copy()
        K[0, 2] = (W - 1) - K[0, 2]
        K[1, 2] = (H - 1) - K[1, 2]
        flip = np.diag([-1.0, -1.0, 1.0, 1.0])
        Tw = None if self.T_world_cam is None else self.T_world_cam @ flip
        Te = None if self.T_ee_cam is None else self.T_ee_cam @ flip
        return CameraCalibration(self.name, K, self.image_size, Tw, Te, self.ee_follow_rotation)

    # ------------------------------------------------------------------ torch accessors
    def K_tensor(self, device=None, dtype=torch.float32) -> torch.Tensor:
        return torch.as_tensor(self.K, dtype=dtype, device=device)

    def T_world_cam_at(
        self, T_world_ee: torch.Tensor | None = None, device=None, dtype=torch.float32
    ) -> torch.Tensor:
        """World-from-camera pose, batched like ``T_world_ee`` (..., 4, 4).

        Static cameras ignore the EE pose (the result is broadcast to its batch shape); EE-mounted
        cameras need it.
        """
        if T_world_ee is not None:
            T_world_ee = torch.as_tensor(T_world_ee)
            if T_world_ee.shape[-2:] != (4, 4):
                raise ValueError(f"T_world_ee must have shape (..., 4, 4), got {tuple(T_world_ee.shape)}")
            device = T_world_ee.device if device is None else device
            dtype = T_world_ee.dtype if T_world_ee.is_floating_point() else dtype
            T_world_ee = T_world_ee.to(device=device, dtype=dtype)
        if self.T_world_cam is not None:
            T = torch.as_tensor(self.T_world_cam, dtype=dtype, device=device)
            if T_world_ee is None:
                return T
            return T.expand(*T_world_ee.shape[:-2], 4, 4).clone()
        if T_world_ee is None:
            raise ValueError(
                f"camera '{self.name}' is mounted on the end effector: pass T_world_ee to get its pose"
            )
        T_ee_cam = torch.as_tensor(self.T_ee_cam, dtype=dtype, device=device)
        if self.ee_follow_rotation:
            return T_world_ee @ T_ee_cam
        out = T_ee_cam.expand(*T_world_ee.shape[:-2], 4, 4).clone()
        out[..., :3, 3] = out[..., :3, 3] + T_world_ee[..., :3, 3]
        return out

    def project(
        self, points_world: torch.Tensor | np.ndarray, T_world_ee: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Pixel coordinates (u, v) (..., N, 2) and depth (..., N) of world points (..., N, 3)."""
        p = torch.as_tensor(points_world, dtype=torch.float64)
        T_wc = self.T_world_cam_at(
            None if T_world_ee is None else torch.as_tensor(T_world_ee, dtype=torch.float64),
            dtype=torch.float64,
        )
        R, t = T_wc[..., :3, :3], T_wc[..., :3, 3]
        p_cam = torch.einsum("...ji,...nj->...ni", R, p - t.unsqueeze(-2))  # R^T (p - t)
        K = torch.as_tensor(self.K, dtype=torch.float64)
        z = p_cam[..., 2]
        uv1 = torch.einsum("ij,...nj->...ni", K, p_cam) / z.unsqueeze(-1)
        return uv1[..., :2], z


def camera_from_mujoco(
    model,
    data,
    cam_name: str,
    image_size: tuple[int, int],
    mounted_on_body: str | None = None,
    mounted_on_site: str | None = None,
    flipped: bool = False,
    name: str | None = None,
) -> CameraCalibration:
    """Calibration of a MuJoCo camera as rendered by ``mujoco.Renderer`` at ``image_size`` (H, W).

    Uses ``fy = 0.5 H / tan(fovy / 2)``, ``fx = fy`` (square pixels), principal point at the image
    centre ``((W-1)/2, (H-1)/2)``, ``R_world_cam = cam_xmat @ diag(1, -1, -1)`` (MuJoCo cameras look
    along -z with y up) and position ``cam_xpos`` of ``data`` (call ``mj_forward`` first).

    ``mounted_on_body`` / ``mounted_on_site``: the EE frame for a camera that moves with the robot.
    ``mode="fixed"`` cameras become ``T_ee_cam``; ``mode="track"`` cameras (constant world offset and
    orientation) become ``T_ee_cam`` with ``ee_follow_rotation=False`` (exact only when the camera's
    body is the EE body or moves rigidly with it). ``flipped``: the images are turned by 180 degrees
    (LeRobot's MetaWorld wrapper does ``np.flip(img, (0, 1))`` on corner2).
    """
    import mujoco

    H, W = (int(v) for v in image_size)
    cid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, cam_name)
    if cid < 0:
        names = [model.camera(i).name for i in range(model.ncam)]
        raise ValueError(f"MuJoCo model has no camera '{cam_name}'; cameras: {names}")
    if hasattr(model, "cam_sensorsize") and np.any(np.asarray(model.cam_sensorsize[cid]) > 0):
        raise ValueError(
            f"camera '{cam_name}' uses sensorsize/focal intrinsics: only fovy cameras are supported"
        )
    fovy = math.radians(float(model.cam_fovy[cid]))
    fy = 0.5 * H / math.tan(0.5 * fovy)
    K = np.array([[fy, 0.0, (W - 1) / 2.0], [0.0, fy, (H - 1) / 2.0], [0.0, 0.0, 1.0]])
    R_world_cam = np.asarray(data.cam_xmat[cid], dtype=np.float64).reshape(3, 3) @ np.diag([1.0, -1.0, -1.0])
    T_world_cam = make_pose(R_world_cam, np.asarray(data.cam_xpos[cid], dtype=np.float64))
    mode = int(model.cam_mode[cid])
    cam = None
    if mounted_on_body is not None or mounted_on_site is not None:
        if mounted_on_body is not None and mounted_on_site is not None:
            raise ValueError("pass at most one of mounted_on_body and mounted_on_site")
        if mounted_on_body is not None:
            bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, mounted_on_body)
            if bid < 0:
                raise ValueError(f"MuJoCo model has no body '{mounted_on_body}'")
            T_world_ee = mujoco_pose(data.xmat[bid], data.xpos[bid])
        else:
            sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, mounted_on_site)
            if sid < 0:
                raise ValueError(f"MuJoCo model has no site '{mounted_on_site}'")
            T_world_ee = mujoco_pose(data.site_xmat[sid], data.site_xpos[sid])
        if mode == int(mujoco.mjtCamLight.mjCAMLIGHT_FIXED):
            cam = CameraCalibration(
                name or cam_name, K, (H, W), T_ee_cam=invert_pose(T_world_ee) @ T_world_cam
            )
        elif mode == int(mujoco.mjtCamLight.mjCAMLIGHT_TRACK):
            T_off = T_world_cam.copy()
            T_off[:3, 3] -= T_world_ee[:3, 3]
            cam = CameraCalibration(name or cam_name, K, (H, W), T_ee_cam=T_off, ee_follow_rotation=False)
        else:
            raise NotImplementedError(
                f"camera '{cam_name}' has mode {mode} (trackcom/targetbody): only fixed and track are supported"
            )
    else:
        bid = int(model.cam_bodyid[cid])
        if bid != 0 and int(model.body_weldid[bid]) != 0:
            raise ValueError(
                f"camera '{cam_name}' is attached to moving body '{model.body(bid).name}': pass "
                "mounted_on_body=<EE body> to express it in the EE frame"
            )
        cam = CameraCalibration(name or cam_name, K, (H, W), T_world_cam=T_world_cam)
    return cam.rotated_180() if flipped else cam
