"""Pure-PyTorch triangle rasteriser: meshes -> RGB, coverage mask, camera-frame point map.

Method (no compiled dependencies; the same code runs on CPU and CUDA):

* Per triangle, three linear functions lam_k(u, v) = A_k u + B_k v + C_k of the pixel
  position are set up such that the pixel ray hits the triangle in front of the camera
  iff all lam_k >= 0, 1/z = sum_k lam_k, and lam_k / sum(lam) are the perspective-correct
  barycentric coordinates. For triangles entirely in front of the near plane they are
  the screen-space edge functions divided by (2 * area * z_k) (float32, relative to the
  triangle so they stay accurate); triangles that cross the near plane use homogeneous
  (2DH, Olano & Greer) rasterisation, lam = (K [v0 v1 v2])^-1 [u, v, 1] in float64, plus a
  per-pixel test z >= near, so they need no geometric clipping.
* Enumeration is scanline-like with static shapes: each triangle owns an R x S block of
  candidate pixels, R rows of its (clipped, on-screen) bounding box and, per row, S
  pixels starting at the row's left edge crossing. S bounds the widest row of the
  triangle (2 * area / height), so long thin triangles cost about their length, not
  their bounding-box area. Triangles are binned into tiers by (rows, span) rounded up to
  powers of two.
* The z-buffer is one int64 key per pixel, (float bits of 1/z) << 32 | triangle slot,
  reduced with ``scatter_reduce(amax)``: the nearest surface wins (exact ties: larger
  slot). Pixels then re-evaluate the winning triangle's functions at their centre:
  points_cam = z * K^-1 [u, v, 1] is the exact ray/plane intersection (it projects back
  onto the pixel centre), rgb = barycentric interpolation of vertex colours.

Two ways to call it:

* ``render(...)`` / ``Rasterizer(...)(..., dynamic=True)``: tiers sized from the actual
  triangles (host syncs, data-dependent shapes); exact, never overflows. Fastest on CPU.
* ``Rasterizer(...)(...)`` (static, default): fixed tier list, each tier with a fixed
  number of triangle slots (capacity per render x N); compaction into the slots is a
  cumsum + scatter; no ``.item()``, ``nonzero`` or boolean indexing, so a call can be
  captured by CUDA graphs / ``torch.compile(fullgraph=True)``. Overflow: a triangle that
  finds no slot (its tier is full, or its box exceeds the largest tier) is NOT drawn in
  that call, and ``RenderOutput.overflow[n]`` is True for every render n that lost a
  triangle. ``Rasterizer.calibrate`` sizes the capacities from example poses.

Conventions (docs/DESIGN.md): OpenCV camera (x right, y down, z forward); pixel (row v,
column u) samples the image point (u, v) (pixel centres at integer coordinates), K is
[[fx, s, cx], [0, fy, cy], [0, 0, 1]].
Winding: a face (i0, i1, i2) is *front facing* when its right-hand normal
(p1 - p0) x (p2 - p0) points towards the camera, i.e. its vertices appear
counter-clockwise on a y-up screen, which in the y-down image is a negative signed area
(u1-u0)(v2-v0) - (u2-u0)(v1-v0) < 0. For meshes with outward normals (trimesh, OBJ,
STL convention: CCW seen from outside) the outside is front facing. Back-face culling
is OFF by default (MJCF meshes can have inconsistent winding); ``cull_backfaces=True``
skips faces seen from behind (about halves the work for closed meshes).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import torch
from torch import Tensor

__all__ = [
    "MeshBatch",
    "RenderOutput",
    "Rasterizer",
    "render",
    "project_points",
    "default_static_tiers",
]

_KEY_SHIFT = 1 << 32
_TID_MASK = (1 << 32) - 1
_INF = float("inf")
_SPAN_MARGIN = 0.05  # px: safety margin on the per-row span bound
_START_MARGIN = 0.01  # px: rows start this much left of the exact edge crossing
_TOL = 1e-4  # px: watertightness margin of the inside test

# rows of the per-triangle float table (14, P)
_F_LAM0 = slice(0, 3)  # lam_k at the box origin (u_lo, v_lo)
_F_A = slice(3, 6)  # d lam_k / du
_F_IZ0, _F_IA = 6, 7  # 1/z = sum_k lam_k at the origin, d/du
_F_B = slice(8, 11)  # d lam_k / dv
_F_IB = 11  # d(1/z)/dv
_F_U0, _F_V0 = 12, 13  # box origin (small integers stored exactly)
_NF = 14
# rows of the per-triangle int64 table (4, P)
_I_PIX, _I_W, _I_H, _I_S = 0, 1, 2, 3  # flat pixel of the box origin n*H*W + v_lo*W + u_lo, box w, h, span
_NI = 4


def _as_tensor(x, dtype, device=None) -> Tensor:
    if isinstance(x, Tensor):
        return x.detach().to(dtype=dtype, device=device)
    return torch.as_tensor(np.ascontiguousarray(x), dtype=dtype, device=device)


@dataclass
class MeshBatch:
    """M meshes padded to common sizes V and F.

    vertices (M,V,3) float32 in the mesh frame ``obj``; faces (M,F,3) int64 vertex ids
    (padding rows are 0 and masked by face_valid (M,F) bool); vertex_colors (M,V,3) float32
    in [0, 1].
    """

    vertices: Tensor
    faces: Tensor
    face_valid: Tensor
    vertex_colors: Tensor

    @classmethod
    def from_meshes(
        cls,
        meshes: Sequence[tuple],
        default_color: Sequence[float] = (0.7, 0.7, 0.7),
        device: torch.device | str | None = None,
    ) -> "MeshBatch":
        """Build from a list of (vertices (V,3), faces (F,3)[, colors]) numpy/torch arrays.

        colors: (V,3) per vertex, (3,) for the whole mesh, or None (``default_color``);
        uint8 colours are divided by 255.
        """
        verts, faces, cols = [], [], []
        for m in meshes:
            v = _as_tensor(m[0], torch.float32).reshape(-1, 3)
            f = _as_tensor(m[1], torch.int64).reshape(-1, 3)
            c = m[2] if len(m) > 2 else None
            if c is None:
                c = torch.tensor(default_color, dtype=torch.float32)
            is_u8 = (isinstance(c, np.ndarray) and c.dtype == np.uint8) or (
                isinstance(c, Tensor) and c.dtype == torch.uint8
            )
            c = _as_tensor(c, torch.float32)
            if is_u8:
                c = c / 255.0
            c = c[:3].expand(v.shape[0], 3) if c.dim() == 1 else c[:, :3]
            if f.numel() and (int(f.min()) < 0 or int(f.max()) >= v.shape[0]):
                raise ValueError("face index out of range")
            verts.append(v)
            faces.append(f)
            cols.append(c.contiguous())
        M = len(verts)
        V = max(1, max(v.shape[0] for v in verts))
        F = max(1, max(f.shape[0] for f in faces))
        vb = torch.zeros(M, V, 3)
        fb = torch.zeros(M, F, 3, dtype=torch.int64)
        valid = torch.zeros(M, F, dtype=torch.bool)
        cb = torch.zeros(M, V, 3)
        for i, (v, f, c) in enumerate(zip(verts, faces, cols)):
            vb[i, : v.shape[0]] = v
            fb[i, : f.shape[0]] = f
            valid[i, : f.shape[0]] = True
            cb[i, : v.shape[0]] = c
        return cls(vb, fb, valid, cb).to(device)

    def to(self, device=None) -> "MeshBatch":
        return MeshBatch(
            self.vertices.to(device=device, dtype=torch.float32),
            self.faces.to(device=device, dtype=torch.int64),
            self.face_valid.to(device=device, dtype=torch.bool),
            self.vertex_colors.to(device=device, dtype=torch.float32),
        )

    @property
    def num_meshes(self) -> int:
        return self.vertices.shape[0]

    @property
    def num_faces(self) -> int:
        return self.faces.shape[1]

    @property
    def device(self) -> torch.device:
        return self.vertices.device


@dataclass
class RenderOutput:
    """rgb (N,3,H,W) float in [0,1] (0 off-mask); mask (N,H,W) bool; points_cam (N,3,H,W)
    camera-frame xyz of the visible surface (0 off-mask); overflow (N,) bool: True where
    the static path had to drop triangles (always False for ``render``)."""

    rgb: Tensor
    mask: Tensor
    points_cam: Tensor
    overflow: Tensor = field(default=None)

    @property
    def depth(self) -> Tensor:
        """(N,H,W) z of the visible surface, 0 off-mask."""
        return self.points_cam[:, 2]


def project_points(K: Tensor, p: Tensor) -> Tensor:
    """Pinhole projection: K (...,3,3), p (...,N,3) camera frame -> (...,N,2) pixel (u, v)."""
    q = p @ K.to(p.dtype).transpose(-1, -2)
    return q[..., :2] / q[..., 2:3]


def _pow2_levels(m: int) -> list[int]:
    out, s = [], 1
    while s < m:
        out.append(s)
        s *= 2
    out.append(m)
    return out


def default_static_tiers(image_size: tuple[int, int]) -> list[tuple[int, int]]:
    """(rows, span) windows for the static path: 1x1, 2x2, 4x4, thin 2xP / 4xP / Px2 / Px4
    and square PxP for powers of two P >= 8 (the last being H x W)."""
    R = _pow2_levels(image_size[0])
    S = _pow2_levels(image_size[1])
    out = [(1, 1), (2, 2), (4, 4)]
    out += [(r, t) for r in R if r > 4 for t in (2, 4)]
    out += [(t, s) for s in S if s > 4 for t in (2, 4)]
    out += list(zip([r for r in R if r > 4], [s for s in S if s > 4]))
    out.append((R[-1], S[-1]))
    return sorted(set(out), key=lambda rs: (rs[0] * rs[1], rs[0]))


def _inv_intrinsics(K: Tensor) -> Tensor:
    """Closed-form inverse of upper-triangular K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]."""
    fx, s, cx = K[..., 0, 0], K[..., 0, 1], K[..., 0, 2]
    fy, cy = K[..., 1, 1], K[..., 1, 2]
    z = torch.zeros_like(fx)
    o = torch.ones_like(fx)
    r0 = torch.stack([1 / fx, -s / (fx * fy), (s * cy - cx * fy) / (fx * fy)], -1)
    r1 = torch.stack([z, 1 / fy, -cy / fy], -1)
    r2 = torch.stack([z, z, o], -1)
    return torch.stack([r0, r1, r2], -2)


class Rasterizer:
    """Rasteriser bound to a mesh batch, an image size and a device.

    Args:
        meshes: the MeshBatch (moved to ``device``).
        image_size: (H, W).
        tiers: static path only: list of (rows R, span S) windows; a triangle goes to the
            cheapest tier with R >= its rows and S >= its widest row (both rounded up to a
            power of two, or to H / W). Default ``default_static_tiers``.
        capacity: static path only: triangle slots per render for each tier; a call with N
            renders has ceil(capacity * N) slots shared by all renders. Default: F for
            windows of <= 16 pixels, else min(F, max(8, 4 F / (R S))). ``calibrate`` sets
            them from example poses.
        near: near plane (m): surface points with z < near are not drawn.
        cull_backfaces: skip faces seen from behind (see the module docstring).
        shading: multiply colours by a two-sided Lambert term with a headlight
            (``ambient`` + (1 - ambient) |cos|); off by default.
        chunk_candidates: candidate pixels evaluated per step (bounds temporary memory).
    """

    @torch.inference_mode(False)  # its constant tables stay normal tensors, usable in every mode
    def __init__(
        self,
        meshes: MeshBatch,
        image_size: tuple[int, int],
        device: torch.device | str | None = None,
        tiers: Sequence[tuple[int, int]] | None = None,
        capacity: Sequence[float] | None = None,
        near: float = 1e-3,
        cull_backfaces: bool = False,
        shading: bool = False,
        ambient: float = 0.35,
        chunk_candidates: int | None = None,
    ):
        device = torch.device(device) if device is not None else meshes.device
        self.device = device
        self.meshes = meshes.to(device)
        self.H, self.W = int(image_size[0]), int(image_size[1])
        self.near = float(near)
        self.cull_backfaces = bool(cull_backfaces)
        self.shading = bool(shading)
        self.ambient = float(ambient)
        self.levels_r = _pow2_levels(self.H)
        self.levels_s = _pow2_levels(self.W)
        F = self.meshes.num_faces
        tiers = [tuple(int(x) for x in t) for t in (tiers or default_static_tiers((self.H, self.W)))]
        self.tiers = tiers
        if capacity is None:
            capacity = [float(F) if r * s <= 16 else min(float(F), max(8.0, 4.0 * F / (r * s))) for r, s in tiers]
        if len(capacity) != len(tiers):
            raise ValueError("one capacity per tier")
        self.capacity = [float(c) for c in capacity]
        if chunk_candidates is None:
            chunk_candidates = (1 << 24) if device.type == "cuda" else (1 << 17)
        self.chunk_candidates = int(chunk_candidates)
        # constants, created once so that calls never copy from the host
        m = self.meshes
        self._face_colors = (
            torch.gather(m.vertex_colors, 1, m.faces.reshape(m.num_meshes, F * 3, 1).expand(-1, -1, 3))
            .reshape(m.num_meshes * F, 9)
            .t()
            .contiguous()
        )  # (9, M*F): vertex k colour c at row 3k + c
        self._lev_r = torch.tensor(self.levels_r, dtype=torch.int64, device=device)
        self._lev_s = torch.tensor(self.levels_s, dtype=torch.int64, device=device)
        nr, ns = len(self.levels_r), len(self.levels_s)
        order = sorted(range(len(tiers)), key=lambda k: (tiers[k][0] * tiers[k][1], k))
        lut = []  # grid cell (rows level, span level) -> cheapest fitting static tier, -1 = none
        for lr in self.levels_r:
            for ls in self.levels_s:
                fit = [k for k in order if tiers[k][0] >= lr and tiers[k][1] >= ls]
                lut.append(fit[0] if fit else -1)
        self._lut = torch.tensor(lut, dtype=torch.int64, device=device)
        self._nr, self._ns = nr, ns
        self._ar: dict[int, Tensor] = {}
        self._arf: dict[int, Tensor] = {}
        for x in set(self.levels_r) | set(self.levels_s) | {x for t in tiers for x in t}:
            self._ar[x] = torch.arange(x, device=device)
            self._arf[x] = torch.arange(x, device=device, dtype=torch.float32)
        # Work buffers and index tables reused between calls, one set per inference mode: a tensor created under
        # torch.inference_mode() is an inference tensor, which may not be updated in place outside it (LeRobot's
        # rollout samples under inference mode; training between rollouts renders the same sizes outside it).
        # Code traced by torch.compile (which cannot ask for the mode) keeps a set of its own.
        self._caches: dict[str, dict] = {"inference": {}, "normal": {}, "compiled": {}}

    @property
    def _cache(self) -> dict:
        """The reusable buffers of the current mode: inference mode, normal, or traced by torch.compile."""
        if torch.compiler.is_compiling():
            return self._caches["compiled"]
        return self._caches["inference" if torch.is_inference_mode_enabled() else "normal"]

    # ------------------------------------------------------------------ setup
    def _prep(self, mesh_index: Tensor, T_cam_obj: Tensor, K: Tensor):
        dev = self.device
        mesh_index = mesh_index.to(device=dev, dtype=torch.int64).reshape(-1)
        N = mesh_index.shape[0]
        T_cam_obj = T_cam_obj.to(device=dev, dtype=torch.float32).reshape(N, 4, 4)
        K = K.to(device=dev, dtype=torch.float32)
        if K.dim() == 2:
            K = K.expand(N, 3, 3)
        return mesh_index, T_cam_obj, K

    def _per_vertex(self, mesh_index: Tensor, T: Tensor, K: Tensor):
        """Camera-frame vertices vc (N,V,3) and flat (N*V,) pixel u, v and depth z."""
        m = self.meshes
        N = mesh_index.shape[0]
        verts = m.vertices.expand(N, -1, -1) if m.num_meshes == 1 else m.vertices[mesh_index]
        vc = torch.baddbmm(T[:, None, :3, 3], verts, T[:, :3, :3].transpose(1, 2))  # (N,V,3)
        x, y, z = vc.unbind(-1)
        iz = 1.0 / torch.where(z.abs() > 1e-30, z, torch.full_like(z, 1e-30))
        Kb = K[:, None]
        u = (Kb[..., 0, 0] * x + Kb[..., 0, 1] * y) * iz + Kb[..., 0, 2]
        v = Kb[..., 1, 1] * y * iz + Kb[..., 1, 2]
        return vc, u.reshape(-1), v.reshape(-1), z.reshape(-1)

    def _face_vertex_ids(self, mesh_index: Tensor):
        """(3, N*F) flat vertex ids (into N*V arrays) of every (render, face), (N*F,) valid."""
        m = self.meshes
        N = mesh_index.shape[0]
        V, F = m.vertices.shape[1], m.num_faces
        if m.num_meshes == 1:
            key = ("gid", N)
            if key not in self._cache:
                off = (torch.arange(N, device=self.device) * V)[None, :, None]
                gid = (m.faces[0].t()[:, None, :] + off).reshape(3, N * F)
                self._cache[key] = (gid, m.face_valid[0].repeat(N))
            return self._cache[key]
        faces = m.faces[mesh_index] + (torch.arange(N, device=self.device) * V)[:, None, None]
        return faces.permute(2, 0, 1).reshape(3, N * F), m.face_valid[mesh_index].reshape(-1)

    def _workspace(self, name: str, shape: tuple, dtype: torch.dtype) -> Tensor:
        """A contiguous tensor of ``shape`` carved from a grow-only buffer reused between
        calls (fresh large CPU allocations are page-faulted on every call, which can cost
        more than the arithmetic). Valid until the next call that asks for ``name``."""
        numel = math.prod(shape)
        buf = self._cache.get(("ws", name))
        if buf is None or buf.numel() < numel or buf.dtype != dtype:
            buf = torch.empty(max(numel, int(numel * 1.25)), dtype=dtype, device=self.device)
            self._cache[("ws", name)] = buf
        return buf[:numel].view(shape)

    def _box(self, umin, vmin, umax, vmax):
        """Pixel-centre range (float) of continuous boxes, clamped to the image.
        Returns u_lo, v_lo, w, h; w or h <= 0 (or NaN) means no pixel centre."""
        H, W = self.H, self.W
        # The extent is measured from the box start clamped at 0 only, so that a box entirely right of
        # (below) the image gets w (h) <= 0; the start is clamped into the image afterwards for indexing.
        u_lo = torch.ceil(umin - 1e-3).clamp_(min=0)
        v_lo = torch.ceil(vmin - 1e-3).clamp_(min=0)
        w = torch.floor(umax + 1e-3).clamp_(-1, W - 1).sub_(u_lo).add_(1)
        h = torch.floor(vmax + 1e-3).clamp_(-1, H - 1).sub_(v_lo).add_(1)
        return u_lo.clamp_(max=W - 1), v_lo.clamp_(max=H - 1), w, h

    def _prepass(self, u: Tensor, v: Tensor, z: Tensor, fvalid: Tensor):
        """Per-triangle box and flags from (3, P) per-vertex pixel u, v and depth z.
        ok: entirely in front of the near plane, not degenerate, covers >= 1 pixel-centre
        row and column of the image. front: front facing (signed area < 0)."""
        u0, u1, u2 = u.unbind(0)
        v0, v1, v2 = v.unbind(0)
        z0, z1, z2 = z.unbind(0)
        umin = torch.minimum(torch.minimum(u0, u1), u2)
        umax = torch.maximum(torch.maximum(u0, u1), u2)
        vmin = torch.minimum(torch.minimum(v0, v1), v2)
        vmax = torch.maximum(torch.maximum(v0, v1), v2)
        zmin = torch.minimum(torch.minimum(z0, z1), z2)
        zmax = torch.maximum(torch.maximum(z0, z1), z2)
        u_lo, v_lo, w, h = self._box(umin, vmin, umax, vmax)
        area2 = (u1 - u0) * (v2 - v0) - (u2 - u0) * (v1 - v0)
        in_front = zmin >= self.near
        ok = (torch.minimum(w, h) > 0) & in_front & fvalid & (area2.abs() > 1e-6)
        return dict(u_lo=u_lo, v_lo=v_lo, w=w, h=h, dv=vmax - vmin, ok=ok, front=area2 < 0, in_front=in_front, zmax=zmax)

    def _int_table(self, n: Tensor, u_lo, v_lo, w, h, s, out: Tensor | None = None) -> Tensor:
        """(4, P) int64 rows: n*H*W + v_lo*W + u_lo, w, h, span (the last three >= 1)."""
        P = u_lo.shape[0]
        tmp = torch.stack([v_lo * self.W + u_lo, w, h, s], 0)  # exact in float32 (< 2^24)
        tmp[1:].clamp_(min=1)
        tmp = torch.nan_to_num_(tmp, nan=1.0)
        tabi = torch.empty(_NI, P, dtype=torch.int64, device=self.device) if out is None else out
        tabi.copy_(tmp)
        tabi[0].add_(n * (self.H * self.W))
        return tabi

    def _screen_tables(self, u, v, z, u_lo, v_lo, w, h, dv, n, out_f=None, out_i=None):
        """Plane functions of triangles entirely in front of the near plane: screen-space
        edge functions relative to the box origin divided by (2 area z_k), float32.
        u, v, z (3, P); box (P,) each; n (P,) render index. Returns tabf (14,P), tabi (4,P)."""
        x = u - u_lo
        y = v - v_lo
        x0, x1, x2 = x.unbind(0)
        y0, y1, y2 = y.unbind(0)
        e = torch.stack([x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0], 0)  # edge fns at origin
        area2 = e[0] + e[1] + e[2]
        sig = (1.0 / area2) / z  # (3,P)
        # A triangle that is degenerate in float32 relative to its box origin is never drawn (lam0 < 0).
        degenerate = (area2 == 0) | ~torch.isfinite(sig).all(0)
        sig = torch.where(degenerate[None], torch.zeros_like(sig), sig)
        lam0 = torch.where(degenerate[None], torch.full_like(e, -1.0), e * sig)
        A = (v.roll(-1, 0) - v.roll(-2, 0)) * sig
        B = (u.roll(-2, 0) - u.roll(-1, 0)) * sig
        # widest row = 2 area / height; pixel centres in it <= floor(width) + 1
        span = torch.floor(area2.abs() / dv.clamp_min(1e-12) + _SPAN_MARGIN).clamp_(max=1e8).add_(1)
        span = torch.minimum(span, w)
        tot = lambda x: (x[0] + x[1] + x[2])[None]  # noqa: E731
        rows = [lam0, A, tot(lam0), tot(A), B, tot(B), u_lo[None], v_lo[None]]
        tabf = torch.cat(rows, 0, out=out_f) if out_f is not None else torch.cat(rows, 0)
        tabi = self._int_table(n, u_lo, v_lo, w, h, span, out=out_i)
        return tabf, tabi

    def _setup_2dh(self, vc: Tensor, K: Tensor, n: Tensor):
        """Homogeneous setup (float64) for triangles that may cross the near plane.
        vc (P,3 vertices,3) camera frame, K (P,3,3), n (P,) render index. Returns tabf
        (14,P), tabi (4,P) (span = box width), ok, front."""
        vc = vc.double()
        K = K.double()
        near = self.near
        P = vc @ K.transpose(-1, -2)  # (P,3,3) homogeneous pixel coordinates [u z, v z, z]
        P0, P1, P2 = P.unbind(-2)
        c0 = torch.linalg.cross(P1, P2, dim=-1)
        c1 = torch.linalg.cross(P2, P0, dim=-1)
        c2 = torch.linalg.cross(P0, P1, dim=-1)
        det = (P0 * c0).sum(-1)  # = fx fy (normal . v0); < 0 <=> front facing
        scale = P0.norm(dim=-1) * P1.norm(dim=-1) * P2.norm(dim=-1)
        z = vc[..., 2]
        inside = z >= near
        ok = (det.abs() > 1e-12 * scale) & torch.isfinite(det) & inside.any(-1)
        front = det < 0
        # box of the triangle clipped at z = near: kept vertices + edge/plane crossings
        zs = torch.where(inside, z, torch.ones_like(z))
        pts = [P[..., :2] / zs[..., None]]
        msk = [inside]
        for a, b in ((0, 1), (1, 2), (2, 0)):
            za, zb = z[..., a], z[..., b]
            crs = (za - near) * (zb - near) < 0
            den = torch.where(crs, zb - za, torch.ones_like(za))
            t = ((near - za) / den)[..., None]
            q = P[..., a, :] + t * (P[..., b, :] - P[..., a, :])
            pts.append((q[..., :2] / near)[..., None, :])
            msk.append(crs[..., None])
        pts = torch.cat(pts, -2)
        msk = torch.cat(msk, -1)[..., None]
        big = 1e9
        lo = torch.where(msk, pts, torch.full_like(pts, big)).amin(-2).float()
        hi = torch.where(msk, pts, torch.full_like(pts, -big)).amax(-2).float()
        u_lo, v_lo, w, h = self._box(lo[..., 0], lo[..., 1], hi[..., 0], hi[..., 1])
        ok = ok & (w > 0) & (h > 0)
        det_s = torch.where(ok, det, torch.ones_like(det))
        Lam = torch.stack([c0, c1, c2], -2) / det_s[..., None, None]  # lam_k = Lam[k] . [u, v, 1]
        org = torch.stack([u_lo, v_lo, torch.ones_like(u_lo)], -1).double()
        lam0 = (Lam * org[..., None, :]).sum(-1)  # (P,3)
        A, B = Lam[..., 0], Lam[..., 1]
        cols = [lam0, A, lam0.sum(-1, keepdim=True), A.sum(-1, keepdim=True), B, B.sum(-1, keepdim=True)]
        tabf = torch.cat(cols, -1).float().t()
        tabf = torch.cat([tabf, u_lo[None], v_lo[None]], 0)
        tabf = torch.where(ok[None], tabf, torch.zeros_like(tabf))
        tabi = self._int_table(n, u_lo, v_lo, w, h, w)
        return tabf, tabi, ok, front

    def _grid_cell(self, tabi: Tensor) -> Tensor:
        ri = torch.bucketize(tabi[_I_H], self._lev_r)
        si = torch.bucketize(tabi[_I_S], self._lev_s)
        return ri.clamp_(max=self._nr - 1) * self._ns + si.clamp_(max=self._ns - 1)

    # ------------------------------------------------------------------ raster
    def _raster(self, zbuf, tabf, tabi, tid, slot_ok, R: int, S: int, near_test: bool):
        """Rasterise table columns ``tid`` (C,) with R x S candidate blocks into zbuf.
        Layout: the triangle axis is innermost, (R, S, c), so that the elementwise ops run
        vectorised over triangles whatever R and S are."""
        C = tid.shape[0]
        if C == 0:
            return
        W = self.W
        izmax = 1.0 / self.near
        arR, arS = self._ar[R][:, None], self._ar[S][:, None]  # (R,1), (S,1)
        jf, if_ = self._arf[R][:, None], self._arf[S][:, None]
        step = max(1, self.chunk_candidates // (R * S))
        if R == 1 and S == 1:
            for c0 in range(0, C, step):
                so = None if slot_ok is None else slot_ok[c0 : c0 + step]
                self._raster_1x1(zbuf, tabf, tabi, tid[c0 : c0 + step], so, near_test)
            return
        for c0 in range(0, C, step):
            t = tid[c0 : c0 + step]
            rf = tabf.index_select(1, t)  # (14,c)
            ri = tabi.index_select(1, t)  # (4,c)
            A = rf[_F_A, None, :]  # (3,1,c)
            Bv = rf[_F_B, None, :]
            wv, hv, sv = ri[_I_W], ri[_I_H], ri[_I_S]  # (c,)
            # per row j: first pixel right of the crossings of the edges whose lam grows with u
            lrow = rf[_F_LAM0, None, :] + Bv * jf  # (3,R,c): lam at (u_lo, v_lo + j)
            pos = A > 1e-20
            lbk = torch.where(pos, lrow / torch.where(pos, -A, torch.ones_like(A)), -_INF)
            lb = torch.maximum(torch.maximum(lbk[0], lbk[1]), lbk[2])  # (R,c)
            start = torch.ceil(lb - _START_MARGIN).clamp_(min=0)
            start = torch.minimum(start, (wv - sv).to(torch.float32))  # offset from u_lo
            tol = (A.abs() + Bv.abs()) * _TOL  # ~1e-4 px margin: watertight shared edges
            rho = lrow + A * start + tol  # (3,R,c) lam at the row start
            rbad = arR >= hv  # (R,c)
            if slot_ok is not None:
                rbad = rbad | ~slot_ok[c0 : c0 + step]
            rho[0] = torch.where(rbad, -_INF, rho[0])
            colA = A * if_  # (3,S,c)
            colA[0] = torch.where(arS >= sv, -_INF, colA[0])
            izr = rf[_F_IZ0] + rf[_F_IB] * jf + rf[_F_IA] * start  # (R,c)
            izc = rf[_F_IA] * if_  # (S,c)
            rowpix = ri[_I_PIX] + torch.minimum(arR, hv - 1) * W + start.to(torch.int64)  # (R,c)
            colpix = torch.minimum(arS, sv - 1)  # (S,c)
            # candidates (R, S, c)
            l0 = rho[0, :, None] + colA[0, None]
            l1 = rho[1, :, None] + colA[1, None]
            torch.minimum(l0, l1, out=l0)
            torch.add(rho[2, :, None], colA[2, None], out=l1)
            torch.minimum(l0, l1, out=l0)
            iz = izr[:, None] + izc[None]
            if near_test:
                torch.neg(iz, out=l1).add_(izmax)
                torch.minimum(l0, l1, out=l0)
            iz = torch.where(l0 >= 0, iz, 0.0)
            key = torch.add(t, iz.view(torch.int32).to(torch.int64), alpha=_KEY_SHIFT)
            pix = rowpix[:, None] + colpix[None]
            zbuf.scatter_reduce_(0, pix.view(-1), key.view(-1), reduce="amax", include_self=True)

    def _raster_1x1(self, zbuf, tabf, tabi, t, slot_ok, near_test: bool):
        """Triangles with one row and at most one pixel centre per row."""
        rf = tabf[:11].index_select(1, t)  # lam0 (3), A (3), iz0, iA, B (3)
        ri = tabi[:2].index_select(1, t)  # pixbase, w
        lam0, A = rf[0:3], rf[3:6]
        tol = (A.abs() + rf[8:11].abs()) * _TOL
        pos = A > 1e-20
        lbk = torch.where(pos, lam0 / torch.where(pos, -A, torch.ones_like(A)), -_INF)
        lb = torch.maximum(torch.maximum(lbk[0], lbk[1]), lbk[2])
        start = torch.minimum(torch.ceil(lb - _START_MARGIN).clamp_(min=0), (ri[1] - 1).to(torch.float32))
        rho = lam0 + A * start + tol
        m = torch.minimum(torch.minimum(rho[0], rho[1]), rho[2])
        iz = rf[6] + rf[7] * start
        if near_test:
            m = torch.minimum(m, 1.0 / self.near - iz)
        ok = m >= 0
        if slot_ok is not None:
            ok = ok & slot_ok
        iz = torch.where(ok, iz, 0.0)
        key = torch.add(t, iz.view(torch.int32).to(torch.int64), alpha=_KEY_SHIFT)
        pix = ri[0] + start.to(torch.int64)
        zbuf.scatter_reduce_(0, pix, key, reduce="amax", include_self=True)

    # ------------------------------------------------------------------ resolve
    def _resolve(self, col_id, u, v, kin, tabf, cidx, gidx, vc, gid):
        """Colours and camera-frame points of the winning triangles at pixel centres.

        col_id: table column per pixel (any shape); u, v: float pixel coordinates and
        kin: (Kinv00, Kinv01, Kinv02, Kinv11, Kinv12), all broadcastable to col_id's
        shape; cidx: per column, row of the face colour table; gidx: per column, global
        render * F + face id (only used with shading). Returns two lists of 3 tensors."""
        shape = col_id.shape
        flat = col_id.reshape(-1)
        rf = tabf.index_select(1, flat).view(_NF, *shape)
        du = u - rf[_F_U0]
        dv = v - rf[_F_V0]
        lam = [(rf[k] + rf[3 + k] * du + rf[8 + k] * dv).clamp_(min=0) for k in range(3)]
        inv = 1.0 / (lam[0] + lam[1] + lam[2]).clamp_(min=1e-30)
        zz = 1.0 / (rf[_F_IZ0] + rf[_F_IA] * du + rf[_F_IB] * dv).clamp_(min=1e-30)
        xr = kin[0] * u + kin[1] * v + kin[2]
        yr = kin[3] * v + kin[4]
        pts = [xr * zz, yr * zz, zz.expand_as(du)]
        fc = self._face_colors.index_select(1, cidx.index_select(0, flat)).view(9, *shape)
        b = [lam[k] * inv for k in range(3)]
        col = [b[0] * fc[c] + b[1] * fc[3 + c] + b[2] * fc[6 + c] for c in range(3)]
        if self.shading:
            vcf = vc.reshape(-1, 3)
            g = gid.index_select(1, flat if gidx is None else gidx.index_select(0, flat))  # (3,P)
            p0, p1, p2 = (vcf.index_select(0, g[k]) for k in range(3))
            nrm = torch.linalg.cross(p1 - p0, p2 - p0, dim=-1).t().reshape(3, *shape)
            ray = [xr.expand_as(du), yr.expand_as(du), torch.ones_like(du)]
            dot = (nrm[0] * ray[0] + nrm[1] * ray[1] + nrm[2] * ray[2]).abs()
            den = (nrm.square().sum(0) * (ray[0].square() + ray[1].square() + 1)).sqrt().clamp_(min=1e-30)
            shade = self.ambient + (1 - self.ambient) * dot / den
            col = [c * shade for c in col]
        col = [c.clamp_(0, 1) for c in col]
        return col, pts

    # ------------------------------------------------------------------ call
    def __call__(
        self,
        mesh_index: Tensor,
        T_cam_obj: Tensor,
        K: Tensor,
        dynamic: bool = False,
        out: RenderOutput | None = None,
    ) -> RenderOutput:
        """Render N views: mesh_index (N,) long, T_cam_obj (N,4,4) mesh -> camera,
        K (N,3,3) or (3,3).

        dynamic=False: static shapes, no host sync, may set ``overflow``.
        dynamic=True: exact tier sizes (host syncs), never overflows.
        out: optional RenderOutput with preallocated tensors of the right shapes to write
        into (saves allocating and page-faulting the outputs on every call).
        """
        mesh_index, T_cam_obj, K = self._prep(mesh_index, T_cam_obj, K)
        N = mesh_index.shape[0]
        with torch.no_grad():
            if dynamic:
                zbuf, tabf, cidx, gidx, vc, gid = self._raster_dynamic(mesh_index, T_cam_obj, K)
                overflow = torch.zeros(N, dtype=torch.bool, device=self.device)
            else:
                zbuf, tabf, cidx, vc, gid, overflow = self._raster_static(mesh_index, T_cam_obj, K)
                gidx = None
            return self._outputs(zbuf, tabf, cidx, gidx, K, vc, gid, N, dynamic, overflow, out)

    def _zbuf(self, N: int) -> Tensor:
        key = ("zbuf", N)
        if key not in self._cache:
            self._cache[key] = torch.empty(N * self.H * self.W, dtype=torch.int64, device=self.device)
        return self._cache[key].zero_()

    def _vertex_data(self, mesh_index, T_cam_obj, K):
        vc, U, Vv, Z = self._per_vertex(mesh_index, T_cam_obj, K)
        gid, fvalid = self._face_vertex_ids(mesh_index)
        flat = gid.reshape(-1)
        u, v, z = (x.index_select(0, flat).view(3, -1) for x in (U, Vv, Z))
        return vc, gid, fvalid, u, v, z

    def _raster_dynamic(self, mesh_index, T_cam_obj, K):
        N = mesh_index.shape[0]
        F = self.meshes.num_faces
        vc, gid, fvalid, u, v, z = self._vertex_data(mesh_index, T_cam_obj, K)
        pre = self._prepass(u, v, z, fvalid)
        ok = pre["ok"] & pre["front"] if self.cull_backfaces else pre["ok"]
        n_ids, f_ids = torch.nonzero(ok.view(N, F)).unbind(1)  # triangles entirely in front of the near plane
        ids = n_ids * F + f_ids
        crossing = torch.nonzero(fvalid & ~pre["in_front"] & (pre["zmax"] >= self.near)).squeeze(1)
        P, Pc = ids.shape[0], crossing.shape[0]
        tabf = self._workspace("tabf", (_NF, P + Pc), torch.float32)
        tabi = self._workspace("tabi", (_NI, P + Pc), torch.int64)
        g = lambda x: x.index_select(-1, ids)  # noqa: E731
        args = (g(u), g(v), g(z), g(pre["u_lo"]), g(pre["v_lo"]), g(pre["w"]), g(pre["h"]), g(pre["dv"]), n_ids)
        if Pc == 0:
            self._screen_tables(*args, out_f=tabf, out_i=tabi)
        else:
            tabf[:, :P], tabi[:, :P] = self._screen_tables(*args)
        gidx = ids
        cidx = f_ids if self.meshes.num_meshes == 1 else mesh_index.index_select(0, n_ids) * F + f_ids
        passes = [(0, P, False)]
        if Pc:
            tri = vc.reshape(-1, 3).index_select(0, gid.index_select(1, crossing).t().reshape(-1)).view(-1, 3, 3)
            nc = crossing // F
            tf, ti, okc, frc = self._setup_2dh(tri, K.index_select(0, nc), nc)
            if self.cull_backfaces:
                okc = okc & frc
            keep = torch.nonzero(okc).squeeze(1)
            Pk = keep.shape[0]
            tabf[:, P : P + Pk] = tf.index_select(1, keep)
            tabi[:, P : P + Pk] = ti.index_select(1, keep)
            gidx = torch.cat([ids, crossing.index_select(0, keep)])
            cidx = torch.cat([cidx, self._colour_rows(mesh_index, crossing.index_select(0, keep))])
            passes.append((P, Pk, True))
        zbuf = self._zbuf(N)
        for start, count, near_test in passes:
            if count == 0:
                continue
            cell = self._grid_cell(tabi[:, start : start + count])
            small = torch.uint8 if self._nr * self._ns <= 256 else torch.int16  # sorts faster
            cell, order = torch.sort(cell.to(small), stable=True)
            cell = cell.to(torch.int64)
            counts = torch.bincount(cell, minlength=self._nr * self._ns).tolist()
            cols = order + start
            pos = 0
            for gc, cnt in enumerate(counts):
                if cnt:
                    R, S = self.levels_r[gc // self._ns], self.levels_s[gc % self._ns]
                    self._raster(zbuf, tabf, tabi, cols[pos : pos + cnt], None, R, S, near_test)
                    pos += cnt
        return zbuf, tabf, cidx, gidx, vc, gid

    def _colour_rows(self, mesh_index: Tensor, gidx: Tensor) -> Tensor:
        """Row of the face colour table (mesh * F + face) for global ids render * F + face."""
        F = self.meshes.num_faces
        n = gidx // F
        f = gidx - n * F
        return f if self.meshes.num_meshes == 1 else mesh_index.index_select(0, n) * F + f

    def _static_tables(self, mesh_index, T_cam_obj, K):
        """Tables for every (render, face): screen-space setup where the triangle is in
        front of the near plane, homogeneous otherwise; ok (N*F,)."""
        N = mesh_index.shape[0]
        F = self.meshes.num_faces
        NF = N * F
        vc, gid, fvalid, u, v, z = self._vertex_data(mesh_index, T_cam_obj, K)
        n_of = self._cache.get(("n_of", N))
        if n_of is None:
            n_of = self._cache.setdefault(("n_of", N), torch.arange(N, device=self.device).repeat_interleave(F))
        pre = self._prepass(u, v, z, fvalid)
        tabf, tabi = self._screen_tables(u, v, z, pre["u_lo"], pre["v_lo"], pre["w"], pre["h"], pre["dv"], n_of)
        tri = vc.reshape(-1, 3).index_select(0, gid.t().reshape(-1)).view(NF, 3, 3)
        tf, ti, okh, frh = self._setup_2dh(tri, K.index_select(0, n_of), n_of)
        in_front = pre["in_front"]
        tabi = torch.where(in_front[None], tabi, ti)
        ok = torch.where(in_front, pre["ok"], okh & fvalid)
        if self.cull_backfaces:
            ok = ok & torch.where(in_front, pre["front"], frh)
        tabf = torch.where(ok[None], torch.where(in_front[None], tabf, tf), torch.zeros_like(tf))
        return tabf, tabi, ok, in_front, vc, gid

    def _raster_static(self, mesh_index, T_cam_obj, K):
        dev = self.device
        N = mesh_index.shape[0]
        F = self.meshes.num_faces
        NF = N * F
        tabf, tabi, ok, in_front, vc, gid = self._static_tables(mesh_index, T_cam_obj, K)
        tier = self._lut.index_select(0, self._grid_cell(tabi))  # -1: no tier is large enough
        dropped = ok & (tier < 0)
        all_ids = torch.arange(NF, device=dev)
        zbuf = self._zbuf(N)
        for k, (R, S) in enumerate(self.tiers):
            C = int(math.ceil(self.capacity[k] * N))
            mk = ok & (tier == k)
            if C <= 0:
                dropped = dropped | mk
                continue
            pos = torch.cumsum(mk, 0) - 1
            fits = mk & (pos < C)
            dropped = dropped | (mk & ~fits)
            slot = torch.where(fits, pos, C)
            buf = torch.zeros(C + 1, dtype=torch.int64, device=dev)
            buf.scatter_(0, slot, all_ids)
            slot_ok = torch.arange(C, device=dev) < (pos[-1:] + 1)
            self._raster(zbuf, tabf, tabi, buf[:C], slot_ok, R, S, True)
        key = ("cidx", N)
        if self.meshes.num_meshes > 1:
            cidx = (mesh_index[:, None] * F + torch.arange(F, device=dev)).reshape(-1)
        else:
            if key not in self._cache:
                self._cache[key] = torch.arange(F, device=dev).repeat(N)
            cidx = self._cache[key]
        return zbuf, tabf, cidx, vc, gid, dropped.view(N, F).any(1)

    def _outputs(self, zbuf, tabf, cidx, gidx, K, vc, gid, N, dynamic, overflow, out):
        H, W = self.H, self.W
        dev = self.device
        mask = (zbuf >= _KEY_SHIFT).view(N, H, W)
        Kinv = _inv_intrinsics(K.double()).float()
        kin = [Kinv[:, 0, 0], Kinv[:, 0, 1], Kinv[:, 0, 2], Kinv[:, 1, 1], Kinv[:, 1, 2]]  # (N,) each
        if out is None:
            out = RenderOutput(
                rgb=torch.empty(N, 3, H, W, device=dev),
                mask=torch.empty(N, H, W, dtype=torch.bool, device=dev),
                points_cam=torch.empty(N, 3, H, W, device=dev),
            )
        out.mask.copy_(mask)
        out.overflow = overflow
        if dynamic:  # only the covered pixels
            n, vq, uq = torch.nonzero(mask).unbind(1)
            base = (n * 3 * H + vq) * W + uq  # channel 0 of (N,3,H,W)
            col_id = zbuf.index_select(0, base - n * (2 * H * W)) & _TID_MASK
            u, v = uq.to(torch.float32), vq.to(torch.float32)
            col, pts = self._resolve(col_id, u, v, [k.index_select(0, n) for k in kin], tabf, cidx, gidx, vc, gid)
            idx = torch.cat([base, base + H * W, base + 2 * H * W])
            out.rgb.zero_().view(-1).index_copy_(0, idx, torch.cat(col))
            out.points_cam.zero_().view(-1).index_copy_(0, idx, torch.cat(pts))
        else:  # every pixel, static shapes
            col_id = (zbuf & _TID_MASK).view(N, H, W)
            u = self._arf[W] if W in self._arf else torch.arange(W, device=dev, dtype=torch.float32)
            v = (self._arf[H] if H in self._arf else torch.arange(H, device=dev, dtype=torch.float32))[:, None]
            col, pts = self._resolve(col_id, u, v, [k.view(N, 1, 1) for k in kin], tabf, cidx, gidx, vc, gid)
            mf = mask.to(torch.float32)
            torch.mul(torch.stack(col, 1), mf[:, None], out=out.rgb)
            torch.mul(torch.stack(pts, 1), mf[:, None], out=out.points_cam)
        return out

    # ------------------------------------------------------------------ helpers
    @torch.no_grad()
    def tier_counts(self, mesh_index: Tensor, T_cam_obj: Tensor, K: Tensor) -> Tensor:
        """(N, num_tiers) number of triangles each static tier receives (host sync)."""
        mesh_index, T_cam_obj, K = self._prep(mesh_index, T_cam_obj, K)
        N = mesh_index.shape[0]
        _, tabi, ok, _, _, _ = self._static_tables(mesh_index, T_cam_obj, K)
        tier = self._lut.index_select(0, self._grid_cell(tabi))
        tier = torch.where(ok, tier, torch.full_like(tier, -2)).view(N, -1)
        return torch.stack([(tier == k).sum(1) for k in range(len(self.tiers))], 1)

    @torch.no_grad()
    def calibrate(self, mesh_index: Tensor, T_cam_obj: Tensor, K: Tensor, margin: float = 1.5, minimum: float = 1.0) -> list[float]:
        """Set the static capacities from example poses (representative of a call: the
        slots are shared by the renders of a call, so what counts is the mean number of
        triangles per render in each tier): margin x that mean, at least ``minimum``
        (per render). Returns the capacities."""
        counts = self.tier_counts(mesh_index, T_cam_obj, K).to(torch.float64)
        mean = (counts.sum(0) / max(1, counts.shape[0])).tolist()
        self.capacity = [max(float(minimum), c * margin) for c in mean]
        return self.capacity

    def candidates_per_render(self) -> float:
        """Static path: candidate pixels evaluated per render (its fixed cost)."""
        return sum(c * r * s for c, (r, s) in zip(self.capacity, self.tiers))


def render(
    meshes: MeshBatch,
    mesh_index: Tensor,
    T_cam_obj: Tensor,
    K: Tensor,
    image_size: tuple[int, int],
    near: float = 1e-3,
    cull_backfaces: bool = False,
    shading: bool = False,
) -> RenderOutput:
    """Render N views: mesh_index (N,) long into ``meshes``, T_cam_obj (N,4,4) mesh frame ->
    OpenCV camera frame, K (N,3,3) or (3,3), image_size (H, W).

    Exact (tiers sized from the actual triangles, host syncs; never overflows).
    Returns RenderOutput(rgb (N,3,H,W), mask (N,H,W), points_cam (N,3,H,W), overflow (N,)).
    For repeated calls build a ``Rasterizer`` once and call it with ``dynamic=True``.
    """
    r = Rasterizer(meshes, image_size, device=T_cam_obj.device, near=near, cull_backfaces=cull_backfaces, shading=shading)
    return r(mesh_index, T_cam_obj, K, dynamic=True)
