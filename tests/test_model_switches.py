"""Switches of the R&D model that shipped configs or the paper use: history overlay, conv patch embedding; and the
per-camera image loss and the uniform training timesteps."""

import pytest
import torch

from tests.helpers import make_policy as _make_policy, training_batch as _training_batch


def test_history_overlay_switch(toy_dataset_root):
    for overlay in (False, True):
        policy, _ = _make_policy(toy_dataset_root, history_rgb_overlay=overlay)
        model = policy.model
        state = torch.tensor([0.0, 0.0, 0.2, 1.0]).repeat(2, 2, 1)
        images = torch.rand(2, 2, 2, 3, 64, 64)
        images, T_world_ee, gripper = model.prepare_observation(images, state)
        T_ee = torch.eye(4).repeat(2, policy.config.chunk_size, 1, 1)
        inputs = model._network_inputs(images, T_world_ee, gripper, T_ee, full_composite=True)
        n_obs = policy.config.n_obs_steps
        history = inputs["obs_rgb"]
        assert inputs["obs_points"].abs().sum() > 0, "the history gripper must be visible for this test"
        torch.testing.assert_close(inputs["composite"][:, :n_obs], history)
        if overlay:
            assert not torch.equal(history, images)
        else:
            torch.testing.assert_close(history, images)  # the real images, untouched
        # Future frames always carry the render.
        assert not torch.equal(inputs["composite"][:, n_obs:], images[:, -1:].expand_as(inputs["composite"][:, n_obs:]))


class _OffsetNetwork(torch.nn.Module):
    """Predicts the (forced) zero target plus 1 in camera 0 and exactly the target in camera 1."""

    def __init__(self, model, inner):
        super().__init__()
        self.model, self.inner = model, inner

    def embed_observation(self, obs_rgb, obs_points):
        return self.inner.embed_observation(obs_rgb, obs_points)

    def forward(self, obs_rgb, obs_points, future_rgb, future_points, gripper_state, timestep, noisy_action,
                patch_index=None, obs_tokens=None):
        _, update, logits = self.inner(obs_rgb, obs_points, future_rgb, future_points, gripper_state, timestep,
                                       noisy_action, patch_index=patch_index, obs_tokens=obs_tokens)
        zero = self.model.normalize_displacement(torch.zeros_like(future_points).flatten(4))
        zero[:, :, 0] += 1.0
        return zero, update, logits


def test_image_loss_is_a_per_camera_mean_summed_over_cameras(toy_dataset_root):
    """Camera 0 off by 1 everywhere, camera 1 exact: the image loss is 1 whatever each camera's pixel count
    (pooling all pixels would give n0 / (n0 + n1))."""
    policy, _ = _make_policy(toy_dataset_root, variant="AI")
    model = policy.model
    original = model.noisy_sample_targets

    def zero_target(*args, **kwargs):
        out = original(*args, **kwargs)
        out["displacement"] = torch.zeros_like(out["displacement"])
        n0 = int(out["target_mask"][:, :, 0].sum())
        n1 = int(out["target_mask"][:, :, 1].sum())
        assert n0 > 0 and n1 > 0 and n0 != n1
        return out

    model.noisy_sample_targets = zero_target
    model.network = _OffsetNetwork(model, model.network)
    batch = _training_batch(toy_dataset_root, policy.config)
    _, info = policy.forward(batch)
    assert abs(info["image_loss"] - 1.0) < 1e-5, info


@pytest.mark.parametrize("kind", ["conv"])
def test_conv_patch_embedding_switch(toy_dataset_root, tmp_path, kind):
    """`patch_embed="conv"` builds a convolutional RGB embedding (the point map keeps the linear
    one), train, and come back from a checkpoint; a patch size they cannot split is refused, naming the field."""
    from lerobot_rnd.configuration_rnd import RnDConfig
    from lerobot_rnd.modeling_rnd import RnDPolicy

    def first_conv(net):
        return next(m for m in net.rgb_patch_embed.modules() if isinstance(m, torch.nn.Conv2d))

    policy, _ = _make_policy(toy_dataset_root, patch_embed=kind)
    net = policy.model.network
    assert not isinstance(net.rgb_patch_embed, torch.nn.Conv2d)
    assert isinstance(net.point_patch_embed, torch.nn.Conv2d)
    loss, _ = policy.forward(_training_batch(toy_dataset_root, policy.config))
    loss.backward()
    assert first_conv(net).weight.grad.abs().sum() > 0
    policy.save_pretrained(tmp_path / "ckpt")
    loaded = RnDPolicy.from_pretrained(tmp_path / "ckpt")
    assert loaded.config.patch_embed == kind
    torch.testing.assert_close(first_conv(loaded.model.network).weight, first_conv(net).weight)
    with pytest.raises(ValueError, match="`patch_embed`"):
        RnDConfig(patch_embed=kind, patch_size=12, image_size=(96, 96))
    with pytest.raises(ValueError, match="`patch_embed` must be one of"):
        RnDConfig(patch_embed="mlp")


def _training_timesteps(policy, batch, repeats: int) -> list[int]:
    """The diffusion timesteps `policy.forward` draws over `repeats` training passes (read at add_noise)."""
    seen: list[int] = []
    scheduler = policy.model.noise_scheduler
    original = scheduler.add_noise

    def recording(sample, noise, timesteps):
        seen.extend(int(t) for t in timesteps)
        return original(sample, noise, timesteps)

    scheduler.add_noise = recording
    try:
        for _ in range(repeats):
            policy.forward(batch)
    finally:
        scheduler.add_noise = original
    return seen


def test_training_timesteps_are_uniform_over_the_schedule(toy_dataset_root):
    """Algorithm 1: k ~ Randint(0, K) for every training sample."""
    policy, _ = _make_policy(toy_dataset_root, variant="AI")
    batch = _training_batch(toy_dataset_root, policy.config, n=8)
    last = policy.config.num_train_timesteps - 1
    uniform = _training_timesteps(policy, batch, repeats=3)
    assert len(uniform) == 24 and len(set(uniform)) > 5 and min(uniform) >= 0 and max(uniform) <= last
