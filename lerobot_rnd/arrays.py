"""NumPy float64 helpers of the embodiment description (calibrations, meshes, EE pose sources).

Single 4x4 transforms as plain arrays, validated when read from user input or JSON; the batched torch
versions of the transform algebra are in :mod:`lerobot_rnd.geometry`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from lerobot_rnd.geometry import check_rigid

#: tolerance of the rigidity check of calibration transforms (last row, R^T R - I)
RIGID_ATOL = 1e-4


def as_matrix(x: Any, shape: tuple[int, ...], what: str) -> np.ndarray:
    """``x`` (nested lists, array or tensor) as a finite float64 array of ``shape`` (ValueError naming
    ``what`` otherwise)."""
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{what} must be a numeric array of shape {shape}, got {x!r}") from e
    if a.shape != shape:
        raise ValueError(f"{what} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{what} contains non-finite values: {a.tolist()}")
    return a


def as_rigid_transform(x: Any, what: str) -> np.ndarray:
    """``x`` as a checked rigid 4x4 float64 transform (see :func:`lerobot_rnd.geometry.check_rigid`)."""
    T = as_matrix(x, (4, 4), what)
    check_rigid(T, what, RIGID_ATOL)
    return T


def make_pose(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """R (3, 3), t (3,) -> T (4, 4) = [[R, t], [0, 1]]."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def invert_pose(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform (4, 4): T_b_a from T_a_b (uses R^T)."""
    out = np.eye(4)
    R = T[:3, :3]
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out


def tolist(a: np.ndarray, decimals: int | None = None) -> list:
    """Nested lists for JSON, optionally rounded to ``decimals``."""
    if decimals is not None:
        a = np.round(a.astype(np.float64), decimals)
    return a.tolist()


def mujoco_pose(xmat: Any, xpos: Any) -> np.ndarray:
    """World pose (4, 4) of a MuJoCo body / site / geom / camera from its ``xmat`` (9,) and ``xpos`` (3,)."""
    return make_pose(np.asarray(xmat, dtype=np.float64).reshape(3, 3), np.asarray(xpos, dtype=np.float64))


def look_at(eye: Any, target: Any, up: Any = (0.0, 0.0, 1.0), roll: float = 0.0) -> np.ndarray:
    """``T_world_cam`` (4, 4) of an OpenCV camera (x right, y down, z forward) at ``eye`` looking at ``target``,
    image-up near ``up``, turned by ``roll`` radians about its optical axis."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = np.cos(roll), np.sin(roll)
    x, y = c * x + s * y, -s * x + c * y
    return make_pose(np.stack([x, y, z], axis=1), eye)
