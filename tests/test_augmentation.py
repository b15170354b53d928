"""`image_shift_augment`: images and principal points move together, so renders stay on the real gripper.
`camera_dropout`: one whole camera of a share of the training samples is blanked and unscored."""

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


def test_camera_dropout_drops_one_camera_of_the_chosen_share_never_all():
    from lerobot_rnd.augmentation import camera_dropout_keep

    g = torch.Generator().manual_seed(0)
    keep = camera_dropout_keep(4000, 2, 0.3, generator=g)
    dropped = (~keep).sum(1)
    assert set(dropped.tolist()) <= {0, 1}  # never both cameras
    assert abs(dropped.float().mean().item() - 0.3) < 0.03  # 3 sigma is 0.022
    assert abs((~keep[:, 0]).float().mean().item() - 0.15) < 0.025  # each camera alike
    assert camera_dropout_keep(50, 1, 1.0, generator=g).all()  # a single camera is never dropped
    assert camera_dropout_keep(50, 3, 0.0, generator=g).all()
    assert ((~camera_dropout_keep(500, 3, 1.0, generator=g)).sum(1) == 1).all()


def test_dropped_cameras_are_blank_and_unscored_the_others_untouched():
    from lerobot_rnd.augmentation import CAMERA_INPUT_KEYS, drop_cameras

    g = torch.Generator().manual_seed(1)
    b, h, t, c = 3, 2, 4, 2
    inputs = {"obs_rgb": torch.rand(b, h, c, 3, 8, 8, generator=g), "obs_points": torch.rand(b, h, c, 3, 8, 8, generator=g),
              "future_rgb": torch.rand(b, t, c, 3, 16, generator=g), "future_points": torch.rand(b, t, c, 3, 16, generator=g),
              "target_mask": torch.ones(b, t, c, 16, dtype=torch.bool), "k": torch.arange(b)}  # fmt: skip
    keep = torch.tensor([[True, True], [False, True], [True, False]])
    out = drop_cameras(inputs, keep)
    for key in CAMERA_INPUT_KEYS:
        for i in range(b):
            for cam in range(c):
                got, orig = out[key][i, :, cam], inputs[key][i, :, cam]
                assert torch.equal(got, orig) if keep[i, cam] else (got == 0).all(), (key, i, cam)
    assert out["target_mask"][1, :, 0].sum() == 0 and out["target_mask"][2, :, 1].sum() == 0
    assert out["target_mask"].sum() == (b * c - 2) * t * 16
    assert out["k"] is inputs["k"]


def test_camera_dropout_is_training_only_and_validated(toy_dataset_root):
    policy, _ = make_policy(toy_dataset_root, camera_dropout=1.0)
    batch = training_batch(toy_dataset_root, policy.config, n=4)
    seen = []
    original = policy.model._run_network

    def spy(network, inputs, *args):
        seen.append(inputs["obs_rgb"].flatten(3).abs().amax(-1).amax(1))  # (B, C): 0 where blanked
        return original(network, inputs, *args)

    policy.model._run_network = spy
    policy.train()
    loss, _ = policy.forward(batch)
    assert torch.isfinite(loss) and ((seen[-1] == 0).sum(1) == 1).all()  # p = 1: every sample lost one camera
    policy.eval()
    with torch.no_grad():
        policy.predict_action_chunk({k: v for k, v in batch.items() if not k.startswith("action")})
    assert all((s > 0).all() for s in seen[1:])
    with pytest.raises(ValueError, match="camera_dropout"):
        make_policy(toy_dataset_root, camera_dropout=1.5)
