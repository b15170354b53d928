"""Embodiment description for Render and Diffuse: gripper meshes, camera calibrations, EE pose source.

Everything R&D needs to know about a robot to render "where the gripper would be":

- :class:`CameraCalibration`: OpenCV intrinsics ``K`` (pixel centres at integer coordinates, see
  docs/DESIGN.md), image size and extrinsics, either static (``T_world_cam``) or mounted on the end
  effector (``T_ee_cam``; with ``ee_follow_rotation=False`` for a camera that follows the EE position
  but keeps a fixed world orientation, like MuJoCo's ``mode="track"`` cameras).
- :class:`GripperMesh`: a triangle mesh in the EE frame with per-vertex colours, loadable from MJCF
  (MuJoCo kinematics), URDF (pytorch_kinematics) or mesh files, simplifiable, with the symmetry-breaking
  texture of the paper.
- :class:`EEPoseSource`: how to read the world-from-EE pose (and the gripper state) from
  ``observation.state``.
- :class:`Embodiment`: all of the above keyed by LeRobot camera feature keys, JSON round-trip and
  validation against a dataset's / policy's features.

The JSON layout is documented in docs/CALIBRATION.md.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

EMBODIMENT_FORMAT = "lerobot_rnd.embodiment"
EMBODIMENT_VERSION = 1

_RIGID_TOL = 1e-4


# --------------------------------------------------------------------------------------------------
# small numpy helpers (plain homogeneous-matrix algebra; the batched torch versions are in geometry.py)
# --------------------------------------------------------------------------------------------------
def _as_matrix(x: Any, shape: tuple[int, ...], what: str) -> np.ndarray:
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


def _check_rigid(T: np.ndarray, what: str) -> None:
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=1e-6):
        raise ValueError(
            f"{what} must be a rigid 4x4 transform with last row [0, 0, 0, 1], got {T[3].tolist()}"
        )
    R = T[:3, :3]
    err = np.abs(R.T @ R - np.eye(3)).max()
    if err > _RIGID_TOL:
        raise ValueError(
            f"{what} has a non-orthonormal rotation block (max |R^T R - I| = {err:.2e}); "
            "pass a rigid transform (no scale or shear)"
        )
    if np.linalg.det(R) < 0:
        raise ValueError(f"{what} has a reflection (det R < 0); pass a proper rotation")


def _inv_rigid(T: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    R = T[:3, :3]
    out[:3, :3] = R.T
    out[:3, 3] = -R.T @ T[:3, 3]
    return out


def _pose(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def _quat_wxyz_to_matrix_np(q: Sequence[float]) -> np.ndarray:
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _tolist(a: np.ndarray, decimals: int | None = None) -> list:
    if decimals is not None:
        a = np.round(a.astype(np.float64), decimals)
    return a.tolist()


# --------------------------------------------------------------------------------------------------
# Camera calibration
# --------------------------------------------------------------------------------------------------
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
        self.K = _as_matrix(self.K, (3, 3), f"camera '{self.name}': K")
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
                T = _as_matrix(val, (4, 4), f"camera '{self.name}': {attr}")
                _check_rigid(T, f"camera '{self.name}': {attr}")
                setattr(self, attr, T)
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
            "K": _tolist(self.K),
            "image_size": [int(self.image_size[0]), int(self.image_size[1])],
        }
        if self.T_world_cam is not None:
            d["T_world_cam"] = _tolist(self.T_world_cam)
        else:
            d["T_ee_cam"] = _tolist(self.T_ee_cam)
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
    T_world_cam = _pose(R_world_cam, np.asarray(data.cam_xpos[cid], dtype=np.float64))
    mode = int(model.cam_mode[cid])
    cam = None
    if mounted_on_body is not None or mounted_on_site is not None:
        if mounted_on_body is not None and mounted_on_site is not None:
            raise ValueError("pass at most one of mounted_on_body and mounted_on_site")
        if mounted_on_body is not None:
            bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, mounted_on_body)
            if bid < 0:
                raise ValueError(f"MuJoCo model has no body '{mounted_on_body}'")
            T_world_ee = _pose(np.asarray(data.xmat[bid]).reshape(3, 3), np.asarray(data.xpos[bid]))
        else:
            sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, mounted_on_site)
            if sid < 0:
                raise ValueError(f"MuJoCo model has no site '{mounted_on_site}'")
            T_world_ee = _pose(np.asarray(data.site_xmat[sid]).reshape(3, 3), np.asarray(data.site_xpos[sid]))
        if mode == int(mujoco.mjtCamLight.mjCAMLIGHT_FIXED):
            cam = CameraCalibration(
                name or cam_name, K, (H, W), T_ee_cam=_inv_rigid(T_world_ee) @ T_world_cam
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


# --------------------------------------------------------------------------------------------------
# Gripper mesh
# --------------------------------------------------------------------------------------------------
def _face_components(n_vertices: int, faces: np.ndarray) -> np.ndarray:
    """Connected-component label per face (faces sharing a vertex are connected)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if len(faces) == 0:
        return np.zeros(0, dtype=np.int64)
    rows = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2]])
    cols = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]])
    g = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_vertices, n_vertices))
    _, vlabel = connected_components(g, directed=False)
    return vlabel[faces[:, 0]]


def _cluster_simplify(v: np.ndarray, f: np.ndarray, c: np.ndarray, max_faces: int):
    """Vertex clustering on a grid, cell size found by bisection so that #faces <= max_faces."""

    def attempt(cell: float):
        keys = np.floor((v - v.min(0)) / cell).astype(np.int64)
        _, inv = np.unique(keys, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        n = inv.max() + 1
        cnt = np.bincount(inv, minlength=n).astype(np.float64)[:, None]
        nv = np.zeros((n, 3))
        np.add.at(nv, inv, v)
        nc = np.zeros((n, 3))
        np.add.at(nc, inv, c)
        nf = inv[f]
        keep = (nf[:, 0] != nf[:, 1]) & (nf[:, 1] != nf[:, 2]) & (nf[:, 0] != nf[:, 2])
        nf = nf[keep]
        if len(nf):
            _, first = np.unique(np.sort(nf, axis=1), axis=0, return_index=True)
            nf = nf[np.sort(first)]
        return nv / cnt, nf, nc / cnt

    diag = float(np.linalg.norm(v.max(0) - v.min(0))) or 1.0
    lo, hi = diag * 1e-4, diag
    best = attempt(hi)
    for _ in range(30):
        mid = math.sqrt(lo * hi)
        res = attempt(mid)
        if len(res[1]) <= max_faces:
            best, hi = res, mid
        else:
            lo = mid
        if hi / lo < 1.02:
            break
    nv, nf, nc = best
    used = np.unique(nf)
    remap = -np.ones(len(nv), dtype=np.int64)
    remap[used] = np.arange(len(used))
    return nv[used], remap[nf], nc[used]


def _quadric_simplify(v: np.ndarray, f: np.ndarray, c: np.ndarray, max_faces: int):
    import trimesh
    from scipy.spatial import cKDTree

    m = trimesh.Trimesh(v, f, process=False)
    s = m.simplify_quadric_decimation(face_count=int(max_faces))
    sv, sf = np.asarray(s.vertices), np.asarray(s.faces)
    _, idx = cKDTree(v).query(sv)
    return sv, sf, c[idx]


def _has_fast_simplification() -> bool:
    try:
        import fast_simplification  # noqa: F401
    except ImportError:
        return False
    return True


def _primitive_trimesh(gtype: str, size: np.ndarray):
    import trimesh

    if gtype == "box":
        return trimesh.creation.box(extents=2.0 * size[:3])
    if gtype == "sphere":
        return trimesh.creation.icosphere(subdivisions=2, radius=float(size[0]))
    if gtype == "ellipsoid":
        m = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        m.vertices = m.vertices * size[:3][None]
        return m
    if gtype == "cylinder":
        return trimesh.creation.cylinder(radius=float(size[0]), height=2.0 * float(size[1]), sections=24)
    if gtype == "capsule":
        return trimesh.creation.capsule(height=2.0 * float(size[1]), radius=float(size[0]), count=[12, 12])
    raise ValueError(f"unsupported primitive type {gtype}")


@dataclass
class GripperMesh:
    """Triangle mesh in the EE frame: vertices (V,3) float32 [m], faces (F,3) int64, colours (V,3) in [0,1]."""

    vertices: Any
    faces: Any
    vertex_colors: Any = None
    name: str = ""

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, dtype=np.float32)
        f = np.asarray(self.faces, dtype=np.int64)
        if v.ndim != 2 or v.shape[1] != 3:
            raise ValueError(f"mesh '{self.name}': vertices must have shape (V, 3), got {v.shape}")
        if f.size == 0:
            f = f.reshape(0, 3)
        if f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"mesh '{self.name}': faces must have shape (F, 3), got {f.shape}")
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(f"mesh '{self.name}': face indices out of range [0, {len(v)})")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"mesh '{self.name}': non-finite vertices")
        if self.vertex_colors is None:
            c = np.full((len(v), 3), 0.5, dtype=np.float32)
        else:
            c = np.asarray(self.vertex_colors, dtype=np.float32)
            if c.ndim == 1 and c.shape[0] in (3, 4):
                c = np.broadcast_to(c[:3], (len(v), 3)).copy()
            if c.ndim != 2 or c.shape[0] != len(v) or c.shape[1] not in (3, 4):
                raise ValueError(f"mesh '{self.name}': vertex_colors must have shape (V, 3), got {c.shape}")
            c = c[:, :3]
            if c.max(initial=0.0) > 1.0 + 1e-6:  # 0..255 colours
                c = c / 255.0
        self.vertices, self.faces, self.vertex_colors = v, f, np.clip(c, 0.0, 1.0).astype(np.float32)

    @property
    def num_vertices(self) -> int:
        return len(self.vertices)

    @property
    def num_faces(self) -> int:
        return len(self.faces)

    def bounds(self) -> np.ndarray:
        return np.stack([self.vertices.min(0), self.vertices.max(0)])

    # ------------------------------------------------------------------ combination
    @staticmethod
    def concatenate(meshes: Sequence[GripperMesh], name: str = "") -> GripperMesh:
        if not meshes:
            raise ValueError("no meshes to concatenate")
        vs, fs, cs, off = [], [], [], 0
        for m in meshes:
            vs.append(m.vertices)
            fs.append(m.faces + off)
            cs.append(m.vertex_colors)
            off += len(m.vertices)
        return GripperMesh(np.concatenate(vs), np.concatenate(fs), np.concatenate(cs), name)

    def transformed(self, T: Any) -> GripperMesh:
        """The mesh with its vertices mapped by the rigid (or any affine) 4x4 transform ``T``."""
        T = _as_matrix(T, (4, 4), "T")
        v = self.vertices.astype(np.float64) @ T[:3, :3].T + T[:3, 3]
        return GripperMesh(v, self.faces.copy(), self.vertex_colors.copy(), self.name)

    # ------------------------------------------------------------------ loaders
    @classmethod
    def from_trimesh(cls, mesh, color: Sequence[float] | None = None, name: str = "") -> GripperMesh:
        v = np.asarray(mesh.vertices)
        f = np.asarray(mesh.faces)
        if color is not None:
            c = np.broadcast_to(np.asarray(color, dtype=np.float64)[:3], (len(v), 3))
        else:
            c = None
            try:
                vc = np.asarray(mesh.visual.vertex_colors)
                if vc.shape[0] == len(v):
                    c = vc[:, :3] / 255.0
            except Exception:  # noqa: BLE001  (textured / no colour)
                c = None
        return cls(v, f, c, name)

    @classmethod
    def from_files(
        cls,
        paths: Sequence[str | os.PathLike],
        transforms: Sequence[Any] | None = None,
        colors: Sequence[Sequence[float]] | None = None,
        name: str = "",
    ) -> GripperMesh:
        """OBJ / STL / PLY files (one mesh each), each mapped by its 4x4 ``T_ee_file`` into the EE frame."""
        import trimesh

        paths = list(paths)
        if transforms is not None and len(transforms) != len(paths):
            raise ValueError(f"{len(transforms)} transforms for {len(paths)} mesh files")
        if colors is not None and len(colors) != len(paths):
            raise ValueError(f"{len(colors)} colours for {len(paths)} mesh files")
        parts = []
        for i, p in enumerate(paths):
            if not Path(p).exists():
                raise FileNotFoundError(f"mesh file not found: {p}")
            tm = trimesh.load(str(p), force="mesh", process=False)
            m = cls.from_trimesh(tm, None if colors is None else colors[i])
            if transforms is not None and transforms[i] is not None:
                m = m.transformed(transforms[i])
            parts.append(m)
        return cls.concatenate(parts, name)

    @classmethod
    def from_mjcf_body(
        cls,
        model,
        body_name: str,
        T_ee_body: Any | None = None,
        include_children: bool = True,
        geom_group: Sequence[int] | None = None,
        ee_body: str | None = None,
        ee_site: str | None = None,
        qpos: Mapping[str, float] | np.ndarray | None = None,
        exclude_bodies: Sequence[str] = (),
        name: str = "",
    ) -> GripperMesh:
        """Every visual geom of ``body_name`` (and its subtree) as one mesh in the EE frame.

        ``model``: ``mujoco.MjModel`` or an MJCF path. Mesh geoms and primitives (box, sphere,
        capsule, cylinder, ellipsoid) are collected with their world poses from ``mj_forward`` at
        ``qpos`` (default ``model.qpos0``; a dict sets named joints on top of qpos0, e.g. the gripper
        open). The EE frame is ``ee_site`` or ``ee_body`` (default: ``body_name``), or, when
        ``T_ee_body`` is given, the body frame mapped by that transform. ``geom_group``: groups to
        keep (default 0, 1, 2: those MuJoCo renders by default); fully transparent geoms are skipped.
        """
        import mujoco

        if isinstance(model, (str, os.PathLike)):
            model = mujoco.MjModel.from_xml_path(str(model))
        data = mujoco.MjData(model)
        if qpos is None:
            data.qpos[:] = model.qpos0
        elif isinstance(qpos, Mapping):
            data.qpos[:] = model.qpos0
            for jname, val in qpos.items():
                jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, jname)
                if jid < 0:
                    raise ValueError(f"MuJoCo model has no joint '{jname}'")
                data.qpos[model.jnt_qposadr[jid]] = val
        else:
            q = np.asarray(qpos, dtype=np.float64)
            if q.shape != (model.nq,):
                raise ValueError(f"qpos must have shape ({model.nq},), got {q.shape}")
            data.qpos[:] = q
        mujoco.mj_forward(model, data)

        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body_name)
        if bid < 0:
            names = [model.body(i).name for i in range(model.nbody)]
            raise ValueError(f"MuJoCo model has no body '{body_name}'; bodies: {names}")
        excluded = set()
        for b in exclude_bodies:
            eid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, b)
            if eid < 0:
                raise ValueError(f"MuJoCo model has no body '{b}'")
            excluded.add(eid)
        bodies = {bid}
        if include_children:
            changed = True
            while changed:
                changed = False
                for b in range(model.nbody):
                    if b not in bodies and int(model.body_parentid[b]) in bodies and b != 0:
                        bodies.add(b)
                        changed = True
        # drop excluded bodies and their subtrees
        if excluded:
            changed = True
            while changed:
                changed = False
                for b in bodies:
                    if int(model.body_parentid[b]) in excluded and b not in excluded:
                        excluded.add(b)
                        changed = True
            bodies -= excluded

        T_world_body = _pose(np.asarray(data.xmat[bid]).reshape(3, 3), np.asarray(data.xpos[bid]))
        if T_ee_body is not None:
            T_ee_world = _as_matrix(T_ee_body, (4, 4), "T_ee_body") @ _inv_rigid(T_world_body)
        elif ee_site is not None:
            sid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, ee_site)
            if sid < 0:
                raise ValueError(f"MuJoCo model has no site '{ee_site}'")
            T_ee_world = _inv_rigid(
                _pose(np.asarray(data.site_xmat[sid]).reshape(3, 3), np.asarray(data.site_xpos[sid]))
            )
        else:
            eb = body_name if ee_body is None else ee_body
            eid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, eb)
            if eid < 0:
                raise ValueError(f"MuJoCo model has no body '{eb}'")
            T_ee_world = _inv_rigid(
                _pose(np.asarray(data.xmat[eid]).reshape(3, 3), np.asarray(data.xpos[eid]))
            )

        groups = (0, 1, 2) if geom_group is None else tuple(int(g) for g in geom_group)
        type_names = {
            int(mujoco.mjtGeom.mjGEOM_BOX): "box",
            int(mujoco.mjtGeom.mjGEOM_SPHERE): "sphere",
            int(mujoco.mjtGeom.mjGEOM_CAPSULE): "capsule",
            int(mujoco.mjtGeom.mjGEOM_CYLINDER): "cylinder",
            int(mujoco.mjtGeom.mjGEOM_ELLIPSOID): "ellipsoid",
        }
        default_rgba = np.array([0.5, 0.5, 0.5, 1.0])
        parts = []
        for g in range(model.ngeom):
            if int(model.geom_bodyid[g]) not in bodies or int(model.geom_group[g]) not in groups:
                continue
            rgba = np.asarray(model.geom_rgba[g], dtype=np.float64)
            matid = int(model.geom_matid[g])
            if matid >= 0 and np.allclose(rgba, default_rgba):
                rgba = np.asarray(model.mat_rgba[matid], dtype=np.float64)
            if rgba[3] <= 0.0:
                continue
            gtype = int(model.geom_type[g])
            if gtype == int(mujoco.mjtGeom.mjGEOM_MESH):
                mid = int(model.geom_dataid[g])
                va, vn = int(model.mesh_vertadr[mid]), int(model.mesh_vertnum[mid])
                fa, fn = int(model.mesh_faceadr[mid]), int(model.mesh_facenum[mid])
                v = np.asarray(model.mesh_vert[va : va + vn], dtype=np.float64)
                f = np.asarray(model.mesh_face[fa : fa + fn], dtype=np.int64)
            elif gtype in type_names:
                tm = _primitive_trimesh(type_names[gtype], np.asarray(model.geom_size[g], dtype=np.float64))
                v, f = np.asarray(tm.vertices, dtype=np.float64), np.asarray(tm.faces, dtype=np.int64)
            else:  # planes, height fields, SDFs: not part of a gripper
                warnings.warn(f"geom {model.geom(g).name!r} of type {gtype} skipped", stacklevel=2)
                continue
            T_world_geom = _pose(np.asarray(data.geom_xmat[g]).reshape(3, 3), np.asarray(data.geom_xpos[g]))
            T = T_ee_world @ T_world_geom
            parts.append(GripperMesh(v @ T[:3, :3].T + T[:3, 3], f, np.broadcast_to(rgba[:3], (len(v), 3))))
        if not parts:
            raise ValueError(f"no visible geoms in body '{body_name}' (groups {groups})")
        return cls.concatenate(parts, name or body_name)

    @classmethod
    def from_urdf(
        cls,
        urdf_path: str | os.PathLike,
        link_names: Sequence[str],
        ee_link: str,
        joint_values: Mapping[str, float] | None = None,
        T_link_ee: Any | None = None,
        mesh_dirs: Sequence[str | os.PathLike] = (),
        name: str = "",
    ) -> GripperMesh:
        """Visual geometry of URDF links in the frame of ``ee_link`` (forward kinematics by pytorch_kinematics).

        ``joint_values``: named joint positions (others 0), e.g. the gripper open. ``T_link_ee``: pose
        of the EE frame in ``ee_link`` (default identity). Mesh filenames (``package://`` stripped) are
        looked up relative to the URDF folder and ``mesh_dirs``.
        """
        import pytorch_kinematics as pk
        import trimesh

        urdf_path = Path(urdf_path)
        xml = urdf_path.read_bytes()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            chain = pk.build_chain_from_urdf(xml).to(dtype=torch.float64)
        joint_names = chain.get_joint_parameter_names()
        q = torch.zeros(1, len(joint_names), dtype=torch.float64)
        for jn, val in (joint_values or {}).items():
            if jn not in joint_names:
                raise ValueError(f"URDF has no movable joint '{jn}'; joints: {joint_names}")
            q[0, joint_names.index(jn)] = float(val)
        fk = chain.forward_kinematics(q) if joint_names else chain.forward_kinematics(torch.zeros(1, 0))
        link_names_all = chain.get_link_names()
        for ln in list(link_names) + [ee_link]:
            if ln not in link_names_all:
                raise ValueError(f"URDF has no link '{ln}'; links: {link_names_all}")

        def world_of(link: str) -> np.ndarray:
            return fk[link].get_matrix()[0].detach().cpu().numpy().astype(np.float64)

        T_ee_link_world = _inv_rigid(world_of(ee_link))
        if T_link_ee is not None:
            T_ee_link_world = _inv_rigid(_as_matrix(T_link_ee, (4, 4), "T_link_ee")) @ T_ee_link_world
        search = [urdf_path.parent, *[Path(d) for d in mesh_dirs]]

        def resolve(fname: str) -> Path:
            fn = fname
            for prefix in ("package://", "file://"):
                fn = fn.removeprefix(prefix)
            cand = [Path(fn)] if Path(fn).is_absolute() else []
            parts = Path(fn).parts
            for base in search:
                for k in range(len(parts)):
                    cand.append(base.joinpath(*parts[k:]))
            for c in cand:
                if c.exists():
                    return c
            raise FileNotFoundError(f"URDF mesh '{fname}' not found under {[str(s) for s in search]}")

        meshes = []
        for ln in link_names:
            link = chain.find_link(ln)
            T_w_link = world_of(ln)
            for vis in link.visuals:
                if vis.geom_type is None:
                    continue
                T_link_vis = np.eye(4) if vis.offset is None else vis.offset.get_matrix()[0].cpu().numpy()
                if vis.geom_type == "mesh":
                    fname, scale = vis.geom_param
                    tm = trimesh.load(str(resolve(fname)), force="mesh", process=False)
                    if scale is not None:
                        tm.apply_scale(np.asarray(scale, dtype=np.float64))
                elif vis.geom_type == "box":
                    tm = trimesh.creation.box(extents=np.asarray(vis.geom_param, dtype=np.float64))
                elif vis.geom_type == "cylinder":
                    r, length = vis.geom_param
                    tm = trimesh.creation.cylinder(radius=float(r), height=float(length), sections=24)
                elif vis.geom_type == "sphere":
                    tm = trimesh.creation.icosphere(subdivisions=2, radius=float(vis.geom_param))
                elif vis.geom_type == "capsule":
                    r, length = vis.geom_param
                    tm = trimesh.creation.capsule(height=float(length), radius=float(r), count=[12, 12])
                else:
                    continue
                m = cls.from_trimesh(tm)
                meshes.append(m.transformed(T_ee_link_world @ T_w_link @ T_link_vis))
        if not meshes:
            raise ValueError(f"no visual geometry in URDF links {list(link_names)}")
        return cls.concatenate(meshes, name)

    # ------------------------------------------------------------------ processing
    def simplified(self, max_faces: int, method: str = "auto", keep_small_parts: int = 256) -> GripperMesh:
        """A copy with at most ``max_faces`` faces.

        Connected parts with at most ``keep_small_parts`` faces (boxes, fingers pads...) are kept
        exactly; the remaining budget is shared among the larger parts in proportion to their size.
        ``method``: "quadric" (trimesh + fast_simplification), "cluster" (grid vertex clustering, no
        extra dependency) or "auto" (quadric when fast_simplification is importable).
        """
        if self.num_faces <= max_faces:
            return GripperMesh(self.vertices.copy(), self.faces.copy(), self.vertex_colors.copy(), self.name)
        if method == "auto":
            method = "quadric" if _has_fast_simplification() else "cluster"
        if method not in ("quadric", "cluster"):
            raise ValueError(f"unknown simplification method {method!r}")
        comp = _face_components(self.num_vertices, self.faces)
        labels, counts = np.unique(comp, return_counts=True)
        small = counts <= keep_small_parts
        budget = max_faces - int(counts[small].sum())
        if budget < 4 * int((~small).sum()):
            raise ValueError(
                f"max_faces={max_faces} is too small: {int(counts[small].sum())} faces are in small parts"
            )
        big_total = int(counts[~small].sum())
        parts = []
        for lab, cnt, is_small in zip(labels, counts, small, strict=True):
            fsel = self.faces[comp == lab]
            used = np.unique(fsel)
            remap = np.zeros(self.num_vertices, dtype=np.int64)
            remap[used] = np.arange(len(used))
            v, f, c = self.vertices[used].astype(np.float64), remap[fsel], self.vertex_colors[used]
            if not is_small:
                target = max(4, int(budget * cnt / big_total))
                if cnt > target:
                    if method == "quadric":
                        v, f, c = _quadric_simplify(v, f, c, target)
                    else:
                        v, f, c = _cluster_simplify(v, f, c, target)
                    if len(f) > target:  # quadric decimation may overshoot slightly
                        v, f, c = _cluster_simplify(v, f, c, target)
            if len(f):
                parts.append(GripperMesh(v, f, c))
        return GripperMesh.concatenate(parts, self.name)

    def with_symmetry_texture(
        self,
        axis: int = 1,
        colors: Sequence[Sequence[float]] = ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    ) -> GripperMesh:
        """Symmetry-breaking texture: ``colors[0]`` where the EE-frame coordinate ``axis`` is >= 0,
        ``colors[1]`` where it is < 0.

        Faces straddling the plane are cut along it and the cut vertices duplicated, so the colour
        boundary is exactly the plane (no colour interpolation across it).
        """
        if axis not in (0, 1, 2):
            raise ValueError(f"axis must be 0, 1 or 2, got {axis}")
        if len(colors) != 2:
            raise ValueError("colors must be two RGB triples (side >= 0, side < 0)")
        sides = []
        for sign, col in ((1.0, colors[0]), (-1.0, colors[1])):
            v, f = _clip_halfspace(self.vertices.astype(np.float64), self.faces, axis, sign)
            if len(f):
                sides.append(GripperMesh(v, f, np.broadcast_to(np.asarray(col, np.float64)[:3], (len(v), 3))))
        return GripperMesh.concatenate(sides, self.name)

    def without_texture(self, color: Sequence[float] = (0.5, 0.5, 0.5)) -> GripperMesh:
        c = np.broadcast_to(np.asarray(color, dtype=np.float32)[:3], (self.num_vertices, 3)).copy()
        return GripperMesh(self.vertices.copy(), self.faces.copy(), c, self.name)

    # ------------------------------------------------------------------ serialisation
    def to_dict(self, decimals: int = 6) -> dict[str, Any]:
        return {
            "name": self.name,
            "vertices": _tolist(self.vertices, decimals),
            "faces": self.faces.tolist(),
            "vertex_colors": _tolist(self.vertex_colors, 4),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> GripperMesh:
        for req in ("vertices", "faces"):
            if req not in d:
                raise ValueError(f"mesh {d.get('name', '?')!r}: missing '{req}'")
        return cls(
            np.asarray(d["vertices"], dtype=np.float32).reshape(-1, 3),
            np.asarray(d["faces"], dtype=np.int64).reshape(-1, 3),
            None
            if d.get("vertex_colors") is None
            else np.asarray(d["vertex_colors"], np.float32).reshape(-1, 3),
            d.get("name", ""),
        )

    def to_trimesh(self):
        import trimesh

        colors = np.concatenate(
            [np.round(self.vertex_colors * 255), np.full((self.num_vertices, 1), 255)], axis=1
        ).astype(np.uint8)
        return trimesh.Trimesh(self.vertices, self.faces, vertex_colors=colors, process=False)


def _clip_halfspace(v: np.ndarray, f: np.ndarray, axis: int, sign: float) -> tuple[np.ndarray, np.ndarray]:
    """Part of the mesh where sign * v[:, axis] >= 0 (side +) or > 0 (side -), cut exactly at the plane."""
    d = sign * v[:, axis]
    inside = d >= 0.0 if sign > 0 else d > 0.0
    new_v: list[np.ndarray] = [v]
    edge_vertex: dict[tuple[int, int], int] = {}
    n = len(v)

    def cut(a: int, b: int) -> int:
        nonlocal n
        key = (a, b) if a < b else (b, a)
        idx = edge_vertex.get(key)
        if idx is None:
            ta = d[a] / (d[a] - d[b])
            p = v[a] + (v[b] - v[a]) * ta
            p[axis] = 0.0
            new_v.append(p[None])
            idx = edge_vertex[key] = n
            n += 1
        return idx

    ins = inside[f]
    cnt = ins.sum(1)
    out_faces = [f[cnt == 3]]
    extra = []
    for fi in np.nonzero((cnt == 1) | (cnt == 2))[0]:
        tri, flags = f[fi], ins[fi]
        if cnt[fi] == 1:
            k = int(np.argmax(flags))  # the inside vertex
            a, b, c = tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]
            extra.append((a, cut(a, b), cut(c, a)))
        else:
            k = int(np.argmin(flags))  # the outside vertex
            o, b, c = tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]
            x_ob, x_co = cut(o, b), cut(c, o)
            extra.append((x_ob, b, c))
            extra.append((x_ob, c, x_co))
    if extra:
        out_faces.append(np.asarray(extra, dtype=np.int64))
    faces = np.concatenate(out_faces).astype(np.int64)
    verts = np.concatenate(new_v)
    if len(faces):
        tri = verts[faces]
        area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        faces = faces[area2 > 1e-14]
    used = np.unique(faces)
    remap = -np.ones(len(verts), dtype=np.int64)
    remap[used] = np.arange(len(used))
    return verts[used], remap[faces].reshape(-1, 3)


# --------------------------------------------------------------------------------------------------
# EE pose source
# --------------------------------------------------------------------------------------------------
EE_POSE_FORMATS = ("none", "quat_wxyz", "quat_xyzw", "rotvec", "rot6d", "euler_xyz", "matrix", "joints")
_ROT_DIMS = {"none": 0, "quat_wxyz": 4, "quat_xyzw": 4, "rotvec": 3, "rot6d": 6, "euler_xyz": 3, "matrix": 9}


def _euler_xyz_to_matrix(e: torch.Tensor) -> torch.Tensor:
    """Extrinsic x-y-z Euler angles (scipy ``"xyz"``): R = Rz(e2) @ Ry(e1) @ Rx(e0)."""
    c, s = torch.cos(e), torch.sin(e)
    one, zero = torch.ones_like(e[..., 0]), torch.zeros_like(e[..., 0])

    def m(rows):
        return torch.stack([torch.stack(r, -1) for r in rows], -2)

    Rx = m([[one, zero, zero], [zero, c[..., 0], -s[..., 0]], [zero, s[..., 0], c[..., 0]]])
    Ry = m([[c[..., 1], zero, s[..., 1]], [zero, one, zero], [-s[..., 1], zero, c[..., 1]]])
    Rz = m([[c[..., 2], -s[..., 2], zero], [s[..., 2], c[..., 2], zero], [zero, zero, one]])
    return Rz @ Ry @ Rx


@dataclass
class EEPoseSource:
    """Where the world-from-EE pose and the gripper state live in ``observation.state``.

    ``format``:
      - "none": position from ``position_indices``, fixed orientation ``fixed_rotation``
        (3x3 R_world_ee or quaternion wxyz; identity by default);
      - "quat_wxyz" / "quat_xyzw" / "rotvec" / "rot6d" / "euler_xyz" (extrinsic xyz, scipy "xyz")
        / "matrix" (row-major 3x3): position from ``position_indices``, rotation from
        ``rotation_indices`` (4, 4, 3, 6, 3, 9 numbers);
      - "joints": joint positions ``joint_indices`` -> forward kinematics of ``urdf_path`` to
        ``ee_link`` (pytorch_kinematics), then ``T_world_base @ T_base_link @ T_link_ee``.
    ``gripper_index``: index of the gripper state; ``gripper_open_value`` / ``gripper_closed_value``:
    its values when fully open / closed.
    """

    format: str = "none"
    position_indices: list[int] | None = None
    rotation_indices: list[int] | None = None
    fixed_rotation: Any | None = None
    urdf_path: str | None = None
    ee_link: str | None = None
    joint_indices: list[int] | None = None
    T_world_base: Any | None = None
    T_link_ee: Any | None = None
    gripper_index: int | None = None
    gripper_open_value: float = 1.0
    gripper_closed_value: float = 0.0
    state_key: str = "observation.state"

    def __post_init__(self) -> None:
        if self.format not in EE_POSE_FORMATS:
            raise ValueError(f"ee_pose_source.format must be one of {EE_POSE_FORMATS}, got {self.format!r}")
        if self.position_indices is not None:
            self.position_indices = [int(i) for i in self.position_indices]
        if self.rotation_indices is not None:
            self.rotation_indices = [int(i) for i in self.rotation_indices]
        if self.joint_indices is not None:
            self.joint_indices = [int(i) for i in self.joint_indices]
        if self.format == "joints":
            if not self.urdf_path or not self.ee_link or not self.joint_indices:
                raise ValueError("ee_pose_source 'joints' needs urdf_path, ee_link and joint_indices")
        else:
            if self.position_indices is None or len(self.position_indices) != 3:
                raise ValueError(
                    f"ee_pose_source '{self.format}' needs 3 position_indices, got {self.position_indices}"
                )
            need = _ROT_DIMS[self.format]
            if need and (self.rotation_indices is None or len(self.rotation_indices) != need):
                raise ValueError(
                    f"ee_pose_source '{self.format}' needs {need} rotation_indices, got {self.rotation_indices}"
                )
        if self.fixed_rotation is not None:
            fr = np.asarray(self.fixed_rotation, dtype=np.float64)
            if fr.shape == (4,):
                fr = _quat_wxyz_to_matrix_np(fr)
            fr = _as_matrix(fr, (3, 3), "ee_pose_source.fixed_rotation")
            _check_rigid(_pose(fr, np.zeros(3)), "ee_pose_source.fixed_rotation")
            self.fixed_rotation = fr
        for attr in ("T_world_base", "T_link_ee"):
            val = getattr(self, attr)
            if val is not None:
                T = _as_matrix(val, (4, 4), f"ee_pose_source.{attr}")
                _check_rigid(T, f"ee_pose_source.{attr}")
                setattr(self, attr, T)
        if self.gripper_index is not None:
            self.gripper_index = int(self.gripper_index)
        self._chain = None

    def used_indices(self) -> list[int]:
        idx = (
            list(self.position_indices or [])
            + list(self.rotation_indices or [])
            + list(self.joint_indices or [])
        )
        if self.gripper_index is not None:
            idx.append(self.gripper_index)
        return idx

    def min_state_dim(self) -> int:
        idx = self.used_indices()
        return max(idx) + 1 if idx else 0

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"format": self.format, "state_key": self.state_key}
        for k in (
            "position_indices",
            "rotation_indices",
            "urdf_path",
            "ee_link",
            "joint_indices",
            "gripper_index",
        ):
            if getattr(self, k) is not None:
                d[k] = getattr(self, k)
        for k in ("fixed_rotation", "T_world_base", "T_link_ee"):
            if getattr(self, k) is not None:
                d[k] = _tolist(getattr(self, k))
        d["gripper_open_value"] = float(self.gripper_open_value)
        d["gripper_closed_value"] = float(self.gripper_closed_value)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> EEPoseSource:
        known = {
            "format", "position_indices", "rotation_indices", "fixed_rotation", "urdf_path", "ee_link",
            "joint_indices", "T_world_base", "T_link_ee", "gripper_index", "gripper_open_value",
            "gripper_closed_value", "state_key",
        }  # fmt: skip
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"ee_pose_source: unknown keys {sorted(unknown)}")
        return cls(**dict(d))

    # ------------------------------------------------------------------ evaluation
    def _rotation(self, state: torch.Tensor) -> torch.Tensor:
        from lerobot_rnd import geometry

        fmt = self.format
        if fmt == "none":
            R = (
                torch.eye(3, dtype=state.dtype, device=state.device)
                if self.fixed_rotation is None
                else (torch.as_tensor(self.fixed_rotation, dtype=state.dtype, device=state.device))
            )
            return R.expand(*state.shape[:-1], 3, 3)
        r = state[..., self.rotation_indices]
        if fmt == "quat_wxyz":
            return geometry.quat_wxyz_to_matrix(r / r.norm(dim=-1, keepdim=True))
        if fmt == "quat_xyzw":
            r = torch.cat([r[..., 3:4], r[..., 0:3]], dim=-1)
            return geometry.quat_wxyz_to_matrix(r / r.norm(dim=-1, keepdim=True))
        if fmt == "rotvec":
            return geometry.so3_exp(r)
        if fmt == "rot6d":
            return geometry.rotation_6d_to_matrix(r)
        if fmt == "euler_xyz":
            return _euler_xyz_to_matrix(r)
        if fmt == "matrix":
            return r.reshape(*r.shape[:-1], 3, 3)
        raise AssertionError(fmt)

    def ee_pose(self, state: torch.Tensor) -> torch.Tensor:
        """World-from-EE pose (..., 4, 4) from a state (..., D) (float tensor, any device)."""
        state = torch.as_tensor(state)
        if not state.is_floating_point():
            state = state.float()
        if state.shape[-1] < self.min_state_dim():
            raise ValueError(
                f"state has {state.shape[-1]} entries but the EE pose source reads index {self.min_state_dim() - 1}"
            )
        if self.format == "joints":
            return self._fk(state)
        R = self._rotation(state)
        T = torch.zeros(*state.shape[:-1], 4, 4, dtype=state.dtype, device=state.device)
        T[..., :3, :3] = R
        T[..., :3, 3] = state[..., self.position_indices]
        T[..., 3, 3] = 1.0
        return T

    def gripper(self, state: torch.Tensor) -> torch.Tensor | None:
        """Gripper closure in [0, 1] (0 open, 1 closed), or None without a gripper index."""
        if self.gripper_index is None:
            return None
        g = torch.as_tensor(state)[..., self.gripper_index]
        return ((g - self.gripper_open_value) / (self.gripper_closed_value - self.gripper_open_value)).clamp(
            0, 1
        )

    def _fk(self, state: torch.Tensor) -> torch.Tensor:
        import pytorch_kinematics as pk

        if self._chain is None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                self._chain = pk.build_serial_chain_from_urdf(Path(self.urdf_path).read_bytes(), self.ee_link)
        chain = self._chain.to(dtype=state.dtype, device=state.device)
        q = state[..., self.joint_indices]
        lead = q.shape[:-1]
        T = chain.forward_kinematics(q.reshape(-1, q.shape[-1])).get_matrix().reshape(*lead, 4, 4)
        if self.T_world_base is not None:
            T = torch.as_tensor(self.T_world_base, dtype=state.dtype, device=state.device) @ T
        if self.T_link_ee is not None:
            T = T @ torch.as_tensor(self.T_link_ee, dtype=state.dtype, device=state.device)
        return T


# --------------------------------------------------------------------------------------------------
# Embodiment
# --------------------------------------------------------------------------------------------------
def _image_hw(feature: Any) -> tuple[int, int] | None:
    """(H, W) of an image feature given as a PolicyFeature (C,H,W) or a dataset feature dict (H,W,C)."""
    ftype = getattr(feature, "type", None)
    if ftype is not None:  # PolicyFeature
        if getattr(ftype, "name", str(ftype)) != "VISUAL":
            return None
        shape = tuple(feature.shape)
    elif isinstance(feature, Mapping):
        if feature.get("dtype") not in ("image", "video"):
            return None
        shape = tuple(feature["shape"])
        names = feature.get("names")
        if names and len(names) == 3 and names[0] in ("channels", "channel", "c"):
            return int(shape[1]), int(shape[2])
        if shape[-1] in (1, 3, 4):
            return int(shape[0]), int(shape[1])
    else:
        return None
    if len(shape) != 3:
        return None
    if shape[0] in (1, 3, 4) and shape[-1] not in (1, 3, 4):
        return int(shape[1]), int(shape[2])
    if shape[-1] in (1, 3, 4) and shape[0] not in (1, 3, 4):
        return int(shape[0]), int(shape[1])
    return int(shape[1]), int(shape[2])  # ambiguous: LeRobot policy features are channel-first


def _state_dim(feature: Any) -> int | None:
    shape = getattr(feature, "shape", None)
    if shape is None and isinstance(feature, Mapping):
        shape = feature.get("shape")
    if shape is None or len(tuple(shape)) == 0:
        return None
    return int(tuple(shape)[-1])


@dataclass
class Embodiment:
    """Cameras (keyed by LeRobot image feature key), gripper meshes and the EE pose source."""

    cameras: dict[str, CameraCalibration]
    meshes: dict[str, GripperMesh]
    camera_mesh: dict[str, str] = field(default_factory=dict)
    ee_pose_source: EEPoseSource = field(default_factory=lambda: EEPoseSource(position_indices=[0, 1, 2]))
    action_adapter: dict[str, Any] | None = None
    symmetry_axis: int = 1
    name: str = ""
    notes: str = ""

    def __post_init__(self) -> None:
        if self.action_adapter is not None:
            if not isinstance(self.action_adapter, Mapping) or "type" not in self.action_adapter:
                raise ValueError(
                    "action_adapter must be a dict with a 'type' key (ee_position_delta, ee_delta, ee_absolute, "
                    f"joint_positions) and the adapter's arguments, got {self.action_adapter!r}"
                )
            self.action_adapter = dict(self.action_adapter)
        if self.symmetry_axis not in (0, 1, 2):
            raise ValueError(f"symmetry_axis must be 0, 1 or 2, got {self.symmetry_axis}")
        if not self.cameras:
            raise ValueError("an embodiment needs at least one camera")
        if not self.meshes:
            raise ValueError("an embodiment needs at least one gripper mesh")
        for k, c in self.cameras.items():
            if not isinstance(c, CameraCalibration):
                raise TypeError(f"cameras['{k}'] must be a CameraCalibration, got {type(c).__name__}")
        for k, m in self.meshes.items():
            if not isinstance(m, GripperMesh):
                raise TypeError(f"meshes['{k}'] must be a GripperMesh, got {type(m).__name__}")
        self.camera_mesh = dict(self.camera_mesh)
        default_mesh = "full" if "full" in self.meshes else next(iter(self.meshes))
        for k in self.cameras:
            self.camera_mesh.setdefault(k, default_mesh)
        for k, mname in self.camera_mesh.items():
            if k not in self.cameras:
                raise ValueError(
                    f"camera_mesh names camera '{k}', which has no calibration; cameras: {list(self.cameras)}"
                )
            if mname not in self.meshes:
                raise ValueError(f"camera_mesh['{k}'] = '{mname}' is not a mesh; meshes: {list(self.meshes)}")

    # ------------------------------------------------------------------ access helpers
    @property
    def camera_keys(self) -> list[str]:
        return list(self.cameras)

    @property
    def mesh_names(self) -> list[str]:
        return list(self.meshes)

    def mesh_index(self, camera_key: str) -> int:
        """Index of the camera's mesh in :attr:`mesh_names` (the order of :meth:`mesh_batch`)."""
        return self.mesh_names.index(self.camera_mesh[camera_key])

    def mesh_batch(self, device=None, textured: bool = False, colors=((1.0, 0.0, 0.0), (0.0, 0.0, 1.0))):
        """All meshes as one padded ``rendering.MeshBatch`` in :attr:`mesh_names` order."""
        from lerobot_rnd.rendering import MeshBatch

        ms = [self.meshes[n] for n in self.mesh_names]
        if textured:
            ms = [m.with_symmetry_texture(self.symmetry_axis, colors) for m in ms]
        return MeshBatch.from_meshes([(m.vertices, m.faces, m.vertex_colors) for m in ms], device=device)

    def with_image_size(self, height: int, width: int, keys: Sequence[str] | None = None) -> Embodiment:
        """A copy with the given cameras (default all) resized to (height, width)."""
        cams = {
            k: (c.resized(height, width) if keys is None or k in keys else c) for k, c in self.cameras.items()
        }
        return self._replace(cameras=cams)

    def _replace(self, **changes) -> Embodiment:
        kw = {
            "cameras": dict(self.cameras), "meshes": dict(self.meshes), "camera_mesh": dict(self.camera_mesh),
            "ee_pose_source": self.ee_pose_source, "action_adapter": self.action_adapter,
            "symmetry_axis": self.symmetry_axis, "name": self.name, "notes": self.notes,
        }  # fmt: skip
        kw.update(changes)
        return Embodiment(**kw)

    def subset(self, camera_keys: Sequence[str]) -> Embodiment:
        missing = [k for k in camera_keys if k not in self.cameras]
        if missing:
            raise ValueError(f"unknown camera keys {missing}; cameras: {list(self.cameras)}")
        return self._replace(
            cameras={k: self.cameras[k] for k in camera_keys},
            camera_mesh={k: self.camera_mesh[k] for k in camera_keys},
        )

    def textured(self, colors: Sequence[Sequence[float]] = ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0))) -> Embodiment:
        """A copy whose meshes carry the symmetry texture about :attr:`symmetry_axis`."""
        return self._replace(
            meshes={k: m.with_symmetry_texture(self.symmetry_axis, colors) for k, m in self.meshes.items()}
        )

    def ee_pose_dict(self) -> dict[str, Any]:
        """The EE pose source in the policy config's ``ee_pose`` layout (see embodiment_binding.py)."""
        src = self.ee_pose_source
        if src.format not in ("none", "quat_wxyz", "quat_xyzw", "rotvec", "rot6d"):
            raise ValueError(
                f"the policy reads EE poses as fixed/quat_wxyz/quat_xyzw/rotvec/rot6d; convert the dataset's "
                f"'{src.format}' state (e.g. forward kinematics) into one of these first"
            )
        return {
            "position_indices": list(src.position_indices),
            "rotation": "fixed" if src.format == "none" else src.format,
            "rotation_indices": list(src.rotation_indices or []),
            "fixed_rotation": _tolist(src.fixed_rotation if src.fixed_rotation is not None else np.eye(3)),
            "gripper_index": src.gripper_index,
            "gripper_open_value": float(src.gripper_open_value),
            "gripper_closed_value": float(src.gripper_closed_value),
            "state_key": src.state_key,
        }

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        return {
            "format": EMBODIMENT_FORMAT,
            "version": EMBODIMENT_VERSION,
            "name": self.name,
            "notes": self.notes,
            "cameras": {k: c.to_dict() for k, c in self.cameras.items()},
            "camera_mesh": dict(self.camera_mesh),
            "ee_pose_source": self.ee_pose_source.to_dict(),
            "action_adapter": self.action_adapter,
            "symmetry_axis": self.symmetry_axis,
            "meshes": {k: m.to_dict() for k, m in self.meshes.items()},
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Embodiment:
        fmt = d.get("format", EMBODIMENT_FORMAT)
        if fmt != EMBODIMENT_FORMAT:
            raise ValueError(
                f"not an embodiment description (format={fmt!r}, expected {EMBODIMENT_FORMAT!r})"
            )
        if int(d.get("version", EMBODIMENT_VERSION)) > EMBODIMENT_VERSION:
            raise ValueError(
                f"embodiment version {d.get('version')} is newer than supported ({EMBODIMENT_VERSION})"
            )
        for req in ("cameras", "meshes"):
            if req not in d:
                raise ValueError(f"embodiment description has no '{req}'")
        return cls(
            cameras={k: CameraCalibration.from_dict(c) for k, c in d["cameras"].items()},
            meshes={k: GripperMesh.from_dict(m) for k, m in d["meshes"].items()},
            camera_mesh=dict(d.get("camera_mesh", {})),
            ee_pose_source=EEPoseSource.from_dict(
                d.get("ee_pose_source", {"format": "none", "position_indices": [0, 1, 2]})
            ),
            action_adapter=d.get("action_adapter"),
            symmetry_axis=int(d.get("symmetry_axis", 1)),
            name=d.get("name", ""),
            notes=d.get("notes", ""),
        )

    def save_json(self, path: str | os.PathLike) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(), separators=(",", ":")))
        return path

    @classmethod
    def load_json(cls, path: str | os.PathLike) -> Embodiment:
        return cls.from_dict(json.loads(Path(path).read_text()))

    # ------------------------------------------------------------------ validation
    def validate_against(self, features: Mapping[str, Any], require_all_cameras: bool = True) -> None:
        """Check the embodiment fits a dataset's or policy's features; raise ValueError naming the fix.

        ``features``: ``{key: PolicyFeature}`` (policy input features, images channel-first) or a
        LeRobot dataset ``meta.features`` dict (images ``{"dtype": "image", "shape": (H, W, C)}``).
        """
        image_feats = {k: hw for k, f in features.items() if (hw := _image_hw(f)) is not None}
        for k in self.cameras:
            if k not in features:
                raise ValueError(
                    f"embodiment camera '{k}' is not a feature; image features are {sorted(image_feats)}. "
                    "Rename the calibration key to the dataset's image key (or map the key with --rename_map)."
                )
            if k not in image_feats:
                raise ValueError(f"embodiment camera '{k}' is a feature but not an image feature")
        if require_all_cameras:
            missing = [k for k in image_feats if k not in self.cameras]
            if missing:
                raise ValueError(
                    f"no camera calibration for image feature(s) {missing}; add a CameraCalibration for each "
                    "(e.g. camera_from_mujoco or a calibration JSON) or drop these cameras from the inputs"
                )
        for k, cam in self.cameras.items():
            if image_feats[k] != tuple(cam.image_size):
                H, W = image_feats[k]
                raise ValueError(
                    f"camera '{k}': calibration is for {cam.image_size[0]}x{cam.image_size[1]} images but the "
                    f"feature is {H}x{W}; use embodiment.with_image_size({H}, {W}) or "
                    f"CameraCalibration.resized({H}, {W}) (crops need a new calibration)"
                )
        skey = self.ee_pose_source.state_key
        need = self.ee_pose_source.min_state_dim()
        if need:
            if skey not in features:
                raise ValueError(f"the EE pose source reads '{skey}', which is not a feature")
            dim = _state_dim(features[skey])
            if dim is not None and dim < need:
                raise ValueError(
                    f"'{skey}' has {dim} entries but the EE pose source reads index {need - 1}; "
                    "fix ee_pose_source indices to the dataset's state layout"
                )


# --------------------------------------------------------------------------------------------------
# MetaWorld Sawyer preset
# --------------------------------------------------------------------------------------------------
#: MetaWorld Sawyer EE frame: body "hand" (its position is MetaWorld's ``obs[:3]``, i.e. LeRobot's
#: ``agent_pos[:3]``; fingers point along its +x axis, the fingers open along its y axis).
SAWYER_EE_BODY = "hand"
#: corner2 position used by LeRobot's MetaWorld env (closer than MetaWorld's own, arXiv:2206.14244).
LEROBOT_CORNER2_POS = (0.75, 0.075, 0.7)
#: Nominal hand orientation (MetaWorld's fixed mocap quaternion [1, 0, 1, 0] normalised, wxyz).
SAWYER_HAND_QUAT_WXYZ = (math.sqrt(0.5), 0.0, math.sqrt(0.5), 0.0)


def metaworld_xml_path(task: str = "reach-v3") -> str:
    """Path of a MetaWorld task's MJCF (all Sawyer tasks share the robot and cameras)."""
    import importlib.util

    spec = importlib.util.find_spec("metaworld")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("metaworld is not installed (pip install 'lerobot[metaworld]')")
    root = Path(next(iter(spec.submodule_search_locations))) / "assets" / "sawyer_xyz"
    name = "sawyer_" + task.replace("-", "_") + ".xml"
    path = root / name
    if not path.exists():
        path = root / "sawyer_reach_v3.xml"
    return str(path)


def sawyer_gripper_meshes(model=None, max_faces: int = 1500, texture: bool = False) -> dict[str, GripperMesh]:
    """MetaWorld Sawyer gripper meshes in the "hand" frame at the open gripper (qpos0).

    "full": body "right_hand" subtree (gripper base mesh, black flange cylinder, rail, finger pads);
    "fingers": the finger bodies "rightclaw" / "leftclaw" (their visible pads). Symmetry texture on
    the hand's y axis (the fingers' opening direction) with ``texture=True`` (the policy textures the
    meshes itself, so the stored meshes keep MuJoCo's colours).
    """
    import mujoco

    if model is None:
        model = mujoco.MjModel.from_xml_path(metaworld_xml_path())
    full = GripperMesh.from_mjcf_body(model, "right_hand", ee_body=SAWYER_EE_BODY, name="full")
    fingers = GripperMesh.concatenate(
        [
            GripperMesh.from_mjcf_body(model, "rightclaw", ee_body=SAWYER_EE_BODY),
            GripperMesh.from_mjcf_body(model, "leftclaw", ee_body=SAWYER_EE_BODY),
        ],
        name="fingers",
    )
    full = full.simplified(max_faces)
    fingers = fingers.simplified(max_faces)
    if texture:
        full, fingers = full.with_symmetry_texture(axis=1), fingers.with_symmetry_texture(axis=1)
    return {"full": full, "fingers": fingers}


def metaworld_ee_pose_source(state_layout: str = "pos_grip_quat") -> EEPoseSource:
    """EE pose source for the MetaWorld state vectors.

    "pos_grip_quat" (this package's ``gym_rnd_metaworld`` env, 8-D): [hand xyz, gripper opening,
    hand quat wxyz]; "pos_grip" (LeRobot's MetaWorld env, 4-D): [hand xyz, gripper opening] with the
    nominal fixed hand orientation. Gripper opening: finger distance / 0.1 m clipped to [0, 1]
    (1 = open; about 0.3 when closed on nothing).
    """
    if state_layout == "pos_grip_quat":
        return EEPoseSource(
            format="quat_wxyz", position_indices=[0, 1, 2], rotation_indices=[4, 5, 6, 7], gripper_index=3
        )
    if state_layout == "pos_grip":
        return EEPoseSource(
            format="none",
            position_indices=[0, 1, 2],
            fixed_rotation=list(SAWYER_HAND_QUAT_WXYZ),
            gripper_index=3,
        )
    raise ValueError(f"unknown MetaWorld state layout {state_layout!r} (pos_grip_quat | pos_grip)")


def sawyer_cameras_from_mujoco(
    model,
    data,
    camera_names: Sequence[str],
    image_size: tuple[int, int],
    flipped: bool | Sequence[str] = False,
    camera_keys: Mapping[str, str] | None = None,
) -> dict[str, CameraCalibration]:
    """Calibrations of MetaWorld cameras keyed by LeRobot feature key (``observation.images.<name>``).

    Cameras on the hand body ("behindGripper", "gripperPOV") are EE-mounted (mode "track": they follow
    the hand position with a fixed world orientation, ``ee_follow_rotation=False``, exact).
    """
    import mujoco

    flip_set = set(camera_names) if flipped is True else (set() if flipped is False else set(flipped))
    hand = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, SAWYER_EE_BODY)
    cams = {}
    for cname in camera_names:
        cid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, cname)
        if cid < 0:
            raise ValueError(f"unknown MetaWorld camera '{cname}'")
        bid = int(model.cam_bodyid[cid])
        moving = bid != 0 and int(model.body_weldid[bid]) != 0
        if moving and bid != hand:
            raise ValueError(f"camera '{cname}' moves with body '{model.body(bid).name}', not the hand")
        key = (camera_keys or {}).get(cname, f"observation.images.{cname}")
        cams[key] = camera_from_mujoco(
            model,
            data,
            cname,
            image_size,
            mounted_on_body=SAWYER_EE_BODY if moving else None,
            flipped=cname in flip_set,
            name=cname,
        )
    return cams


def metaworld_sawyer_embodiment(
    camera_names: Sequence[str] = ("corner2", "behindGripper"),
    image_size: tuple[int, int] = (128, 128),
    flipped: bool | Sequence[str] = False,
    corner2_pos: Sequence[float] | None = LEROBOT_CORNER2_POS,
    state_layout: str = "pos_grip_quat",
    camera_keys: Mapping[str, str] | None = None,
    max_faces: int = 1500,
    wrist_cameras: Sequence[str] = ("gripperPOV",),
) -> Embodiment:
    """Embodiment of MetaWorld's Sawyer as rendered by ``lerobot_rnd.sim`` (defaults) or LeRobot.

    - This package's env (``gym_rnd_metaworld/<task>``): the defaults (corner2 moved to LeRobot's
      position, no flips, 8-D state).
    - LeRobot's ``--env.type=metaworld`` (one 480x480 corner2 image turned by 180 degrees, key
      ``observation.image``, 4-D state): ``metaworld_sawyer_embodiment(("corner2",), (480, 480),
      flipped=True, state_layout="pos_grip", camera_keys={"corner2": "observation.image"})``.
    ``corner2_pos=None`` keeps MetaWorld's own corner2 position. Cameras in ``wrist_cameras`` render
    only the fingers mesh; the others the full gripper.
    """
    import mujoco

    model = mujoco.MjModel.from_xml_path(metaworld_xml_path())
    if corner2_pos is not None:
        model.cam_pos[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, "corner2")] = np.asarray(
            corner2_pos
        )
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    cams = sawyer_cameras_from_mujoco(model, data, camera_names, image_size, flipped, camera_keys)
    meshes = sawyer_gripper_meshes(model, max_faces=max_faces)
    camera_mesh = {k: ("fingers" if c.name in wrist_cameras else "full") for k, c in cams.items()}
    return Embodiment(
        cameras=cams,
        meshes=meshes,
        camera_mesh=camera_mesh,
        ee_pose_source=metaworld_ee_pose_source(state_layout),
        action_adapter=metaworld_action_adapter(),
        symmetry_axis=1,
        name="metaworld_sawyer",
        notes=(
            "MetaWorld Sawyer; EE frame = body 'hand' (fingers along +x, opening along y); "
            f"state layout {state_layout}; corner2_pos={None if corner2_pos is None else list(corner2_pos)}"
        ),
    )


def metaworld_action_adapter() -> dict[str, Any]:
    """Action adapter spec for MetaWorld's 4-D action (``lerobot_rnd.action_adapters``)."""
    return {"type": "ee_position_delta", "scale": 0.01, "clip": True, "clip_limit": 1.0}


def panda_robotiq_embodiment(
    camera_names: Sequence[str] = ("front", "wrist"),
    image_size: tuple[int, int] = (128, 128),
    max_faces: int | None = None,
) -> Embodiment:
    """Franka Panda + Robotiq 2F-85 of this package's ``gym_rnd_panda`` envs / ``lerobot-rnd-record
    --suite panda`` datasets (``lerobot_rnd.sim.panda_env``; needs gym-hil's assets).

    Cameras ``front`` (static) and ``wrist`` (rigid on the hand, fingers-only mesh) from MuJoCo; EE frame =
    site ``pinch``; state [ee xyz, quat wxyz, gripper opening (1 open, 0 closed)]; action adapter
    ``ee_delta`` (world frame, 0.02 m / 0.1 rad per unit, clipped to [-1, 1]). ``max_faces`` defaults to
    ``panda_env.GRIPPER_MESH_FACES``.
    """
    from lerobot_rnd.sim.panda_env import GRIPPER_MESH_FACES, panda_embodiment

    return panda_embodiment(
        tuple(camera_names), tuple(image_size), max_faces=GRIPPER_MESH_FACES if max_faces is None else max_faces
    )


#: Named embodiments for ``--policy.embodiment=<name>`` (``load_embodiment``).
EMBODIMENT_PRESETS: dict[str, Any] = {
    # this package's gym_rnd_metaworld env / lerobot-rnd-record datasets (default settings)
    "metaworld_sawyer": lambda: metaworld_sawyer_embodiment(),
    # LeRobot's own --env.type=metaworld (corner2 480x480 turned by 180 degrees, 4-D state)
    "metaworld_sawyer_lerobot": lambda: metaworld_sawyer_embodiment(
        ("corner2",),
        (480, 480),
        flipped=True,
        state_layout="pos_grip",
        camera_keys={"corner2": "observation.image"},
    ),
    # this package's gym_rnd_panda envs / lerobot-rnd-record --suite panda datasets (gym-hil's assets)
    "panda_robotiq": lambda: panda_robotiq_embodiment(),
}


def load_embodiment(source: str | os.PathLike | Mapping[str, Any] | Embodiment) -> Embodiment:
    """An embodiment from a preset name (:data:`EMBODIMENT_PRESETS`), a JSON path, a dataset root
    (reads ``meta/rnd_embodiment.json``), a dict or an :class:`Embodiment`."""
    if isinstance(source, Embodiment):
        return source
    if isinstance(source, Mapping):
        return Embodiment.from_dict(source)
    if isinstance(source, str) and source in EMBODIMENT_PRESETS:
        return EMBODIMENT_PRESETS[source]()
    path = Path(source)
    if path.is_dir():
        path = path / "meta" / "rnd_embodiment.json"
    if not path.is_file():
        raise FileNotFoundError(
            f"embodiment source {str(source)!r} is neither a preset ({', '.join(sorted(EMBODIMENT_PRESETS))}) "
            "nor an existing JSON file / dataset folder with meta/rnd_embodiment.json"
        )
    return Embodiment.load_json(path)
