"""`image_shift_augment`: images and principal points move together, so renders stay on the real gripper."""

import pytest
import torch

from lerobot_rnd.augmentation import shift_images_and_intrinsics
from tests.helpers import make_policy, training_batch


def _gripper_images(model, b=3):
    """Renders of the toy gripper at a few poses, standing in for camera images: (B, H, C, 3, h, w), poses."""
    h_obs = model.config.n_obs_steps
    state = torch.tensor([[0.01, -0.02, 0.2, 1.0], [-0.03, 0.01, 0.18, 1.0], [0.02, 0.03, 0.22, -1.0]])[:b]
    state = state[:, None].expand(b, h_obs, 4)
    images = torch.zeros(b, h_obs, len(model.camera_keys), 3, *model.config.image_size)
    _, T_world_ee, _ = model.prepare_observation(images, state)
    rgb, mask, _, _, _ = model.render_frames(T_world_ee, T_world_ee)
    return torch.where(mask[:, :, :, None], rgb, torch.full_like(rgb, 0.5)), mask, T_world_ee


def test_shifted_images_match_renders_with_the_shifted_intrinsics(toy_dataset_root):
    """Independent reference: the rasteriser itself, run with the shifted K. Away from the replicated border,
    shifting the rendered pixels must give the render at the shifted principal point."""
    policy, _ = make_policy(toy_dataset_root)
    model = policy.model
    images, mask, T_world_ee = _gripper_images(model)
    assert mask.sum() > 100, "the gripper must be visible for this test"
    s = 6
    shifted, K = shift_images_and_intrinsics(images, model.rig.K, s, generator=torch.Generator().manual_seed(3))
    rgb, mask_k, _, _, _ = model.render_frames(T_world_ee, T_world_ee, K)
    expected = torch.where(mask_k[:, :, :, None], rgb, torch.full_like(rgb, 0.5))
    inner = (slice(None),) * 4 + (slice(s, -s), slice(s, -s))
    changed = (K - model.rig.K).abs().amax((-1, -2)) > 0
    assert changed.any(), "some (sample, camera) must be shifted"
    mismatch = (shifted[inner] - expected[inner]).abs().amax(2)  # (B, H, C, h', w')
    # Anti-aliasing-free rasteriser: a pixel can flip only on a silhouette edge under float rounding.
    assert (mismatch > 1e-4).float().mean() < 2e-3
    torch.testing.assert_close(K[..., :2, :2], model.rig.K.expand_as(K)[..., :2, :2])


def test_offsets_cover_the_range_and_zero_is_the_identity():
    images = torch.rand(64, 2, 2, 3, 16, 16)
    K = torch.tensor([[20.0, 0, 8], [0, 20.0, 8], [0, 0, 1]]).expand(2, 3, 3)
    _, K_s = shift_images_and_intrinsics(images, K, 3, generator=torch.Generator().manual_seed(0))
    d = (K_s[..., :2, 2] - K[..., :2, 2]).flatten()
    assert set(d.round().int().tolist()) == set(range(-3, 4))
    out, K0 = shift_images_and_intrinsics(images, K, 0)
    assert out is images and torch.equal(K0, K.expand(64, 2, 3, 3))
    # A pure shift moves content: output (v, u) = input (v - dy, u - dx).
    one = torch.zeros(1, 1, 1, 3, 16, 16)
    one[..., 5, 7] = 1.0
    out, K1 = shift_images_and_intrinsics(one, K[:1], 2, generator=torch.Generator().manual_seed(1))
    dx, dy = (K1[0, 0, :2, 2] - K[0, :2, 2]).round().int().tolist()
    assert out[0, 0, 0, 0].nonzero().tolist() == [[5 + dy, 7 + dx]]


def test_training_only_and_validated(toy_dataset_root):
    policy, _ = make_policy(toy_dataset_root, image_shift_augment=4)
    batch = training_batch(toy_dataset_root, policy.config, n=4)
    policy.train()
    calls = []
    original = policy.model.render_frames

    def spy(*args, **kwargs):
        calls.append(args[2] if len(args) > 2 else kwargs.get("K"))
        return original(*args, **kwargs)

    policy.model.render_frames = spy
    loss, _ = policy.forward(batch)
    assert torch.isfinite(loss) and calls and all(k is not None and k.shape[0] == 4 for k in calls)
    calls.clear()
    policy.eval()
    with torch.no_grad():
        policy.predict_action_chunk({k: v for k, v in batch.items() if not k.startswith("action")})
    assert calls and all(k is None for k in calls)
    with pytest.raises(ValueError, match="image_shift_augment"):
        make_policy(toy_dataset_root, image_shift_augment=-1)
