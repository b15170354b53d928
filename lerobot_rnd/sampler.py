"""Diffusion pieces of R&D: noise schedule, training targets, and the DDIM + SVD update.

Everything here is batched and free of host synchronisation (no `.item()`, no data-dependent shapes), so
the inference loop can be captured by `torch.compile` / CUDA graphs.
"""

import torch
from diffusers.schedulers.scheduling_ddim import DDIMScheduler
from torch import Tensor

from lerobot_rnd.geometry import invert_transform, weighted_rigid_registration


def make_noise_scheduler(num_train_timesteps: int, beta_schedule: str) -> DDIMScheduler:
    """DDIM scheduler predicting the clean sample, as in the research implementation.

    "trailing" timestep spacing makes the first inference step k = K - 1, where the sample is pure noise
    (diffusers' default "leading" spacing would start at K - K/S, telling the network the noise is smaller
    than it is).
    """
    return DDIMScheduler(
        num_train_timesteps=num_train_timesteps,
        beta_schedule=beta_schedule,
        prediction_type="sample",
        clip_sample=False,
        set_alpha_to_one=True,
        timestep_spacing="trailing",
    )


def inference_schedule(scheduler: DDIMScheduler, num_inference_steps: int) -> tuple[list[int], Tensor, Tensor]:
    """The DDIM steps k and the cumulative alphas at k and at the step after it.

    Returns (timesteps, alpha_bar (S,), alpha_bar_prev (S,)); the last step goes to alpha_bar_prev = 1.
    """
    scheduler.set_timesteps(num_inference_steps)
    timesteps = [int(k) for k in scheduler.timesteps]
    alphas = scheduler.alphas_cumprod
    alpha_bar = torch.stack([alphas[k] for k in timesteps])
    prev = [alphas[k] for k in timesteps[1:]] + [scheduler.final_alpha_cumprod]
    return timesteps, alpha_bar.float(), torch.stack(prev).float()


def ddim_step(x_k: Tensor, x0_hat: Tensor, alpha_bar: Tensor, alpha_bar_prev: Tensor) -> Tensor:
    """Deterministic DDIM update x_k -> x_{k-1} from the predicted clean sample (eta = 0).

    x_{k-1} = sqrt(a_{k-1}) x0 + sqrt((1 - a_{k-1}) / (1 - a_k)) (x_k - sqrt(a_k) x0).
    `alpha_bar` and `alpha_bar_prev` are scalars or broadcastable tensors.
    """
    c_eps = torch.sqrt((1.0 - alpha_bar_prev) / (1.0 - alpha_bar).clamp_min(1e-12))
    return torch.sqrt(alpha_bar_prev) * x0_hat + c_eps * (x_k - torch.sqrt(alpha_bar) * x0_hat)


def interpolation_step(x_k: Tensor, x0_hat: Tensor, alpha_bar: Tensor, alpha_bar_prev: Tensor) -> Tensor:
    """Translation-equivariant variant of `ddim_step` for metric points: moves x_k towards x0_hat by the
    same fraction as DDIM does, without DDIM's rescaling about the origin (the camera centre for points)."""
    c_eps = torch.sqrt((1.0 - alpha_bar_prev) / (1.0 - alpha_bar).clamp_min(1e-12))
    c_x0 = torch.sqrt(alpha_bar_prev) - c_eps * torch.sqrt(alpha_bar)
    fraction = c_x0 / (c_x0 + c_eps)
    return x_k + fraction * (x0_hat - x_k)


def displacement_target(points_cam: Tensor, T_cam_noisy: Tensor, T_cam_target: Tensor) -> Tensor:
    """Ground-truth per-pixel displacement F_gt = T(a_gt, a_noisy) P - P.

    points_cam: (..., 3, *pixels) camera-frame points of the gripper rendered at the noisy pose (pixels: (H, W)
        or (N,)). T_cam_noisy, T_cam_target: (..., 4, 4) gripper poses in the camera frame for the noisy and the
        ground-truth action. Returns (..., 3, *pixels); zero where points_cam is zero is NOT implied (mask it).
    """
    T_target_noisy = T_cam_target @ invert_transform(T_cam_noisy)
    rot = T_target_noisy[..., :3, :3]
    trans = T_target_noisy[..., :3, 3]
    lead = T_target_noisy.shape[:-2]
    flat = points_cam.reshape(*lead, 3, -1)
    moved = torch.einsum("...ij,...jn->...in", rot, flat) + trans[..., None]
    return (moved - flat).reshape(points_cam.shape)


def register_point_update(
    points_k_cam: Tensor,
    points_prev_cam: Tensor,
    mask: Tensor,
    T_world_cam: Tensor,
    min_points: int,
) -> tuple[Tensor, Tensor]:
    """Rigid transform, in the world frame, that moves the rendered gripper from P_k to P_{k-1}.

    All cameras are pooled: for each sample and horizon step one weighted SVD over every visible pixel.
    points_k_cam, points_prev_cam: (B, T, C, 3, *pixels) camera-frame points (pixels: (H, W) or (N,));
    mask: (B, T, C, *pixels) bool;
    T_world_cam: (B, T, C, 4, 4). Returns (T_world_delta (B, T, 4, 4), valid (B, T) bool); valid is False
    where fewer than `min_points` pixels are visible over all cameras, and T_world_delta is then the identity
    (the caller falls back to the action space). Solved in float64 (world coordinates of a metre or more would
    otherwise cost about 1e-6 m of float32 precision); returned in the input dtype. Degenerate point sets
    follow `weighted_rigid_registration`; visible points that differ only by the input dtype's rounding (in
    camera or world coordinates) count as one point: translation only.
    """
    b, t, c = mask.shape[:3]
    dtype = points_k_cam.dtype
    points_k_cam, points_prev_cam = points_k_cam.double(), points_prev_cam.double()
    rot = T_world_cam[..., :3, :3].double()
    trans = T_world_cam[..., :3, 3].double()

    def to_world(points: Tensor) -> Tensor:
        flat = points.flatten(4)  # (B, T, C, 3, N)
        world = torch.einsum("btcij,btcjn->btcni", rot, flat) + trans[..., None, :]
        return world.reshape(b, t, -1, 3)  # (B, T, C*HW, 3)

    weights = mask.reshape(b, t, -1).to(points_k_cam.dtype)
    world_k, world_prev = to_world(points_k_cam), to_world(points_prev_cam)

    def max_norm(points: Tensor) -> Tensor:  # (B, T, C*N, 3) -> (B, T): largest |p| over the visible pixels
        return torch.where(weights > 0, points.norm(dim=-1), 0.0).amax(-1)

    def cam(points: Tensor) -> Tensor:
        return points.flatten(4).transpose(-1, -2).reshape(b, t, -1, 3)

    # the inputs hold `dtype`'s rounding in camera coordinates, and in world coordinates through T_world_cam
    scale = torch.maximum(max_norm(cam(points_k_cam)), max_norm(cam(points_prev_cam))) + torch.maximum(
        max_norm(world_k), max_norm(world_prev)
    )
    T_world_delta, valid = weighted_rigid_registration(
        world_k, world_prev, weights, point_tol=32 * torch.finfo(dtype).eps * scale
    )
    valid = valid & (weights.sum(-1) >= min_points)
    eye = torch.eye(4, dtype=T_world_delta.dtype, device=T_world_delta.device)
    T_world_delta = torch.where(valid[..., None, None], T_world_delta, eye)
    return T_world_delta.to(dtype), valid
