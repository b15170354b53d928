"""The diffusion side of R&D: noise schedule, training targets, and the whole sampling loop.

Equation numbers are the paper's (Vosylius et al., "Render and Diffuse", RSS 2024): (1) the forward diffusion,
(6) the image-space target F_gt = T(a_gt, a_noisy) P - P, (7) the DDIM step on the rendered gripper's points,
(8) the rigid registration of two point clouds by SVD (Arun et al.). Sec. IV-D describes the inference loop that
`sample_actions` implements; the paper's Sec. IV-B (R&D-AI) the fallback to, and final pass in, action space.

The model supplies one callable, `denoise_fn(a, T_ee_target, timestep, full_composite) -> DenoiserOutput`: render
the gripper at the actions, run the network; and the space of the diffused variable `a` (B, T, D)
(`lerobot_rnd.diffusion_space`: `to_pose(a) -> T_ee_target`, `from_pose(T_ee_target) -> a`). Everything here is batched and free of host synchronisation (no
`.item()`, no data-dependent shapes), so the loop can be captured by `torch.compile` / CUDA graphs.
"""

from collections.abc import Callable
from dataclasses import dataclass

import torch
from diffusers.schedulers.scheduling_ddim import DDIMScheduler
from torch import Tensor

from lerobot_rnd.geometry import invert_transform, rigid_transform_from_moments

#: The noise schedule (diffusers' name): squared cosine, as the authors' research code.
BETA_SCHEDULE = "squaredcos_cap_v2"
#: Fewer visible rendered pixels than this over all cameras make a step fall back to the action-space update.
MIN_VISIBLE_POINTS = 3


def make_noise_scheduler(num_train_timesteps: int) -> DDIMScheduler:
    """DDIM scheduler predicting the clean sample, as in the research implementation; `add_noise` is Eq. (1).

    "trailing" timestep spacing makes the first inference step k = K - 1, where the sample is pure noise
    (diffusers' default "leading" spacing would start at K - K/S, telling the network the noise is smaller
    than it is).
    """
    return DDIMScheduler(
        num_train_timesteps=num_train_timesteps,
        beta_schedule=BETA_SCHEDULE,
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
    """Deterministic DDIM update x_k -> x_{k-1} from the predicted clean sample (eta = 0); Eq. (7) for points.

    x_{k-1} = sqrt(a_{k-1}) x0 + sqrt((1 - a_{k-1}) / (1 - a_k)) (x_k - sqrt(a_k) x0).
    `alpha_bar` and `alpha_bar_prev` are scalars or broadcastable tensors.
    """
    c_eps = torch.sqrt((1.0 - alpha_bar_prev) / (1.0 - alpha_bar).clamp_min(1e-12))
    return torch.sqrt(alpha_bar_prev) * x0_hat + c_eps * (x_k - torch.sqrt(alpha_bar) * x0_hat)


def displacement_target(points_cam: Tensor, T_cam_noisy: Tensor, T_cam_target: Tensor) -> Tensor:
    """Ground-truth per-pixel displacement, Eq. (6): F_gt = T(a_gt, a_noisy) P - P.

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
    min_points: int = MIN_VISIBLE_POINTS,
) -> tuple[Tensor, Tensor]:
    """Rigid transform, in the world frame, that moves the rendered gripper from P_k to P_{k-1}: Eq. (8).

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


# ----------------------------------------------------------------------------------------------------------------
# The sampling loop.


@dataclass
class DenoiserOutput:
    """One network pass on rendered actions, as the sampler needs it.

    update: (B, T, D) normalised action-space update (variants A, AI) or None.
    logits: (B, T) gripper logits.
    displacement: (B, T, C, 3, N) metric camera-frame displacement F of the rendered pixels (variants I, AI) or
        None; points (B, T, C, 3, N) those pixels' camera-frame points P; mask (B, T, C, N) where they are set;
        T_world_cam (B, T, C, 4, 4) the cameras of the future frames.
    composite: (B, F, C, 3, h, w) the images the network saw (for visualisation), or None.
    """

    update: Tensor | None
    logits: Tensor
    displacement: Tensor | None = None
    points: Tensor | None = None
    mask: Tensor | None = None
    T_world_cam: Tensor | None = None
    composite: Tensor | None = None


#: denoise_fn(a (B, T, D) normalised, T_ee_target (B, T, 4, 4), timestep (B,) long, full_composite) -> output
DenoiseFn = Callable[[Tensor, Tensor, Tensor, bool], DenoiserOutput]


def image_space_action(
    a: Tensor, T_ee_target: Tensor, out: DenoiserOutput, T_world_ee_now: Tensor, space,
    alpha_bar: Tensor, alpha_bar_prev: Tensor, point_update: str,
) -> tuple[Tensor, Tensor]:
    """The next action from the image-space prediction (Sec. IV-D): P_0 = P_k + F, then either

    - "x0": one registration P_k -> P_0 (Eq. 8) gives the clean action estimate, and the DDIM step (Eq. 7) is
      taken in normalised action space (as diffusers does for sample prediction; independent of where the
      cameras are), or
    - "ddim": the paper's Eq. (7) applied to the camera-frame points (P_k -> P_{k-1}), then Eq. (8) (it rescales
      the cloud about each camera centre).

    a, T_ee_target: the current actions (B, T, D) normalised and their poses (B, T, 4, 4); T_world_ee_now
    (B, 1, 4, 4); space: the diffused variable's (`from_pose`). Returns (a_next (B, T, D), valid (B, T) bool: enough
    rendered pixels were visible).
    """
    p_k = out.points.float()
    p0 = p_k + out.displacement
    p_target = p0 if point_update == "x0" else ddim_step(p_k, p0, alpha_bar, alpha_bar_prev)
    T_world_delta, valid = register_point_update(p_k, p_target, out.mask, out.T_world_cam, MIN_VISIBLE_POINTS)
    # T_ee_moved = T_world_ee_now^-1 T_world_delta T_world_ee_now T_ee_target, composed in float64 for precision.
    T_now = T_world_ee_now.double()
    T_ee_moved = (invert_transform(T_now) @ T_world_delta.double() @ T_now @ T_ee_target.double()).float()
    a_image = space.from_pose(T_ee_moved)
    if point_update == "x0":
        a_image = ddim_step(a, a_image.clamp(-1, 1), alpha_bar, alpha_bar_prev)
    return a_image, valid


def sampler_step(
    denoise_fn: DenoiseFn, a: Tensor, timestep: int, alpha_bar: Tensor, alpha_bar_prev: Tensor, space,
    T_world_ee_now: Tensor, point_update: str = "x0", full_composite: bool = False,
) -> tuple[Tensor, Tensor, Tensor | None, Tensor | None]:
    """One denoising step a_k -> a_{k-1} (Sec. IV-D): render the actions, predict, update.

    a: (B, T, D) normalised actions at diffusion step `timestep` (`space`: their diffusion space); alpha_bar / alpha_bar_prev: that step's
    cumulative alphas. The clean estimate comes from the image space where enough rendered pixels are visible
    (variants I, AI; `image_space_action`), else from the action space (a + update for A and AI; the current
    action for I), followed by a DDIM step (Eq. 7 in action space).
    Returns (a_next (B, T, D), gripper logits (B, T), valid (B, T) bool or None without image-space predictions,
    the composite images when `full_composite`, else None).
    """
    a = a.clamp(-1, 1)
    T_ee_target = space.to_pose(a)
    steps = torch.full((a.shape[0],), timestep, device=a.device, dtype=torch.long)
    out = denoise_fn(a, T_ee_target, steps, full_composite)
    x0_action = (a + out.update).clamp(-1, 1) if out.update is not None else a
    a_next = ddim_step(a, x0_action, alpha_bar, alpha_bar_prev)
    valid = None
    if out.displacement is not None:
        a_image, valid = image_space_action(
            a, T_ee_target, out, T_world_ee_now, space, alpha_bar, alpha_bar_prev, point_update
        )
        a_next = torch.where(valid[..., None], a_image, a_next)
    return a_next, out.logits, valid, out.composite


def sample_actions(
    denoise_fn: DenoiseFn, noise: Tensor, timesteps: list[int], alpha_bar: Tensor, alpha_bar_prev: Tensor,
    space, T_world_ee_now: Tensor, point_update: str = "x0", final_action_step: bool = True,
    on_visibility: Callable[[Tensor], None] | None = None, record: list | None = None,
) -> tuple[Tensor, Tensor]:
    """The R&D sampler (Sec. IV-D): from Gaussian noise in normalised action space, one `sampler_step` per
    inference timestep, then (`final_action_step`, variants A and AI) one more pass at timestep 0 whose
    action-space prediction gives the final, precise action (Sec. IV-B, R&D-AI).

    noise: (B, T, D); space: the diffused variable's (`lerobot_rnd.diffusion_space`); timesteps: the S DDIM steps k; alpha_bar, alpha_bar_prev: (S,) their cumulative alphas
    (`inference_schedule`); T_world_ee_now: (B, 1, 4, 4) the current end-effector pose; `on_visibility(valid)`
    is called with each step's (B, T) visibility; `record`, a list, receives the composite images of every pass.
    Returns (a_0 (B, T, D) normalised, gripper logits (B, T)).
    """
    a = noise
    logits = None
    for i, k in enumerate(timesteps):
        a, logits, valid, composite = sampler_step(
            denoise_fn, a, k, alpha_bar[i], alpha_bar_prev[i], space, T_world_ee_now, point_update,
            full_composite=record is not None,
        )
        if valid is not None and on_visibility is not None:
            on_visibility(valid)
        if record is not None:
            record.append(composite)
    a = a.clamp(-1, 1)
    if final_action_step:
        T_ee_target = space.to_pose(a)
        out = denoise_fn(a, T_ee_target, torch.zeros((a.shape[0],), device=a.device, dtype=torch.long),
                         record is not None)  # fmt: skip
        if record is not None:
            record.append(out.composite)
        logits = out.logits
        a = (a + out.update).clamp(-1, 1)
    return a, logits
