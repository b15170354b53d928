"""The R&D sampler against independent references: ground-truth displacements, an oracle denoiser, batching."""

import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from lerobot_rnd.sampler import ddim_step, displacement_target, register_point_update
from tests.helpers import StandInNetwork
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


def test_ddim_step_reaches_the_prediction_on_the_last_step_and_matches_the_hand_formula():
    x_k, x0 = torch.randn(10, 3), torch.randn(10, 3)
    np.testing.assert_allclose(ddim_step(x_k, x0, torch.tensor(0.3), torch.tensor(1.0)), x0, atol=1e-6)
    # Eq. (7) by hand at alpha_k = 0.36, alpha_{k-1} = 0.64: 0.8 x0 + sqrt(0.36 / 0.64) (x_k - 0.6 x0)
    expected = 0.8 * x0 + 0.75 * (x_k - 0.6 * x0)
    np.testing.assert_allclose(ddim_step(x_k, x0, torch.tensor(0.36), torch.tensor(0.64)), expected, atol=1e-6)


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
    # pixels outside the mask may hold anything (NaN, huge values): same result
    junk_k, junk_prev = to_cam(pts_world).clone(), to_cam(moved_world).clone()
    junk_k.masked_fill_(~mask[:, :, :, None], float("nan"))
    junk_prev.masked_fill_(~mask[:, :, :, None], 1e30)
    got_junk, valid_junk = register_point_update(junk_k, junk_prev, mask, T_world_cam, min_points=3)
    assert torch.equal(valid_junk, valid)
    np.testing.assert_allclose(got_junk.numpy(), got.numpy(), atol=1e-12)


def _exact_displacement(model, future_points, T_world_ee_now, T_ee_from, T_ee_to):
    """Reference F = T_cam_to T_cam_from^-1 P - P per pixel, from the future point maps (B, T, C, 3, ...) and
    the camera poses."""
    T_world_cam = model.rig.T_world_cam(T_world_ee_now[:, None].expand(-1, T_ee_from.shape[1], 4, 4))
    cam_from_world = torch.linalg.inv(T_world_cam)
    rel = cam_from_world @ (T_world_ee_now[:, None, None] @ T_ee_to[:, :, None]) @ torch.linalg.inv(
        cam_from_world @ (T_world_ee_now[:, None, None] @ T_ee_from[:, :, None])
    )
    points = future_points.flatten(4)  # (B, T, C, 3, N), metres
    moved = torch.einsum("btcij,btcjn->btcin", rel[..., :3, :3], points) + rel[..., :3, 3, None]
    return (moved - points).reshape(future_points.shape)


class _OracleNetwork(StandInNetwork):
    """Stands in for the ViT: returns the true image-space displacement and action update for a known target.

    The displacement is computed from the point map it is given and the camera poses, independently of the
    sampler's code: F = T_cam_target T_cam_noisy^-1 P - P per pixel.
    """

    def __init__(self, model, a_target_norm, T_world_ee_now):
        super().__init__()
        self.model = model
        self.a_target = a_target_norm
        self.T_world_ee_now = T_world_ee_now  # (B, 4, 4)

    def forward(self, obs_rgb, obs_points, future_rgb, future_points, gripper_state, timestep, noisy_action,
                patch_index=None, obs_tokens=None):
        from lerobot_rnd.geometry import pose_from_action

        m = self.model
        stats = m.action_stats
        T_ee_noisy = pose_from_action(stats.unnormalize(noisy_action.clamp(-1, 1)))
        T_ee_target = pose_from_action(stats.unnormalize(self.a_target))
        moved = _exact_displacement(m, future_points, self.T_world_ee_now, T_ee_noisy, T_ee_target)
        displacement = m.normalize_displacement(moved.flatten(4)).reshape(moved.shape)
        update = self.a_target - noisy_action
        logits = torch.ones(noisy_action.shape[:2])
        return displacement, update, logits


class _ZeroDisplacementNetwork(StandInNetwork):
    """Predicts "the gripper is already where it should be": zero metric displacement, no action update."""

    def __init__(self, model):
        super().__init__()
        self.model = model

    def forward(self, obs_rgb, obs_points, future_rgb, future_points, gripper_state, timestep, noisy_action,
                patch_index=None, obs_tokens=None):
        b, t = noisy_action.shape[:2]
        zero_metric = torch.zeros_like(future_points)
        return self.model.normalize_displacement(zero_metric.flatten(4)).reshape(zero_metric.shape), torch.zeros_like(noisy_action), torch.ones(b, t)


def _observation(model, b=3):
    state = torch.tensor([[0.02, -0.03, 0.21, 1.0], [-0.04, 0.02, 0.18, 1.0], [0.0, 0.05, 0.2, 1.0]])[:b]
    state = state[:, None].expand(b, 2, 4)
    images = torch.rand(b, 2, len(model.camera_keys), 3, 64, 64, generator=torch.Generator().manual_seed(1))
    return model.prepare_observation(images, state)


def _target_chunk(b=3, seed=3):
    """A target chunk inside the data range: the gripper moves a few cm and turns by up to ~10 degrees."""
    rng = np.random.default_rng(seed)
    return torch.tensor(
        np.concatenate([rng.uniform(-0.02, 0.02, (b, 4, 3)), rng.uniform(-0.15, 0.15, (b, 4, 3))], -1),
        dtype=torch.float32,
    )


POINT_UPDATE_MODES = ("x0", "ddim")


@pytest.mark.parametrize("point_update", POINT_UPDATE_MODES)
@pytest.mark.parametrize("variant", ["I", "AI"])
def test_sampler_with_an_oracle_denoiser_reaches_the_target_from_any_noise_level(
    toy_dataset_root, point_update, variant
):
    """Every point-update mode lands on the target at the final step, whatever step the sampler starts at."""
    policy, _ = _make_policy(
        toy_dataset_root, variant=variant, num_inference_steps=4, final_action_step=False,
        point_update=point_update,
    )
    model = policy.model
    images, T_world_ee, gripper = _observation(model)
    a_target = _target_chunk()
    model.action_stats.set(torch.full((6,), -0.2), torch.full((6,), 0.2))
    a_target_norm = model.action_stats.normalize(a_target)
    model.network = _OracleNetwork(model, a_target_norm, T_world_ee[:, -1])
    for start in range(4):  # start from pure noise (0) down to the last step (3)
        a = torch.randn(3, 4, 6, generator=torch.Generator().manual_seed(start)) * (1.0 if start == 0 else 0.5)
        with torch.no_grad():
            for i in range(start, 4):
                a, _, _ = model.sampler_step(images, T_world_ee, gripper, a, i)
        got = model.action_stats.unnormalize(a)
        trans_err = (got[..., :3] - a_target[..., :3]).norm(dim=-1)
        rot_err = Rotation.from_rotvec(got[..., 3:].reshape(-1, 3).double().numpy()).inv() * Rotation.from_rotvec(
            a_target[..., 3:].reshape(-1, 3).double().numpy()
        )
        assert trans_err.max() < 1e-4, (start, trans_err.max())
        assert rot_err.magnitude().max() < 1e-4, (start, rot_err.magnitude().max())


def test_full_sampler_with_gripper_patches_and_an_oracle_reaches_the_target(toy_dataset_root):
    """With only the gripper's patches as tokens, the SVD over the covered pixels still lands on the target."""
    policy, _ = _make_policy(toy_dataset_root, variant="I", gripper_patches=4, final_action_step=False)
    model = policy.model
    images, T_world_ee, gripper = _observation(model)
    a_target = _target_chunk()
    model.action_stats.set(torch.full((6,), -0.2), torch.full((6,), 0.2))
    model.network = _OracleNetwork(model, model.action_stats.normalize(a_target), T_world_ee[:, -1])
    with torch.no_grad():
        a, _ = model.denoise(images, T_world_ee, gripper, torch.randn(3, 4, 6, generator=torch.Generator().manual_seed(0)))
    got = model.action_stats.unnormalize(a)
    assert (got[..., :3] - a_target[..., :3]).norm(dim=-1).max() < 1e-4


def _move_camera_back(model, cam: int, distance: float) -> None:
    """Move camera `cam` back along its optical axis by `distance` metres (its view shrinks, nothing else)."""
    back = torch.eye(4)
    back[2, 3] = -distance
    if bool(model.rig.mounted[cam]):
        model.rig.T_ee_cam[cam] = model.rig.T_ee_cam[cam] @ back
    else:
        model.rig.T_world_cam_static[cam] = model.rig.T_world_cam_static[cam] @ back


@pytest.mark.parametrize("cameras", [("front",), ("wrist",), ("front", "wrist")])
@pytest.mark.parametrize("point_update", ["x0"])
def test_zero_displacement_does_not_move_the_gripper_and_ignores_camera_distance(
    toy_dataset_root, cameras, point_update
):
    """A network predicting zero displacement: `x0` takes exactly the action-space DDIM step with x0 = the
    current action; moving a camera away changes nothing."""
    from lerobot_rnd.sampler import ddim_step

    policy, _ = _make_policy_cameras(toy_dataset_root, cameras, variant="I", point_update=point_update)
    model = policy.model
    model.action_stats.set(torch.full((6,), -0.05), torch.full((6,), 0.05))
    model.network = _ZeroDisplacementNetwork(model)
    images, T_world_ee, gripper = _observation(model)
    a = 0.5 * torch.randn(3, 4, 6, generator=torch.Generator().manual_seed(0)).clamp(-1.8, 1.8)
    a = a.clamp(-1, 1)
    results = []
    for move in (0.0, 0.3):
        for c in range(len(cameras)):
            _move_camera_back(model, c, move)
        model._rasterizers.clear()
        with torch.no_grad():
            a_next, _, composite = model.sampler_step(images, T_world_ee, gripper, a, 1, full_composite=True)
        n_obs = model.config.n_obs_steps
        assert (composite[:, n_obs:] != images[:, -1:]).any(), "the gripper must be visible for this test"
        results.append(a_next)
    alpha, alpha_prev = model.inference_alpha_bar[1], model.inference_alpha_bar_prev[1]
    expected = ddim_step(a, a, alpha, alpha_prev)
    for got in results:
        np.testing.assert_allclose(got.numpy(), expected.numpy(), atol=1e-5)


def test_paper_literal_ddim_point_update_moves_the_gripper_on_zero_displacement(toy_dataset_root):
    """The ablation mode `point_update="ddim"` rescales the cloud about the camera centre: with a network that
    predicts zero displacement it still moves the gripper (the bias the default modes remove)."""
    policy, _ = _make_policy_cameras(toy_dataset_root, ("front",), variant="I", point_update="ddim")
    model = policy.model
    model.action_stats.set(torch.full((6,), -0.05), torch.full((6,), 0.05))
    model.network = _ZeroDisplacementNetwork(model)
    images, T_world_ee, gripper = _observation(model)
    a = torch.zeros(3, 4, 6)
    with torch.no_grad():
        a_next, _, _ = model.sampler_step(images, T_world_ee, gripper, a, 1)
    moved = model.action_stats.unnormalize(a_next)[..., :3].norm(dim=-1)
    assert moved.min() > 1e-3, moved


def test_default_point_update_is_camera_independent():
    from lerobot_rnd.configuration_rnd import RnDConfig

    assert RnDConfig().point_update == "x0"


def _make_policy_cameras(root, cameras, **overrides):
    """A tiny policy on the toy dataset that uses only the given cameras ("front" static, "wrist" mounted)."""
    from lerobot.configs.types import FeatureType
    from lerobot.datasets.lerobot_dataset import LeRobotDatasetMetadata
    from lerobot.datasets.utils import dataset_to_policy_features

    from lerobot_rnd.configuration_rnd import RnDConfig
    from lerobot_rnd.modeling_rnd import RnDPolicy
    from tests.helpers import TINY_POLICY_KWARGS

    meta = LeRobotDatasetMetadata("local/toy_reach", root=root)
    features = dataset_to_policy_features(meta.features)
    keep = {f"observation.images.{c}" for c in cameras}
    features = {k: f for k, f in features.items() if f.type is not FeatureType.VISUAL or k in keep}
    cfg = RnDConfig(**{**TINY_POLICY_KWARGS, **overrides})
    cfg.output_features = {k: f for k, f in features.items() if f.type is FeatureType.ACTION}
    cfg.input_features = {k: f for k, f in features.items() if k not in cfg.output_features}
    return RnDPolicy(cfg, dataset_meta=meta), meta


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


def test_the_network_hears_each_ddim_timestep_and_intermediate_steps_keep_noise(toy_dataset_root):
    """With a network that always predicts a constant clean chunk, the sampler tells it the schedule's timesteps
    (trailing spacing: the first is pure noise), the DDIM steps keep part of the noise in between, and the last
    step lands on the prediction."""
    policy, _ = _make_policy(toy_dataset_root, variant="A", num_inference_steps=4, final_action_step=False)
    model = policy.model
    images, T_world_ee, gripper = _observation(model)
    target = torch.full((3, 4, 6), 0.25)
    steps, states = [], []

    class Constant(StandInNetwork):  # predicts the constant target's action update; records the timesteps
        def forward(self, *args, **kwargs):
            timestep, noisy = args[5], args[6]
            steps.append(timestep.tolist())
            states.append(noisy.clone())
            return None, target - noisy, torch.zeros(noisy.shape[:2])

    model.network = Constant()
    noise = torch.randn(3, 4, 6, generator=torch.Generator().manual_seed(0)).clamp(-1, 1)
    with torch.no_grad():
        a, _ = model.denoise(images, T_world_ee, gripper, noise)
    k = model.config.num_train_timesteps
    assert [s[0] for s in steps] == model.inference_timesteps == [k - 1 - i * k // 4 for i in range(4)]
    assert all(len(set(s)) == 1 for s in steps)
    assert not torch.allclose(states[1], target, atol=1e-3)  # DDIM keeps noise in the intermediate steps
    torch.testing.assert_close(a, target)


@pytest.mark.parametrize("gripper_patches", [0, 4])
def test_denoise_embeds_the_observation_once_per_chunk_and_matches_the_uncached_sampler(
    toy_dataset_root, gripper_patches
):
    """The past/current frames' patch tokens are computed once per chunk, not in each of the 5 network passes,
    and the chunk is the one the sampler gives when every pass embeds them itself."""
    policy, _ = _make_policy(toy_dataset_root, variant="AI", gripper_patches=gripper_patches)
    model = policy.model.eval()
    images, T_world_ee, gripper = _observation(model)
    net = model.network
    embed = net.embed_observation
    calls = []

    def counting(obs_rgb, obs_points, skip_first=False):
        calls.append(obs_rgb.shape)
        return None if skip_first and len(calls) == 1 else embed(obs_rgb, obs_points)

    noise = torch.randn(3, 4, 6, generator=torch.Generator().manual_seed(5))
    with torch.no_grad():
        net.embed_observation = counting
        cached, cached_logits = model.denoise(images, T_world_ee, gripper, noise)
        n_cached = len(calls)
        calls.clear()
        net.embed_observation = lambda rgb, pts: counting(rgb, pts, skip_first=True)  # no cache: every pass embeds
        uncached, uncached_logits = model.denoise(images, T_world_ee, gripper, noise)
    passes = model.config.num_inference_steps + int(model.config.final_action_step)
    assert n_cached == 1
    assert len(calls) == 1 + passes
    torch.testing.assert_close(cached, uncached, atol=1e-6, rtol=0)
    torch.testing.assert_close(cached_logits, uncached_logits, atol=1e-5, rtol=0)


def test_sample_actions_calls_the_denoiser_once_per_step_then_once_for_the_final_action():
    """`sampler.sample_actions` on its own, with a stand-in denoiser (no model): it hears the DDIM timesteps then 0,
    sees the actions it is given rendered at their poses, and ends on the final pass's action-space estimate."""
    from lerobot_rnd.diffusion_space import EEPoseSpace
    from lerobot_rnd.geometry import pose_from_action
    from lerobot_rnd.sampler import DenoiserOutput, inference_schedule, make_noise_scheduler, sample_actions
    from lerobot_rnd.statistics import MinMaxStats

    timesteps, alpha_bar, alpha_bar_prev = inference_schedule(make_noise_scheduler(50), 4)
    stats = MinMaxStats((6,))
    stats.set(torch.full((6,), -0.1), torch.full((6,), 0.1))
    target = torch.full((2, 3, 6), 0.3)
    calls = []

    def denoise_fn(a, T_ee_target, timestep, full_composite):
        torch.testing.assert_close(T_ee_target, pose_from_action(stats.unnormalize(a)))
        calls.append(timestep.tolist())
        return DenoiserOutput(update=target - a, logits=torch.full(a.shape[:2], float(len(calls))))

    noise = torch.randn(2, 3, 6, generator=torch.Generator().manual_seed(0))
    a, logits = sample_actions(denoise_fn, noise, timesteps, alpha_bar, alpha_bar_prev, EEPoseSpace(stats),
                               torch.eye(4).expand(2, 1, 4, 4))  # fmt: skip
    assert calls == [[k, k] for k in timesteps] + [[0, 0]]
    torch.testing.assert_close(a, target)
    assert torch.equal(logits, torch.full((2, 3), 5.0))  # the final pass's logits
    calls.clear()
    a, _ = sample_actions(denoise_fn, noise, timesteps, alpha_bar, alpha_bar_prev, EEPoseSpace(stats),
                          torch.eye(4).expand(2, 1, 4, 4), final_action_step=False)  # fmt: skip
    assert len(calls) == 4
    torch.testing.assert_close(a, target)  # the last DDIM step goes to alpha_prev = 1: the clean estimate
