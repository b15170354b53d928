"""Property tests of lerobot_rnd.geometry and the sampler's point update (issue 11), CPU.

Each property is checked on many random cases in one batched call, against an independent reference:
scipy.spatial.transform.Rotation for rotations, a hand-computed case, and a float64 numpy Kabsch/Arun
solver for the weighted rigid registration. Tests of single cases live in tests/test_geometry.py and
tests/test_sampler.py; this file does not repeat them.

Stated tolerances: every output transform is finite, has the last row [0, 0, 0, 1] exactly, and a
rotation block with max |R^T R - I| and |det R - 1| below RIGID_TOL[dtype].
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from lerobot_rnd.geometry import (
    ROTATION_DIMS,
    action_from_pose,
    compose_transforms,
    invert_transform,
    make_transform,
    pose_from_action,
    relative_transform,
    rotation_to_matrix,
    so3_exp,
    so3_log,
    transform_points,
    weighted_rigid_registration,
)
from lerobot_rnd.sampler import register_point_update
from tests.helpers import StandInNetwork

DTYPES = [torch.float64, torch.float32]
METHODS = ["svd", "horn"]
#: max |R^T R - I| and |det R - 1| of every returned rotation
RIGID_TOL = {torch.float64: 1e-12, torch.float32: 4e-6}
#: agreement of a rotation matrix with scipy's (float64) for the same input
ROT_TOL = {torch.float64: 1e-12, torch.float32: 2e-6}
#: rotation angles where closed forms are hard: 0, the Taylor/closed-form switch (0.1 in float64,
#: 0.5 in float32) and just below pi
EXTREME_ANGLES = [
    0.0,
    1e-300,
    1e-15,
    1e-10,
    1e-7,
    1e-4,
    0.1,
    0.5,
    1.0,
    math.pi / 2,
    math.pi - 1e-2,
    math.pi - 1e-4,
    math.pi - 1e-6,
    math.pi - 1e-9,
    math.pi,
]


def assert_rigid(T: torch.Tensor, dtype: torch.dtype) -> None:
    """Every (4, 4) in T is finite, has last row [0, 0, 0, 1] and a proper orthonormal rotation block."""
    assert T.dtype == dtype and T.shape[-2:] == (4, 4)
    assert torch.isfinite(T).all(), "non-finite transform"
    bottom = torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=dtype)
    assert torch.equal(T[..., 3, :], bottom.expand_as(T[..., 3, :])), "last row is not [0, 0, 0, 1]"
    assert_rotation(T[..., :3, :3], dtype)


def assert_rotation(R: torch.Tensor, dtype: torch.dtype) -> None:
    assert torch.isfinite(R).all(), "non-finite rotation"
    Rd = R.double()
    orth = (Rd.transpose(-1, -2) @ Rd - torch.eye(3, dtype=torch.float64)).abs().amax()
    det = (torch.linalg.det(Rd) - 1).abs().amax()
    assert orth <= RIGID_TOL[dtype], f"max |R^T R - I| = {orth:.2e} > {RIGID_TOL[dtype]:g}"
    assert det <= RIGID_TOL[dtype], f"max |det R - 1| = {det:.2e} > {RIGID_TOL[dtype]:g}"


def _unit(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _rotvecs(rng, n_random: int, n_axes: int) -> np.ndarray:
    """n_random uniform rotations (angle in [0, pi]) plus every EXTREME_ANGLES value on n_axes random axes."""
    rand = Rotation.random(n_random, random_state=rng).as_rotvec()
    extreme = (_unit(rng, n_axes)[:, None, :] * np.array(EXTREME_ANGLES)[None, :, None]).reshape(-1, 3)
    return np.concatenate([rand, extreme])


def _random_transforms(rng, n: int, trans_scale: float = 1.0) -> np.ndarray:
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=rng).as_matrix()
    T[:, :3, 3] = rng.normal(size=(n, 3)) * trans_scale
    return T


def _rotation_angle_between(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """Angle (rad) of Ra^T Rb per element, from scipy (float64)."""
    return Rotation.from_matrix(np.swapaxes(Ra, -1, -2) @ Rb).magnitude()


# ------------------------------------------------------------------------ SO(3) / SE(3) maps


@pytest.mark.parametrize("dtype", DTYPES, ids=str)
def test_so3_exp_log_round_trips_vs_scipy_incl_angles_near_0_and_pi(dtype):
    rng = np.random.default_rng(100)
    rv = _rotvecs(rng, n_random=2000, n_axes=40)
    rv_t = torch.tensor(rv, dtype=dtype)
    rv64 = rv_t.double().numpy()  # the input as the function sees it
    angle = np.linalg.norm(rv64, axis=-1)

    # exp: matches scipy for the same input, rigid
    R = so3_exp(rv_t)
    assert R.dtype == dtype
    assert_rotation(R, dtype)
    R_ref = Rotation.from_rotvec(rv64).as_matrix()
    np.testing.assert_allclose(R.double().numpy(), R_ref, atol=ROT_TOL[dtype])

    # log of a rotation matrix: angle in [0, pi], matches scipy's rotation vector (up to the axis sign at pi)
    R_in = torch.tensor(R_ref, dtype=dtype)
    w = so3_log(R_in)
    assert torch.isfinite(w).all()
    w64 = w.double().numpy()
    w_angle = np.linalg.norm(w64, axis=-1)
    assert (w_angle <= math.pi + 10 * ROT_TOL[dtype]).all()
    log_tol = {torch.float64: 1e-12, torch.float32: 4e-6}[dtype]
    away = angle < math.pi - 1e-3  # below pi the rotation vector is unique and well conditioned
    np.testing.assert_allclose(w64[away], rv64[away], atol=log_tol)
    # at and near pi: the log is a rotation vector of the same rotation, of angle ~pi
    np.testing.assert_allclose(w_angle[~away], angle[~away], atol=log_tol)
    err = _rotation_angle_between(Rotation.from_rotvec(w64).as_matrix(), R_in.double().numpy())
    assert err.max() < 10 * ROT_TOL[dtype], err.max()

    # exp(log(R)) = R, rigid
    R_back = so3_exp(w)
    assert_rotation(R_back, dtype)
    np.testing.assert_allclose(R_back.double().numpy(), R_in.double().numpy(), atol=10 * ROT_TOL[dtype])


@pytest.mark.parametrize("dtype", DTYPES, ids=str)
def test_composition_and_inversion_vs_scipy(dtype):
    rng = np.random.default_rng(101)
    n = 1000
    Ta, Tb = _random_transforms(rng, n), _random_transforms(rng, n)
    ra, rb = Rotation.from_matrix(Ta[:, :3, :3]), Rotation.from_matrix(Tb[:, :3, :3])
    Ta_t, Tb_t = torch.tensor(Ta, dtype=dtype), torch.tensor(Tb, dtype=dtype)
    tol = {torch.float64: 1e-12, torch.float32: 5e-6}[dtype]

    Tab = compose_transforms(Ta_t, Tb_t)
    assert_rigid(Tab, dtype)
    np.testing.assert_allclose(Tab[:, :3, :3].double().numpy(), (ra * rb).as_matrix(), atol=tol)
    np.testing.assert_allclose(
        Tab[:, :3, 3].double().numpy(), ra.apply(Tb[:, :3, 3]) + Ta[:, :3, 3], atol=tol
    )

    Ti = invert_transform(Ta_t)
    assert_rigid(Ti, dtype)
    np.testing.assert_allclose(Ti[:, :3, :3].double().numpy(), ra.inv().as_matrix(), atol=tol)
    np.testing.assert_allclose(Ti[:, :3, 3].double().numpy(), -ra.inv().apply(Ta[:, :3, 3]), atol=tol)
    eye = np.broadcast_to(np.eye(4), (n, 4, 4))
    np.testing.assert_allclose((Ti @ Ta_t).double().numpy(), eye, atol=tol)
    np.testing.assert_allclose((Ta_t @ Ti).double().numpy(), eye, atol=tol)
    np.testing.assert_allclose(invert_transform(Ti).double().numpy(), Ta_t.double().numpy(), atol=tol)
    # inv(A B) = inv(B) inv(A); relative_transform(A, B) = inv(A) B
    np.testing.assert_allclose(
        invert_transform(Tab).double().numpy(), (invert_transform(Tb_t) @ Ti).double().numpy(), atol=tol
    )
    rel = relative_transform(Ta_t, Tb_t)
    assert_rigid(rel, dtype)
    np.testing.assert_allclose(rel[:, :3, :3].double().numpy(), (ra.inv() * rb).as_matrix(), atol=tol)


def test_hand_computed_transform():
    """T = [Rz(90 deg), (1, 2, 3)]: every number below is worked out by hand."""
    Rz90 = torch.tensor([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]], dtype=torch.float64)
    T = make_transform(Rz90, torch.tensor([1.0, 2, 3], dtype=torch.float64))
    p = torch.tensor([[1.0, 0, 0], [0, 1, 0], [0, 0, 0]], dtype=torch.float64)
    # Rz90 (1,0,0) = (0,1,0); Rz90 (0,1,0) = (-1,0,0)
    expected = torch.tensor([[1.0, 3, 3], [0, 2, 3], [1, 2, 3]], dtype=torch.float64)
    torch.testing.assert_close(transform_points(T, p), expected, atol=1e-15, rtol=0)
    # T^-1 = [Rz(-90), -Rz(-90) (1,2,3)] = [Rz(-90), -(2, -1, 3)]
    T_inv = invert_transform(T)
    torch.testing.assert_close(T_inv[:3, :3], Rz90.T, atol=0, rtol=0)
    torch.testing.assert_close(
        T_inv[:3, 3], torch.tensor([-2.0, 1, -3], dtype=torch.float64), atol=1e-15, rtol=0
    )
    # T T = [Rz(180), Rz90 (1,2,3) + (1,2,3)] = [diag(-1,-1,1), (-2,1,3) + (1,2,3)]
    TT = compose_transforms(T, T)
    torch.testing.assert_close(TT[:3, :3], torch.diag(torch.tensor([-1.0, -1, 1], dtype=torch.float64)))
    torch.testing.assert_close(TT[:3, 3], torch.tensor([-1.0, 3, 6], dtype=torch.float64))
    # log / exp: Rz90 <-> (0, 0, pi/2); a rotation by pi about x is diag(1, -1, -1)
    torch.testing.assert_close(so3_log(Rz90), torch.tensor([0, 0, math.pi / 2], dtype=torch.float64))
    Rx180 = so3_exp(torch.tensor([math.pi, 0, 0], dtype=torch.float64))
    torch.testing.assert_close(Rx180, torch.diag(torch.tensor([1.0, -1, -1], dtype=torch.float64)))
    torch.testing.assert_close(
        action_from_pose(T), torch.tensor([1.0, 2, 3, 0, 0, math.pi / 2], dtype=torch.float64)
    )


@pytest.mark.parametrize("dtype", DTYPES, ids=str)
def test_pose_from_action_and_action_from_pose_round_trip(dtype):
    rng = np.random.default_rng(102)
    rv = _rotvecs(rng, n_random=1000, n_axes=20)
    a = np.concatenate([rng.normal(size=rv.shape) * 0.1, rv], -1)
    a_t = torch.tensor(a, dtype=dtype)
    a64 = a_t.double().numpy()
    T = pose_from_action(a_t)
    assert_rigid(T, dtype)
    np.testing.assert_allclose(T[:, :3, 3].double().numpy(), a64[:, :3], atol=0)
    np.testing.assert_allclose(
        T[:, :3, :3].double().numpy(), Rotation.from_rotvec(a64[:, 3:]).as_matrix(), atol=ROT_TOL[dtype]
    )
    back = action_from_pose(T)
    assert torch.isfinite(back).all()
    away = np.linalg.norm(a64[:, 3:], axis=-1) < math.pi - 1e-3
    tol = {torch.float64: 1e-12, torch.float32: 4e-6}[dtype]
    np.testing.assert_allclose(back.double().numpy()[away], a64[away], atol=tol)
    # near pi the rotation vector may flip to -axis * angle: the pose is what must come back
    np.testing.assert_allclose(
        pose_from_action(back).double().numpy(), T.double().numpy(), atol=10 * ROT_TOL[dtype]
    )

    # the other way round, from random poses built by scipy
    Tr = torch.tensor(_random_transforms(rng, 1000, 0.3), dtype=dtype)
    Tr_back = pose_from_action(action_from_pose(Tr))
    assert_rigid(Tr_back, dtype)
    np.testing.assert_allclose(Tr_back.double().numpy(), Tr.double().numpy(), atol=10 * ROT_TOL[dtype])


def _nearly_parallel_6d(rng, n):
    """6-D rotations whose second column is within 1e-5..1e-2 rad of +-the first (both of random length)."""
    a1 = rng.normal(size=(n, 3))
    a2 = a1 * rng.uniform(-3, 3, size=(n, 1)) + _unit(rng, n) * np.linalg.norm(a1, axis=-1, keepdims=True) * (
        10.0 ** rng.uniform(-5, -2, size=(n, 1))
    )
    return np.concatenate([a1, a2], -1)


@pytest.mark.parametrize("dtype", DTYPES, ids=str)
def test_rotation_formats_map_arbitrary_inputs_to_rigid_rotations(dtype):
    """Unnormalised quaternions, arbitrary 6-D vectors (also nearly parallel columns), large Euler angles and rotation vectors beyond pi all give
    proper rotations; scipy agrees where it defines the map."""
    rng = np.random.default_rng(103)
    n = 1000
    q = rng.normal(size=(n, 4)) * rng.uniform(0.1, 10, size=(n, 1))
    inputs = {
        "quat_wxyz": q,
        "quat_xyzw": q,
        "rotvec": _unit(rng, n) * rng.uniform(0, 4 * math.pi, size=(n, 1)),
        "rot6d": np.concatenate([rng.normal(size=(n // 2, 6)), _nearly_parallel_6d(rng, n - n // 2)]),
        "euler_xyz": rng.uniform(-4 * math.pi, 4 * math.pi, size=(n, 3)),
    }
    refs = {
        "quat_wxyz": lambda r: Rotation.from_quat(np.concatenate([r[:, 1:], r[:, :1]], -1)),
        "quat_xyzw": Rotation.from_quat,
        "rotvec": Rotation.from_rotvec,
        "euler_xyz": lambda r: Rotation.from_euler("xyz", r),
    }
    assert set(inputs) | {"matrix"} == set(ROTATION_DIMS)
    for fmt, r in inputs.items():
        r_t = torch.tensor(r, dtype=dtype)
        R = rotation_to_matrix(r_t, fmt)
        assert_rotation(R, dtype)
        if fmt in refs:
            R_ref = refs[fmt](r_t.double().numpy()).as_matrix()
            atol = ROT_TOL[dtype] * (10 if fmt in ("rotvec", "euler_xyz") else 1)  # angles up to 4 pi
            np.testing.assert_allclose(R.double().numpy(), R_ref, atol=atol, err_msg=fmt)


# ------------------------------------------------------------------------ weighted rigid registration


def kabsch_np(src: np.ndarray, dst: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Float64 numpy reference: weighted Kabsch/Arun, det fixed to +1. (B,N,3), (B,N,3), (B,N) -> (B,4,4)."""
    wn = w / w.sum(-1, keepdims=True)
    mu_s = np.einsum("bn,bni->bi", wn, src)
    mu_d = np.einsum("bn,bni->bi", wn, dst)
    H = np.einsum("bn,bni,bnj->bij", wn, src - mu_s[:, None], dst - mu_d[:, None])
    U, _, Vt = np.linalg.svd(H)
    V = np.swapaxes(Vt, -1, -2)
    d = np.sign(np.linalg.det(V @ np.swapaxes(U, -1, -2)))
    D = np.ones((len(src), 3))
    D[:, 2] = d
    R = (V * D[:, None, :]) @ np.swapaxes(U, -1, -2)
    T = np.tile(np.eye(4), (len(src), 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = mu_d - np.einsum("bij,bj->bi", R, mu_s)
    return T


def _cost(T: np.ndarray, src: np.ndarray, dst: np.ndarray, w: np.ndarray) -> np.ndarray:
    moved = np.einsum("bij,bnj->bni", T[:, :3, :3], src) + T[:, None, :3, 3]
    return (w * ((moved - dst) ** 2).sum(-1)).sum(-1)


def _object_points(rng, b: int, n: int) -> np.ndarray:
    """b point sets of n points: ~10 cm objects about 1 m from the origin (like a gripper in world coordinates)."""
    return rng.normal(size=(b, 1, 3)) + rng.normal(size=(b, n, 3)) * 0.1


def _soft_weights(rng, b: int, n: int, min_visible: int = 4) -> np.ndarray:
    """Weights in [0.2, 2], about a quarter of them 0, never fewer than min_visible positive."""
    w = rng.uniform(0.2, 2.0, size=(b, n)) * (rng.uniform(size=(b, n)) > 0.25)
    w[:, :min_visible] = rng.uniform(0.2, 2.0, size=(b, min_visible))
    return w


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("dtype", DTYPES, ids=str)
def test_registration_recovers_random_rigid_transforms_from_noiseless_correspondences(method, dtype):
    rng = np.random.default_rng(200)
    b, n = 500, 16
    T_true = _random_transforms(rng, b, 0.3)
    src = _object_points(rng, b, n)
    dst = np.einsum("bij,bnj->bni", T_true[:, :3, :3], src) + T_true[:, None, :3, 3]
    w = _soft_weights(rng, b, n)
    dst_in = np.where(w[..., None] > 0, dst, np.nan)  # points with weight 0 may hold anything
    T, valid = weighted_rigid_registration(
        torch.tensor(src, dtype=dtype),
        torch.tensor(dst_in, dtype=dtype),
        torch.tensor(w, dtype=dtype),
        method=method,
    )
    assert valid.all()
    assert_rigid(T, dtype)
    T = T.double().numpy()
    rot_tol, trans_tol = {torch.float64: (1e-12, 1e-12), torch.float32: (1e-5, 2e-5)}[dtype]
    assert _rotation_angle_between(T[:, :3, :3], T_true[:, :3, :3]).max() < rot_tol
    assert np.abs(T[:, :3, 3] - T_true[:, :3, 3]).max() < trans_tol


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("dtype", DTYPES, ids=str)
def test_registration_with_noise_matches_float64_numpy_kabsch(method, dtype):
    rng = np.random.default_rng(201)
    b, n = 500, 16
    T_true = _random_transforms(rng, b, 0.3)
    src = _object_points(rng, b, n)
    dst = np.einsum("bij,bnj->bni", T_true[:, :3, :3], src) + T_true[:, None, :3, 3]
    dst = dst + rng.normal(size=dst.shape) * 0.01  # 1 cm on a 10 cm object
    w = _soft_weights(rng, b, n)
    src_t, dst_t, w_t = (torch.tensor(x, dtype=dtype) for x in (src, dst, w))
    T, valid = weighted_rigid_registration(src_t, dst_t, w_t, method=method)
    assert valid.all()
    assert_rigid(T, dtype)
    # the reference solves the same (rounded) inputs
    src64, dst64, w64 = (x.double().numpy() for x in (src_t, dst_t, w_t))
    ref = kabsch_np(src64, dst64, w64)
    T = T.double().numpy()
    tol = {torch.float64: 1e-12, torch.float32: 2e-5}[dtype]
    np.testing.assert_allclose(T, ref, atol=tol)
    # never worse than the reference optimum (relative to the residual)
    cost, cost_ref = _cost(T, src64, dst64, w64), _cost(ref, src64, dst64, w64)
    assert (cost <= cost_ref * (1 + {torch.float64: 1e-11, torch.float32: 5e-5}[dtype])).all()


@pytest.mark.parametrize("method", METHODS)
def test_registration_of_reflected_point_sets_returns_a_proper_rotation(method):
    """dst = M src + t with M orthogonal, det M = -1 (+ noise): the best orthogonal map is the reflection M; the
    result must still have det +1 and be the best proper rotation (the numpy reference's)."""
    rng = np.random.default_rng(202)
    b, n = 400, 12
    src = _object_points(rng, b, n)
    M = -Rotation.random(b, random_state=rng).as_matrix()  # improper: det -1
    dst = np.einsum("bij,bnj->bni", M, src) + rng.normal(size=(b, 1, 3)) + rng.normal(size=(b, n, 3)) * 1e-3
    w = _soft_weights(rng, b, n)
    # it is a reflection case: the unconstrained orthogonal Procrustes solution has det -1
    wn = w / w.sum(-1, keepdims=True)
    xs = src - np.einsum("bn,bni->bi", wn, src)[:, None]
    xd = dst - np.einsum("bn,bni->bi", wn, dst)[:, None]
    U, _, Vt = np.linalg.svd(np.einsum("bn,bni,bnj->bij", wn, xs, xd))
    assert (np.linalg.det(np.swapaxes(Vt, -1, -2) @ np.swapaxes(U, -1, -2)) < 0).all()
    for dtype in DTYPES:
        T, valid = weighted_rigid_registration(
            torch.tensor(src, dtype=dtype),
            torch.tensor(dst, dtype=dtype),
            torch.tensor(w, dtype=dtype),
            method=method,
        )
        assert valid.all()
        assert_rigid(T, dtype)
        ref = kabsch_np(src, dst, w)
        cost, cost_ref = _cost(T.double().numpy(), src, dst, w), _cost(ref, src, dst, w)
        assert (cost <= cost_ref * (1 + {torch.float64: 1e-11, torch.float32: 5e-5}[dtype])).all()

    # coplanar points mirrored in a line of their plane: a rotation by pi maps them exactly (cost 0)
    plane = rng.normal(size=(b, n, 2)) * 0.1
    basis = Rotation.random(b, random_state=rng).as_matrix()
    src_p = np.einsum("bij,bnj->bni", basis[:, :, :2], plane) + rng.normal(size=(b, 1, 3))
    mirror = np.einsum("bij,jk,blk->bil", basis, np.diag([-1.0, 1, 1]), basis)  # flips the plane's first axis
    dst_p = np.einsum("bij,bnj->bni", mirror, src_p)
    T, valid = weighted_rigid_registration(
        torch.tensor(src_p), torch.tensor(dst_p), torch.tensor(w), method=method
    )
    assert valid.all()
    assert_rigid(T, torch.float64)
    moved = transform_points(T, torch.tensor(src_p)).numpy()
    assert np.abs(moved - dst_p).max() < 1e-12


# ------------------------------------------------------------------------ degenerate point sets

N_DEGENERATE = 12  # points per set
K_EACH = 40  # random cases of each kind in the batch
KINDS = [
    "healthy",
    "all_equal",  # every weighted src point and every dst point is one point
    "dst_collapsed",  # spread src, every dst point is one point
    "collinear",
    "coplanar",
    "three_visible",
    "zero_visible",
    "one_visible",
    "two_visible",
    "zero_weights_nan_points",  # zero, negative and NaN weights on non-finite points
    "healthy_2",
]


def _degenerate_batch(rng):
    """K_EACH random cases of every kind, interleaved in one batch, and the known transform for each."""
    # interleaved: each kind has neighbours of every other kind
    kinds = np.tile(np.arange(len(KINDS)), K_EACH)
    b, n = len(kinds), N_DEGENERATE
    T_true = _random_transforms(rng, b, 0.3)
    src = _object_points(rng, b, n)
    w = rng.uniform(0.2, 2.0, size=(b, n))
    name = np.array(KINDS)[kinds]
    centre = rng.normal(size=(b, 1, 3))
    line = _unit(rng, b)[:, None, :] * rng.normal(size=(b, n, 1)) * 0.1 + centre
    plane_axes = Rotation.random(b, random_state=rng).as_matrix()[:, :, :2]
    plane = np.einsum("bij,bnj->bni", plane_axes, rng.normal(size=(b, n, 2)) * 0.1) + centre
    src = np.where((name == "all_equal")[:, None, None], centre, src)
    src = np.where((name == "collinear")[:, None, None], line, src)
    src = np.where((name == "coplanar")[:, None, None], plane, src)
    dst = np.einsum("bij,bnj->bni", T_true[:, :3, :3], src) + T_true[:, None, :3, 3]
    dst = np.where((name == "dst_collapsed")[:, None, None], rng.normal(size=(b, 1, 3)), dst)
    n_visible = {"three_visible": 3, "zero_visible": 0, "one_visible": 1, "two_visible": 2}
    for kind, k in n_visible.items():
        w[name == kind, k:] = 0
    bad = name == "zero_weights_nan_points"
    w[bad] = np.array([0.0, -1.0, np.nan, -np.inf])[np.arange(n) % 4]
    src[bad, ::2] = np.nan
    dst[bad, 1::2] = np.inf
    return name, T_true, src, dst, w


def _expected_valid(name):
    return ~np.isin(name, ["zero_visible", "one_visible", "two_visible", "zero_weights_nan_points"])


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("dtype", DTYPES, ids=str)
def test_registration_degenerate_point_sets_are_finite_rigid_and_follow_the_documented_fallback(
    method, dtype
):
    rng = np.random.default_rng(300)
    name, T_true, src, dst, w = _degenerate_batch(rng)
    src_t, dst_t, w_t = (torch.tensor(x, dtype=dtype) for x in (src, dst, w))
    T, valid = weighted_rigid_registration(src_t, dst_t, w_t, method=method)
    assert_rigid(T, dtype)
    np.testing.assert_array_equal(valid.numpy(), _expected_valid(name))
    # fewer than 3 points with weight > 0: the identity
    eye = torch.eye(4, dtype=dtype)
    assert torch.equal(T[~valid], eye.expand(int((~valid).sum()), 4, 4))

    T64 = T.double().numpy()
    src64, dst64 = src_t.double().numpy(), dst_t.double().numpy()
    atol = {torch.float64: 1e-12, torch.float32: 5e-5}[dtype]
    # healthy, coplanar (>= 3 non-collinear points) and 3 visible points: the true transform
    exact = np.isin(name, ["healthy", "healthy_2", "coplanar", "three_visible"])
    np.testing.assert_allclose(T64[exact], T_true[exact], atol=atol)
    # collinear: any rotation about the line is optimal; the line maps onto its image
    col = name == "collinear"
    moved = np.einsum("bij,bnj->bni", T64[col, :3, :3], src64[col]) + T64[col, None, :3, 3]
    np.testing.assert_allclose(moved, dst64[col], atol=atol)
    # one point (all src equal, or all dst equal): the rotation is not determined; the documented fallback is a
    # pure translation from the weighted src centroid to the weighted dst centroid
    single = np.isin(name, ["all_equal", "dst_collapsed"])
    np.testing.assert_allclose(T64[single, :3, :3], np.broadcast_to(np.eye(3), (single.sum(), 3, 3)), atol=0)
    wn = w[single] / w[single].sum(-1, keepdims=True)
    shift = np.einsum("bn,bni->bi", wn, dst64[single] - src64[single])
    np.testing.assert_allclose(T64[single, :3, 3], shift, atol=atol)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("dtype", DTYPES, ids=str)
def test_registration_degenerate_elements_do_not_change_healthy_ones(method, dtype):
    rng = np.random.default_rng(301)
    name, _, src, dst, w = _degenerate_batch(rng)
    src_t, dst_t, w_t = (torch.tensor(x, dtype=dtype) for x in (src, dst, w))
    T_mixed, _ = weighted_rigid_registration(src_t, dst_t, w_t, method=method)
    healthy = torch.tensor(np.isin(name, ["healthy", "healthy_2"]))
    T_alone, valid_alone = weighted_rigid_registration(
        src_t[healthy], dst_t[healthy], w_t[healthy], method=method
    )
    assert valid_alone.all()
    tol = {torch.float64: 1e-12, torch.float32: 1e-6}[dtype]
    torch.testing.assert_close(T_mixed[healthy], T_alone, atol=tol, rtol=0)


# ------------------------------------------------------------------------ the sampler's point update


def _point_update_case(rng, min_points: int):
    """register_point_update inputs with one sample per case kind (B = 16 cases, T = 8 horizon steps, C = 2 cameras)
    and the expected valid flags.

    Horizon steps: 0 healthy, 1 no pixel visible, 2 one, 3 two, 4 min_points - 1 (>= 3), 5 every visible pixel of
    both cameras at one world point (float32 camera coordinates), 6 collinear, 7 healthy.
    """
    b, t, c, n = 16, 8, 2, 10
    T_world_cam = np.stack([_random_transforms(rng, c, 1.0) for _ in range(b)])[:, None].repeat(t, 1)
    T_delta = np.stack([_random_transforms(rng, t, 0.05) for _ in range(b)])
    world = _object_points(rng, b * t * c, n).reshape(b, t, c, n, 3)
    world[:, 5] = rng.normal(size=(b, 1, 1, 3))
    direction = _unit(rng, b)[:, None, None, :]
    world[:, 6] = world[:, 6, :1, :1] + direction * rng.normal(size=(b, c, n, 1)) * 0.1
    moved = np.einsum("btij,btcnj->btcni", T_delta[..., :3, :3], world) + T_delta[:, :, None, None, :3, 3]
    cam_from_world = np.linalg.inv(T_world_cam)

    def to_cam(p):
        q = np.einsum("btcij,btcnj->btcni", cam_from_world[..., :3, :3], p) + cam_from_world[..., None, :3, 3]
        return torch.tensor(np.swapaxes(q, -1, -2), dtype=torch.float32)  # (B, T, C, 3, N)

    mask = np.zeros((b, t, c, n), dtype=bool)
    mask[:, [0, 5, 6, 7]] = rng.uniform(size=(b, 4, c, n)) > 0.3
    mask[:, [0, 5, 6, 7], 0, :2] = True
    mask[:, 2, 1, 3] = True
    mask[:, 3, 0, 4] = mask[:, 3, 1, 7] = True
    mask[:, 4, 0, : min_points - 1] = True
    expected_valid = np.ones((b, t), dtype=bool)
    expected_valid[:, 1:5] = False
    return (
        to_cam(world),
        to_cam(moved),
        torch.tensor(mask),
        torch.tensor(T_world_cam, dtype=torch.float32),
        T_delta,
        expected_valid,
    )


def test_register_point_update_degenerate_steps_fall_back_and_do_not_change_healthy_steps():
    rng = np.random.default_rng(400)
    min_points = 5
    p_k, p_prev, mask, T_world_cam, T_delta, expected_valid = _point_update_case(rng, min_points)
    T, valid = register_point_update(p_k, p_prev, mask, T_world_cam, min_points)
    assert T.shape == (16, 8, 4, 4) and T.dtype == torch.float32
    assert_rigid(T, torch.float32)
    np.testing.assert_array_equal(valid.numpy(), expected_valid)
    # where valid is False (fewer than min_points visible pixels): the identity, whatever the pixels say
    assert torch.equal(T[~valid], torch.eye(4).expand(int((~valid).sum()), 4, 4))
    # healthy steps: the true motion (float32 camera coordinates of points ~1 m from the origin)
    for step in (0, 7):
        np.testing.assert_allclose(T[:, step].double().numpy(), T_delta[:, step], atol=5e-6)
    # all visible pixels at one world point: translation only
    np.testing.assert_allclose(T[:, 5, :3, :3].numpy(), np.broadcast_to(np.eye(3), (16, 3, 3)), atol=0)
    np.testing.assert_allclose(
        T[:, 5, :3, 3].double().numpy(),
        np.einsum("bij,bj->bi", T_delta[:, 5, :3, :3] - np.eye(3), _world_point(p_k, T_world_cam))
        + T_delta[:, 5, :3, 3],
        atol=5e-6,
    )
    # collinear: the line maps onto its moved image
    world_k = _world_points(p_k[:, 6], T_world_cam[:, 6])
    world_prev = _world_points(p_prev[:, 6], T_world_cam[:, 6])
    moved = torch.einsum("bij,bnj->bni", T[:, 6, :3, :3].double(), world_k) + T[:, 6, None, :3, 3].double()
    np.testing.assert_allclose(moved.numpy(), world_prev.numpy(), atol=5e-6)
    # a healthy step alone gives the same transform as in the mixed batch
    keep = [0, 7]
    T_alone, valid_alone = register_point_update(
        p_k[:, keep], p_prev[:, keep], mask[:, keep], T_world_cam[:, keep], min_points
    )
    assert valid_alone.all()
    torch.testing.assert_close(T_alone, T[:, keep], atol=1e-7, rtol=0)


def _world_points(p_cam, T_world_cam):
    """(B, C, 3, N) camera points, (B, C, 4, 4) -> (B, C * N, 3) float64 world points."""
    T = T_world_cam.double()
    w = torch.einsum("bcij,bcjn->bcni", T[..., :3, :3], p_cam.double()) + T[..., None, :3, 3]
    return w.flatten(1, 2)


def _world_point(p_k, T_world_cam):
    """The single world point of horizon step 5 (first pixel of camera 0), float64 numpy (B, 3)."""
    return _world_points(p_k[:, 5], T_world_cam[:, 5])[:, 0].numpy()


class _GarbageDisplacementNetwork(StandInNetwork):
    """Predicts a large random displacement and a fixed action update (the denoiser's interface)."""

    def __init__(self, update: torch.Tensor):
        super().__init__()
        self.update = update

    def forward(
        self,
        obs_rgb,
        obs_points,
        future_rgb,
        future_points,
        gripper_state,
        timestep,
        noisy_action,
        patch_index=None,
        obs_tokens=None,
    ):
        displacement = 10 * torch.randn(future_points.shape, generator=torch.Generator().manual_seed(0))
        return displacement, self.update, torch.ones(noisy_action.shape[:2])


def test_sampler_step_falls_back_to_the_action_space_below_min_visible_points(toy_dataset_root, monkeypatch):
    """Where fewer than `MIN_VISIBLE_POINTS` rendered pixels are predicted (here: never enough), the sampler step
    is the action-space DDIM step with x0 = a + update, whatever the image space predicts."""
    from lerobot_rnd import sampler
    from lerobot_rnd.sampler import ddim_step
    from tests.helpers import make_policy

    monkeypatch.setattr(sampler, "MIN_VISIBLE_POINTS", 10**9)
    policy, _ = make_policy(toy_dataset_root, variant="AI", point_update="x0")
    model = policy.model
    b = 3
    state = torch.tensor([[0.02, -0.03, 0.21, 1.0], [-0.04, 0.02, 0.18, 1.0], [0.0, 0.05, 0.2, 1.0]])
    images = torch.rand(b, 2, len(model.camera_keys), 3, 64, 64, generator=torch.Generator().manual_seed(1))
    images, T_world_ee, gripper = model.prepare_observation(images, state[:, None].expand(b, 2, 4))
    gen = torch.Generator().manual_seed(2)
    a = (0.5 * torch.randn(b, 4, 6, generator=gen)).clamp(-1, 1)
    update = 0.3 * torch.randn(b, 4, 6, generator=gen)
    model.network = _GarbageDisplacementNetwork(update)
    with torch.no_grad(), pytest.warns(UserWarning, match="visible in none of the cameras"):
        a_next, _, composite = model.sampler_step(images, T_world_ee, gripper, a, 1, full_composite=True)
    n_obs = model.config.n_obs_steps
    assert (composite[:, n_obs:] != images[:, -1:]).any(), "the gripper must be rendered for this test"
    expected = ddim_step(
        a, (a + update).clamp(-1, 1), model.inference_alpha_bar[1], model.inference_alpha_bar_prev[1]
    )
    assert torch.isfinite(a_next).all()
    torch.testing.assert_close(a_next, expected, atol=1e-6, rtol=0)
