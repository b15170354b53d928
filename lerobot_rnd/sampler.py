"""Diffusion pieces of R&D: noise schedule, training targets, and the DDIM + SVD update.

Everything here is batched and free of host synchronisation (no `.item()`, no data-dependent shapes), so
the inference loop can be captured by `torch.compile` / CUDA graphs.
"""

import torch
from diffusers.schedulers.scheduling_ddim import DDIMScheduler
from torch import Tensor

from lerobot_rnd.geometry import invert_transform, rigid_transform_from_moments


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


def network_timesteps(timesteps: list[int], denoise_step: str) -> list[int]:
    """The timestep the network is told at each sampler step: the schedule's own, or for "refine" (clean jumps
    after a first step from pure noise) the first one, then len - 2, ..., 0: the input is nearly clean by then."""
    if denoise_step != "refine":
        return list(timesteps)
    return [timesteps[0]] + list(range(len(timesteps) - 2, -1, -1))


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

    All cameras are pooled: for each sample and horizon step one weighted least-squares fit over every visible
    pixel. points_k_cam, points_prev_cam: (B, T, C, 3, *pixels) camera-frame points (pixels: (H, W) or (N,));
    mask: (B, T, C, *pixels) bool (points outside it may hold anything, NaN included);
    T_world_cam: (B, T, C, 4, 4). Returns (T_world_delta (B, T, 4, 4), valid (B, T) bool); valid is False
    where fewer than max(3, `min_points`) pixels are visible over all cameras, and T_world_delta is then the
    identity (the caller falls back to the action space). Returned in the input dtype.

    The pixels are reduced once, per camera and in the camera frame, to their weighted moments (count, centroid,
    cross-covariance: one matrix product in float64), which are then moved into the world frame and pooled: the
    same solution as registering the world points themselves (`weighted_rigid_registration`), without building
    them. Degenerate point sets follow `weighted_rigid_registration`; visible points that differ only by the input
    dtype's rounding (in camera or world coordinates) count as one point: translation only.
    """
    dtype = points_k_cam.dtype
    p, q = points_k_cam.flatten(4), points_prev_cam.flatten(4)
    x = torch.empty((*p.shape[:-2], 7, p.shape[-1]), dtype=torch.float64, device=p.device)
    x[..., :3, :], x[..., 3:6, :], x[..., 6, :] = p, q, 1.0
    x.masked_fill_(~mask.flatten(3)[..., None, :], 0.0)  # (B, T, C, 7, N): [p; q; 1] at visible pixels, else 0
    moments = torch.einsum("...in,...jn->...ij", x, x)  # (B, T, C, 7, 7); the weights are 0/1, so w = w^2
    count_c = moments[..., 6, 6]  # (B, T, C)
    sum_p, sum_q = moments[..., :3, 6], moments[..., 3:6, 6]  # (B, T, C, 3)
    S_pq = moments[..., :3, 3:6]  # sum w p q^T
    sq_p = torch.diagonal(moments[..., :3, :3], dim1=-2, dim2=-1).sum(-1)  # sum w |p|^2
    sq_q = torch.diagonal(moments[..., 3:6, 3:6], dim1=-2, dim2=-1).sum(-1)
    # per camera, centred in the camera frame
    safe_c = count_c.clamp_min(1.0)[..., None]
    mu_p_c, mu_q_c = sum_p / safe_c, sum_q / safe_c  # (B, T, C, 3)
    cov_c = S_pq - count_c[..., None, None] * mu_p_c[..., :, None] * mu_q_c[..., None, :]
    spread_p_c = (sq_p - count_c * mu_p_c.square().sum(-1)).clamp_min(0)  # sum w |p - mu_p_c|^2
    spread_q_c = (sq_q - count_c * mu_q_c.square().sum(-1)).clamp_min(0)
    # into the world frame, pooled over cameras
    rot = T_world_cam[..., :3, :3].double()
    trans = T_world_cam[..., :3, 3].double()
    m_p = (rot @ mu_p_c[..., None])[..., 0] + trans  # (B, T, C, 3) world centroid of each camera's pixels
    m_q = (rot @ mu_q_c[..., None])[..., 0] + trans
    count = count_c.sum(-1)  # (B, T)
    share = count_c / count.clamp_min(1.0)[..., None]  # (B, T, C)
    mu_p = (share[..., None] * m_p).sum(-2)  # (B, T, 3)
    mu_q = (share[..., None] * m_q).sum(-2)
    dp, dq = m_p - mu_p[..., None, :], m_q - mu_q[..., None, :]
    cross_cov = (
        rot @ cov_c @ rot.transpose(-1, -2) + count_c[..., None, None] * dp[..., :, None] * dq[..., None, :]
    ).sum(-3)  # (B, T, 3, 3) sum over every visible pixel of w (world_k - mu_p)(world_prev - mu_q)^T
    spread_p = ((spread_p_c + count_c * dp.square().sum(-1)).sum(-1) / count.clamp_min(1.0)).sqrt()
    spread_q = ((spread_q_c + count_c * dq.square().sum(-1)).sum(-1) / count.clamp_min(1.0)).sqrt()

    def rms(sum_sq: Tensor) -> Tensor:  # (B, T, C) -> (B, T)
        return (sum_sq.sum(-1) / count.clamp_min(1.0)).sqrt()

    def world_sum_sq(sum_x: Tensor, sum_sq: Tensor) -> Tensor:  # sum w |R x + t|^2 per camera
        return sum_sq + 2 * (trans * (rot @ sum_x[..., None])[..., 0]).sum(-1) + count_c * trans.square().sum(-1)

    # the inputs hold `dtype`'s rounding in camera coordinates, and in world coordinates through T_world_cam
    scale = torch.maximum(rms(sq_p), rms(sq_q)) + torch.maximum(
        rms(world_sum_sq(sum_p, sq_p)), rms(world_sum_sq(sum_q, sq_q))
    )
    tol = 32 * torch.finfo(dtype).eps * scale
    one_point = (spread_p <= tol) | (spread_q <= tol)
    valid = count >= max(3, min_points)
    T_world_delta = rigid_transform_from_moments(mu_p, mu_q, cross_cov, one_point, valid)
    return T_world_delta.to(dtype), valid
