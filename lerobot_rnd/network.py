"""The R&D denoiser: a ViT over (frames x views x patches) tokens plus gripper, step and action tokens.

Shapes use B = batch, F = frames (H past/current + T future), C = cameras (views), T = future steps,
D = model width, p = patch size, h x w = image size, P = (h/p)(w/p) patches per view.
"""

import math

import torch
import torch.nn.functional as F  # noqa: N812
from torch import Tensor, nn

from lerobot_rnd.configuration_rnd import PATCH_EMBEDS

#: Standard deviation of the initial frame, view, future-step and register embeddings (the authors use 1 and report
#: that small values work much worse).
EMBEDDING_INIT_STD = 1.0
#: Hidden width of the transformer's MLP blocks relative to the model width (the paper's 4).
MLP_RATIO = 4.0


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
        if qkv.device.type == "cpu" and qkv.dtype == torch.bfloat16:
            qkv = qkv.float()  # PyTorch's CPU flash attention is ~3x slower in bf16 than in float32
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


def patch_embedding(kind: str, n_views: int, out_per_view: int, patch_size: int) -> nn.Module:
    """Per-view patch embedding (grouped over views): (B', C*3, h, w) -> (B', C*out_per_view, h/p, w/p).

    "linear": one linear map per patch (kernel = stride = p), the ViT's. "conv": 4x4 then 2x2 then (p/8)x(p/8)
    convolutions with kernel = stride and GELU between them, so a small feature (the goal marker) is detected
    at 4-px resolution before the patch is pooled. Both are patch-local: a patch's token depends only on its
    own pixels, so the selected gripper patches embed exactly as they would in the full image.
    """
    in_ch = 3 * n_views
    if kind == "linear":
        return nn.Conv2d(in_ch, n_views * out_per_view, patch_size, patch_size, groups=n_views)
    if kind != "conv" or patch_size % 8:
        raise ValueError(f"patch_embed must be one of {PATCH_EMBEDS} ('conv' needs a patch_size divisible by 8), "
                         f"got {kind!r} with patch_size {patch_size}")  # fmt: skip
    c1, c2 = max(out_per_view // 4, 8), max(out_per_view // 2, 8)
    return nn.Sequential(
        nn.Conv2d(in_ch, n_views * c1, 4, 4, groups=n_views),
        nn.GELU(),
        nn.Conv2d(n_views * c1, n_views * c2, 2, 2, groups=n_views),
        nn.GELU(),
        nn.Conv2d(n_views * c2, n_views * out_per_view, patch_size // 8, patch_size // 8, groups=n_views),
    )


class RnDDenoiser(nn.Module):
    """ViT that maps rendered observations to image-space displacements, action updates and gripper logits.

    Inputs (all for one batch):
        obs_rgb: (B, H, C, 3, h, w) past/current camera images in [0, 1] (with the history gripper pasted over
            them when `history_rgb_overlay`).
        obs_points: (B, H, C, 3, h, w) camera-frame xyz of the rendered history gripper (zeros elsewhere), scaled.
        future_rgb: (B, T, C, 3, h, w) the current image with each future step's noisy gripper rendered on it;
            with `gripper_patches` = K > 0, only the selected patches' pixels (B, T, C, 3, K*p*p), patch-major
            (see `gather_patch_pixels`).
        future_points: the future steps' point maps, same shape as `future_rgb`.
        gripper_state: (B, H) gripper state of the past/current frames, roughly in [-1, 1].
        timestep: (B,) diffusion step k.
        noisy_action: (B, T, D) noisy normalised action (used by the A and AI variants; D = `action_dim`).
        patch_index: (B, T, C, K) long, required when `gripper_patches` > 0: which patches `future_*` hold
            (`select_gripper_patches`: those the rendered gripper covers most). A future frame's other patches
            equal the current frame's, which is tokenised in full.
    Outputs:
        displacement: normalised per-pixel 3-D displacement (I and AI variants, else None), (B, T, C, 3, h, w),
            or (B, T, C, 3, K*p*p) on the selected pixels with `gripper_patches` > 0.
        action_update: (B, T, D) normalised action-space update (A and AI variants, else None).
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
        gripper_patches: int = 0,
        patch_embed: str = "linear",
        n_tasks: int = 0,
        action_dim: int = 6,
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
        if not 0 <= gripper_patches <= self.n_patches:
            raise ValueError(f"gripper_patches must be in [0, {self.n_patches}] (patches per view), got {gripper_patches}")
        self.gripper_patches = gripper_patches
        self.future_patches = gripper_patches or self.n_patches  # tokens per future frame and view
        d = dim_model

        # Per-view patch embeddings (grouped convolutions: one group per view), half width each; the point map
        # (smooth, rendered) always takes the linear one.
        in_ch = 3 * n_views
        self.rgb_patch_embed = patch_embedding(patch_embed, n_views, d // 2, patch_size)
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
        self.action_embed = nn.Linear(action_dim, d) if predict_action else None

        self.blocks = nn.ModuleList(
            [TransformerBlock(d, n_heads, mlp_ratio, dropout) for _ in range(n_layers)]
        )
        self.norm = nn.LayerNorm(d)

        # Heads: per-view image decoder (a linear layer per patch, equivalent to a transposed convolution
        # with kernel = stride = patch size), gripper logits per future step, action-space update MLP.
        self.image_head = PerViewLinear(n_views, d, 3 * patch_size * patch_size) if predict_image else None
        self.gripper_head = nn.Linear(d, 1)
        self.action_head = (
            nn.Sequential(nn.Linear(d, d), nn.GELU(), nn.Linear(d, action_dim)) if predict_action else None
        )
        for p in (self.frame_embed, self.view_embed, self.register_token, self.future_pos_embed):
            nn.init.normal_(p, std=EMBEDDING_INIT_STD)
        if self.image_head is not None:
            # Start from "no displacement" so early training is stable.
            nn.init.zeros_(self.image_head.weight)
        # One learned token per task (the paper's goal embedding for its multi-task policy), made last so that a
        # model without tasks draws the same initial weights as before.
        self.task_embed = nn.Embedding(n_tasks, d) if n_tasks else None
        self.n_tokens = (
            (n_obs_steps * self.n_patches + horizon * self.future_patches) * n_views + self.n_frames + 2 + horizon
            + (1 if n_tasks else 0)
        )

    def _patchify(self, images: Tensor, embed: nn.Module) -> Tensor:
        """(B, F, C, 3, h, w) -> (B, F, C, P, D/2) with the view's own patch embedding."""
        b, f, c, _, h, w = images.shape
        x = embed(images.reshape(b * f, c * 3, h, w))  # (B*F, C*D/2, gh, gw)
        x = x.reshape(b, f, c, -1, self.n_patches)
        return x.transpose(-1, -2)

    def _patchify_selected(self, pixels: Tensor, embed: nn.Module) -> Tensor:
        """Embed selected patches: pixels (B, T, C, 3, K*p*p) patch-major -> (B, T, C, K, D/2), with the same
        (per-view) weights as `_patchify`."""
        b, t, c, ch, n = pixels.shape
        p = self.patch_size
        k = n // (p * p)
        patches = pixels.reshape(b, t, c, ch, k, p, p).permute(0, 1, 4, 2, 3, 5, 6)  # (B, T, K, C, 3, p, p)
        x = embed(patches.reshape(b * t * k, c * ch, p, p))  # (B*T*K, C*D/2, 1, 1)
        return x.reshape(b, t, k, c, -1).transpose(2, 3)

    def forward(
        self,
        obs_rgb: Tensor,
        obs_points: Tensor,
        future_rgb: Tensor,
        future_points: Tensor,
        gripper_state: Tensor,
        timestep: Tensor,
        noisy_action: Tensor | None,
        patch_index: Tensor | None = None,
        obs_tokens: Tensor | None = None,
        task_index: Tensor | None = None,
    ) -> tuple[Tensor | None, Tensor | None, Tensor]:
        """`obs_tokens`: `embed_observation(obs_rgb, obs_points)` if already computed (the sampler computes it
        once per chunk: the past/current frames do not change between denoising steps). `task_index`: (B,) long,
        each sample's task, required exactly when the network was built with tasks (`n_tasks` > 0)."""
        b, n_obs, c = obs_rgb.shape[:3]
        t_h = self.horizon
        if bool(self.gripper_patches) != (patch_index is not None):
            raise ValueError(
                f"gripper_patches={self.gripper_patches}: pass `patch_index` (B, T, C, K) exactly when "
                "gripper_patches > 0."
            )
        if (self.task_embed is not None) != (task_index is not None):
            raise ValueError(
                f"n_tasks={0 if self.task_embed is None else self.task_embed.num_embeddings}: pass `task_index` (B,) "
                "exactly when the network conditions on tasks."
            )
        if obs_tokens is None:
            obs_tokens = self.embed_observation(obs_rgb, obs_points)  # (B, H, C, P, D)
        fut_tokens = self._embed_frames(future_rgb, future_points, sparse=patch_index is not None)  # (B,T,C,K,D)
        if patch_index is None:
            fut_tokens = fut_tokens + self.patch_pos_embed[None, None, None]
        else:
            fut_tokens = fut_tokens + self.patch_pos_embed[patch_index]
        frame_view = self.frame_embed[:, None] + self.view_embed[None]  # (F, C, D)
        obs_tokens = obs_tokens + frame_view[None, :n_obs, :, None]
        fut_tokens = fut_tokens + frame_view[None, n_obs:, :, None]
        image_tokens = torch.cat([obs_tokens.flatten(1, 3), fut_tokens.flatten(1, 3)], dim=1)

        gripper_in = torch.cat([gripper_state, gripper_state.new_zeros(b, t_h)], dim=1)  # future: zeros
        gripper_tokens = self.gripper_embed(gripper_in[..., None]) + self.frame_embed[None]
        d = image_tokens.shape[-1]
        step_token = self.step_mlp(sinusoidal_step_embedding(timestep, d))[:, None]
        future_tokens = self.future_pos_embed[None].expand(b, -1, -1)
        if self.action_embed is not None:
            future_tokens = future_tokens + self.action_embed(noisy_action)

        task_tokens = [] if task_index is None else [self.task_embed(task_index)[:, None]]
        x = torch.cat(
            [image_tokens, gripper_tokens, step_token, *task_tokens, self.register_token.expand(b, -1, -1),
             future_tokens],
            dim=1,
        )  # fmt: skip
        for block in self.blocks:
            x = block(x)
        x = self.norm(x)

        future_out = x[:, -t_h:]
        gripper_logits = self.gripper_head(future_out).squeeze(-1)
        action_update = self.action_head(future_out) if self.action_head is not None else None

        displacement = None
        if self.image_head is not None:
            n_obs_tokens = self.n_obs_steps * c * self.n_patches
            k = self.future_patches
            fut = x[:, n_obs_tokens : n_obs_tokens + t_h * c * k]
            fut = fut.reshape(b, t_h, c, k, d).transpose(2, 3)  # (B, T, K, C, D)
            patches = self.image_head(fut).transpose(2, 3)  # (B, T, C, K, 3 p p)
            if patch_index is None:
                displacement = patches_to_image(patches, self.grid, self.patch_size)
            else:
                p = self.patch_size
                displacement = patches.reshape(b, t_h, c, k, 3, p * p).transpose(3, 4).reshape(b, t_h, c, 3, k * p * p)
        return displacement, action_update, gripper_logits

    def embed_observation(self, obs_rgb: Tensor, obs_points: Tensor) -> Tensor:
        """Past/current frames (B, H, C, 3, h, w) each -> their patch tokens (B, H, C, P, D), with the patch
        position embedding (frame and view embeddings are added in `forward`)."""
        return self._embed_frames(obs_rgb, obs_points, sparse=False) + self.patch_pos_embed[None, None, None]

    def _embed_frames(self, rgb: Tensor, points: Tensor, sparse: bool) -> Tensor:
        """Images and point maps (B, F', C, 3, h, w), or selected pixels (B, F', C, 3, K*p*p) when `sparse`
        -> (B, F', C, P or K, D) patch tokens (no position embeddings)."""
        patchify = self._patchify_selected if sparse else self._patchify
        rgb_tokens = patchify(rgb * 2.0 - 1.0, self.rgb_patch_embed)
        if self.point_patch_embed is None:
            return torch.cat([rgb_tokens, torch.zeros_like(rgb_tokens)], dim=-1)
        return torch.cat([rgb_tokens, patchify(points, self.point_patch_embed)], dim=-1)


def patch_pixel_index(patch_index: Tensor, grid: tuple[int, int], patch_size: int) -> Tensor:
    """Flat (row-major) pixel numbers of selected patches: (..., K) -> (..., K*p*p), patch-major, then rows,
    then columns within a patch."""
    gh, gw = grid
    p = patch_size
    w = gw * p
    row0 = (patch_index // gw) * p
    col0 = (patch_index % gw) * p
    offsets = torch.arange(p, device=patch_index.device)
    pix = (row0[..., None, None] + offsets[:, None]) * w + col0[..., None, None] + offsets[None, :]
    return pix.flatten(-3)


def gather_patch_pixels(x: Tensor, pixel_index: Tensor) -> Tensor:
    """x (..., ch, h, w) (or (..., h, w) with no channel dim when `x.ndim == pixel_index.ndim + 1`),
    pixel_index (..., N) -> (..., ch, N) (or (..., N)). Reads only the selected pixels."""
    if x.ndim == pixel_index.ndim + 1:  # no channel dimension
        return torch.gather(x.flatten(-2), -1, pixel_index)
    flat = x.flatten(-2)  # (..., ch, h*w)
    index = pixel_index[..., None, :].expand(*pixel_index.shape[:-1], flat.shape[-2], pixel_index.shape[-1])
    return torch.gather(flat, -1, index)


def patches_to_image(patches: Tensor, grid: tuple[int, int], patch_size: int) -> Tensor:
    """(..., P, ch * p * p) per-patch values, P = gh * gw row-major -> (..., ch, gh * p, gw * p)."""
    *lead, n, m = patches.shape
    gh, gw = grid
    p = patch_size
    ch = m // (p * p)
    x = patches.reshape(*lead, gh, gw, ch, p, p)
    nd = x.ndim
    # (..., gh, gw, ch, p, p) -> (..., ch, gh, p, gw, p)
    x = x.permute(*range(nd - 5), nd - 3, nd - 5, nd - 2, nd - 4, nd - 1)
    return x.reshape(*lead, ch, gh * p, gw * p)


def select_gripper_patches(mask: Tensor, patch_size: int, k: int) -> Tensor:
    """The k patches of each image that the rendered gripper covers most (ties: lower patch number first).

    mask: (..., h, w) bool -> patch_index (..., k) long, sorted ascending (row-major patch numbers).
    """
    *lead, h, w = mask.shape
    p = patch_size
    counts = mask.reshape(*lead, h // p, p, w // p, p).sum((-1, -3)).flatten(-2).float()  # (..., P)
    n = counts.shape[-1]
    # Stable tie-break towards lower patch numbers without a data-dependent sort.
    score = counts * n + (n - 1 - torch.arange(n, device=mask.device, dtype=counts.dtype))
    return torch.topk(score, k, dim=-1).indices.sort(dim=-1).values
