"""SO(3) / SE(3) maps, rotation conversions, rigidity checks and weighted rigid registration.

Pure PyTorch, batched over any leading shape ``...``, CPU and CUDA, float32 and float64.
Conventions (docs/DESIGN.md): ``T_a_b`` maps points in frame ``b`` into frame ``a``;
rotation vectors are axis * angle (rad); quaternions are named by their order
(``quat_wxyz``: scalar first, MuJoCo). SE(3) twists are ``xi = [v, w]`` (translation
part first). Except the input checks (``check_finite``, ``check_rigid``), no function here
synchronises with the host (no ``.item()``, no boolean indexing, no data-dependent shapes),
so they can be captured in CUDA graphs.
"""

from __future__ import annotations

import torch
from torch import Tensor

__all__ = [
    "hat",
    "so3_exp",
    "so3_log",
    "se3_exp",
    "se3_log",
    "quat_wxyz_to_matrix",
    "matrix_to_quat_wxyz",
    "quat_xyzw_to_wxyz",
    "quat_wxyz_to_xyzw",
    "rotation_6d_to_matrix",
    "matrix_to_rotation_6d",
    "euler_xyz_to_matrix",
    "ROTATION_DIMS",
    "rotation_to_matrix",
    "matrix_to_rotation",
    "make_transform",
    "invert_transform",
    "compose_transforms",
    "relative_transform",
    "transform_points",
    "pose_from_action",
    "action_from_pose",
    "weighted_rigid_registration",
    "rigid_transform_from_moments",
    "check_finite",
    "check_rigid",
]


def _small_threshold(dtype: torch.dtype) -> float:
    # Below this angle the closed forms lose precision; Taylor series are used instead.
    return 0.1 if dtype == torch.float64 else 0.5


def hat(w: Tensor) -> Tensor:
    """Skew-symmetric matrix: (...,3) -> (...,3,3) with hat(w) @ x = cross(w, x)."""
    wx, wy, wz = w.unbind(-1)
    z = torch.zeros_like(wx)
    return torch.stack(
        [torch.stack([z, -wz, wy], -1), torch.stack([wz, z, -wx], -1), torch.stack([-wy, wx, z], -1)], -2
    )


def _so3_coeffs(theta2: Tensor, dtype: torch.dtype):
    """A = sin(t)/t, B = (1-cos t)/t^2, C = (t - sin t)/t^3 for theta^2 = t^2 (stable, NaN-free grads)."""
    thr = _small_threshold(dtype)
    small = theta2 < thr * thr
    t2s = torch.where(small, torch.ones_like(theta2), theta2)  # safe value for the closed form
    t = torch.sqrt(t2s)
    s = torch.sin(t)
    half = 0.5 * t
    sinc_half = torch.sin(half) / half
    A_big = s / t
    B_big = 0.5 * sinc_half * sinc_half  # (1 - cos t)/t^2 = 2 sin^2(t/2)/t^2, no cancellation
    C_big = (t - s) / (t2s * t)
    x = theta2
    A_small = 1 - x / 6 * (1 - x / 20 * (1 - x / 42))
    B_small = 0.5 - x / 24 * (1 - x / 30 * (1 - x / 56))
    C_small = 1.0 / 6 - x / 120 * (1 - x / 42 * (1 - x / 72 * (1 - x / 110)))
    A = torch.where(small, A_small, A_big)
    B = torch.where(small, B_small, B_big)
    C = torch.where(small, C_small, C_big)
    return A, B, C


def _eye_plus(w: Tensor, a: Tensor, b: Tensor) -> Tensor:
    """I + a hat(w) + b hat(w)^2 (...,3,3) for coefficients a, b (...)."""
    K = hat(w)
    eye = torch.eye(3, dtype=w.dtype, device=w.device).expand(K.shape)
    return eye + a[..., None, None] * K + b[..., None, None] * (K @ K)


def so3_exp(rotvec: Tensor) -> Tensor:
    """Rotation vector (...,3) -> rotation matrix (...,3,3) (Rodrigues, stable near 0)."""
    A, B, _ = _so3_coeffs((rotvec * rotvec).sum(-1), rotvec.dtype)
    return _eye_plus(rotvec, A, B)


def quat_wxyz_to_matrix(q: Tensor) -> Tensor:
    """Quaternion (...,4) [w,x,y,z] (normalised here; any sign) -> rotation matrix (...,3,3)."""
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(torch.finfo(q.dtype).tiny)
    w, x, y, z = q.unbind(-1)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    row0 = torch.stack([1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy)], -1)
    row1 = torch.stack([2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx)], -1)
    row2 = torch.stack([2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy)], -1)
    return torch.stack([row0, row1, row2], -2)


def matrix_to_quat_wxyz(R: Tensor) -> Tensor:
    """Rotation matrix (...,3,3) -> unit quaternion (...,4) [w,x,y,z] with w >= 0.

    Robust for all angles: of the four standard formulas the one with the largest
    denominator is selected (per element, without data-dependent shapes).
    """
    m00, m01, m02 = R[..., 0, 0], R[..., 0, 1], R[..., 0, 2]
    m10, m11, m12 = R[..., 1, 0], R[..., 1, 1], R[..., 1, 2]
    m20, m21, m22 = R[..., 2, 0], R[..., 2, 1], R[..., 2, 2]
    # 4 * component^2 for w, x, y, z
    sq = torch.stack(
        [1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1
    )
    # candidate i is (4 q_i) * q, i.e. q scaled by 4 q_i
    cand = torch.stack(
        [
            torch.stack([sq[..., 0], m21 - m12, m02 - m20, m10 - m01], -1),
            torch.stack([m21 - m12, sq[..., 1], m10 + m01, m02 + m20], -1),
            torch.stack([m02 - m20, m10 + m01, sq[..., 2], m12 + m21], -1),
            torch.stack([m10 - m01, m02 + m20, m12 + m21, sq[..., 3]], -1),
        ],
        -2,
    )
    best = sq.argmax(-1, keepdim=True)  # (...,1)
    q = torch.gather(cand, -2, best[..., None].expand(*best.shape[:-1], 1, 4)).squeeze(-2)
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(torch.finfo(q.dtype).tiny)
    return torch.where(q[..., :1] < 0, -q, q)


def quat_xyzw_to_wxyz(q: Tensor) -> Tensor:
    """[x,y,z,w] (scipy) -> [w,x,y,z] (MuJoCo)."""
    return torch.cat([q[..., 3:4], q[..., 0:3]], -1)


def quat_wxyz_to_xyzw(q: Tensor) -> Tensor:
    """[w,x,y,z] (MuJoCo) -> [x,y,z,w] (scipy)."""
    return torch.cat([q[..., 1:4], q[..., 0:1]], -1)


def _quat_wxyz_to_rotvec(q: Tensor) -> Tensor:
    """Unit quaternion with w >= 0 -> rotation vector, stable near 0 and near pi."""
    w = q[..., 0]
    v = q[..., 1:]
    n = v.norm(dim=-1)
    angle = 2 * torch.atan2(n, w)  # in [0, pi]
    small = n < 1e-6 if q.dtype == torch.float64 else n < 1e-3
    n_safe = torch.where(small, torch.ones_like(n), n)
    # small: 2 atan(n/w)/n ~ (2/w)(1 - n^2/(3 w^2)); here w ~ 1
    w_safe = torch.where(small, w, torch.ones_like(w)).clamp_min(0.5)
    r = n * n / (w_safe * w_safe)
    scale_small = 2 / w_safe * (1 - r / 3 + r * r / 5)
    scale = torch.where(small, scale_small, angle / n_safe)
    return v * scale[..., None]


def so3_log(R: Tensor) -> Tensor:
    """Rotation matrix (...,3,3) -> rotation vector (...,3), angle in [0, pi].

    Goes through a robustly extracted quaternion, so it is accurate near 0 and near pi
    (at exactly pi the sign of the axis is arbitrary, as it must be).
    """
    return _quat_wxyz_to_rotvec(matrix_to_quat_wxyz(R))


def so3_left_jacobian(w: Tensor) -> Tensor:
    """Left Jacobian J(w) (...,3,3) of SO(3): se3_exp([v, w]) translation is J(w) @ v."""
    _, B, C = _so3_coeffs((w * w).sum(-1), w.dtype)
    return _eye_plus(w, B, C)


def so3_left_jacobian_inv(w: Tensor) -> Tensor:
    """Inverse left Jacobian (...,3,3): I - K/2 + D K^2, D = (1 - (t/2) cot(t/2)) / t^2.

    Valid for angles in [0, pi] (as returned by so3_log); stable near 0 and at pi.
    """
    theta2 = (w * w).sum(-1)
    thr = _small_threshold(w.dtype)
    small = theta2 < thr * thr
    t = torch.sqrt(torch.where(small, torch.ones_like(theta2), theta2))
    half = 0.5 * t
    D_big = (1 - half * torch.cos(half) / torch.sin(half)) / (t * t)
    x = theta2
    D_small = 1.0 / 12 + x * (1.0 / 720 + x * (1.0 / 30240 + x * (1.0 / 1209600 + x / 47900160)))
    D = torch.where(small, D_small, D_big)
    K = hat(w)
    eye = torch.eye(3, dtype=w.dtype, device=w.device).expand(K.shape)
    return eye - 0.5 * K + D[..., None, None] * (K @ K)


def make_transform(R: Tensor, t: Tensor) -> Tensor:
    """R (...,3,3), t (...,3) -> T (...,4,4) = [[R, t], [0, 1]] (shapes broadcast)."""
    shape = torch.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    R = R.expand(*shape, 3, 3)
    t = t.expand(*shape, 3)
    top = torch.cat([R, t[..., None]], -1)
    bottom = torch.zeros(*shape, 1, 4, dtype=R.dtype, device=R.device)
    bottom[..., 0, 3] = 1
    return torch.cat([top, bottom], -2)


def se3_exp(xi: Tensor) -> Tensor:
    """Twist xi (...,6) = [v, w] -> T (...,4,4) = expm([[hat(w), v], [0, 0]])."""
    v, w = xi[..., :3], xi[..., 3:]
    R = so3_exp(w)
    t = (so3_left_jacobian(w) @ v[..., None])[..., 0]
    return make_transform(R, t)


def se3_log(T: Tensor) -> Tensor:
    """T (...,4,4) -> twist xi (...,6) = [v, w] with |w| in [0, pi]; inverse of se3_exp."""
    w = so3_log(T[..., :3, :3])
    v = (so3_left_jacobian_inv(w) @ T[..., :3, 3:4])[..., 0]
    return torch.cat([v, w], -1)


def rotation_6d_to_matrix(d6: Tensor) -> Tensor:
    """6-D rotation (...,6) = [column 0 (3), column 1 (3)] (Zhou et al. 2019) -> R (...,3,3).

    Gram-Schmidt: b1 = a1/|a1|, b2 = normalised a2 minus its b1 part, b3 = b1 x b2. The b1 part is removed
    twice, so b2 stays orthogonal to b1 (to rounding) even when a2 is nearly parallel to a1; a1 = 0 or a2
    exactly parallel to a1 define no rotation (the result may then not be one).
    """
    a1, a2 = d6[..., :3], d6[..., 3:]
    eps = torch.finfo(d6.dtype).tiny
    b1 = a1 / a1.norm(dim=-1, keepdim=True).clamp_min(eps)
    for _ in range(2):  # one pass leaves a b1 part of ~eps |a2| / |a2 - b1 part|: large for near-parallel a2
        a2 = a2 - (b1 * a2).sum(-1, keepdim=True) * b1
    b2 = a2 / a2.norm(dim=-1, keepdim=True).clamp_min(eps)
    b3 = torch.linalg.cross(b1, b2, dim=-1)
    return torch.stack([b1, b2, b3], -1)


def matrix_to_rotation_6d(R: Tensor) -> Tensor:
    """R (...,3,3) -> (...,6): first column then second column."""
    return torch.cat([R[..., :, 0], R[..., :, 1]], -1)


def euler_xyz_to_matrix(e: Tensor) -> Tensor:
    """Extrinsic x-y-z Euler angles (...,3) (scipy ``"xyz"``) -> R (...,3,3) = Rz(e2) @ Ry(e1) @ Rx(e0)."""
    c, s = torch.cos(e), torch.sin(e)
    one, zero = torch.ones_like(e[..., 0]), torch.zeros_like(e[..., 0])

    def m(rows):
        return torch.stack([torch.stack(r, -1) for r in rows], -2)

    Rx = m([[one, zero, zero], [zero, c[..., 0], -s[..., 0]], [zero, s[..., 0], c[..., 0]]])
    Ry = m([[c[..., 1], zero, s[..., 1]], [zero, one, zero], [-s[..., 1], zero, c[..., 1]]])
    Rz = m([[c[..., 2], -s[..., 2], zero], [s[..., 2], c[..., 2], zero], [zero, zero, one]])
    return Rz @ Ry @ Rx


#: Rotation formats of state / action vectors and how many numbers each takes ("matrix": row-major 3x3).
ROTATION_DIMS = {"quat_wxyz": 4, "quat_xyzw": 4, "rotvec": 3, "rot6d": 6, "euler_xyz": 3, "matrix": 9}
#: format -> (to matrix, from matrix or None)
_ROTATION_MAPS = {
    "quat_wxyz": (quat_wxyz_to_matrix, matrix_to_quat_wxyz),
    "quat_xyzw": (
        lambda r: quat_wxyz_to_matrix(quat_xyzw_to_wxyz(r)),
        lambda R: quat_wxyz_to_xyzw(matrix_to_quat_wxyz(R)),
    ),
    "rotvec": (so3_exp, so3_log),
    "rot6d": (rotation_6d_to_matrix, matrix_to_rotation_6d),
    "euler_xyz": (euler_xyz_to_matrix, None),
    "matrix": (lambda r: r.reshape(*r.shape[:-1], 3, 3), lambda R: R.reshape(*R.shape[:-2], 9)),
}


def rotation_to_matrix(r: Tensor, fmt: str) -> Tensor:
    """Rotation (..., ROTATION_DIMS[fmt]) in format ``fmt`` -> R (...,3,3). Quaternions are normalised."""
    if fmt not in _ROTATION_MAPS:
        raise ValueError(f"unknown rotation format {fmt!r}; formats: {list(ROTATION_DIMS)}")
    return _ROTATION_MAPS[fmt][0](r)


def matrix_to_rotation(R: Tensor, fmt: str) -> Tensor:
    """R (...,3,3) -> rotation (..., ROTATION_DIMS[fmt]) in format ``fmt`` (quaternions with w >= 0)."""
    if _ROTATION_MAPS.get(fmt, (None, None))[1] is None:
        raise ValueError(f"no conversion from a matrix to rotation format {fmt!r}")
    return _ROTATION_MAPS[fmt][1](R)


def invert_transform(T: Tensor) -> Tensor:
    """Inverse of a rigid transform (...,4,4): T_b_a from T_a_b (uses R^T, exact for rigid T)."""
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    Rt = R.transpose(-1, -2)
    return make_transform(Rt, -(Rt @ t[..., None])[..., 0])


def compose_transforms(T_a_b: Tensor, T_b_c: Tensor) -> Tensor:
    """T_a_c = T_a_b @ T_b_c (broadcast)."""
    return T_a_b @ T_b_c


def relative_transform(T_w_a: Tensor, T_w_b: Tensor) -> Tensor:
    """T_a_b = inv(T_w_a) @ T_w_b: pose of frame b expressed in frame a."""
    return invert_transform(T_w_a) @ T_w_b


def transform_points(T: Tensor, p: Tensor) -> Tensor:
    """Apply T_a_b (...,4,4) to points p_b (...,N,3) -> p_a (...,N,3)."""
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    return p @ R.transpose(-1, -2) + t[..., None, :]


def pose_from_action(a: Tensor) -> Tensor:
    """R&D action (...,6) = [translation (3), rotation vector (3)] -> T_ee_target (...,4,4)."""
    return make_transform(so3_exp(a[..., 3:6]), a[..., 0:3])


def action_from_pose(T: Tensor) -> Tensor:
    """T_ee_target (...,4,4) -> R&D action (...,6) = [translation, rotation vector]."""
    return torch.cat([T[..., :3, 3], so3_log(T[..., :3, :3])], -1)


# ----------------------------------------------------------------------------------------
# weighted rigid registration
# ----------------------------------------------------------------------------------------

_JACOBI_PAIRS = ((0, 1), (2, 3), (0, 2), (1, 3), (0, 3), (1, 2))


def _sym_eig4_jacobi(A: Tensor, sweeps: int) -> tuple[Tensor, Tensor]:
    """Eigen-decomposition of symmetric (...,4,4) by cyclic Jacobi with a fixed number of
    sweeps (no host sync, no data-dependent control flow). Returns (eigvals (...,4), V)."""
    dtype, device = A.dtype, A.device
    eye = torch.eye(4, dtype=dtype, device=device)
    V = eye.expand(A.shape).clone()
    tiny = torch.finfo(dtype).tiny
    for _ in range(sweeps):
        for p, q in _JACOBI_PAIRS:
            app = A[..., p, p]
            aqq = A[..., q, q]
            apq = A[..., p, q]
            nz = apq.abs() > tiny
            apq_s = torch.where(nz, apq, torch.ones_like(apq))
            theta = (aqq - app) / (2 * apq_s)
            sgn = torch.where(theta >= 0, 1.0, -1.0).to(dtype)
            t = sgn / (theta.abs() + torch.hypot(theta, torch.ones_like(theta)))
            t = torch.where(nz, t, torch.zeros_like(t))
            c = torch.rsqrt(t * t + 1)
            s = t * c
            # J = I + (c-1)(e_p e_p^T + e_q e_q^T) + s (e_p e_q^T - e_q e_p^T)
            Epq = torch.zeros(4, 4, dtype=dtype, device=device)
            Epq[p, p] = 1
            Epq[q, q] = 1
            Sk = torch.zeros(4, 4, dtype=dtype, device=device)
            Sk[p, q] = 1
            Sk[q, p] = -1
            J = eye + (c - 1)[..., None, None] * Epq + s[..., None, None] * Sk
            A = J.transpose(-1, -2) @ A @ J
            V = V @ J
    return torch.diagonal(A, dim1=-2, dim2=-1), V


def weighted_rigid_registration(
    src: Tensor,
    dst: Tensor,
    weights: Tensor,
    method: str = "auto",
    jacobi_sweeps: int = 8,
    point_tol: Tensor | float | None = None,
) -> tuple[Tensor, Tensor]:
    """Weighted least-squares rigid transform: argmin_T sum_i w_i |T src_i - dst_i|^2.

    src, dst: (...,N,3) corresponding points (frames: src in ``src``, dst in ``dst``);
    weights: (...,N) >= 0 (0 = ignored; masked sets of different sizes solve in one call;
    points with weight 0 may hold any finite or non-finite values; negative or non-finite
    weights count as 0).
    Returns T_dst_src (...,4,4) (proper rotation, det +1) and valid (...) bool = at least
    3 points with weight > 0. Invalid entries return the identity. Never NaN.

    Degenerate sets (valid, each batch element solved on its own):
    - one point: if the weighted points of src, or those of dst, have a weighted RMS spread about
      their centroid of at most ``point_tol`` (...) (default: 32 eps of the dtype times their RMS
      distance from the origin, i.e. they differ only by rounding), every rotation is optimal and the
      rotation is the identity: T is the translation from the src centroid to the dst centroid;
    - collinear: the rotation about the line is not determined by the data; one optimal one is returned;
    - coplanar (3 or more non-collinear points): the unique solution.
    When the best orthogonal map is a reflection, the best proper rotation is returned.

    method: "svd" = weighted Kabsch/Arun (SVD of the 3x3 cross-covariance, reflection fixed
    by the determinant sign; torch.linalg.svd synchronises with the host on CUDA);
    "horn" = Horn's quaternion method (largest eigenvector of the 4x4 symmetric matrix) by
    fixed-sweep Jacobi in plain tensor ops, free of host syncs (CUDA-graph capturable);
    "auto" = "svd" on CPU, "horn" elsewhere. Both solve the same problem.
    """
    if method not in ("auto", "svd", "horn"):
        raise ValueError(f"unknown method {method!r}")
    dtype = src.dtype
    w = weights.to(dtype).clamp_min(0)
    w = torch.where(torch.isfinite(w), w, torch.zeros_like(w))
    pos = w > 0
    src = torch.where(pos[..., None], src, torch.zeros_like(src))
    dst = torch.where(pos[..., None], dst, torch.zeros_like(dst))
    valid = pos.sum(-1) >= 3
    wsum = w.sum(-1, keepdim=True)  # (...,1)
    wn = w / wsum.clamp_min(torch.finfo(dtype).tiny)
    mu_s = (wn[..., None] * src).sum(-2)  # (...,3)
    mu_d = (wn[..., None] * dst).sum(-2)
    xs = src - mu_s[..., None, :]
    xd = dst - mu_d[..., None, :]
    # One point (spread at the rounding level): H would hold only rounding noise and give an arbitrary rotation.
    spread_s = (wn * xs.square().sum(-1)).sum(-1).sqrt()
    spread_d = (wn * xd.square().sum(-1)).sum(-1).sqrt()
    if point_tol is None:
        rel = 32 * torch.finfo(dtype).eps
        tol_s = rel * (wn * src.square().sum(-1)).sum(-1).sqrt()
        tol_d = rel * (wn * dst.square().sum(-1)).sum(-1).sqrt()
    else:
        tol_s = tol_d = torch.as_tensor(point_tol, dtype=dtype, device=src.device)
    one_point = (spread_s <= tol_s) | (spread_d <= tol_d)
    H = (xs * wn[..., None]).transpose(-1, -2) @ xd  # (...,3,3) = sum w xs xd^T
    T = rigid_transform_from_moments(mu_s, mu_d, H, one_point, valid, method=method, jacobi_sweeps=jacobi_sweeps)
    return T, valid


def rigid_transform_from_moments(
    mu_src: Tensor,
    mu_dst: Tensor,
    cross_cov: Tensor,
    one_point: Tensor,
    valid: Tensor,
    method: str = "auto",
    jacobi_sweeps: int = 8,
) -> Tensor:
    """The rigid transform T_dst_src (...,4,4) of `weighted_rigid_registration` from the weighted moments.

    mu_src, mu_dst: (...,3) weighted centroids; cross_cov: (...,3,3) sum_i w_i (src_i - mu_src)(dst_i - mu_dst)^T
    (any positive scale: only its direction matters); one_point: (...) bool, where the rotation is the identity
    (translation from centroid to centroid); valid: (...) bool, the identity where False. Never NaN.
    See `weighted_rigid_registration` for `method`.
    """
    if method == "auto":
        method = "svd" if mu_src.device.type == "cpu" else "horn"
    dtype = mu_src.dtype
    # scale-normalise for conditioning (rotation is scale invariant)
    H = cross_cov
    scale = H.abs().amax(dim=(-1, -2), keepdim=True)
    H = H / torch.where(scale > 0, scale, torch.ones_like(scale))
    H = torch.where(torch.isfinite(H), H, torch.zeros_like(H))

    if method == "svd":
        U, _, Vh = torch.linalg.svd(H)
        V = Vh.transpose(-1, -2)
        d = torch.det(V @ U.transpose(-1, -2))
        sign = torch.where(d < 0, -1.0, 1.0).to(dtype)
        D = torch.ones(*H.shape[:-2], 3, dtype=dtype, device=H.device)
        D = torch.cat([D[..., :2], sign[..., None]], -1)
        R = (V * D[..., None, :]) @ U.transpose(-1, -2)
    elif method == "horn":
        Sxx, Sxy, Sxz = H[..., 0, 0], H[..., 0, 1], H[..., 0, 2]
        Syx, Syy, Syz = H[..., 1, 0], H[..., 1, 1], H[..., 1, 2]
        Szx, Szy, Szz = H[..., 2, 0], H[..., 2, 1], H[..., 2, 2]
        N = torch.stack(
            [
                torch.stack([Sxx + Syy + Szz, Syz - Szy, Szx - Sxz, Sxy - Syx], -1),
                torch.stack([Syz - Szy, Sxx - Syy - Szz, Sxy + Syx, Szx + Sxz], -1),
                torch.stack([Szx - Sxz, Sxy + Syx, -Sxx + Syy - Szz, Syz + Szy], -1),
                torch.stack([Sxy - Syx, Szx + Sxz, Syz + Szy, -Sxx - Syy + Szz], -1),
            ],
            -2,
        )
        evals, evecs = _sym_eig4_jacobi(N, jacobi_sweeps)
        best = evals.argmax(-1)  # (...)
        q = torch.gather(evecs, -1, best[..., None, None].expand(*best.shape, 4, 1))[..., 0]
        R = quat_wxyz_to_matrix(q)
    else:
        raise ValueError(f"unknown method {method!r}")

    R = torch.where(one_point[..., None, None], torch.eye(3, dtype=dtype, device=mu_src.device), R)
    t = mu_dst - (R @ mu_src[..., None])[..., 0]
    T = make_transform(R, t)
    eye = torch.eye(4, dtype=dtype, device=mu_src.device).expand(T.shape)
    return torch.where(valid[..., None, None] & torch.isfinite(T).all(-1).all(-1)[..., None, None], T, eye)


# ----------------------------------------------------------------------------------------
# input checks (validation only: these synchronise with the host)
# ----------------------------------------------------------------------------------------


def check_finite(x: Tensor, name: str) -> None:
    """Raise ValueError naming ``name`` if ``x`` holds NaN or Inf."""
    if x.numel() and not bool(torch.isfinite(x).all()):
        n_bad = int((~torch.isfinite(x)).sum())
        raise ValueError(f"{name} contains {n_bad} NaN/Inf value(s) (shape {tuple(x.shape)})")


def check_rigid(T, name: str, atol: float = 1e-4) -> None:
    """Raise ValueError naming ``name`` unless ``T`` (..., 4, 4) (tensor or array) is a finite proper rigid
    transform: last row [0, 0, 0, 1] and an orthonormal rotation block with det +1, within ``atol``."""
    T = torch.as_tensor(T)
    if T.ndim < 2 or tuple(T.shape[-2:]) != (4, 4):
        raise ValueError(f"{name} must have shape (..., 4, 4), got {tuple(T.shape)}")
    check_finite(T, name)
    if T.numel() == 0:
        return
    Td = T.detach().double()
    ref = torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=Td.dtype, device=Td.device)
    bottom_err = float((Td[..., 3, :] - ref).abs().max())
    if bottom_err > atol:
        raise ValueError(
            f"{name} is not a rigid transform: its last row must be [0, 0, 0, 1] "
            f"(max error {bottom_err:.2e}, tolerance {atol:g})"
        )
    R = Td[..., :3, :3]
    eye = torch.eye(3, dtype=Td.dtype, device=Td.device)
    orth_err = float((R.transpose(-1, -2) @ R - eye).abs().max())
    if orth_err > atol:
        raise ValueError(
            f"{name} is not a rigid transform: non-orthonormal rotation block (max |R^T R - I| = "
            f"{orth_err:.2e}, tolerance {atol:g}); pass a rigid transform (no scale or shear)"
        )
    if float(torch.linalg.det(R).min()) < 0.0:
        raise ValueError(
            f"{name} is not a rigid transform: it has a reflection (det R < 0); pass a proper rotation"
        )
