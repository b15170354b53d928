"""The R&D denoiser: a ViT over (frames x views x patches) tokens plus gripper, step and action tokens.

Shapes use B = batch, F = frames (H past/current + T future), C = cameras (views), T = future steps,
D = model width, p = patch size, h x w = image size, P = (h/p)(w/p) patches per view.
"""

import math

import torch
import torch.nn.functional as F  # noqa: N812
from torch import Tensor, nn


def sincos_2d_position_embedding(grid_h: int, grid_w: int, dim: int) -> Tensor:
    """Fixed 2-D sine-cosine patch position embedding (MAE style). Returns (grid_h * grid_w, dim)."""
    if dim % 4 != 0:
        raise ValueError(f"dim must be divisible by 4 for a 2-D sin-cos embedding, got {dim}")
    ys, xs = torch.meshgrid(
        torch.arange(grid_h, dtype=torch.float64), torch.arange(grid_w, dtype=torch.float64), indexing="ij"
    )
    omega = 1.0 / 10000 ** (torch.arange(dim // 4, dtype=torch.float64) / (dim // 4))
    out = []
    for coord in (ys.reshape(-1), xs.reshape(-1)):
        angles = coord[:, None] * omega[None]
        out += [torch.sin(angles), torch.cos(angles)]
    return torch.cat(out, dim=1).float()


def sinusoidal_step_embedding(timesteps: Tensor, dim: int) -> Tensor:
    """Sinusoidal embedding of diffusion steps (B,) -> (B, dim)."""
    half = dim // 2
    freqs = torch.exp(-math.log(10000) * torch.arange(half, device=timesteps.device) / max(half - 1, 1))
    angles = timesteps.float()[:, None] * freqs[None]
    return torch.cat([angles.sin(), angles.cos()], dim=-1)


class TransformerBlock(nn.Module):
    """Pre-norm self-attention block using `scaled_dot_product_attention`."""

    def __init__(self, dim: int, n_heads: int, mlp_ratio: float, dropout: float):
        super().__init__()
        self.n_heads = n_heads
        self.dropout = dropout
        self.norm1 = nn.LayerNorm(dim)
        self.qkv = nn.Linear(dim, 3 * dim)
        self.proj = nn.Linear(dim, dim)
        self.norm2 = nn.LayerNorm(dim)
        hidden = int(dim * mlp_ratio)
        self.mlp = nn.Sequential(
            nn.Linear(dim, hidden), nn.GELU(), nn.Dropout(dropout), nn.Linear(hidden, dim), nn.Dropout(dropout)
        )

    def forward(self, x: Tensor) -> Tensor:
        """x: (B, N, D) -> (B, N, D)."""
        b, n, d = x.shape
        qkv = self.qkv(self.norm1(x)).reshape(b, n, 3, self.n_heads, d // self.n_heads).permute(2, 0, 3, 1, 4)
        attn = F.scaled_dot_product_attention(
            qkv[0], qkv[1], qkv[2], dropout_p=self.dropout if self.training else 0.0
        )
        x = x + self.proj(attn.transpose(1, 2).reshape(b, n, d))
        return x + self.mlp(self.norm2(x))


class PerViewLinear(nn.Module):
    """A separate linear layer per camera view, applied in one batched einsum.

    Input (..., C, in_dim) -> (..., C, out_dim).
    """

    def __init__(self, n_views: int, in_dim: int, out_dim: int):
        super().__init__()
        self.weight = nn.Parameter(torch.empty(n_views, in_dim, out_dim))
        self.bias = nn.Parameter(torch.zeros(n_views, out_dim))
        nn.init.xavier_uniform_(self.weight.view(n_views * in_dim, out_dim))
        # xavier on the flattened view spreads the fan-in over views; rescale to per-view fan-in.
        with torch.no_grad():
            self.weight.mul_(math.sqrt(n_views * in_dim + out_dim) / math.sqrt(in_dim + out_dim))

    def forward(self, x: Tensor) -> Tensor:
        return torch.einsum("...ci,cio->...co", x, self.weight) + self.bias


class RnDDenoiser(nn.Module):
    """ViT that maps rendered observations to image-space displacements, action updates and gripper logits.

    Inputs (all for one batch):
        rgb: (B, F, C, 3, h, w) camera images with the gripper rendered over them, in [0, 1]; frames are the
            H past/current frames then the T future steps (each future frame is the current image with the
            noisy action's gripper rendered on it).
        point_map: (B, F, C, 3, h, w) camera-frame xyz of the rendered gripper (zeros elsewhere), scaled.
        gripper_state: (B, H) gripper state of the past/current frames, roughly in [-1, 1].
        timestep: (B,) diffusion step k.
        noisy_action: (B, T, 6) noisy normalised action (used by the A and AI variants).
    Outputs:
        displacement: (B, T, C, 3, h, w) normalised per-pixel 3-D displacement (I and AI variants, else None).
        action_update: (B, T, 6) normalised action-space update (A and AI variants, else None).
        gripper_logits: (B, T).
    """

    def __init__(
        self,
        n_views: int,
        n_obs_steps: int,
        horizon: int,
        image_size: tuple[int, int],
        patch_size: int,
        dim_model: int,
        n_layers: int,
        n_heads: int,
        mlp_ratio: float,
        dropout: float,
        predict_image: bool,
        predict_action: bool,
        use_point_map_input: bool,
    ):
        super().__init__()
        self.n_views = n_views
        self.n_obs_steps = n_obs_steps
        self.horizon = horizon
        self.n_frames = n_obs_steps + horizon
        self.patch_size = patch_size
        self.grid = (image_size[0] // patch_size, image_size[1] // patch_size)
        self.n_patches = self.grid[0] * self.grid[1]
        self.predict_image = predict_image
        self.predict_action = predict_action
        self.use_point_map_input = use_point_map_input
        d = dim_model

        # Per-view patch embeddings (grouped convolutions: one group per view), half width each.
        in_ch = 3 * n_views
        self.rgb_patch_embed = nn.Conv2d(in_ch, n_views * d // 2, patch_size, patch_size, groups=n_views)
        self.point_patch_embed = (
            nn.Conv2d(in_ch, n_views * d // 2, patch_size, patch_size, groups=n_views)
            if use_point_map_input
            else None
        )
        self.frame_embed = nn.Parameter(torch.zeros(self.n_frames, d))
        self.view_embed = nn.Parameter(torch.zeros(n_views, d))
        self.register_buffer(
            "patch_pos_embed", sincos_2d_position_embedding(*self.grid, d), persistent=False
        )
        self.gripper_embed = nn.Linear(1, d)
        self.step_mlp = nn.Sequential(nn.Linear(d, d), nn.SiLU(), nn.Linear(d, d))
        self.register_token = nn.Parameter(torch.zeros(1, 1, d))
        self.future_pos_embed = nn.Parameter(torch.zeros(horizon, d))
        self.action_embed = nn.Linear(6, d) if predict_action else None

        self.blocks = nn.ModuleList(
            [TransformerBlock(d, n_heads, mlp_ratio, dropout) for _ in range(n_layers)]
        )
        self.norm = nn.LayerNorm(d)

        # Heads: per-view image decoder (a linear layer per patch, equivalent to a transposed convolution
        # with kernel = stride = patch size), gripper logits per future step, action-space update MLP.
        self.image_head = PerViewLinear(n_views, d, 3 * patch_size * patch_size) if predict_image else None
        self.gripper_head = nn.Linear(d, 1)
        self.action_head = (
            nn.Sequential(nn.Linear(d, d), nn.GELU(), nn.Linear(d, 6)) if predict_action else None
        )
        for p in (self.frame_embed, self.view_embed, self.register_token, self.future_pos_embed):
            nn.init.normal_(p, std=0.02)
        if self.image_head is not None:
            # Start from "no displacement" so early training is stable.
            nn.init.zeros_(self.image_head.weight)
        self.n_tokens = self.n_frames * n_views * self.n_patches + self.n_frames + 2 + horizon

    def _patchify(self, images: Tensor, embed: nn.Conv2d) -> Tensor:
        """(B, F, C, 3, h, w) -> (B, F, C, P, D/2) with the view's own patch embedding."""
        b, f, c, _, h, w = images.shape
        x = embed(images.reshape(b * f, c * 3, h, w))  # (B*F, C*D/2, gh, gw)
        x = x.reshape(b, f, c, -1, self.n_patches)
        return x.transpose(-1, -2)

    def forward(
        self,
        rgb: Tensor,
        point_map: Tensor,
        gripper_state: Tensor,
        timestep: Tensor,
        noisy_action: Tensor | None,
    ) -> tuple[Tensor | None, Tensor | None, Tensor]:
        b, f, c = rgb.shape[:3]
        t_h = self.horizon
        rgb_tokens = self._patchify(rgb * 2.0 - 1.0, self.rgb_patch_embed)
        if self.point_patch_embed is not None:
            point_tokens = self._patchify(point_map, self.point_patch_embed)
        else:
            point_tokens = torch.zeros_like(rgb_tokens)
        image_tokens = torch.cat([rgb_tokens, point_tokens], dim=-1)  # (B, F, C, P, D)
        image_tokens = (
            image_tokens
            + self.frame_embed[None, :, None, None]
            + self.view_embed[None, None, :, None]
            + self.patch_pos_embed[None, None, None]
        )
        image_tokens = image_tokens.reshape(b, f * c * self.n_patches, -1)

        gripper_in = torch.cat([gripper_state, gripper_state.new_zeros(b, t_h)], dim=1)  # future: zeros
        gripper_tokens = self.gripper_embed(gripper_in[..., None]) + self.frame_embed[None]
        d = image_tokens.shape[-1]
        step_token = self.step_mlp(sinusoidal_step_embedding(timestep, d))[:, None]
        future_tokens = self.future_pos_embed[None].expand(b, -1, -1)
        if self.action_embed is not None:
            future_tokens = future_tokens + self.action_embed(noisy_action)

        x = torch.cat(
            [image_tokens, gripper_tokens, step_token, self.register_token.expand(b, -1, -1), future_tokens],
            dim=1,
        )
        for block in self.blocks:
            x = block(x)
        x = self.norm(x)

        future_out = x[:, -t_h:]
        gripper_logits = self.gripper_head(future_out).squeeze(-1)
        action_update = self.action_head(future_out) if self.action_head is not None else None

        displacement = None
        if self.image_head is not None:
            n_obs_tokens = self.n_obs_steps * c * self.n_patches
            fut = x[:, n_obs_tokens : n_obs_tokens + t_h * c * self.n_patches]
            fut = fut.reshape(b, t_h, c, self.n_patches, d).transpose(2, 3)  # (B, T, P, C, D)
            patches = self.image_head(fut)  # (B, T, P, C, 3 p p)
            gh, gw = self.grid
            p = self.patch_size
            patches = patches.reshape(b, t_h, gh, gw, c, 3, p, p)
            displacement = patches.permute(0, 1, 4, 5, 2, 6, 3, 7).reshape(b, t_h, c, 3, gh * p, gw * p)
        return displacement, action_update, gripper_logits
