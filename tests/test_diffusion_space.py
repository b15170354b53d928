"""What R&D diffuses (lerobot_rnd/diffusion_space.py, `--policy.diffusion_space`): the paper's 6-D end-effector
motion, or an arm's joint targets with the gripper drawn at their forward kinematics. References: scipy's rotation
vectors, MuJoCo's kinematics of the upstream SO-101 model, the dataset's own joint columns."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from lerobot_rnd import so101
from lerobot_rnd.action_adapters import ActionAdapter
from lerobot_rnd.diffusion_space import EEPoseSpace, JointSpace
from lerobot_rnd.statistics import MinMaxStats
from tests.helpers import make_policy, training_batch
from tests.test_so101 import GRIPPER_FRAME_PITCH, GRIPPER_FRAME_XYZ, _mujoco_poses, _ry

JOINT_MIN = torch.tensor([-40.0, -60.0, -20.0, 20.0, -50.0])  # degrees
JOINT_MAX = torch.tensor([40.0, 20.0, 60.0, 90.0, 50.0])


@pytest.fixture(scope="module")
def toy_so101_root(tmp_path_factory):
    from lerobot_rnd.testing import record_toy_so101_dataset

    return record_toy_so101_dataset(tmp_path_factory.mktemp("toy_so101") / "toy_so101")


def _joint_space(state_now: torch.Tensor) -> JointSpace:
    stats = MinMaxStats((5,))
    stats.set(JOINT_MIN, JOINT_MAX)
    return JointSpace(stats, ActionAdapter.from_dict(so101.so101_action_adapter()), state_now)


def _mujoco_T_base_ee(q_deg: np.ndarray) -> np.ndarray:
    """(N, 4, 4) gripper frame of the MJCF's kinematics at body joints q_deg (N, 5) degrees, converted by hand."""
    q_rad = np.concatenate([np.radians(q_deg), np.zeros((len(q_deg), 1))], axis=1)
    poses, _ = _mujoco_poses(q_rad)
    T_link_frame = np.eye(4)
    T_link_frame[:3, :3] = _ry(GRIPPER_FRAME_PITCH)
    T_link_frame[:3, 3] = GRIPPER_FRAME_XYZ
    return np.stack([T_body @ T_link_frame for T_body, _, _ in poses])


def test_joint_space_draws_the_gripper_at_mujocos_forward_kinematics_of_the_joints():
    rng = np.random.default_rng(0)
    q_now = rng.uniform(JOINT_MIN.numpy(), JOINT_MAX.numpy(), size=(2, 5))
    state_now = torch.tensor(np.concatenate([q_now, [[50.0], [80.0]]], axis=1), dtype=torch.float32)
    space = _joint_space(state_now)
    a = torch.tensor(rng.uniform(-1, 1, size=(2, 3, 5)), dtype=torch.float32)
    T_ee_target = space.to_pose(a)
    assert T_ee_target.shape == (2, 3, 4, 4)
    q_target = (a.double() + 1) / 2 * (JOINT_MAX - JOINT_MIN).double() + JOINT_MIN.double()  # by hand
    T_now = _mujoco_T_base_ee(q_now)
    T_target = _mujoco_T_base_ee(q_target.reshape(-1, 5).numpy()).reshape(2, 3, 4, 4)
    expected = np.linalg.inv(T_now)[:, None] @ T_target
    np.testing.assert_allclose(T_ee_target.double().numpy(), expected, atol=2e-4)


def test_joint_space_from_pose_finds_the_joints_of_a_reachable_pose_and_stays_finite_for_an_unreachable_one():
    rng = np.random.default_rng(1)
    q_now = rng.uniform(-20, 20, size=(3, 5)) + np.array([0.0, -20.0, 20.0, 55.0, 0.0])
    state_now = torch.tensor(np.concatenate([q_now, np.full((3, 1), 50.0)], axis=1), dtype=torch.float32)
    space = _joint_space(state_now)
    # targets a few degrees from the current joints: IK seeded there lands on them
    q_target = torch.tensor(q_now[:, None] + rng.uniform(-6, 6, size=(3, 4, 5)), dtype=torch.float32)
    a = 2 * (q_target - JOINT_MIN) / (JOINT_MAX - JOINT_MIN) - 1
    back = space.from_pose(space.to_pose(a))
    q_back = (back + 1) / 2 * (JOINT_MAX - JOINT_MIN) + JOINT_MIN
    torch.testing.assert_close(q_back, q_target, atol=0.2, rtol=0)  # degrees
    # a pose turned 0.5 rad about the gripper's x axis, which a 5-joint arm cannot add: a finite compromise
    T_turned = space.to_pose(a).clone()
    T_turned[..., :3, :3] = T_turned[..., :3, :3] @ torch.tensor(
        Rotation.from_rotvec([0.5, 0.0, 0.0]).as_matrix(), dtype=torch.float32
    )
    assert bool(torch.isfinite(space.from_pose(T_turned)).all())


def test_ee_pose_space_is_the_rotation_vector_of_the_motion():
    stats = MinMaxStats((6,))
    lo = torch.tensor([-0.1, -0.1, -0.1, -0.5, -0.5, -0.5])
    stats.set(lo, -lo)
    space = EEPoseSpace(stats)
    a = torch.tensor([[[0.2, -0.4, 0.6, 0.5, -0.3, 0.1]]])
    T = space.to_pose(a)[0, 0].double().numpy()
    x = (a[0, 0].double() * -lo.double()).numpy()  # symmetric range: unnormalised = a * max
    np.testing.assert_allclose(T[:3, 3], x[:3], atol=1e-6)
    np.testing.assert_allclose(T[:3, :3], Rotation.from_rotvec(x[3:]).as_matrix(), atol=1e-6)
    torch.testing.assert_close(space.from_pose(space.to_pose(a)), a, atol=1e-5, rtol=0)


def test_joints_needs_a_joint_position_adapter_and_a_known_value(toy_dataset_root):
    from lerobot_rnd.configuration_rnd import RnDConfig

    with pytest.raises(ValueError, match="diffusion_space.*joint_positions.*ee_pose"):
        make_policy(toy_dataset_root, diffusion_space="joints")  # the toy arm's actions are xyz deltas
    with pytest.raises(ValueError, match="`diffusion_space` must be one of"):
        RnDConfig(diffusion_space="joint")


def test_joint_space_statistics_are_the_datasets_joint_ranges(toy_so101_root):
    import pandas as pd

    policy, _ = make_policy(toy_so101_root, diffusion_space="joints")
    model = policy.model
    assert model.action_dim == 5
    assert model.network.action_embed.in_features == 5 and model.network.action_head[-1].out_features == 5
    frames = pd.concat(pd.read_parquet(f) for f in sorted((toy_so101_root / "data").glob("**/*.parquet")))
    action = np.stack(frames["action"].to_numpy())[:, :5]
    lo, hi = action.min(0), action.max(0)
    pad = 0.05 * (hi - lo)  # statistics.STATS_MARGIN, written out
    np.testing.assert_allclose(model.action_stats.min.numpy(), lo - pad, atol=1e-3)
    np.testing.assert_allclose(model.action_stats.max.numpy(), hi + pad, atol=1e-3)


def test_joint_space_training_noises_the_dataset_joints_and_renders_them_where_mujoco_puts_them(toy_so101_root):
    policy, _ = make_policy(toy_so101_root, diffusion_space="joints")
    model = policy.model
    batch = training_batch(toy_so101_root, policy.config, n=2)
    images = policy._stack_images(batch)["observation.images"]
    state = batch["observation.state"]
    images, T_world_ee, gripper = model.prepare_observation(images, state)
    T_ee_target, _ = model.action_adapter.to_rnd(batch["action"], T_world_ee[:, -1], state=state[:, -1])
    x_target = model.diffusion_space(state[:, -1]).target(batch["action"], T_ee_target)
    sample = model.noisy_sample_targets(images, T_world_ee, gripper, T_ee_target, x_target, state[:, -1],
                                        generator=torch.Generator().manual_seed(0))  # fmt: skip
    torch.testing.assert_close(model.action_stats.unnormalize(sample["a_gt"]), batch["action"][..., :5],
                               atol=1e-3, rtol=0)  # fmt: skip
    q_noisy = model.action_stats.unnormalize(sample["a_noisy"]).double().numpy()  # (B, T, 5) degrees
    T_world_target = _mujoco_T_base_ee(q_noisy.reshape(-1, 5)).reshape(*q_noisy.shape[:2], 4, 4)  # base = world
    T_world_cam = sample["T_world_cam"].double().numpy()  # (B, T, C, 4, 4)
    expected = np.linalg.inv(T_world_cam) @ T_world_target[:, :, None]
    np.testing.assert_allclose(sample["T_cam_obj"].double().numpy(), expected, atol=5e-4)


class _ToTargetNetwork(torch.nn.Module):
    """Stands in for the denoiser: its action-space update takes any noisy action to `a_target` (B, T, D); no
    image-space prediction; gripper logits +5 (closed)."""

    def __init__(self, a_target: torch.Tensor):
        super().__init__()
        self.a_target = a_target

    def forward(self, obs_rgb, obs_points, future_rgb, future_points, gripper_state, timestep, noisy_action,
                patch_index=None, obs_tokens=None, **kwargs):
        return None, self.a_target - noisy_action, torch.full(noisy_action.shape[:2], 5.0)

    def embed_observation(self, obs_rgb, obs_points):
        return None


def test_a_joint_space_policy_returns_its_denoised_joints_and_round_trips_through_a_checkpoint(
    toy_so101_root, tmp_path
):
    from lerobot_rnd.modeling_rnd import RnDPolicy

    policy, _ = make_policy(toy_so101_root, diffusion_space="joints")
    policy.save_pretrained(tmp_path / "ckpt")
    loaded = RnDPolicy.from_pretrained(tmp_path / "ckpt")
    assert loaded.config.diffusion_space == "joints" and loaded.model.action_dim == 5
    torch.testing.assert_close(loaded.model.action_stats.max, policy.model.action_stats.max)

    batch = training_batch(toy_so101_root, policy.config, n=2)
    obs = {k: v for k, v in batch.items() if k != "action"}
    a_target = torch.tensor([0.5, -0.25, 0.0, 0.75, -0.5]).expand(2, policy.config.chunk_size, 5)
    loaded.model.network = _ToTargetNetwork(a_target)

    def no_ik(*args, **kwargs):
        raise AssertionError("a joint-space policy's action passed through IK")

    loaded.model.action_adapter.inverse_kinematics = no_ik  # the stand-in predicts no image-space update
    chunk = loaded.predict_action_chunk(obs)
    lo, hi = loaded.model.action_stats.min, loaded.model.action_stats.max
    expected = (a_target + 1) / 2 * (hi - lo) + lo  # the joints themselves: no IK between them and the action
    torch.testing.assert_close(chunk[..., :5], expected, atol=1e-4, rtol=0)
    closed = loaded.model.action_adapter.gripper_closed
    assert bool((chunk[..., 5] == closed).all()) and not math.isnan(closed)
