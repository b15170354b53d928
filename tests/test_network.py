"""The ViT denoiser: gripper-patch tokens against the dense model, patch selection against a hand count,
embedding initialisation."""

import pytest
import torch

from lerobot_rnd.network import (
    RnDDenoiser,
    gather_patch_pixels,
    patch_pixel_index,
    select_gripper_patches,
)


def _net(gripper_patches=0, **kw):
    torch.manual_seed(0)
    args = dict(
        n_views=2, n_obs_steps=2, horizon=3, image_size=(32, 48), patch_size=8, dim_model=32, n_layers=2,
        n_heads=4, mlp_ratio=2.0, dropout=0.0, predict_image=True, predict_action=True, use_point_map_input=True,
    )
    args.update(kw)
    return RnDDenoiser(**args, gripper_patches=gripper_patches)


def _inputs(b=2, f=5, c=2, h=32, w=48, seed=0):
    """rgb, points (B, F, C, 3, h, w) with F = 2 history + 3 future frames, gripper, step, action."""
    g = torch.Generator().manual_seed(seed)
    return (
        torch.rand(b, f, c, 3, h, w, generator=g),
        torch.randn(b, f, c, 3, h, w, generator=g),
        torch.rand(b, 2, generator=g),
        torch.randint(0, 50, (b,), generator=g),
        torch.randn(b, 3, 6, generator=g),
    )


def _call(net, rgb, pm, g, k, a, patch_index=None):
    """Run the network; with patch_index, feed only the selected patches' pixels of the future frames."""
    fut_rgb, fut_pm = rgb[:, 2:], pm[:, 2:]
    if patch_index is not None:
        pix = patch_pixel_index(patch_index, net.grid, net.patch_size)
        fut_rgb, fut_pm = gather_patch_pixels(fut_rgb, pix), gather_patch_pixels(fut_pm, pix)
    return net(rgb[:, :2], pm[:, :2], fut_rgb, fut_pm, g, k, a, patch_index=patch_index)


def _scatter(displacement, patch_index, net):
    """Selected-pixel displacement (B, T, C, 3, N) -> full image (B, T, C, 3, h, w), zeros elsewhere."""
    b, t, c = displacement.shape[:3]
    h, w = net.grid[0] * net.patch_size, net.grid[1] * net.patch_size
    pix = patch_pixel_index(patch_index, net.grid, net.patch_size)
    full = torch.zeros(b, t, c, 3, h * w)
    full.scatter_(-1, pix[:, :, :, None].expand(-1, -1, -1, 3, -1), displacement)
    return full.reshape(b, t, c, 3, h, w)


@pytest.mark.parametrize("patch_embed", ["linear", "conv"])
def test_selecting_every_patch_reproduces_the_dense_model(patch_embed):
    dense = _net(0, patch_embed=patch_embed)
    sparse = _net(24, patch_embed=patch_embed)  # 4 x 6 patches per view: all of them
    sparse.load_state_dict(dense.state_dict())
    x = _inputs()
    index = torch.arange(24).expand(2, 3, 2, 24)
    d_dense, u_dense, g_dense = _call(dense, *x)
    d_sparse, u_sparse, g_sparse = _call(sparse, *x, patch_index=index)
    torch.testing.assert_close(_scatter(d_sparse, index, sparse), d_dense, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(u_sparse, u_dense, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(g_sparse, g_dense, atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("patch_embed", ["linear", "conv"])
def test_gripper_patch_tokens_depend_only_on_the_selected_patches(patch_embed):
    net = _net(3, patch_embed=patch_embed)
    rgb, pm, g, k, a = _inputs()
    index = torch.tensor([0, 7, 20]).expand(2, 3, 2, 3)
    d1, u1, _ = _call(net, rgb, pm, g, k, a, patch_index=index)
    # Change a future-frame patch that is not selected (patch 1 = rows 0-7, columns 8-15): nothing changes.
    rgb2, pm2 = rgb.clone(), pm.clone()
    rgb2[:, 2:, :, :, 0:8, 8:16] = 0.5
    pm2[:, 2:, :, :, 0:8, 8:16] = 3.0
    d2, u2, _ = _call(net, rgb2, pm2, g, k, a, patch_index=index)
    torch.testing.assert_close(u1, u2)
    torch.testing.assert_close(d1, d2)
    assert d1.shape == (2, 3, 2, 3, 3 * 8 * 8)  # only the selected patches' pixels


def test_patch_pixels_are_the_selected_patches():
    img = torch.arange(16 * 24, dtype=torch.float32).reshape(1, 1, 16, 24)  # (B, ch, h, w), 2 x 3 patches of 8
    index = torch.tensor([[5, 1]])  # patch 5 = rows 8-15, cols 16-23; patch 1 = rows 0-7, cols 8-15
    got = gather_patch_pixels(img, patch_pixel_index(index, (2, 3), 8)).reshape(1, 1, 2, 8, 8)
    torch.testing.assert_close(got[0, 0, 0], img[0, 0, 8:16, 16:24])
    torch.testing.assert_close(got[0, 0, 1], img[0, 0, 0:8, 8:16])


def test_select_gripper_patches_picks_the_most_covered_patches():
    mask = torch.zeros(1, 16, 16, dtype=torch.bool)  # 4 x 4 patches of 4 px
    mask[0, 0:4, 0:4] = True  # patch 0: 16 px
    mask[0, 5:7, 9:12] = True  # patch 6: 6 px
    mask[0, 12, 12] = True  # patch 15: 1 px
    mask[0, 8:10, 4:6] = True  # patch 9: 4 px
    index = select_gripper_patches(mask, 4, 3)
    assert index.tolist() == [[0, 6, 9]]
    # Ties go to the lower patch number; an empty mask still yields k distinct patches.
    assert select_gripper_patches(torch.zeros(2, 16, 16, dtype=torch.bool), 4, 2).tolist() == [[0, 1], [0, 1]]


def test_embedding_initialisation_std():
    """The frame, view, future-step and register embeddings start with std 1, as the authors' (small values
    worked much worse for them)."""
    std = 1.0
    net = _net(0, dim_model=256)
    for p in (net.frame_embed, net.view_embed, net.future_pos_embed, net.register_token):
        assert abs(float(p.detach().std()) - std) < 0.25 * std


def test_token_count_with_gripper_patches():
    assert _net(0).n_tokens == (5 * 2 * 24) + 5 + 2 + 3
    assert _net(4).n_tokens == (2 * 2 * 24 + 3 * 2 * 4) + 5 + 2 + 3


@pytest.mark.parametrize("kind", ["conv"])
def test_conv_patch_embedding_is_patch_local_and_resolves_a_dot_inside_a_patch(kind):
    """The conv embedding is patch-local (a patch's token sees only its pixels, even a pixel on the patch's
    border) and,
    unlike any linear embedding, a token for a red dot is not the sum of its tokens for the dot's halves: it is
    a nonlinear detector. Views do not mix."""
    from lerobot_rnd.network import patch_embedding

    torch.manual_seed(0)
    embed = patch_embedding(kind, n_views=1, out_per_view=16, patch_size=8)
    img = torch.zeros(1, 3, 16, 16)
    base = embed(img)
    assert base.shape == (1, 16, 2, 2)
    for row, col in [(2, 3), (2, 7), (7, 7)]:  # inside, on the right border, on the corner of patch (0, 0)
        img2 = img.clone()
        img2[0, 0, row, col] = 1.0
        diff = (embed(img2) - base).abs()[0].sum(0)  # (2, 2) patch grid
        assert diff[0, 0] > 0 and diff[0, 1] == 0 and diff[1, 0] == 0 and diff[1, 1] == 0, (row, col)
    two_views = patch_embedding(kind, n_views=2, out_per_view=16, patch_size=8)
    pair = torch.rand(1, 6, 16, 16)
    other = pair.clone()
    other[:, 3:] = torch.rand(1, 3, 16, 16)  # the second view only
    d = (two_views(other) - two_views(pair)).abs()
    assert d[:, :16].max() == 0 and d[:, 16:].max() > 0
    a, b, ab = img.clone(), img.clone(), img.clone()
    a[0, 0, 2, 3] = b[0, 0, 5, 6] = 1.0
    ab[0, 0, 2, 3] = ab[0, 0, 5, 6] = 1.0
    nonlinear = (embed(ab) - embed(a) - embed(b) + base).abs().max()
    assert nonlinear > 1e-4
    with pytest.raises(ValueError, match="divisible by 8"):
        patch_embedding(kind, 1, 16, 12)


@pytest.mark.parametrize("gripper_patches", [0, 3])
def test_precomputed_observation_tokens_give_the_same_outputs(gripper_patches):
    """forward(..., obs_tokens=embed_observation(obs)) equals forward(...) computing them itself."""
    net = _net(gripper_patches).eval()
    rgb, pm, g, k, a = _inputs()
    patch_index = None
    if gripper_patches:
        patch_index = torch.stack([torch.randperm(net.n_patches)[:gripper_patches] for _ in range(2 * 3 * 2)])
        patch_index = patch_index.reshape(2, 3, 2, gripper_patches)
    fut_rgb, fut_pm = rgb[:, 2:], pm[:, 2:]
    if patch_index is not None:
        pix = patch_pixel_index(patch_index, net.grid, net.patch_size)
        fut_rgb, fut_pm = gather_patch_pixels(fut_rgb, pix), gather_patch_pixels(fut_pm, pix)
    tokens = net.embed_observation(rgb[:, :2], pm[:, :2])
    assert tokens.shape == (2, 2, 2, net.n_patches, 32)
    with torch.no_grad():
        ref = net(rgb[:, :2], pm[:, :2], fut_rgb, fut_pm, g, k, a, patch_index=patch_index)
        got = net(rgb[:, :2], pm[:, :2], fut_rgb, fut_pm, g, k, a, patch_index=patch_index, obs_tokens=tokens)
        flipped = net(rgb[:, :2].flip(-1), pm[:, :2], fut_rgb, fut_pm, g, k, a, patch_index=patch_index)
    for r, o in zip(ref, got):
        torch.testing.assert_close(o, r, atol=1e-6, rtol=0)
    assert (flipped[1] - ref[1]).abs().max() > 1e-4  # the observation frames matter: the comparison can fail
