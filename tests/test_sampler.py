"""The R&D sampler against independent references: ground-truth displacements, an oracle denoiser, batching."""

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from lerobot_rnd.sampler import ddim_step, displacement_target, interpolation_step, register_point_update
from tests.helpers import make_policy as _make_policy


def _random_pose(rng, trans_scale=0.1):
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    T[:3, 3] = rng.normal(size=3) * trans_scale
    return T


def test_displacement_target_matches_per_point_rigid_motion():
    rng = np.random.default_rng(0)
    T_cam_noisy, T_cam_target = _random_pose(rng), _random_pose(rng)
    points = rng.normal(size=(3, 5, 7))  # (3, H, W)
    got = displacement_target(
        torch.tensor(points), torch.tensor(T_cam_noisy), torch.tensor(T_cam_target)
    ).numpy()
    # Reference: take each point back into the gripper frame at the noisy pose, then out at the target pose.
    for v in range(5):
        for u in range(7):
            p = np.append(points[:, v, u], 1.0)
            p_obj = np.linalg.solve(T_cam_noisy, p)
            expected = (T_cam_target @ p_obj)[:3] - points[:, v, u]
            np.testing.assert_allclose(got[:, v, u], expected, atol=1e-9)


def test_ddim_step_reaches_the_prediction_on_the_last_step_and_interpolation_is_translation_equivariant():
    x_k, x0 = torch.randn(10, 3), torch.randn(10, 3)
    np.testing.assert_allclose(ddim_step(x_k, x0, torch.tensor(0.3), torch.tensor(1.0)), x0, atol=1e-6)
    np.testing.assert_allclose(interpolation_step(x_k, x0, torch.tensor(0.3), torch.tensor(1.0)), x0, atol=1e-6)
    shift = torch.tensor([1.0, -2.0, 0.5])
    a = interpolation_step(x_k + shift, x0 + shift, torch.tensor(0.3), torch.tensor(0.6))
    b = interpolation_step(x_k, x0, torch.tensor(0.3), torch.tensor(0.6)) + shift
    np.testing.assert_allclose(a, b, atol=1e-5)


def test_register_point_update_pools_cameras_and_flags_invisible_steps():
    rng = np.random.default_rng(1)
    b, t, c, h, w = 2, 3, 2, 6, 5
    T_world_cam = torch.tensor(np.stack([_random_pose(rng, 1.0) for _ in range(c)]), dtype=torch.float64)
    T_world_cam = T_world_cam.expand(b, t, c, 4, 4)
    T_delta = torch.tensor(np.stack([[_random_pose(rng, 0.05) for _ in range(t)] for _ in range(b)]))
    pts_world = torch.tensor(rng.normal(size=(b, t, c, h * w, 3)))
    moved_world = torch.einsum("btij,btcnj->btcni", T_delta[..., :3, :3], pts_world) + T_delta[:, :, None, None, :3, 3]
    cam_from_world = torch.linalg.inv(T_world_cam)

    def to_cam(p):
        q = torch.einsum("btcij,btcnj->btcni", cam_from_world[..., :3, :3], p) + cam_from_world[..., None, :3, 3]
        return q.transpose(-1, -2).reshape(b, t, c, 3, h, w)

    mask = torch.zeros(b, t, c, h, w, dtype=torch.bool)
    mask[:, :, 0, :2, :3] = True  # 6 pixels in camera 0
    mask[:, :, 1, 4:, :] = True  # 10 pixels in camera 1
    mask[1, 2] = False  # nothing visible for one step
    mask[1, 2, 0, 0, :2] = True  # only 2 pixels: too few
    got, valid = register_point_update(to_cam(pts_world), to_cam(moved_world), mask, T_world_cam, min_points=3)
    expected_valid = torch.ones(b, t, dtype=torch.bool)
    expected_valid[1, 2] = False
    assert torch.equal(valid, expected_valid)
    np.testing.assert_allclose(got[valid].numpy(), T_delta[valid].numpy(), atol=1e-6)


class _OracleNetwork(torch.nn.Module):
    """Stands in for the ViT: returns the true image-space displacement and action update for a known target.

    The displacement is computed from the point map it is given and the camera poses, independently of the
    sampler's code: F = T_cam_target T_cam_noisy^-1 P - P per pixel.
    """

    def __init__(self, model, a_target_norm, T_world_ee_now):
        super().__init__()
        self.model = model
        self.a_target = a_target_norm
        self.T_world_ee_now = T_world_ee_now  # (B, 4, 4)

    def forward(self, rgb, point_map, gripper_state, timestep, noisy_action):
        from lerobot_rnd.geometry import pose_from_action

        m = self.model
        n_obs = m.config.n_obs_steps
        stats = m.action_stats
        T_ee_noisy = pose_from_action(stats.unnormalize(noisy_action.clamp(-1, 1)))
        T_ee_target = pose_from_action(stats.unnormalize(self.a_target))
        T_world_cam = m.rig.T_world_cam(self.T_world_ee_now[:, None].expand(-1, T_ee_noisy.shape[1], 4, 4))
        cam_from_world = torch.linalg.inv(T_world_cam)
        rel = cam_from_world @ (self.T_world_ee_now[:, None, None] @ T_ee_target[:, :, None]) @ torch.linalg.inv(
            cam_from_world @ (self.T_world_ee_now[:, None, None] @ T_ee_noisy[:, :, None])
        )
        points = point_map[:, n_obs:] * m.config.point_map_scale  # (B, T, C, 3, h, w)
        moved = torch.einsum("btcij,btcjhw->btcihw", rel[..., :3, :3], points) + rel[..., :3, 3, None, None]
        displacement = m.displacement_stats.normalize(moved - points)
        update = self.a_target - noisy_action
        logits = torch.ones(noisy_action.shape[:2])
        return displacement, update, logits


@pytest.mark.parametrize("variant", ["I", "AI"])
def test_sampler_with_an_oracle_denoiser_reaches_the_target(toy_dataset_root, variant):
    """Image-space path (I: SVD only) and the full R&D-AI sampler must land on the target action."""
    policy, _ = _make_policy(toy_dataset_root, variant=variant, num_inference_steps=4, final_action_step=False)
    model = policy.model
    b = 3
    state = torch.tensor([[0.02, -0.03, 0.21, 1.0], [-0.04, 0.02, 0.18, 1.0], [0.0, 0.05, 0.2, 1.0]])
    state = state[:, None].expand(b, 2, 4)
    images = torch.rand(b, 2, 2, 3, 64, 64)
    _, T_world_ee, gripper = model.prepare_observation(images, state)
    # A target chunk inside the data range: the gripper moves a few cm and turns by up to ~10 degrees.
    rng = np.random.default_rng(3)
    a_target = torch.tensor(
        np.concatenate([rng.uniform(-0.02, 0.02, (b, 4, 3)), rng.uniform(-0.15, 0.15, (b, 4, 3))], -1),
        dtype=torch.float32,
    )
    model.action_stats.set(torch.full((6,), -0.2), torch.full((6,), 0.2))
    a_target_norm = model.action_stats.normalize(a_target)
    model.network = _OracleNetwork(model, a_target_norm, T_world_ee[:, -1])
    noise = torch.randn(b, 4, 6, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        a_final, _ = model.denoise(model.prepare_observation(images, state)[0], T_world_ee, gripper, noise)
    got = model.action_stats.unnormalize(a_final)
    trans_err = (got[..., :3] - a_target[..., :3]).norm(dim=-1)
    rot_err = Rotation.from_rotvec(got[..., 3:].reshape(-1, 3).double().numpy()).inv() * Rotation.from_rotvec(
        a_target[..., 3:].reshape(-1, 3).double().numpy()
    )
    assert trans_err.max() < 1e-3, trans_err
    assert np.degrees(rot_err.magnitude()).max() < 1.0


def test_batched_and_per_sample_inference_agree(toy_dataset_root):
    policy, _ = _make_policy(toy_dataset_root)
    policy.eval()
    b = 3
    images = torch.rand(b, 2, 2, 3, 64, 64)
    state = torch.tensor([0.0, 0.01, 0.2, 1.0]).repeat(b, 2, 1) + torch.randn(b, 2, 4) * 0.01
    noise = torch.randn(b, 4, 6)
    batched = policy.model.generate_actions(images, state, noise=noise)
    single = torch.cat([policy.model.generate_actions(images[i : i + 1], state[i : i + 1], noise=noise[i : i + 1])
                        for i in range(b)])
    torch.testing.assert_close(batched, single, atol=1e-4, rtol=1e-4)
