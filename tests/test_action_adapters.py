"""Tests of lerobot_rnd.action_adapters (CPU; CUDA case skipped without a GPU)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from lerobot_rnd.action_adapters import (
    AbsoluteEEPoseAdapter,
    ActionAdapter,
    EEDeltaAdapter,
    EEPositionDeltaAdapter,
    JointPositionAdapter,
    chunk_to_vector,
    make_action_adapter,
    vector_to_chunk,
)
from tests.helpers import six_joint_urdf

DT = torch.float64


def random_pose(*shape, seed=0, trans_scale=0.5):
    """Random rigid transforms (*shape, 4, 4) built with scipy (independent of geometry.py)."""
    rng = np.random.default_rng(seed)
    n = int(np.prod(shape)) if shape else 1
    T = np.tile(np.eye(4), (n, 1, 1))
    T[:, :3, :3] = Rotation.random(n, random_state=rng).as_matrix()
    T[:, :3, 3] = rng.normal(size=(n, 3)) * trans_scale
    return torch.tensor(T.reshape(*shape, 4, 4), dtype=DT)


def gripper_values(*shape, seed=0):
    g = torch.rand(*shape, generator=torch.Generator().manual_seed(seed), dtype=DT) * 2 - 1
    return torch.where(g > 0, torch.ones_like(g), -torch.ones_like(g))


def rot_err_deg(Ra, Rb):
    Rrel = Ra.transpose(-1, -2) @ Rb
    c = ((Rrel.diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2).clamp(-1, 1)
    return torch.rad2deg(torch.arccos(c))


# ------------------------------------------------------------------ chunk <-> vector


def test_chunk_vector_roundtrip():
    v = torch.randn(3, 8, 7, dtype=DT) * 0.3
    v[..., 6] = gripper_values(3, 8)
    T, g = vector_to_chunk(v)
    assert T.shape == (3, 8, 4, 4) and g.shape == (3, 8)
    torch.testing.assert_close(chunk_to_vector(T, g), v)
    # translation and rotation follow the DESIGN.md convention T(a) = [exp(a[3:6]) | a[0:3]]
    R_ref = Rotation.from_rotvec(v[0, 0, 3:6].numpy()).as_matrix()
    np.testing.assert_allclose(T[0, 0, :3, :3].numpy(), R_ref, atol=1e-12)
    np.testing.assert_allclose(T[0, 0, :3, 3].numpy(), v[0, 0, :3].numpy())


# ------------------------------------------------------------------ 1. position deltas


def test_ee_position_delta_hand_example():
    ad = EEPositionDeltaAdapter(scale=0.01)
    T_world_ee = torch.eye(4, dtype=DT)
    T_world_ee[:3, :3] = torch.tensor(Rotation.from_euler("z", 90, degrees=True).as_matrix())
    T_world_ee[:3, 3] = torch.tensor([0.3, -0.2, 0.5])
    action = torch.tensor([[1.0, 0.0, 0.0, -0.5], [0.0, 1.0, 0.0, 0.3]], dtype=DT)
    T, g = ad.to_rnd(action, T_world_ee)
    # world displacements (0.01,0,0) then (0.01,0.01,0); EE x = world y, EE y = -world x
    torch.testing.assert_close(T[:, :3, 3], torch.tensor([[0.0, -0.01, 0.0], [0.01, -0.01, 0.0]], dtype=DT))
    torch.testing.assert_close(T[:, :3, :3], torch.eye(3, dtype=DT).expand(2, 3, 3))
    torch.testing.assert_close(g, torch.tensor([-1.0, 1.0], dtype=DT))
    # world targets are where the mocap would go
    T_world_target = T_world_ee @ T
    expected = torch.tensor([[0.31, -0.2, 0.5], [0.31, -0.19, 0.5]], dtype=DT)
    torch.testing.assert_close(T_world_target[:, :3, 3], expected)
    back = ad.from_rnd(T, g, T_world_ee)
    torch.testing.assert_close(back, torch.tensor([[1.0, 0.0, 0.0, -1.0], [0.0, 1.0, 0.0, 1.0]], dtype=DT))


def test_ee_position_delta_roundtrip_and_clip():
    ad = EEPositionDeltaAdapter(scale=[0.01, 0.02, 0.005])
    T_world_ee = random_pose(4, 5, seed=1)
    action = torch.rand(4, 5, 8, 4, dtype=DT) * 2 - 1
    action[..., 3] = gripper_values(4, 5, 8)
    T, g = ad.to_rnd(action, T_world_ee)
    assert T.shape == (4, 5, 8, 4, 4)
    torch.testing.assert_close(ad.from_rnd(T, g, T_world_ee), action)
    # broadcasting: one EE pose for the whole batch
    T1, _ = ad.to_rnd(action, T_world_ee[0, 0])
    torch.testing.assert_close(T1[0, 0], ad.to_rnd(action[0, 0], T_world_ee[0, 0])[0])
    # out of range displacements are clipped like MetaWorld
    big = T.clone()
    big[..., :3, 3] *= 10
    out = ad.from_rnd(big, g, T_world_ee)
    assert out[..., :3].abs().max() <= 1.0 and out[..., :3].abs().max() == 1.0
    unclipped = EEPositionDeltaAdapter(scale=[0.01, 0.02, 0.005], clip=False).from_rnd(big, g, T_world_ee)
    assert unclipped[..., :3].abs().max() > 1.0


# ------------------------------------------------------------------ 2. pose deltas


def _ee_delta_reference(action, T_world_ee, frame, pos_scale, rot_scale):
    """Sequential numpy/scipy composition of one chunk (T, 7) -> world targets (T, 4, 4)."""
    cur = T_world_ee.numpy().copy()
    out = []
    for a in action.numpy():
        D = Rotation.from_rotvec(a[3:6] * rot_scale).as_matrix()
        nxt = cur.copy()
        if frame == "ee":
            step = np.eye(4)
            step[:3, :3], step[:3, 3] = D, a[:3] * pos_scale
            nxt = cur @ step
        else:
            nxt[:3, :3] = D @ cur[:3, :3]
            nxt[:3, 3] = cur[:3, 3] + a[:3] * pos_scale
        out.append(nxt)
        cur = nxt
    return np.stack(out)


@pytest.mark.parametrize("frame", ["ee", "world"])
def test_ee_delta_against_sequential_reference_and_roundtrip(frame):
    ad = make_action_adapter("ee_delta", pos_scale=0.05, rot_scale=0.2, frame=frame)
    T_world_ee = random_pose(3, seed=2)
    action = torch.rand(3, 7, 7, dtype=DT) * 2 - 1
    action[..., 6] = gripper_values(3, 7)
    T, g = ad.to_rnd(action, T_world_ee)
    for b in range(3):
        ref = _ee_delta_reference(action[b], T_world_ee[b], frame, 0.05, 0.2)
        np.testing.assert_allclose((T_world_ee[b] @ T[b]).numpy(), ref, atol=1e-10)
    torch.testing.assert_close(ad.from_rnd(T, g, T_world_ee), action)


def test_ee_delta_horizon_one_and_empty_batch():
    ad = EEDeltaAdapter()
    a = torch.tensor([[[0.1, 0.2, 0.3, 0.0, 0.0, 0.5, 1.0]]], dtype=DT)
    T, g = ad.to_rnd(a, torch.eye(4, dtype=DT))
    torch.testing.assert_close(T[0, 0, :3, 3], a[0, 0, :3])
    torch.testing.assert_close(ad.from_rnd(T, g, torch.eye(4, dtype=DT)), a)
    T0, g0 = ad.to_rnd(torch.zeros(0, 8, 7), torch.eye(4))
    assert T0.shape == (0, 8, 4, 4) and g0.shape == (0, 8)


# ------------------------------------------------------------------ 3. absolute poses


@pytest.mark.parametrize("fmt", ["quat_wxyz", "quat_xyzw", "rotvec", "rot6d"])
def test_absolute_against_scipy_and_roundtrip(fmt):
    rng = np.random.default_rng(3)
    B, T = 2, 6
    T_world_ee = random_pose(B, seed=4)
    rots = Rotation.random(B * T, random_state=rng)
    pos = rng.normal(size=(B * T, 3))
    if fmt == "quat_wxyz":
        r = rots.as_quat()[:, [3, 0, 1, 2]]
    elif fmt == "quat_xyzw":
        r = rots.as_quat()
    elif fmt == "rotvec":
        r = rots.as_rotvec()
    else:
        m = rots.as_matrix()
        r = np.concatenate([m[:, :, 0], m[:, :, 1]], axis=-1)
    grip = rng.uniform(-1, 1, size=(B * T, 1))
    action = torch.tensor(np.concatenate([pos, r, grip], -1).reshape(B, T, -1), dtype=DT)
    ad = AbsoluteEEPoseAdapter(rotation_format=fmt)
    assert ad.action_dim == action.shape[-1]
    T_ee_target, g = ad.to_rnd(action, T_world_ee)
    M = np.tile(np.eye(4), (B * T, 1, 1))
    M[:, :3, :3], M[:, :3, 3] = rots.as_matrix(), pos
    ref = np.linalg.inv(T_world_ee.numpy())[:, None] @ M.reshape(B, T, 4, 4)
    np.testing.assert_allclose(T_ee_target.numpy(), ref, atol=1e-10)
    torch.testing.assert_close(g, torch.tensor(np.sign(grip[:, 0]).reshape(B, T), dtype=DT))
    back = ad.from_rnd(T_ee_target, torch.tensor(grip[:, 0].reshape(B, T)), T_world_ee)
    if fmt.startswith("quat"):  # q and -q are the same rotation
        qs = slice(3, 7)
        sign = torch.sign((back[..., qs] * action[..., qs]).sum(-1, keepdim=True))
        back = torch.cat([back[..., :3], back[..., qs] * sign, back[..., 7:]], -1)
    torch.testing.assert_close(back, action)


def test_absolute_with_frame_offset():
    T_world_frame = random_pose(seed=5)
    ad = AbsoluteEEPoseAdapter(rotation_format="rotvec", T_world_frame=T_world_frame.tolist(), gripper=False)
    T_world_ee = random_pose(seed=6)
    action = torch.randn(4, 6, dtype=DT) * 0.5
    T, g = ad.to_rnd(action, T_world_ee)
    assert torch.all(g == -1)
    T_frame_target = torch.eye(4, dtype=DT).repeat(4, 1, 1)
    T_frame_target[:, :3, :3] = torch.tensor(Rotation.from_rotvec(action[:, 3:].numpy()).as_matrix())
    T_frame_target[:, :3, 3] = action[:, :3]
    torch.testing.assert_close(T_world_ee @ T, T_world_frame @ T_frame_target)
    torch.testing.assert_close(ad.from_rnd(T, None, T_world_ee), action)


# ------------------------------------------------------------------ 4. joint positions

@pytest.fixture(scope="module")
def joint_adapter():
    return JointPositionAdapter(urdf=six_joint_urdf(), ee_link="tool", ik_max_iterations=200)


def test_joint_fk_planar_hand_computed(joint_adapter):
    assert joint_adapter.joint_names == ["j1", "j2", "j3", "j4", "j5", "j6"]
    a, b, c = 0.4, 0.7, -0.6
    q = torch.tensor([[0, a, b, 0, 0, 0], [c, a, b, 0, 0, 0]], dtype=DT)
    T = joint_adapter.forward_kinematics(q)
    # pitch joints rotate about y: x-axis -> (cos, 0, -sin); 0.45 m from j3 to the tool
    x = 0.3 * math.cos(a) + 0.45 * math.cos(a + b)
    z = 0.1 + 0.2 - 0.3 * math.sin(a) - 0.45 * math.sin(a + b)
    Ry = Rotation.from_euler("y", a + b).as_matrix()
    np.testing.assert_allclose(T[0, :3, 3].numpy(), [x, 0, z], atol=1e-9)
    np.testing.assert_allclose(T[0, :3, :3].numpy(), Ry, atol=1e-9)
    # base yaw rotates the planar solution about z
    Rz = Rotation.from_euler("z", c).as_matrix()
    np.testing.assert_allclose(T[1, :3, 3].numpy(), Rz @ [x, 0, z], atol=1e-9)
    np.testing.assert_allclose(T[1, :3, :3].numpy(), Rz @ Ry, atol=1e-9)


def _random_joint_chunk(B, T, seed):
    g = torch.Generator().manual_seed(seed)
    q_home = torch.tensor([0.2, -0.5, 1.2, 0.3, 0.8, -0.4], dtype=DT)
    q_now = q_home + 0.2 * (torch.rand(B, 6, generator=g, dtype=DT) - 0.5)
    steps = 0.08 * (torch.rand(B, T, 6, generator=g, dtype=DT) - 0.5)
    q_target = q_now[:, None] + torch.cumsum(steps, dim=1)
    return q_now, q_target


def test_joint_to_rnd_and_ik_roundtrip(joint_adapter):
    ad = joint_adapter
    B, T = 3, 8
    q_now, q_target = _random_joint_chunk(B, T, seed=7)
    grip = torch.tensor([0.0, 1.0, 0.2, 0.9] * 6, dtype=DT)[: B * T].reshape(B, T)
    ad2 = JointPositionAdapter(urdf=six_joint_urdf(), ee_link="tool", gripper_open=0.0, gripper_closed=1.0)
    action = torch.cat([q_target, grip[..., None]], -1)
    T_world_ee = ad.forward_kinematics(q_now)
    T_rnd, g = ad2.to_rnd(action, T_world_ee, state=q_now)
    torch.testing.assert_close(g, torch.where(grip > 0.5, 1.0, -1.0).to(DT))
    # reference: relative pose of the two FK results
    ref = torch.linalg.inv(T_world_ee)[:, None] @ ad.forward_kinematics(q_target)
    torch.testing.assert_close(T_rnd, ref)
    # without state the current pose comes from T_world_ee (T_world_base = identity)
    torch.testing.assert_close(ad2.to_rnd(action, T_world_ee)[0], ref)
    # IK back to joints, seeded from the current joints
    out = ad2.from_rnd(T_rnd, g, T_world_ee, state=q_now)
    assert out.shape == action.shape
    T_reached = ad.forward_kinematics(out[..., :6])
    T_goal = ad.forward_kinematics(q_target)
    assert (T_reached[..., :3, 3] - T_goal[..., :3, 3]).norm(dim=-1).max() < 1e-3
    assert rot_err_deg(T_reached[..., :3, :3], T_goal[..., :3, :3]).max() < 1.0
    assert bool(ad2.last_ik_info["converged"].all())
    torch.testing.assert_close(out[..., 6], torch.where(g > 0, 1.0, 0.0).to(DT))


def test_joint_ik_float32_state_with_extra_dims(joint_adapter):
    ad = JointPositionAdapter(
        urdf=six_joint_urdf(), ee_link="tool", gripper=False, state_joint_indices=[1, 2, 3, 4, 5, 6]
    )
    q_now, q_target = _random_joint_chunk(2, 4, seed=8)
    q_now, q_target = q_now.float(), q_target.float()
    state = torch.cat([torch.full((2, 1), 9.0), q_now, torch.zeros(2, 1)], -1)  # [junk, joints, gripper]
    T_world_ee = ad.forward_kinematics(q_now)
    T_rnd, _ = ad.to_rnd(q_target, T_world_ee, state=state)
    q = ad.from_rnd(T_rnd, None, T_world_ee, state=state)
    T_reached, T_goal = ad.forward_kinematics(q), ad.forward_kinematics(q_target)
    assert (T_reached[..., :3, 3] - T_goal[..., :3, 3]).norm(dim=-1).max() < 1e-3
    assert rot_err_deg(T_reached[..., :3, :3].double(), T_goal[..., :3, :3].double()).max() < 1.0


def test_joint_errors(joint_adapter):
    with pytest.raises(ValueError, match="j1, j2, j3, j4, j5, j6, gripper"):
        joint_adapter.to_rnd(torch.zeros(2, 8, 6), torch.eye(4))
    T = torch.eye(4).expand(2, 8, 4, 4)
    with pytest.raises(ValueError, match="state"):
        joint_adapter.from_rnd(T, torch.ones(2, 8), torch.eye(4))
    with pytest.raises(ValueError, match="nope"):
        JointPositionAdapter(urdf=six_joint_urdf(), ee_link="nope")


# ------------------------------------------------------------------ factory, serialisation


def test_factory_and_dict_roundtrip(joint_adapter):
    adapters = [
        make_action_adapter("ee_position_delta", scale=0.02),
        make_action_adapter("ee_delta", frame="world", pos_scale=0.1, clip=1.0),
        make_action_adapter("ee_absolute", rotation_format="rot6d", gripper_open=0.08, gripper_closed=0.0),
        joint_adapter,
    ]
    dims = [4, 7, 10, 7]
    for ad, dim in zip(adapters, dims, strict=True):
        assert isinstance(ad, ActionAdapter) and ad.action_dim == dim
        d = json.loads(json.dumps(ad.to_dict()))
        ad2 = ActionAdapter.from_dict(d)
        assert type(ad2) is type(ad) and ad2.to_dict() == ad.to_dict()
    with pytest.raises(ValueError, match="unknown action adapter"):
        make_action_adapter("joint_velocity")
    with pytest.raises(ValueError, match="rotation_format"):
        make_action_adapter("ee_absolute", rotation_format="euler")


def test_gripper_mapping_inverted_values():
    ad = EEPositionDeltaAdapter(gripper_open=0.08, gripper_closed=0.0)  # finger width: small = closed
    g = ad.gripper_to_rnd(torch.tensor([0.08, 0.05, 0.03, 0.0]))
    torch.testing.assert_close(g, torch.tensor([-1.0, -1.0, 1.0, 1.0]))
    torch.testing.assert_close(ad.gripper_from_rnd(torch.tensor([-1.0, 1.0])), torch.tensor([0.08, 0.0]))


# ------------------------------------------------------------------ validation


def test_validation_errors():
    ad = EEPositionDeltaAdapter()
    with pytest.raises(ValueError, match=r"expects action dimension 4 \(dx, dy, dz, gripper\).*dimension 7"):
        ad.to_rnd(torch.zeros(2, 8, 7), torch.eye(4))
    bad = torch.zeros(2, 8, 4)
    bad[1, 3, 0] = float("nan")
    with pytest.raises(ValueError, match="NaN"):
        ad.to_rnd(bad, torch.eye(4))
    with pytest.raises(ValueError, match="not a rigid transform"):
        ad.to_rnd(torch.zeros(2, 8, 4), 2 * torch.eye(4))
    reflect = torch.diag(torch.tensor([1.0, 1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match="not a rigid transform"):
        ad.to_rnd(torch.zeros(2, 8, 4), reflect)
    with pytest.raises(ValueError, match=r"\(\.\.\., 4, 4\)"):
        ad.to_rnd(torch.zeros(2, 8, 4), torch.eye(3))
    with pytest.raises(ValueError, match="NaN"):
        T = torch.eye(4).repeat(8, 1, 1)
        T[2, 0, 3] = float("inf")
        ad.from_rnd(T, torch.ones(8), torch.eye(4))
    with pytest.raises(ValueError, match="frame"):
        EEDeltaAdapter(frame="base")


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_roundtrips(joint_adapter):
    dev = torch.device("cuda")
    T_world_ee = random_pose(4, seed=11).float().to(dev)
    cases = [
        (EEPositionDeltaAdapter(), 4),
        (EEDeltaAdapter(frame="world"), 7),
        (AbsoluteEEPoseAdapter(rotation_format="rot6d"), 10),
    ]
    for ad, A in cases:
        if A == 10:
            v = torch.cat([torch.randn(4, 8, 6, device=dev) * 0.3, torch.ones(4, 8, 1, device=dev)], -1)
            T, g = vector_to_chunk(v)
            a = ad.from_rnd(T, g, T_world_ee)
        else:
            a = (torch.rand(4, 8, A, device=dev) * 2 - 1).clamp(-0.99, 0.99)
        T, g = ad.to_rnd(a, T_world_ee)
        assert T.device.type == "cuda"
        torch.testing.assert_close(ad.from_rnd(T, g, T_world_ee), a, atol=1e-4, rtol=1e-4)
    q_now, q_target = _random_joint_chunk(2, 4, seed=12)
    q_now, q_target = q_now.float().to(dev), q_target.float().to(dev)
    action = torch.cat([q_target, torch.ones(2, 4, 1, device=dev)], -1)
    T_w = joint_adapter.forward_kinematics(q_now)
    T, g = joint_adapter.to_rnd(action, T_w, state=q_now)
    q = joint_adapter.from_rnd(T, g, T_w, state=q_now)
    fk = joint_adapter.forward_kinematics
    err = fk(q[..., :6])[..., :3, 3] - fk(q_target)[..., :3, 3]
    assert err.norm(dim=-1).max() < 1e-3
