#!/usr/bin/env python
"""Render and Diffuse (R&D) policy.

"Render and Diffuse: Aligning Image and Action Spaces for Diffusion-based Behaviour Cloning",
Vosylius, Seo, Wang and Johns, RSS 2024 (https://arxiv.org/abs/2405.18196).

Shapes: B batch, H observation steps, T future steps, F = H + T frames, C cameras, h x w network image size.
"""

import logging
from collections import deque

import torch
import torch.nn.functional as F  # noqa: N812
from torch import Tensor, nn

from lerobot.policies.pretrained import PreTrainedPolicy
from lerobot.policies.utils import populate_queues
from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE

from lerobot_rnd.action_adapters import ActionAdapter
from lerobot_rnd.configuration_rnd import RnDConfig
from lerobot_rnd.embodiment_binding import (
    CameraRig,
    EEPoseReader,
    MeshBuffers,
    resolve_embodiment,
)
from lerobot_rnd.geometry import action_from_pose, invert_transform, pose_from_action
from lerobot_rnd.network import RnDDenoiser
from lerobot_rnd.rendering import Rasterizer
from lerobot_rnd.sampler import (
    ddim_step,
    displacement_target,
    inference_schedule,
    interpolation_step,
    make_noise_scheduler,
    register_point_update,
)
from lerobot_rnd.statistics import MinMaxStats, estimate_rnd_statistics

logger = logging.getLogger(__name__)


class RnDPolicy(PreTrainedPolicy):
    """Render and Diffuse: diffusion over actions drawn into the camera images as renders of the gripper."""

    config_class = RnDConfig
    name = "rnd"

    def __init__(self, config: RnDConfig, dataset_stats=None, dataset_meta=None, **kwargs):
        """
        Args:
            config: Policy configuration. Its embodiment is resolved here (from `config.embodiment`, or the
                dataset's `meta/rnd_embodiment.json`) unless it already carries resolved calibration.
            dataset_stats: LeRobot dataset statistics (unused: R&D estimates its own).
            dataset_meta: Dataset metadata, given when training from scratch: used to find the embodiment and
                to estimate the normalisation statistics of R&D's action-space and image-space targets.
        """
        super().__init__(config)
        config.validate_features()
        self.config = config
        embodiment_meshes = resolve_embodiment(config, dataset_meta)
        self.model = RnDModel(config, embodiment_meshes)
        if dataset_meta is not None:
            self.model.fit_statistics(dataset_meta)
        self._queues = None
        self.reset()

    def get_optim_params(self) -> dict:
        return self.model.network.parameters()

    def reset(self):
        """Clear observation and action queues. Call on `env.reset()`."""
        self._queues = {
            OBS_STATE: deque(maxlen=self.config.n_obs_steps),
            OBS_IMAGES: deque(maxlen=self.config.n_obs_steps),
            ACTION: deque(maxlen=self.config.n_action_steps),
        }

    def _stack_images(self, batch: dict[str, Tensor]) -> dict[str, Tensor]:
        """Stack the cameras into batch[OBS_IMAGES] (..., C, 3, h, w), resized to the network's image size."""
        missing = [key for key in self.config.image_features if key not in batch]
        if missing:
            raise KeyError(
                f"R&D expects camera keys {list(self.config.image_features)} but the batch lacks {missing} "
                f"(batch keys: {sorted(batch)}). Rename the cameras (e.g. lerobot-eval --rename_map) or "
                "calibrate these cameras."
            )
        batch = dict(batch)
        images = [resize_images(batch[key], self.config.image_size, key) for key in self.config.image_features]
        batch[OBS_IMAGES] = torch.stack(images, dim=-4)
        return batch

    @torch.no_grad()
    def predict_action_chunk(self, batch: dict[str, Tensor], noise: Tensor | None = None) -> Tensor:
        """Predict a chunk of actions (B, chunk_size, action_dim) in the dataset's action space.

        Works on its own (no queues): observations may carry history (B, H, ...) or be single frames (B, ...),
        in which case the current frame stands in for the past ones.
        """
        self.eval()
        if OBS_IMAGES not in batch:
            batch = self._stack_images(batch)
        images, state = batch[OBS_IMAGES], batch[OBS_STATE]
        if images.ndim == 5:  # (B, C, 3, h, w): no history given
            images = images[:, None].expand(-1, self.config.n_obs_steps, -1, -1, -1, -1)
        if state.ndim == 2:
            state = state[:, None].expand(-1, self.config.n_obs_steps, -1)
        return self.model.generate_actions(images, state, noise=noise)

    @torch.no_grad()
    def select_action(self, batch: dict[str, Tensor], noise: Tensor | None = None) -> Tensor:
        """Select one action (B, action_dim), querying the model every `n_action_steps` steps."""
        self.eval()
        batch = self._stack_images({k: v for k, v in batch.items() if k != ACTION})
        self._queues = populate_queues(self._queues, batch)
        if len(self._queues[ACTION]) == 0:
            stacked = {
                OBS_IMAGES: torch.stack(list(self._queues[OBS_IMAGES]), dim=1),
                OBS_STATE: torch.stack(list(self._queues[OBS_STATE]), dim=1),
            }
            actions = self.predict_action_chunk(stacked, noise=noise)[:, : self.config.n_action_steps]
            self._queues[ACTION].extend(actions.transpose(0, 1))
        return self._queues[ACTION].popleft()

    def forward(self, batch: dict[str, Tensor]) -> tuple[Tensor, dict]:
        """Training loss on a batch with history: images (B, H, 3, h, w) per camera, state (B, H, D),
        action (B, T, A), optional `action_is_pad` (B, T)."""
        batch = self._stack_images(batch)
        images, state = batch[OBS_IMAGES], batch[OBS_STATE]
        if images.ndim == 5:
            images, state = images[:, None], state[:, None] if state.ndim == 2 else state
        action_is_pad = batch.get("action_is_pad")
        return self.model.compute_loss(images, state, batch[ACTION], action_is_pad)

    def generate_model_card(self, dataset_repo_id, model_type, license, tags):  # noqa: A002
        from lerobot_rnd.model_card import make_rnd_model_card

        return make_rnd_model_card(self.config, dataset_repo_id, license, tags)


def resize_images(images: Tensor, size: tuple[int, int], key: str = "image") -> Tensor:
    """Resize (..., 3, h0, w0) images to `size` (H, W); the aspect ratio must match (intrinsics scale with it)."""
    h, w = size
    h0, w0 = images.shape[-2:]
    if (h0, w0) == (h, w):
        return images
    if h0 * w != w0 * h:
        raise ValueError(
            f"{key}: images are {h0}x{w0}, whose aspect ratio differs from the policy's {h}x{w}: crop the images "
            "or recalibrate the camera for this size."
        )
    lead = images.shape[:-3]
    flat = images.reshape(-1, images.shape[-3], h0, w0).float()
    out = F.interpolate(flat, size=(h, w), mode="bilinear", antialias=True, align_corners=False)
    return out.reshape(*lead, images.shape[-3], h, w)


class RnDModel(nn.Module):
    """Rendering, normalisation, denoiser and sampler of R&D (everything but LeRobot's queues)."""

    def __init__(self, config: RnDConfig, meshes: dict | None):
        super().__init__()
        self.config = config
        self.camera_keys = list(config.image_features)
        self.rig = CameraRig(config, self.camera_keys)
        self.meshes = MeshBuffers(config, meshes)
        self.ee_reader = EEPoseReader(config.ee_pose, config.robot_state_feature.shape[0])
        self.action_adapter = ActionAdapter.from_dict(dict(config.action_adapter))
        self._check_action_dim()
        t = config.chunk_size
        action_shape = (t, 6) if config.per_horizon_action_normalization else (6,)
        self.action_stats = MinMaxStats(action_shape)
        self.displacement_stats = MinMaxStats((len(self.camera_keys), 3, 1, 1))

        self.predict_image = config.variant in ("I", "AI")
        self.predict_action = config.variant in ("A", "AI")
        self.network = RnDDenoiser(
            n_views=len(self.camera_keys),
            n_obs_steps=config.n_obs_steps,
            horizon=t,
            image_size=config.image_size,
            patch_size=config.patch_size,
            dim_model=config.dim_model,
            n_layers=config.n_layers,
            n_heads=config.n_heads,
            mlp_ratio=config.mlp_ratio,
            dropout=config.dropout,
            predict_image=self.predict_image,
            predict_action=self.predict_action,
            use_point_map_input=config.use_point_map_input,
        )
        self.noise_scheduler = make_noise_scheduler(config.num_train_timesteps, config.beta_schedule)
        self.register_buffer(
            "alphas_cumprod", self.noise_scheduler.alphas_cumprod.float().clone(), persistent=False
        )
        timesteps, alpha_bar, alpha_bar_prev = inference_schedule(
            self.noise_scheduler, config.num_inference_steps
        )
        self.inference_timesteps = timesteps
        self.register_buffer("inference_alpha_bar", alpha_bar, persistent=False)
        self.register_buffer("inference_alpha_bar_prev", alpha_bar_prev, persistent=False)
        self._compiled_sampler = None
        self._static_render = False
        self._render_overflow = torch.zeros((), dtype=torch.bool)
        self._rasterizers: dict = {}
        # Rasterizers hold copies of the mesh buffers: rebuild them after a checkpoint is loaded.
        self.meshes.register_load_state_dict_post_hook(lambda module, keys: self._rasterizers.clear())

    def rasterizer(self, static: bool = False) -> Rasterizer:
        """The rasteriser for the model's meshes, image size and device (built once, cached)."""
        device = self.meshes.vertices.device
        key = (self.config.render_texture, str(device), static)
        if key not in self._rasterizers:
            self._rasterizers[key] = Rasterizer(
                self.meshes.mesh_batch(self.config.render_texture), self.config.image_size, device=device
            )
        return self._rasterizers[key]

    def _check_action_dim(self) -> None:
        dataset_dim = self.config.action_feature.shape[0]
        if self.action_adapter.action_dim != dataset_dim:
            raise ValueError(
                f"The action adapter {self.config.action_adapter.get('type')!r} produces "
                f"{self.action_adapter.action_dim}-D actions but the dataset's 'action' is {dataset_dim}-D. "
                "Pick the adapter that matches the dataset (--policy.action_adapter) or fix the embodiment."
            )

    # ------------------------------------------------------------------------------------------------
    # Statistics.
    def fit_statistics(self, dataset_meta) -> None:
        """Estimate the min/max of the action-space and image-space targets from the dataset on disk."""
        stats = estimate_rnd_statistics(self, dataset_meta)
        self.action_stats.set(stats["action_min"], stats["action_max"])
        self.displacement_stats.set(stats["displacement_min"], stats["displacement_max"])

    # ------------------------------------------------------------------------------------------------
    # Observation preparation.
    def prepare_observation(self, images: Tensor, state: Tensor) -> tuple[Tensor, Tensor, Tensor]:
        """Check shapes and read poses.

        images: (B, H, C, 3, h, w) in [0, 1] at the network's image size; state: (B, H, D).
        Returns images (B, H, C, 3, h, w), T_world_ee (B, H, 4, 4), gripper state (B, H) in [-1 open, +1 closed].
        """
        if images.shape[1] != self.config.n_obs_steps or state.shape[1] != self.config.n_obs_steps:
            raise ValueError(
                f"Expected {self.config.n_obs_steps} observation steps, got images {tuple(images.shape)} and "
                f"state {tuple(state.shape)}."
            )
        if images.shape[2] != len(self.camera_keys):
            raise ValueError(f"Expected {len(self.camera_keys)} cameras, got {images.shape[2]}.")
        if not torch.isfinite(state).all():
            raise ValueError("observation.state contains NaN or inf.")
        images = resize_images(images, self.config.image_size).float().clamp(0, 1)
        T_world_ee = self.ee_reader.pose(state)
        gripper = self.ee_reader.gripper(state)
        return images, T_world_ee, gripper

    # ------------------------------------------------------------------------------------------------
    # Rendering.
    def render_frames(self, T_world_ee_frames: Tensor, T_world_ee_images: Tensor):
        """Render the gripper for every frame and camera in one call.

        T_world_ee_frames: (B, F, 4, 4) where the gripper is drawn; T_world_ee_images: (B, F, 4, 4) the EE pose
        when the frame's image was taken (moves the cameras mounted on the EE).
        Returns rgb (B, F, C, 3, h, w), mask (B, F, C, h, w), points (B, F, C, 3, h, w) camera frame,
        T_cam_obj (B, F, C, 4, 4), T_world_cam (B, F, C, 4, 4).
        """
        b, f = T_world_ee_frames.shape[:2]
        c = len(self.camera_keys)
        T_world_cam = self.rig.T_world_cam(T_world_ee_images)  # (B, F, C, 4, 4)
        T_cam_obj = invert_transform(T_world_cam) @ T_world_ee_frames[:, :, None]
        n = b * f * c
        static = self._static_render
        with torch.autocast(device_type=T_cam_obj.device.type, enabled=False):
            out = self.rasterizer(static)(
                self.rig.mesh_index.expand(b, f, c).reshape(n),
                T_cam_obj.reshape(n, 4, 4).float(),
                self.rig.K.expand(b, f, c, 3, 3).reshape(n, 3, 3),
                dynamic=not static,
            )
        if static:
            self._render_overflow = out.overflow.any() | self._render_overflow
        h, w = self.config.image_size
        return (
            out.rgb.reshape(b, f, c, 3, h, w),
            out.mask.reshape(b, f, c, h, w),
            out.points_cam.reshape(b, f, c, 3, h, w),
            T_cam_obj,
            T_world_cam,
        )

    def _network_inputs(self, images, T_world_ee, gripper, T_ee_future):
        """Build the network's rendered inputs for the current noisy actions.

        images (B, H, C, 3, h, w), T_world_ee (B, H, 4, 4), T_ee_future (B, T, 4, 4) = T_ee_target.
        """
        b, n_obs = T_world_ee.shape[:2]
        t = T_ee_future.shape[1]
        T_world_ee_now = T_world_ee[:, -1:]
        T_world_future = T_world_ee_now @ T_ee_future
        frames = torch.cat([T_world_ee, T_world_future], dim=1)
        image_poses = torch.cat([T_world_ee, T_world_ee_now.expand(b, t, 4, 4)], dim=1)
        rgb_r, mask, points, T_cam_obj, T_world_cam = self.render_frames(frames, image_poses)
        if not self.config.render_history:
            keep = torch.ones_like(mask)
            keep[:, :n_obs] = False
            mask = mask & keep
            points = points * keep[:, :, :, None]
        frame_images = torch.cat([images, images[:, -1:].expand(-1, t, -1, -1, -1, -1)], dim=1)
        composite = torch.where(mask[:, :, :, None], rgb_r, frame_images)
        point_map = points / self.config.point_map_scale
        return composite, point_map, mask, points, T_cam_obj, T_world_cam

    # ------------------------------------------------------------------------------------------------
    # Training.
    def compute_loss(
        self, images: Tensor, state: Tensor, action: Tensor, action_is_pad: Tensor | None
    ) -> tuple[Tensor, dict]:
        """R&D training loss: L1 image-space displacement + L1 action-space update + BCE gripper."""
        self.meshes.check_loaded()
        cfg = self.config
        if action.shape[1] != cfg.chunk_size:
            raise ValueError(f"Expected {cfg.chunk_size} future actions, got action {tuple(action.shape)}.")
        if not torch.isfinite(action).all():
            raise ValueError("The action batch contains NaN or inf.")
        images, T_world_ee, gripper = self.prepare_observation(images, state)
        b, t = action.shape[:2]
        T_ee_target, gripper_target = self.action_adapter.to_rnd(action, T_world_ee[:, -1], state=state[:, -1])
        a_gt = self.action_stats.normalize(action_from_pose(T_ee_target)).clamp(-1, 1)

        k = torch.randint(0, cfg.num_train_timesteps, (b,), device=action.device)
        eps = torch.randn_like(a_gt)
        a_noisy = self.noise_scheduler.add_noise(a_gt, eps, k).clamp(-1, 1)
        T_ee_noisy = pose_from_action(self.action_stats.unnormalize(a_noisy))

        with torch.no_grad():
            composite, point_map, mask, points, T_cam_obj, T_world_cam = self._network_inputs(
                images, T_world_ee, gripper, T_ee_noisy
            )
        displacement, update, logits = self.network(composite, point_map, gripper, k, a_noisy)

        valid_step = torch.ones(b, t, dtype=torch.bool, device=action.device)
        if action_is_pad is not None:
            valid_step = ~action_is_pad
        valid_f = valid_step.float()
        loss_dict = {}
        loss = action.new_zeros(())
        n_obs = cfg.n_obs_steps
        if displacement is not None:
            with torch.no_grad():
                T_cam_target = invert_transform(T_world_cam[:, n_obs:]) @ (
                    T_world_ee[:, -1:, None] @ T_ee_target[:, :, None]
                )
                target = displacement_target(points[:, n_obs:], T_cam_obj[:, n_obs:], T_cam_target)
                target = self.displacement_stats.normalize(target)
            pix = (mask[:, n_obs:] & valid_step[:, :, None, None, None]).unsqueeze(3).float()
            image_loss = ((displacement - target).abs() * pix).sum() / (3 * pix.sum()).clamp_min(1.0)
            loss = loss + cfg.image_loss_weight * image_loss
            loss_dict["image_loss"] = image_loss.item()
        if update is not None:
            action_loss = ((update - (a_gt - a_noisy)).abs().mean(-1) * valid_f).sum() / valid_f.sum().clamp_min(1)
            loss = loss + cfg.action_loss_weight * action_loss
            loss_dict["action_loss"] = action_loss.item()
        gripper_bce = F.binary_cross_entropy_with_logits(logits, (gripper_target > 0).float(), reduction="none")
        gripper_loss = (gripper_bce * valid_f).sum() / valid_f.sum().clamp_min(1)
        loss = loss + cfg.gripper_loss_weight * gripper_loss
        loss_dict["gripper_loss"] = gripper_loss.item()
        return loss, loss_dict

    # ------------------------------------------------------------------------------------------------
    # Inference.
    def denoise(self, images, T_world_ee, gripper, noise: Tensor, record: list | None = None):
        """The R&D sampler: DDIM steps updating actions through image space (SVD) and/or action space,
        then an optional final action-space pass. Returns (a_0 normalised (B, T, 6), gripper logits (B, T)).

        If `record` is a list, the composite images of every step are appended to it (for visualisation).
        """
        cfg = self.config
        n_obs = cfg.n_obs_steps
        b = noise.shape[0]
        a = noise
        T_world_ee_now = T_world_ee[:, -1:]
        logits = None
        point_update = ddim_step if cfg.point_update == "ddim" else interpolation_step
        for i, k in enumerate(self.inference_timesteps):
            a = a.clamp(-1, 1)
            T_ee = pose_from_action(self.action_stats.unnormalize(a))
            composite, point_map, mask, points, _, T_world_cam = self._network_inputs(
                images, T_world_ee, gripper, T_ee
            )
            if record is not None:
                record.append(composite)
            timestep = torch.full((b,), k, device=a.device, dtype=torch.long)
            displacement, update, logits = self.network(composite, point_map, gripper, timestep, a)
            alpha, alpha_prev = self.inference_alpha_bar[i], self.inference_alpha_bar_prev[i]
            if update is not None:
                a_next = ddim_step(a, (a + update).clamp(-1, 1), alpha, alpha_prev)
            else:
                a_next = a
            if displacement is not None:
                p_k = points[:, n_obs:].float()
                p0 = p_k + self.displacement_stats.unnormalize(displacement.float())
                p_prev = point_update(p_k, p0, alpha, alpha_prev)
                m = mask[:, n_obs:]
                T_delta, valid = register_point_update(p_k, p_prev, m, T_world_cam[:, n_obs:], cfg.min_visible_points)
                T_world_next = T_delta @ (T_world_ee_now @ T_ee)
                a_image = self.action_stats.normalize(
                    action_from_pose(invert_transform(T_world_ee_now) @ T_world_next)
                )
                a_next = torch.where(valid[..., None], a_image, a_next)
            a = a_next
        a = a.clamp(-1, 1)
        if cfg.final_action_step and self.predict_action:
            T_ee = pose_from_action(self.action_stats.unnormalize(a))
            composite, point_map, *_ = self._network_inputs(images, T_world_ee, gripper, T_ee)
            if record is not None:
                record.append(composite)
            timestep = torch.zeros((b,), device=a.device, dtype=torch.long)
            _, update, logits = self.network(composite, point_map, gripper, timestep, a)
            a = (a + update).clamp(-1, 1)
        return a, logits

    def _denoise_compiled(self, images, T_world_ee, gripper, noise):
        """`denoise` compiled with `torch.compile` (CUDA graphs on GPU) over static-shape rendering.

        The static rasteriser has fixed triangle capacities; if a render overflows them (a gripper far larger
        on screen than usual), the chunk is recomputed eagerly with the exact renderer, so nothing is lost.
        """
        if self._compiled_sampler is None:
            mode = "reduce-overhead" if images.device.type == "cuda" else "default"
            self._compiled_sampler = torch.compile(self.denoise, mode=mode, dynamic=False)
        self._static_render = True
        self._render_overflow = torch.zeros((), dtype=torch.bool, device=images.device)
        try:
            a, logits = self._compiled_sampler(images, T_world_ee, gripper, noise)
            overflow = bool(self._render_overflow)
        finally:
            self._static_render = False
        if overflow:
            logger.warning("Static rendering overflowed its triangle capacity; recomputing this chunk eagerly.")
            a, logits = self.denoise(images, T_world_ee, gripper, noise)
        return a.clone(), logits.clone()

    @torch.no_grad()
    def generate_actions(self, images: Tensor, state: Tensor, noise: Tensor | None = None) -> Tensor:
        """images (B, H, C, 3, h0, w0), state (B, H, D) -> dataset actions (B, chunk_size, action_dim)."""
        self.meshes.check_loaded()
        images, T_world_ee, gripper = self.prepare_observation(images, state)
        b = images.shape[0]
        if noise is None:
            noise = torch.randn(b, self.config.chunk_size, 6, device=images.device)
        if self.config.inference_compile and images.device.type == "cuda":
            a, logits = self._denoise_compiled(images, T_world_ee, gripper, noise)
        else:
            a, logits = self.denoise(images, T_world_ee, gripper, noise)
        T_ee_target = pose_from_action(self.action_stats.unnormalize(a))
        gripper_action = torch.where(logits > 0, 1.0, -1.0)
        return self.action_adapter.from_rnd(T_ee_target, gripper_action, T_world_ee[:, -1], state=state[:, -1])
