"""Pure-PyTorch triangle rasteriser: meshes -> RGB, coverage mask, camera-frame point map.

Method (no compiled dependencies, CPU and CUDA):

* Homogeneous (2DH) rasterisation. For a triangle with camera-frame vertices v0, v1, v2
  (columns of M) and a pixel (u, v) with ray d = K^-1 [u, v, 1], the three numbers
  lam = M^-1 d are linear in (u, v); the ray hits the triangle in front of the camera
  iff all lam_k >= 0, the hit point is d / sum(lam) and 1 / z = sum(lam). So the
  coverage test, the perspective-correct barycentrics lam / sum(lam) and the depth come
  from three plane equations per triangle, and triangles crossing z = 0 need no
  geometric clipping. The near plane is a per-pixel test z >= near; the screen bounding
  box of a triangle is taken from its polygon clipped at z = near.
* Each triangle enumerates a fixed S x S window of pixel centres starting at the lower
  corner of its (clipped, on-screen) bounding box. Triangles are binned into tiers by
  the size of that box (S = 1, 2, 4, ... up to max(H, W)), so the work is proportional
  to the covered area. The z-buffer is one int64 key per pixel, (float bits of 1/z) << 32
  | triangle id, reduced with ``scatter_reduce(amax)`` (nearest surface wins, exact ties
  go to the larger triangle id). Pixels then re-evaluate the winning triangle's planes
  at their centre: points_cam is the exact ray/plane intersection (it projects back onto
  the pixel centre), colours are barycentric vertex colours.
* ``Rasterizer(..., dynamic=False)`` is the static-shape path: every tier has a fixed
  capacity (triangle slots per render), compaction into the slots is a cumsum + scatter,
  and nothing reads data back to the host, so a call can be captured by CUDA graphs or
  ``torch.compile(fullgraph=True)``. Overflow: triangles that do not fit their tier's
  capacity are not drawn in that call and ``RenderOutput.overflow[n]`` is set for every
  render n that lost a triangle (never silent). ``render()`` / ``dynamic=True`` sizes the
  tiers from the actual counts (one host sync) and never overflows.

Conventions (docs/DESIGN.md): OpenCV camera (x right, y down, z forward); pixel (row v,
column u) samples the image point (u, v) (pixel centres at integer coordinates).
Winding: a face (i0, i1, i2) is *front facing* when its right-hand normal
(v1 - v0) x (v2 - v0) points towards the camera, i.e. counter-clockwise as seen from the
camera = outward normals for the usual CCW-from-outside meshes (trimesh, OBJ, STL).
Back-face culling is OFF by default (MJCF meshes often have inconsistent winding);
with ``cull_backfaces=True`` faces seen from behind are skipped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import torch
from torch import Tensor

__all__ = ["MeshBatch", "RenderOutput", "Rasterizer", "render", "default_tier_windows", "project_points"]

_KEY_SHIFT = 1 << 32
_TID_MASK = (1 << 32) - 1
_INF = float("inf")

# float table columns (per render x face)
_C_LAM0 = slice(0, 3)  # lam_k at the window origin (u0, v0)
_C_A = slice(3, 6)  # d lam_k / du
_C_B = slice(6, 9)  # d lam_k / dv
_C_IZ0, _C_IA, _C_IB = 9, 10, 11  # 1/z plane at the origin and its gradients
_C_U0, _C_V0 = 12, 13  # window origin (integers stored as float)
_C_N = slice(14, 17)  # unit face normal in the camera frame
_NCOL = 17


def _as_tensor(x, dtype, device=None) -> Tensor:
    if isinstance(x, Tensor):
        return x.detach().to(dtype=dtype, device=device)
    return torch.as_tensor(np.asarray(x), dtype=dtype, device=device)


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
        """Build from a list of (vertices (V,3), faces (F,3)[, colors (V,3) or (3,) or None]).

        Arrays may be numpy or torch; uint8 colours are divided by 255.
        """
        verts, faces, cols = [], [], []
        for m in meshes:
            v = _as_tensor(m[0], torch.float32).reshape(-1, 3)
            f = _as_tensor(m[1], torch.int64).reshape(-1, 3)
            c = m[2] if len(m) > 2 else None
            if c is None:
                c = torch.tensor(default_color, dtype=torch.float32).expand(v.shape[0], 3)
            else:
                is_u8 = (isinstance(c, np.ndarray) and c.dtype == np.uint8) or (
                    isinstance(c, Tensor) and c.dtype == torch.uint8
                )
                c = _as_tensor(c, torch.float32)
                if is_u8:
                    c = c / 255.0
                c = c[..., :3].expand(v.shape[0], 3) if c.dim() == 1 else c[:, :3]
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


def default_tier_windows(image_size: tuple[int, int]) -> list[int]:
    """Window sizes 1, 2, 4, ... and finally max(H, W) (which covers any on-screen box)."""
    m = max(image_size)
    out, s = [], 1
    while s < m:
        out.append(s)
        s *= 2
    out.append(m)
    return out


def project_points(K: Tensor, p: Tensor) -> Tensor:
    """Pinhole projection: K (...,3,3), p (...,N,3) camera frame -> (...,N,2) pixel (u, v)."""
    q = p @ K.transpose(-1, -2)
    return q[..., :2] / q[..., 2:3]


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
        tiers: window sizes S (ascending; the last should be >= max(H, W), otherwise
            larger boxes are reported as overflow) -- default ``default_tier_windows``.
        capacity: triangle slots per render for each tier (static path only; the slots of
            a call are ceil(capacity * N), shared by the N renders). Default: every face
            fits the tiers with S <= 4, F/4 for S = 8, F/16 for S = 16, and so on (at
            least 4). ``calibrate`` sets them from example poses.
        near: near plane (m); surface points with z < near are not drawn.
        cull_backfaces: skip faces whose right-hand normal points away from the camera.
        shading: multiply the colours by a two-sided Lambert term with a headlight
            (ambient ``ambient``); off by default.
        chunk_candidates: candidate pixels evaluated per step (bounds temporary memory;
            default 1 << 16 on CPU, 1 << 24 on CUDA).
        setup_dtype: dtype of the per-triangle setup (float64 default; per-pixel work is
            float32).
    """

    def __init__(
        self,
        meshes: MeshBatch,
        image_size: tuple[int, int],
        device: torch.device | str | None = None,
        tiers: Sequence[int] | None = None,
        capacity: Sequence[float] | None = None,
        near: float = 1e-3,
        cull_backfaces: bool = False,
        shading: bool = False,
        ambient: float = 0.35,
        chunk_candidates: int | None = None,
        setup_dtype: torch.dtype = torch.float64,
    ):
        device = torch.device(device) if device is not None else meshes.device
        self.device = device
        self.meshes = meshes.to(device)
        self.H, self.W = int(image_size[0]), int(image_size[1])
        self.near = float(near)
        self.cull_backfaces = bool(cull_backfaces)
        self.shading = bool(shading)
        self.ambient = float(ambient)
        self.setup_dtype = setup_dtype
        self.tiers = list(tiers) if tiers is not None else default_tier_windows((self.H, self.W))
        if sorted(self.tiers) != self.tiers or self.tiers[0] < 1:
            raise ValueError("tiers must be ascending positive window sizes")
        F = self.meshes.num_faces
        if capacity is None:
            capacity = [float(F) if s <= 4 else max(4.0, F / (s / 4) ** 2) for s in self.tiers]
        if len(capacity) != len(self.tiers):
            raise ValueError("one capacity per tier")
        self.capacity = [float(c) for c in capacity]
        if chunk_candidates is None:
            chunk_candidates = (1 << 24) if device.type == "cuda" else (1 << 16)
        self.chunk_candidates = int(chunk_candidates)
        # constants (created once so that calls never copy from the host)
        m = self.meshes
        Fm = m.faces.shape[1]
        fcol = torch.gather(
            m.vertex_colors, 1, m.faces.reshape(m.num_meshes, Fm * 3, 1).expand(-1, -1, 3)
        )  # (M, F*3, 3)
        self._face_colors = fcol.reshape(m.num_meshes * Fm, 9).contiguous()
        self._tier_bounds = torch.tensor(self.tiers, dtype=torch.int64, device=device)
        self._ar = {s: torch.arange(s, device=device) for s in self.tiers}
        self._arf = {s: torch.arange(s, device=device, dtype=torch.float32) for s in self.tiers}

    # ------------------------------------------------------------------ setup
    def _setup(self, mesh_index: Tensor, T_cam_obj: Tensor, K: Tensor):
        """Per (render, face) plane equations, windows and tiers."""
        m = self.meshes
        dev, sd = self.device, self.setup_dtype
        N = mesh_index.shape[0]
        F = m.num_faces
        H, W = self.H, self.W
        T = T_cam_obj.to(device=dev, dtype=sd)
        Kd = K.to(device=dev, dtype=sd)
        if m.num_meshes == 1:
            verts = m.vertices.to(sd).expand(N, -1, -1)
            faces = m.faces.expand(N, -1, -1)
            fvalid = m.face_valid.expand(N, -1)
        else:
            verts = m.vertices.to(sd)[mesh_index]
            faces = m.faces[mesh_index]
            fvalid = m.face_valid[mesh_index]
        vc = verts @ T[:, :3, :3].transpose(1, 2) + T[:, None, :3, 3]  # (N,V,3) camera frame
        tri = torch.gather(vc, 1, faces.reshape(N, F * 3, 1).expand(-1, -1, 3)).view(N, F, 3, 3)
        v0, v1, v2 = tri.unbind(2)  # (N,F,3)
        c0 = torch.linalg.cross(v1, v2, dim=-1)
        c1 = torch.linalg.cross(v2, v0, dim=-1)
        c2 = torch.linalg.cross(v0, v1, dim=-1)
        nrm = torch.linalg.cross(v1 - v0, v2 - v0, dim=-1)  # = c0 + c1 + c2
        det = (v0 * c0).sum(-1)  # = n . v0 ; < 0 <=> front facing
        scale = v0.norm(dim=-1) * v1.norm(dim=-1) * v2.norm(dim=-1)
        ok = fvalid & (det.abs() > 1e-9 * scale) & torch.isfinite(det)
        if self.cull_backfaces:
            ok = ok & (det < 0)
        det_s = torch.where(ok, det, torch.ones_like(det))
        Kinv = _inv_intrinsics(Kd)[:, None]  # (N,1,3,3)
        Lam = torch.stack([c0, c1, c2], -2) @ Kinv / det_s[..., None, None]  # (N,F,3,3): lam_k = Lam[k] . [u,v,1]
        Iz = (nrm[..., None, :] @ Kinv)[..., 0, :] / det_s[..., None]  # (N,F,3)

        # screen bounding box of the triangle clipped at z = near
        near = self.near
        z = tri[..., 2]  # (N,F,3)
        P = tri @ Kd[:, None].transpose(-1, -2)  # (N,F,3,3) homogeneous pixel coords
        inside = z >= near
        zs = torch.where(inside, z, torch.ones_like(z))
        uv = P[..., :2] / zs[..., None]
        pts = [uv]
        msk = [inside]
        for a, b in ((0, 1), (1, 2), (2, 0)):
            za, zb = z[..., a], z[..., b]
            cross = (za - near) * (zb - near) < 0
            den = torch.where(cross, zb - za, torch.ones_like(za))
            s = ((near - za) / den)[..., None]
            q = P[..., a, :] + s * (P[..., b, :] - P[..., a, :])
            pts.append((q[..., :2] / near)[..., None, :])
            msk.append(cross[..., None])
        pts = torch.cat(pts, -2)  # (N,F,6,2)
        msk = torch.cat(msk, -1)  # (N,F,6)
        ok = ok & msk.any(-1)
        big = 1e9
        lo = torch.where(msk[..., None], pts, torch.full_like(pts, big)).amin(-2).clamp(-2.0, big)
        hi = torch.where(msk[..., None], pts, torch.full_like(pts, -big)).amax(-2).clamp(-big, big)
        eps = 1e-3
        u_lo = torch.ceil(lo[..., 0] - eps).clamp(0, W - 1)
        v_lo = torch.ceil(lo[..., 1] - eps).clamp(0, H - 1)
        u_hi = torch.floor(hi[..., 0] + eps).clamp(-1, W - 1)
        v_hi = torch.floor(hi[..., 1] + eps).clamp(-1, H - 1)
        w = (u_hi - u_lo + 1).to(torch.int64)
        h = (v_hi - v_lo + 1).to(torch.int64)
        ok = ok & (w > 0) & (h > 0)
        ext = torch.where(ok, torch.maximum(w, h), torch.zeros_like(w))  # (N,F)

        # plane values at the window origin
        org = torch.stack([u_lo, v_lo, torch.ones_like(u_lo)], -1)  # (N,F,3)
        lam0 = (Lam * org[..., None, :]).sum(-1)  # (N,F,3)
        iz0 = (Iz * org).sum(-1)
        nunit = nrm / nrm.norm(dim=-1, keepdim=True).clamp_min(1e-30)
        tab = torch.cat(
            [
                lam0,
                Lam[..., 0],
                Lam[..., 1],
                iz0[..., None],
                Iz[..., 0:1],
                Iz[..., 1:2],
                u_lo[..., None],
                v_lo[..., None],
                nunit,
            ],
            -1,
        )
        tab = torch.where(ok[..., None], tab, torch.zeros_like(tab)).to(torch.float32).reshape(N * F, _NCOL)
        n_ar = torch.arange(N, device=dev)[:, None]
        pixbase = n_ar * (H * W) + v_lo.to(torch.int64) * W + u_lo.to(torch.int64)
        tabi = torch.stack([pixbase, w.clamp_min(1), h.clamp_min(1)], -1).reshape(N * F, 3)
        # tier = first window >= ext; -1 = not drawn
        tier = torch.bucketize(ext, self._tier_bounds)
        tier = torch.where(ext > 0, tier, torch.full_like(tier, -1)).reshape(N * F)
        return tab.contiguous(), tabi.contiguous(), tier

    # ------------------------------------------------------------------ raster
    def _raster_tier(self, zbuf: Tensor, tab: Tensor, tabi: Tensor, tid: Tensor, slot_ok: Tensor | None, S: int):
        """Rasterise the triangles ``tid`` (C,) with S x S windows into zbuf (N*H*W,) int64."""
        C = tid.shape[0]
        if C == 0:
            return
        W = self.W
        izmax = 1.0 / self.near
        arf = self._arf[S]  # (S,)
        ar = self._ar[S]
        step = max(1, self.chunk_candidates // (S * S))
        for c0 in range(0, C, step):
            t = tid[c0 : c0 + step]
            rows = tab.index_select(0, t)  # (c,17)
            ri = tabi.index_select(0, t)  # (c,3)
            lam0 = rows[:, _C_LAM0]
            A = rows[:, _C_A]
            B = rows[:, _C_B]
            tol = 1e-4 * (A.abs() + B.abs())  # ~1e-4 px watertightness margin
            # row (u offset i) and column (v offset j) parts, (c,3,S)
            rpart = (lam0 + tol)[:, :, None] + A[:, :, None] * arf
            cpart = B[:, :, None] * arf
            wv, hv = ri[:, 1:2], ri[:, 2:3]
            rbad = ar >= wv  # (c,S)
            cbad = ar >= hv
            if slot_ok is not None:
                rbad = rbad | ~slot_ok[c0 : c0 + step, None]
            rpart[:, 0, :] = torch.where(rbad, -_INF, rpart[:, 0, :])
            cpart[:, 0, :] = torch.where(cbad, -_INF, cpart[:, 0, :])
            izr = rows[:, _C_IZ0, None] + rows[:, _C_IA, None] * arf  # (c,S)
            izc = rows[:, _C_IB, None] * arf
            nzr = izmax - izr  # near test: 1/z <= 1/near
            pu = ri[:, 0:1] + torch.minimum(ar, wv - 1)  # (c,S)
            pv = torch.minimum(ar, hv - 1) * W
            # candidates (c, S[j], S[i])
            l0 = rpart[:, None, 0, :] + cpart[:, 0, :, None]
            l1 = rpart[:, None, 1, :] + cpart[:, 1, :, None]
            l2 = rpart[:, None, 2, :] + cpart[:, 2, :, None]
            torch.minimum(l0, l1, out=l0)
            torch.minimum(l0, l2, out=l0)
            torch.sub(nzr[:, None, :], izc[:, :, None], out=l1)
            torch.minimum(l0, l1, out=l0)
            iz = izr[:, None, :] + izc[:, :, None]
            iz = torch.where(l0 >= 0, iz, 0.0)
            key = torch.add(t[:, None, None], iz.view(torch.int32).to(torch.int64), alpha=_KEY_SHIFT)
            pix = pu[:, None, :] + pv[:, :, None]
            zbuf.scatter_reduce_(0, pix.reshape(-1), key.reshape(-1), reduce="amax", include_self=True)

    # ------------------------------------------------------------------ resolve
    def _resolve(self, key: Tensor, pix: Tensor, tab: Tensor, mesh_index: Tensor, Kinv: Tensor, N: int):
        """Attributes at pixels ``pix`` (flat n*H*W + v*W + u) whose zbuf key is ``key``.

        Returns rgb (P,3)/(3,P)-like tuple: colours (3,P), points (3,P)."""
        H, W = self.H, self.W
        HW = H * W
        F = self.meshes.num_faces
        tid = key & _TID_MASK
        rows = tab.index_select(0, tid)  # (P,17)
        n = pix // HW
        p = pix - n * HW
        v = (p // W).to(torch.float32)
        u = (p - (p // W) * W).to(torch.float32)
        du = u - rows[:, _C_U0]
        dv = v - rows[:, _C_V0]
        lam = rows[:, _C_LAM0] + rows[:, _C_A] * du[:, None] + rows[:, _C_B] * dv[:, None]  # (P,3)
        lam = lam.clamp_min(0)
        bary = lam / lam.sum(-1, keepdim=True).clamp_min(1e-30)
        iz = rows[:, _C_IZ0] + rows[:, _C_IA] * du + rows[:, _C_IB] * dv
        zz = 1.0 / iz.clamp_min(1e-30)
        Ki = Kinv.index_select(0, n)  # (P,3,3) float32
        xr = Ki[:, 0, 0] * u + Ki[:, 0, 1] * v + Ki[:, 0, 2]
        yr = Ki[:, 1, 1] * v + Ki[:, 1, 2]
        pts = torch.stack([xr * zz, yr * zz, zz], 0)  # (3,P)
        f = tid - (tid // F) * F
        mi = mesh_index.index_select(0, n) if self.meshes.num_meshes > 1 else torch.zeros_like(n)
        fc = self._face_colors.index_select(0, mi * F + f).view(-1, 3, 3)  # (P, vertex, rgb)
        col = (bary[:, :, None] * fc).sum(1).t()  # (3,P)
        if self.shading:
            nrm = rows[:, _C_N]
            ray = torch.stack([xr, yr, torch.ones_like(xr)], -1)
            cos = (nrm * ray).sum(-1).abs() / ray.norm(dim=-1)
            col = col * (self.ambient + (1 - self.ambient) * cos)
        return col.clamp(0, 1), pts

    # ------------------------------------------------------------------ call
    def __call__(
        self, mesh_index: Tensor, T_cam_obj: Tensor, K: Tensor, dynamic: bool = False
    ) -> RenderOutput:
        """Render N views: mesh_index (N,) long, T_cam_obj (N,4,4), K (N,3,3) or (3,3).

        dynamic=False: static shapes, no host sync (CUDA graph / torch.compile friendly),
        may set ``overflow``. dynamic=True: exact tier sizes (host syncs), never overflows.
        """
        dev = self.device
        mesh_index = mesh_index.to(device=dev, dtype=torch.int64).reshape(-1)
        N = mesh_index.shape[0]
        T_cam_obj = T_cam_obj.to(dev).reshape(N, 4, 4)
        K = K.to(dev)
        if K.dim() == 2:
            K = K.expand(N, 3, 3)
        H, W = self.H, self.W
        HW = H * W
        F = self.meshes.num_faces
        tab, tabi, tier = self._setup(mesh_index, T_cam_obj, K)
        zbuf = torch.zeros(N * HW, dtype=torch.int64, device=dev)
        NF = N * F
        overflow = torch.zeros(N, dtype=torch.bool, device=dev)
        if dynamic:
            ids = torch.nonzero(tier >= 0).squeeze(1)
            tids = tier.index_select(0, ids)
            for k, S in enumerate(self.tiers):
                sel = ids[tids == k]
                self._raster_tier(zbuf, tab, tabi, sel, None, S)
        else:
            dropped = tier >= len(self.tiers)  # box larger than the largest window
            all_ids = torch.arange(NF, device=dev)
            for k, S in enumerate(self.tiers):
                C = int(math.ceil(self.capacity[k] * N))
                if C <= 0:
                    dropped = dropped | (tier == k)
                    continue
                mk = tier == k
                pos = torch.cumsum(mk, 0) - 1
                fits = mk & (pos < C)
                dropped = dropped | (mk & ~fits)
                slot = torch.where(fits, pos, C)
                buf = torch.zeros(C + 1, dtype=torch.int64, device=dev)
                buf.scatter_(0, slot, all_ids)
                count = pos[-1:] + 1
                slot_ok = torch.arange(C, device=dev) < count
                self._raster_tier(zbuf, tab, tabi, buf[:C], slot_ok, S)
            overflow = dropped.view(N, F).any(1)

        mask_flat = zbuf >= _KEY_SHIFT
        Kinv = _inv_intrinsics(K.to(torch.float64)).to(torch.float32)
        if dynamic:
            pix = torch.nonzero(mask_flat).squeeze(1)
            col, pts = self._resolve(zbuf.index_select(0, pix), pix, tab, mesh_index, Kinv, N)
            n = pix // HW
            p = pix - n * HW
            base = n * (3 * HW) + p
            rgb = torch.zeros(N * 3 * HW, device=dev)
            points = torch.zeros(N * 3 * HW, device=dev)
            for c in range(3):
                rgb.index_put_((base + c * HW,), col[c])
                points.index_put_((base + c * HW,), pts[c])
            rgb = rgb.view(N, 3, H, W)
            points = points.view(N, 3, H, W)
        else:
            pix = torch.arange(N * HW, device=dev)
            col, pts = self._resolve(zbuf, pix, tab, mesh_index, Kinv, N)
            mf = mask_flat.to(torch.float32)
            rgb = (col * mf).view(3, N, H, W).transpose(0, 1).contiguous()
            points = (pts * mf).view(3, N, H, W).transpose(0, 1).contiguous()
        return RenderOutput(rgb=rgb, mask=mask_flat.view(N, H, W), points_cam=points, overflow=overflow)

    # ------------------------------------------------------------------ helpers
    @torch.no_grad()
    def tier_counts(self, mesh_index: Tensor, T_cam_obj: Tensor, K: Tensor) -> Tensor:
        """(num_tiers,) number of triangles per tier summed over the N renders (host sync)."""
        mesh_index = mesh_index.to(self.device).reshape(-1)
        K = K.to(self.device)
        if K.dim() == 2:
            K = K.expand(mesh_index.shape[0], 3, 3)
        _, _, tier = self._setup(mesh_index, T_cam_obj.to(self.device), K)
        t = tier[tier >= 0]
        return torch.bincount(t, minlength=len(self.tiers) + 1)[: len(self.tiers)]

    @torch.no_grad()
    def calibrate(
        self, mesh_index: Tensor, T_cam_obj: Tensor, K: Tensor, margin: float = 1.5, minimum: float = 1.0
    ) -> list[float]:
        """Set per-render capacities from example poses: for every tier, margin x the
        largest per-render count seen among the N example renders (at least ``minimum``)."""
        mesh_index = mesh_index.to(self.device).reshape(-1)
        N = mesh_index.shape[0]
        K = K.to(self.device)
        if K.dim() == 2:
            K = K.expand(N, 3, 3)
        _, _, tier = self._setup(mesh_index, T_cam_obj.to(self.device), K)
        tier = tier.view(N, -1)
        caps = []
        for k in range(len(self.tiers)):
            per = (tier == k).sum(1).max().item()
            caps.append(max(float(minimum), math.ceil(per * margin)))
        self.capacity = caps
        return caps


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
    """Render N views of meshes: mesh_index (N,) long into ``meshes``, T_cam_obj (N,4,4)
    (mesh frame -> OpenCV camera frame), K (N,3,3) or (3,3), image_size (H, W).

    Exact (tiers sized from the actual triangles, one host sync; never overflows).
    Returns RenderOutput(rgb (N,3,H,W), mask (N,H,W), points_cam (N,3,H,W), overflow (N,)).
    """
    dev = T_cam_obj.device
    r = Rasterizer(meshes, image_size, device=dev, near=near, cull_backfaces=cull_backfaces, shading=shading)
    return r(mesh_index, T_cam_obj, K, dynamic=True)
