"""Tests of lerobot_rnd.geometry against independent references (scipy), CPU.

The CUDA case (graph capture of the registration) is skipped without a GPU.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from lerobot_rnd.geometry import (
    ROTATION_DIMS,
    action_from_pose,
    check_rigid,
    euler_xyz_to_matrix,
    invert_transform,
    make_transform,
    matrix_to_quat_wxyz,
    matrix_to_rotation,
    matrix_to_rotation_6d,
    pose_from_action,
    quat_wxyz_to_matrix,
    quat_wxyz_to_xyzw,
    quat_xyzw_to_wxyz,
    relative_transform,
    rotation_6d_to_matrix,
    rotation_to_matrix,
    se3_exp,
    se3_log,
    so3_exp,
    so3_log,
    transform_points,
    weighted_rigid_registration,
)

DTYPES = [torch.float64, torch.float32]
TOL = {torch.float64: 1e-10, torch.float32: 2e-5}


def _random_rotvecs(rng, shape, max_angle=math.pi):
    axis = rng.normal(size=shape + (3,))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    angle = rng.uniform(0, max_angle, size=shape + (1,))
    return axis * angle


def _hat_np(w):
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


@pytest.mark.parametrize("dtype", DTYPES)
def test_so3_exp_log_vs_scipy_leading_shape(dtype):
    rng = np.random.default_rng(0)
    rv = _random_rotvecs(rng, (4, 5), max_angle=math.pi * 0.999)
    R = so3_exp(torch.tensor(rv, dtype=dtype))
    assert R.shape == (4, 5, 3, 3) and R.dtype == dtype
    R_ref = Rotation.from_rotvec(rv.reshape(-1, 3)).as_matrix().reshape(4, 5, 3, 3)
    np.testing.assert_allclose(R.double().numpy(), R_ref, atol=TOL[dtype])
    back = so3_log(torch.tensor(R_ref, dtype=dtype))
    np.testing.assert_allclose(back.double().numpy(), rv, atol=5 * TOL[dtype])


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("angle", [0.0, 1e-12, 1e-7, 1e-4, 1e-2, 0.3, 0.5, math.pi - 1e-2, math.pi - 1e-5])
def test_so3_small_and_large_angles(dtype, angle):
    rng = np.random.default_rng(1)
    rv = _random_rotvecs(rng, (16,), max_angle=1.0)
    rv = rv / np.maximum(np.linalg.norm(rv, axis=-1, keepdims=True), 1e-30) * angle
    R = so3_exp(torch.tensor(rv, dtype=dtype))
    np.testing.assert_allclose(R.double().numpy(), Rotation.from_rotvec(rv).as_matrix(), atol=TOL[dtype])
    back = so3_log(torch.tensor(Rotation.from_rotvec(rv).as_matrix(), dtype=dtype)).double().numpy()
    assert np.isfinite(back).all()
    # near pi the rotation angle is sensitive to the matrix (d angle ~ dR / sin): compare rotations
    np.testing.assert_allclose(Rotation.from_rotvec(back).as_matrix(), Rotation.from_rotvec(rv).as_matrix(), atol=5 * TOL[dtype])
    if angle < 3.0:
        np.testing.assert_allclose(back, rv, atol=5 * TOL[dtype] + 1e-3 * (dtype == torch.float32) * angle)


@pytest.mark.parametrize("dtype", DTYPES)
def test_so3_log_at_pi(dtype):
    for axis in np.eye(3).tolist() + [[1 / math.sqrt(2), -1 / math.sqrt(2), 0.0], [0.6, 0.0, 0.8]]:
        rv = np.array(axis) * math.pi
        R = torch.tensor(Rotation.from_rotvec(rv).as_matrix(), dtype=dtype)
        w = so3_log(R).double().numpy()
        assert abs(np.linalg.norm(w) - math.pi) < 10 * TOL[dtype]
        assert min(np.abs(w - rv).max(), np.abs(w + rv).max()) < 10 * TOL[dtype]  # axis sign is arbitrary


@pytest.mark.parametrize("dtype", DTYPES)
def test_quaternion_orders_vs_scipy(dtype):
    rng = np.random.default_rng(2)
    rot = Rotation.random(50, random_state=3)
    q_xyzw = rot.as_quat()  # scipy: scalar last
    q_wxyz = np.concatenate([q_xyzw[:, 3:], q_xyzw[:, :3]], -1)
    sign = rng.choice([-1.0, 1.0], size=(50, 1))
    R = quat_wxyz_to_matrix(torch.tensor(q_wxyz * sign * 2.5, dtype=dtype))  # any sign and norm
    np.testing.assert_allclose(R.double().numpy(), rot.as_matrix(), atol=TOL[dtype])
    q = matrix_to_quat_wxyz(torch.tensor(rot.as_matrix(), dtype=dtype)).double().numpy()
    assert (q[:, 0] >= 0).all()
    q_ref = np.where(q_wxyz[:, :1] < 0, -q_wxyz, q_wxyz)
    np.testing.assert_allclose(q, q_ref, atol=5 * TOL[dtype])
    np.testing.assert_allclose(quat_wxyz_to_xyzw(torch.tensor(q_wxyz)).numpy(), q_xyzw)
    np.testing.assert_allclose(quat_xyzw_to_wxyz(torch.tensor(q_xyzw)).numpy(), q_wxyz)
    # 180 degree rotations (w = 0) are the hard case for the trace formula
    for axis in np.eye(3):
        Rp = torch.tensor(Rotation.from_rotvec(axis * math.pi).as_matrix(), dtype=dtype)
        qp = matrix_to_quat_wxyz(Rp)
        np.testing.assert_allclose(quat_wxyz_to_matrix(qp).double().numpy(), Rp.double().numpy(), atol=TOL[dtype])


@pytest.mark.parametrize("fmt", list(ROTATION_DIMS))
def test_rotation_formats_vs_scipy(fmt):
    rot = Rotation.random(20, random_state=4)
    R_ref = rot.as_matrix()
    q_xyzw = rot.as_quat()
    r = {
        "quat_wxyz": np.concatenate([q_xyzw[:, 3:], q_xyzw[:, :3]], -1) * 1.7,  # any norm
        "quat_xyzw": q_xyzw * 0.6,
        "rotvec": rot.as_rotvec(),
        "rot6d": np.concatenate([R_ref[:, :, 0], R_ref[:, :, 1]], -1),
        "euler_xyz": rot.as_euler("xyz"),
        "matrix": R_ref.reshape(20, 9),
    }[fmt]
    assert r.shape[-1] == ROTATION_DIMS[fmt]
    R = rotation_to_matrix(torch.tensor(r), fmt)
    np.testing.assert_allclose(R.numpy(), R_ref, atol=1e-10)
    if fmt == "euler_xyz":
        np.testing.assert_allclose(euler_xyz_to_matrix(torch.tensor(r)).numpy(), R_ref, atol=1e-10)
        with pytest.raises(ValueError, match="no conversion"):
            matrix_to_rotation(R, fmt)
        return
    back = matrix_to_rotation(torch.tensor(R_ref), fmt)
    np.testing.assert_allclose(rotation_to_matrix(back, fmt).numpy(), R_ref, atol=1e-10)
    if fmt.startswith("quat"):
        w = back[:, 0] if fmt == "quat_wxyz" else back[:, 3]
        assert (w >= 0).all() and torch.allclose(back.norm(dim=-1), torch.ones(20, dtype=back.dtype))
    with pytest.raises(ValueError, match="unknown rotation format"):
        rotation_to_matrix(torch.tensor(r), "quaternion")


@pytest.mark.parametrize(
    "T, match",
    [
        (np.diag([2.0, 1, 1, 1]), "non-orthonormal"),
        (np.diag([-1.0, 1, 1, 1]), "reflection"),
        (np.array([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0.1, 1]]), r"last row"),
        (np.full((4, 4), np.nan), "NaN"),
        (np.eye(3), r"\(\.\.\., 4, 4\)"),
    ],
)
def test_check_rigid_names_the_problem(T, match):
    with pytest.raises(ValueError, match=match):
        check_rigid(T, "T_test")
    check_rigid(make_transform(torch.eye(3), torch.ones(3)).expand(5, 4, 4), "ok")
    check_rigid(np.eye(4) + 1e-6, "almost", atol=1e-5)


@pytest.mark.parametrize("dtype", DTYPES)
def test_transforms_compose_and_invert_vs_scipy(dtype):
    r1, r2 = Rotation.random(8, random_state=4), Rotation.random(8, random_state=5)
    rng = np.random.default_rng(6)
    t1, t2 = rng.normal(size=(8, 3)), rng.normal(size=(8, 3))
    T1 = make_transform(torch.tensor(r1.as_matrix(), dtype=dtype), torch.tensor(t1, dtype=dtype))
    T2 = make_transform(torch.tensor(r2.as_matrix(), dtype=dtype), torch.tensor(t2, dtype=dtype))
    T12 = T1 @ T2
    np.testing.assert_allclose(T12[:, :3, :3].double().numpy(), (r1 * r2).as_matrix(), atol=TOL[dtype])
    np.testing.assert_allclose(T12[:, :3, 3].double().numpy(), r1.apply(t2) + t1, atol=TOL[dtype])
    Ti = invert_transform(T1)
    np.testing.assert_allclose(Ti[:, :3, :3].double().numpy(), r1.inv().as_matrix(), atol=TOL[dtype])
    np.testing.assert_allclose(Ti[:, :3, 3].double().numpy(), -r1.inv().apply(t1), atol=TOL[dtype])
    np.testing.assert_allclose((Ti @ T1).double().numpy(), np.broadcast_to(np.eye(4), (8, 4, 4)), atol=TOL[dtype])
    p = rng.normal(size=(8, 11, 3))
    out = transform_points(T1, torch.tensor(p, dtype=dtype)).double().numpy()
    ref = np.stack([r1[i].apply(p[i]) + t1[i] for i in range(8)])
    np.testing.assert_allclose(out, ref, atol=TOL[dtype] * 10)
    # relative transform: pose of b in a
    Tab = relative_transform(T1, T2)
    np.testing.assert_allclose((T1 @ Tab).double().numpy(), T2.double().numpy(), atol=TOL[dtype] * 10)
    # broadcasting of make_transform: one rotation, many translations
    Tb = make_transform(torch.eye(3, dtype=dtype), torch.tensor(t1, dtype=dtype))
    assert Tb.shape == (8, 4, 4)


@pytest.mark.parametrize("dtype", DTYPES)
def test_se3_exp_vs_matrix_exponential_and_log_round_trip(dtype):
    rng = np.random.default_rng(7)
    v = rng.normal(size=(3, 4, 3)) * 0.5
    w = _random_rotvecs(rng, (3, 4), max_angle=math.pi * 0.99)
    w[0, 0] = 0.0  # pure translation
    w[0, 1] *= 1e-9  # tiny rotation
    xi = np.concatenate([v, w], -1)
    T = se3_exp(torch.tensor(xi, dtype=dtype))
    assert T.shape == (3, 4, 4, 4)
    for idx in np.ndindex(3, 4):
        twist = np.zeros((4, 4))
        twist[:3, :3] = _hat_np(w[idx])
        twist[:3, 3] = v[idx]
        np.testing.assert_allclose(T[idx].double().numpy(), expm(twist), atol=10 * TOL[dtype])
    back = se3_log(T).double().numpy()
    np.testing.assert_allclose(back, xi, atol=50 * TOL[dtype])


@pytest.mark.parametrize("dtype", DTYPES)
def test_se3_log_near_pi(dtype):
    rng = np.random.default_rng(8)
    w = _random_rotvecs(rng, (6,), max_angle=1.0)
    w = w / np.linalg.norm(w, axis=-1, keepdims=True) * (math.pi - 1e-4)
    xi = np.concatenate([rng.normal(size=(6, 3)), w], -1)
    T = se3_exp(torch.tensor(xi, dtype=dtype))
    back = se3_exp(se3_log(T))
    np.testing.assert_allclose(back.double().numpy(), T.double().numpy(), atol=200 * TOL[dtype])


@pytest.mark.parametrize("dtype", DTYPES)
def test_rotation_6d(dtype):
    rot = Rotation.random(20, random_state=9)
    R = torch.tensor(rot.as_matrix(), dtype=dtype)
    d6 = matrix_to_rotation_6d(R)
    assert d6.shape == (20, 6)
    np.testing.assert_allclose(d6[:, :3].double().numpy(), rot.as_matrix()[:, :, 0], atol=TOL[dtype])
    np.testing.assert_allclose(d6[:, 3:].double().numpy(), rot.as_matrix()[:, :, 1], atol=TOL[dtype])
    np.testing.assert_allclose(rotation_6d_to_matrix(d6).double().numpy(), rot.as_matrix(), atol=TOL[dtype])
    # arbitrary (non-orthonormal) inputs map to proper rotations; first column keeps its direction
    raw = torch.randn(7, 2, 6, dtype=dtype, generator=torch.Generator().manual_seed(0))
    Rr = rotation_6d_to_matrix(raw)
    eye = torch.eye(3, dtype=dtype)
    np.testing.assert_allclose((Rr.transpose(-1, -2) @ Rr).double().numpy(), eye.expand(7, 2, 3, 3).double().numpy(), atol=TOL[dtype])
    np.testing.assert_allclose(torch.det(Rr).double().numpy(), np.ones((7, 2)), atol=TOL[dtype])
    a1 = raw[..., :3] / raw[..., :3].norm(dim=-1, keepdim=True)
    np.testing.assert_allclose(Rr[..., :, 0].double().numpy(), a1.double().numpy(), atol=TOL[dtype])


@pytest.mark.parametrize("dtype", DTYPES)
def test_pose_from_action_round_trip(dtype):
    rng = np.random.default_rng(10)
    a = np.concatenate([rng.normal(size=(2, 8, 3)) * 0.05, _random_rotvecs(rng, (2, 8), max_angle=3.0)], -1)
    T = pose_from_action(torch.tensor(a, dtype=dtype))
    assert T.shape == (2, 8, 4, 4)
    R_ref = Rotation.from_rotvec(a[..., 3:].reshape(-1, 3)).as_matrix().reshape(2, 8, 3, 3)
    np.testing.assert_allclose(T[..., :3, :3].double().numpy(), R_ref, atol=TOL[dtype])
    np.testing.assert_allclose(T[..., :3, 3].double().numpy(), a[..., :3], atol=TOL[dtype])
    np.testing.assert_allclose(T[..., 3, :].double().numpy(), np.broadcast_to([0, 0, 0, 1.0], (2, 8, 4)))
    np.testing.assert_allclose(action_from_pose(T).double().numpy(), a, atol=20 * TOL[dtype])


# ------------------------------------------------------------------------ registration


def _scipy_registration(src, dst, w):
    """Independent reference: weighted centroids + scipy's Wahba solver (proper rotation)."""
    m = w > 0
    mu_s = (w[:, None] * src).sum(0) / w.sum()
    mu_d = (w[:, None] * dst).sum(0) / w.sum()
    rot, _ = Rotation.align_vectors((dst - mu_d)[m], (src - mu_s)[m], weights=w[m])
    T = np.eye(4)
    T[:3, :3] = rot.as_matrix()
    T[:3, 3] = mu_d - rot.apply(mu_s)
    return T


@pytest.mark.parametrize("method", ["svd", "horn"])
@pytest.mark.parametrize("dtype", DTYPES)
def test_registration_recovers_transforms_batched_masked(method, dtype):
    rng = np.random.default_rng(11)
    B, N = 24, 60
    rot = Rotation.random(B, random_state=12)
    t = rng.normal(size=(B, 3)) * 0.3
    src = rng.normal(size=(B, N, 3)) * 0.1
    clean = np.einsum("bij,bnj->bni", rot.as_matrix(), src) + t[:, None]
    noise = rng.normal(size=clean.shape) * 1e-4  # 0.1 mm on a ~10 cm object
    dst = clean + noise
    # different set sizes per batch element (3..60 points), soft weights on the kept points
    counts = rng.integers(3, N + 1, size=B)
    counts[0] = N
    w = np.zeros((B, N))
    for b in range(B):
        keep = rng.permutation(N)[: counts[b]]
        w[b, keep] = rng.uniform(0.5, 2.0, size=counts[b])
    dst_garbage = np.where(w[..., None] > 0, dst, np.nan)  # ignored points may hold anything
    T, valid = weighted_rigid_registration(
        torch.tensor(src, dtype=dtype), torch.tensor(dst_garbage, dtype=dtype), torch.tensor(w, dtype=dtype), method=method
    )
    assert T.shape == (B, 4, 4) and valid.shape == (B,) and valid.all()
    assert torch.isfinite(T).all()
    T = T.double().numpy()
    for b in range(B):
        ref = _scipy_registration(src[b], dst[b], w[b])
        # same optimum as the independent solver
        np.testing.assert_allclose(T[b], ref, atol=2e-4 if dtype == torch.float32 else 1e-8)
        # close to the true transform (noise 1e-4 m on >= 3 points spread over ~0.1 m)
        if counts[b] >= 10:
            ang = Rotation.from_matrix(T[b, :3, :3] @ rot[b].as_matrix().T).magnitude()
            assert ang < 1e-2, ang
            assert np.abs(T[b, :3, 3] - t[b]).max() < 2e-3


@pytest.mark.parametrize("method", ["svd", "horn"])
def test_registration_exact_and_batch_shapes(method):
    rng = np.random.default_rng(13)
    rot = Rotation.random(6, random_state=14)
    t = rng.normal(size=(6, 3))
    src = rng.normal(size=(6, 9, 3))
    dst = np.einsum("bij,bnj->bni", rot.as_matrix(), src) + t[:, None]
    T, valid = weighted_rigid_registration(
        torch.tensor(src).view(2, 3, 9, 3), torch.tensor(dst).view(2, 3, 9, 3), torch.ones(2, 3, 9, dtype=torch.float64), method=method
    )
    assert T.shape == (2, 3, 4, 4) and valid.shape == (2, 3) and valid.all()
    T = T.view(6, 4, 4).numpy()
    np.testing.assert_allclose(T[:, :3, :3], rot.as_matrix(), atol=1e-9)
    np.testing.assert_allclose(T[:, :3, 3], t, atol=1e-9)


@pytest.mark.parametrize("method", ["svd", "horn"])
def test_registration_reflection_case(method):
    # dst is the mirror image (x -> -x) of a non-planar point set: the unconstrained
    # orthogonal Procrustes solution is the reflection diag(-1, 1, 1) (det -1).
    src = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1], [0.3, 0.4, 0.5], [-0.2, 0.1, 0.0]])
    dst = src * np.array([-1.0, 1, 1])
    w = np.ones(5)
    # naive SVD (no determinant fix), computed here by hand
    mu_s, mu_d = src.mean(0), dst.mean(0)
    H = (src - mu_s).T @ (dst - mu_d)
    U, _, Vt = np.linalg.svd(H)
    naive = Vt.T @ U.T
    assert np.linalg.det(naive) < 0
    T, valid = weighted_rigid_registration(torch.tensor(src), torch.tensor(dst), torch.tensor(w), method=method)
    R = T[:3, :3].numpy()
    assert valid and abs(np.linalg.det(R) - 1) < 1e-9
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-9)
    ref = _scipy_registration(src, dst, w)  # best proper rotation

    def cost(M):
        return (((src @ M[:3, :3].T + M[:3, 3]) - dst) ** 2).sum()

    assert cost(T.numpy()) <= cost(ref) + 1e-9


@pytest.mark.parametrize("method", ["svd", "horn"])
@pytest.mark.parametrize("dtype", DTYPES)
def test_registration_degenerate_inputs(method, dtype):
    B, N = 6, 8
    src = torch.randn(B, N, 3, dtype=dtype, generator=torch.Generator().manual_seed(0))
    dst = src + 0.1
    w = torch.zeros(B, N, dtype=dtype)
    w[0, :2] = 1  # 2 points -> invalid
    w[1, :] = 0  # no points -> invalid
    w[2, :3] = 1  # 3 points -> valid
    w[3, :] = 1  # all points, but collinear (below)
    w[4, :3] = 1  # 3 collinear points
    w[5, :] = 1  # all points identical
    line = torch.linspace(0, 1, N, dtype=dtype)[:, None] * torch.tensor([1.0, 2.0, -0.5], dtype=dtype)
    src[3] = line
    dst[3] = line * torch.tensor([1.0, 1.0, 1.0], dtype=dtype) + 0.3
    src[4] = line
    dst[4] = line.flip(0)
    src[5] = 0.5
    dst[5] = -0.5
    T, valid = weighted_rigid_registration(src, dst, w, method=method)
    assert valid.tolist() == [False, False, True, True, True, True]
    assert torch.isfinite(T).all()
    eye = torch.eye(4, dtype=dtype)
    assert torch.equal(T[0], eye) and torch.equal(T[1], eye)
    for b in range(2, B):
        R = T[b, :3, :3]
        assert torch.allclose(R.T @ R, torch.eye(3, dtype=dtype), atol=1e-5)
        assert abs(torch.det(R).item() - 1) < 1e-5
    # the collinear case still maps the line onto its image
    mapped = transform_points(T[3], src[3])
    assert torch.allclose(mapped, dst[3], atol=1e-5)


def test_registration_horn_traces_as_one_graph():
    """method="horn" has no host syncs / data-dependent shapes: dynamo traces it whole."""
    src = torch.randn(5, 20, 3, generator=torch.Generator().manual_seed(1))
    dst = src @ so3_exp(torch.tensor([0.3, -0.2, 0.5])).T + 0.1
    w = torch.ones(5, 20)
    ref, _ = weighted_rigid_registration(src, dst, w, method="horn")
    torch._dynamo.reset()
    try:
        fn = torch.compile(lambda a, b, c: weighted_rigid_registration(a, b, c, method="horn"), backend="eager", fullgraph=True)
        T, valid = fn(src, dst, w)
    finally:
        torch._dynamo.reset()
    assert valid.all() and torch.allclose(T, ref)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_registration_cuda_graph_capture():
    dev = torch.device("cuda")
    src = torch.randn(64, 50, 3, device=dev)
    R = so3_exp(torch.randn(64, 3, device=dev))
    dst = src @ R.transpose(-1, -2) + 0.1
    w = (torch.rand(64, 50, device=dev) > 0.3).float()
    weighted_rigid_registration(src, dst, w, method="horn")  # warm up
    torch.cuda.synchronize()
    g = torch.cuda.CUDAGraph()
    with torch.cuda.graph(g):
        T_g, valid_g = weighted_rigid_registration(src, dst, w, method="horn")
    g.replay()
    torch.cuda.synchronize()
    T_ref, _ = weighted_rigid_registration(src.cpu().double(), dst.cpu().double(), w.cpu().double(), method="svd")
    assert valid_g.all()
    assert torch.allclose(T_g.cpu().double(), T_ref, atol=1e-4)
