"""The compiled inference path (torch.compile over static-shape rendering) gives the eager path's actions."""

import pytest
import torch

from tests.helpers import make_policy


@pytest.mark.skipif(not torch.cuda.is_available(), reason="compiled inference is for CUDA (tracing on CPU takes >10 min)")
def test_compiled_sampler_matches_eager(toy_dataset_root):
    device = "cuda"
    policy, _ = make_policy(toy_dataset_root)
    policy.to(device).eval()
    b = 2
    images = torch.rand(b, 2, 2, 3, 64, 64, device=device)
    state = torch.tensor([0.01, -0.02, 0.2, 1.0], device=device).repeat(b, 2, 1)
    noise = torch.randn(b, 4, 6, device=device)
    eager = policy.model.generate_actions(images, state, noise=noise)
    policy.config.inference_compile = True
    compiled = policy.model.generate_actions(images, state, noise=noise)
    again = policy.model.generate_actions(images, state, noise=noise)  # replay, no recompilation
    torch.testing.assert_close(compiled, eager, atol=2e-4, rtol=1e-4)
    torch.testing.assert_close(again, compiled)


def test_static_rendering_in_the_model_matches_dynamic(toy_dataset_root):
    """Without compiling: the static rasteriser path used by the compiled sampler draws what the exact one does."""
    policy, _ = make_policy(toy_dataset_root)
    model = policy.model
    b = 2
    T = torch.eye(4).repeat(b, 6, 1, 1)
    T[..., :3, 3] = torch.tensor([0.0, 0.0, 0.2]) + torch.randn(b, 6, 3) * 0.03
    T[..., :3, :3] = torch.tensor([[1.0, 0, 0], [0, -1, 0], [0, 0, -1]])
    dyn = model.render_frames(T, T)
    model._static_render = True
    model._render_overflow = torch.zeros((), dtype=torch.bool)
    try:
        sta = model.render_frames(T, T)
    finally:
        model._static_render = False
    assert not bool(model._render_overflow)
    assert dyn[1].any()
    for x, y in zip(dyn[:3], sta[:3]):
        torch.testing.assert_close(x, y)
