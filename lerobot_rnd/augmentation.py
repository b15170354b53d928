"""Training-time image augmentation that keeps the camera calibration consistent with the pixels.

`shift_images_and_intrinsics` moves every camera's images by a random whole-pixel offset (the same for all
frames of a sample, as DrQ's and Diffusion Policy's random crops do) and moves that camera's principal point by
the same offset. A 3-D point that projected to pixel (u, v) now projects to (u + dx, v + dy), where its image
content went, so the gripper R&D renders with the shifted intrinsics still lands on the real gripper.

`camera_dropout_keep` / `drop_cameras` blank one whole camera of a random share of the training samples (its
RGB and point maps, observed and rendered, and its image-space loss), so the network cannot lean on one view
(the authors' research code can drop a view's tokens for a whole batch, off by default).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor


def shift_images_and_intrinsics(
    images: Tensor, K: Tensor, max_shift: int, generator: torch.Generator | None = None
) -> tuple[Tensor, Tensor]:
    """Shift each (sample, camera)'s images by a random offset in [-max_shift, max_shift] pixels.

    images: (B, H, C, 3, h, w) history frames per camera; K: (C, 3, 3) intrinsics at (h, w).
    Returns the shifted images (B, H, C, 3, h, w), border pixels replicated, and the per-sample intrinsics
    K_shifted (B, C, 3, 3) with cx + dx, cy + dy.
    """
    b, n_hist, c, ch, h, w = images.shape
    s = int(max_shift)
    if s <= 0:
        return images, K.expand(b, c, 3, 3)
    device = images.device
    offsets = torch.randint(-s, s + 1, (b, c, 2), generator=generator, device="cpu").to(device)  # (dx, dy)
    padded = F.pad(images.reshape(b, n_hist * c * ch, h, w), (s, s, s, s), mode="replicate")
    padded = padded.reshape(b, n_hist, c, ch, h + 2 * s, w + 2 * s).permute(0, 2, 1, 3, 4, 5)  # (B, C, H, 3, ., .)
    # Output pixel (v, u) shows input pixel (v - dy, u - dx), i.e. padded (v - dy + s, u - dx + s).
    rows = torch.arange(h, device=device)[None, None, :] - offsets[..., 1:2] + s  # (B, C, h)
    cols = torch.arange(w, device=device)[None, None, :] - offsets[..., 0:1] + s  # (B, C, w)
    bi = torch.arange(b, device=device)[:, None, None, None]
    ci = torch.arange(c, device=device)[None, :, None, None]
    shifted = padded[bi, ci, :, :, rows[:, :, :, None], cols[:, :, None, :]]  # (B, C, h, w, H, 3)
    shifted = shifted.permute(0, 4, 1, 5, 2, 3).contiguous()  # (B, H, C, 3, h, w)
    K_shifted = K.expand(b, c, 3, 3).clone()
    K_shifted[..., 0, 2] += offsets[..., 0].to(K.dtype)
    K_shifted[..., 1, 2] += offsets[..., 1].to(K.dtype)
    return shifted, K_shifted


# Keys of `RnDModel._network_inputs` that carry per-camera pixels, camera on dim 2: (B, H or T, C, ...).
CAMERA_INPUT_KEYS = ("obs_rgb", "obs_points", "future_rgb", "future_points")


def camera_dropout_keep(
    b: int, c: int, p: float, generator: torch.Generator | None = None, device: torch.device | str = "cpu"
) -> Tensor:
    """(B, C) bool: which cameras each sample keeps. With probability `p` a sample loses one camera, chosen
    uniformly; a sample never loses all its cameras (one camera: always kept)."""
    if p <= 0 or c < 2:
        return torch.ones(b, c, dtype=torch.bool, device=device)
    drop = torch.rand(b, generator=generator, device="cpu") < p
    which = torch.randint(0, c, (b,), generator=generator, device="cpu")
    keep = ~(drop[:, None] & (torch.arange(c)[None, :] == which[:, None]))
    return keep.to(device)


def drop_cameras(inputs: dict, keep: Tensor) -> dict:
    """Blank the dropped cameras of `_network_inputs`-style `inputs`: CAMERA_INPUT_KEYS become 0 and
    `target_mask` (B, T, C, N) False there, so the dropped view neither informs the network nor is scored.
    keep: (B, C) bool from `camera_dropout_keep`. Returns a new dict; the other entries are shared."""
    out = dict(inputs)
    for key in CAMERA_INPUT_KEYS:
        x = inputs[key]
        out[key] = x * keep.view(keep.shape[0], 1, keep.shape[1], *([1] * (x.dim() - 3))).to(x.dtype)
    out["target_mask"] = inputs["target_mask"] & keep[:, None, :, None]
    return out
