#!/usr/bin/env python
"""Render and Diffuse (R&D) policy.

"Render and Diffuse: Aligning Image and Action Spaces for Diffusion-based Behaviour Cloning",
Vosylius, Seo, Uruç and James, RSS 2024 (https://arxiv.org/abs/2405.18196).

Shapes: B batch, H observation steps, T future steps, F = H + T frames, C cameras, h x w network image size.
"""

import contextvars
import logging
import warnings
from collections import deque
from pathlib import Path

import torch
import torch.nn.functional as F  # noqa: N812
from lerobot.policies.pretrained import PreTrainedPolicy
from lerobot.policies.utils import populate_queues
from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE
from torch import Tensor, nn

from lerobot_rnd.action_adapters import ActionAdapter
from lerobot_rnd.anchor import anchor_state
from lerobot_rnd.configuration_rnd import RnDConfig, migrate_saved_config
from lerobot_rnd.diffusion_space import EEPoseSpace, JointSpace, check_diffusion_space, diffusion_dim
from lerobot_rnd.embodiment_binding import (
    CameraRig,
    EEPoseReader,
    MeshBuffers,
    resolve_embodiment,
)
from lerobot_rnd.geometry import invert_transform
from lerobot_rnd.network import (
    MLP_RATIO,
    RnDDenoiser,
    gather_patch_pixels,
    patch_pixel_index,
    select_gripper_patches,
)
from lerobot_rnd.precision import bf16_autocast
from lerobot_rnd.rendering import Rasterizer
from lerobot_rnd.sampler import (
    DenoiserOutput,
    displacement_target,
    inference_schedule,
    make_noise_scheduler,
    sample_actions,
    sampler_step,
)
from lerobot_rnd.statistics import MinMaxStats, estimate_rnd_statistics, load_episode_arrays
from lerobot_rnd.tasks import TASK_KEY, resolve_task_conditioning, task_indices

#: Batch key of the last action the policy sent (B, A), given to `predict_action_chunk` by `select_action`.
PREVIOUS_ACTION = "rnd.previous_action"
logger = logging.getLogger(__name__)

# True while `RnDPolicy.from_pretrained` builds the policy: LeRobot's `make_policy` passes the dataset's metadata to
# the loader too (`lerobot-train --resume=true`, scripts with a dataset), and the statistics the checkpoint already
# holds must not be estimated again from the dataset (tens of seconds on a CPU) only to be overwritten.
_LOADING_PRETRAINED: contextvars.ContextVar[bool] = contextvars.ContextVar("rnd_loading_pretrained", default=False)


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
        if dataset_meta is not None and not getattr(dataset_meta, "total_frames", 1):
            raise ValueError(
                f"Dataset {getattr(dataset_meta, 'repo_id', '?')} at {getattr(dataset_meta, 'root', '?')} has no "
                "frames: record or add episodes before training (R&D estimates its statistics from them)."
            )
        embodiment_meshes = resolve_embodiment(config, dataset_meta)
        resolve_task_conditioning(config, dataset_meta)
        if dataset_meta is not None:  # training from scratch: fail now, not after the run, if the push cannot work
            from lerobot_rnd.dataset_query import install_column_first_queries
            from lerobot_rnd.model_card import check_hub_push_ready

            check_hub_push_ready(config)
            install_column_first_queries()  # an rnd training run reads its dataset column first (dataset_query.py)
        self.model = RnDModel(config, embodiment_meshes)
        if dataset_meta is not None and not _LOADING_PRETRAINED.get():  # a checkpoint brings its own statistics
            self.model.fit_statistics(dataset_meta)
        self._queues = None
        self.reset()

    @classmethod
    def from_pretrained(cls, pretrained_name_or_path, *, config: RnDConfig | None = None, **kwargs):
        """LeRobot's loader, plus: a checkpoint saved before a field existed loads with the value it was
        trained with (`LEGACY_FIELD_VALUES`), and a missing or damaged checkpoint names its folder."""
        hub_kwargs = {k: kwargs[k] for k in _HUB_KWARGS if k in kwargs}
        if config is None:
            from lerobot.configs.policies import PreTrainedConfig

            config = PreTrainedConfig.from_pretrained(pretrained_name_or_path, **hub_kwargs)
        saved = _read_saved_config(pretrained_name_or_path, hub_kwargs)
        if saved is not None:
            migrated = migrate_saved_config(config, saved)
            if migrated:
                logger.info(
                    "R&D checkpoint %s predates %s: loaded with %s",
                    pretrained_name_or_path,
                    ", ".join(migrated),
                    ", ".join(f"{k}={getattr(config, k)!r}" for k in migrated),
                )
        loading = _LOADING_PRETRAINED.set(True)
        try:
            return super().from_pretrained(pretrained_name_or_path, config=config, **kwargs)
        finally:
            _LOADING_PRETRAINED.reset(loading)

    @classmethod
    def _load_as_safetensor(cls, model, model_file: str, map_location: str, strict: bool):
        """LeRobot's loader, but a damaged file or weights that do not fit config.json raise an error naming the
        checkpoint (LeRobot loads non-strictly and would keep random weights for every missing tensor)."""
        from safetensors import safe_open

        checkpoint = Path(model_file).parent
        try:
            with safe_open(model_file, framework="pt") as f:
                saved = set(f.keys())
        except Exception as err:  # safetensors raises its own error types
            raise ValueError(
                f"R&D checkpoint {checkpoint}: {Path(model_file).name} cannot be read ({err}). The file is damaged "
                "or was only partly written (an interrupted save, copy or download): use another checkpoint or "
                "fetch this one again."
            ) from err
        expected = set(model.state_dict())
        missing = sorted(expected - saved - set(OPTIONAL_CHECKPOINT_KEYS))
        unexpected = sorted(saved - expected)
        if missing or unexpected:
            cfg = model.config
            raise ValueError(
                f"R&D checkpoint {checkpoint}: model.safetensors does not fit its config.json (variant "
                f"{cfg.variant!r}, dim_model {cfg.dim_model}, n_layers {cfg.n_layers}): "
                f"{len(missing)} tensor(s) missing (e.g. {missing[:3]}), {len(unexpected)} unexpected (e.g. "
                f"{unexpected[:3]}). The two files come from different runs: copy config.json and "
                "model.safetensors from the same checkpoint folder."
            )
        return super()._load_as_safetensor(model, model_file, map_location, strict)

    def _save_pretrained(self, save_directory: Path) -> None:
        """config.json and model.safetensors as LeRobot writes them, without the local path of the embodiment
        file (the calibration and meshes are inside the checkpoint), and a README.md model card."""
        source = self.config.embodiment
        local_source = source is not None and (source.endswith(".json") or "/" in source or Path(source).exists())
        if local_source:
            self.config.embodiment = None
        try:
            super()._save_pretrained(save_directory)
        finally:
            if local_source:
                self.config.embodiment = source
        if not (Path(save_directory) / "README.md").exists():
            card = self.generate_model_card(None, self.config.type, self.config.license, self.config.tags)
            card.save(str(Path(save_directory) / "README.md"))

    def get_optim_params(self) -> dict:
        return self.model.network.parameters()

    def reset(self):
        """Clear observation and action queues. Call on `env.reset()`."""
        self._queues = {
            OBS_STATE: deque(maxlen=self.config.n_obs_steps),
            OBS_IMAGES: deque(maxlen=self.config.n_obs_steps),
            ACTION: deque(maxlen=self.config.n_action_steps),
        }
        self._previous_action = None  # the last action sent (B, A): where the next chunk starts (anchor.py)

    def _stack_images(self, batch: dict[str, Tensor]) -> dict[str, Tensor]:
        """Stack the cameras into batch[OBS_IMAGES] (..., C, 3, h, w), resized to the network's image size."""
        missing = [key for key in self.config.image_features if key not in batch]
        if missing:
            names = ",".join(key.removeprefix(OBS_IMAGES + ".") for key in self.config.image_features)
            raise KeyError(
                f"R&D expects camera keys {list(self.config.image_features)} but the batch lacks {missing} "
                f"(batch keys: {sorted(batch)}). Evaluate with the cameras the policy was trained on (the plugin's "
                f"sim envs: --env.camera_names=[{names}]), "
                "rename the cameras (lerobot-eval --rename_map) or calibrate these cameras."
            )
        batch = dict(batch)
        images = [
            resize_images(as_float_images(batch[key], key), self.config.image_size, key)
            for key in self.config.image_features
        ]
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
        task_index = self._task_index(batch, state.shape[0], state.device)
        state = anchor_state(self.model.action_adapter, state, batch.get(PREVIOUS_ACTION), None)
        return self.model.generate_actions(images, state, noise=noise, task_index=task_index)

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
            if TASK_KEY in batch:
                stacked[TASK_KEY] = batch[TASK_KEY]
            if self._previous_action is not None:
                stacked[PREVIOUS_ACTION] = self._previous_action
            actions = self.predict_action_chunk(stacked, noise=noise)[:, : self.config.n_action_steps]
            self._queues[ACTION].extend(actions.transpose(0, 1))
        self._previous_action = self._queues[ACTION].popleft()
        return self._previous_action

    def forward(self, batch: dict[str, Tensor]) -> tuple[Tensor, dict]:
        """Training loss on a batch with history: images (B, H, 3, h, w) per camera, state (B, H, D),
        action (B, T, A) or, as the dataset gives it (`action_delta_indices`), (B, 1 + T, A) with the step before
        the chunk first, optional `action_is_pad` (B, T) or (B, 1 + T)."""
        batch = self._stack_images(batch)
        images, state = batch[OBS_IMAGES], batch[OBS_STATE]
        if images.ndim == 5:
            images, state = images[:, None], state[:, None] if state.ndim == 2 else state
        action, action_is_pad = batch[ACTION], batch.get("action_is_pad")
        if action.shape[1] == self.config.chunk_size + 1:
            has_previous = None if action_is_pad is None else ~action_is_pad[:, 0]
            state = anchor_state(self.model.action_adapter, state, action[:, 0], has_previous)
            action, action_is_pad = action[:, 1:], None if action_is_pad is None else action_is_pad[:, 1:]
        task_index = self._task_index(batch, state.shape[0], state.device)
        return self.model.compute_loss(images, state, action, action_is_pad, task_index=task_index)

    def _task_index(self, batch: dict, batch_size: int, device) -> Tensor | None:
        """The batch's task indices (B,) in `config.tasks` when the policy conditions on tasks, else None (a
        one-task policy needs no `task` string)."""
        if not self.config.task_conditioning:
            return None
        return task_indices(self.config.tasks, batch.get(TASK_KEY), batch_size, device)

    def generate_model_card(self, dataset_repo_id, model_type, license, tags):  # noqa: A002
        from lerobot_rnd.model_card import make_rnd_model_card

        return make_rnd_model_card(self.config, dataset_repo_id, license, tags)


#: Tensors a checkpoint may lack, with why: they load with their initial value.
OPTIONAL_CHECKPOINT_KEYS = {
    "model.gripper_pos_weight": "training-only gripper class weight, added after the first checkpoints",
}

_HUB_KWARGS = ("force_download", "resume_download", "proxies", "token", "cache_dir", "local_files_only", "revision")


def _read_saved_config(pretrained_name_or_path, hub_kwargs: dict) -> dict | None:
    """The checkpoint's config.json as a dict (local folder or the Hub cache), or None where unreadable."""
    import json

    path = Path(str(pretrained_name_or_path)) / "config.json"
    if not path.is_file():
        try:
            from huggingface_hub import hf_hub_download

            path = Path(hf_hub_download(str(pretrained_name_or_path), "config.json", **hub_kwargs))
        except Exception:  # noqa: BLE001 - the loader itself reports an unreachable checkpoint
            return None
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def as_float_images(images: Tensor, key: str = "image") -> Tensor:
    """Camera images (..., 3, h, w) as float in [0, 1], checked.

    uint8 images (0-255) are divided by 255 (the one conversion done silently); other integer types, NaN/Inf
    pixels and float values far outside [0, 1] (0-255 floats, mean/std-normalised images) raise a ValueError
    naming the camera key.
    """
    if images.dtype == torch.uint8:
        return images.float() / 255.0
    if not torch.is_floating_point(images):
        raise ValueError(f"{key}: images must be float in [0, 1] (or uint8 in [0, 255]), got dtype {images.dtype}.")
    bad = ~torch.isfinite(images)
    if bad.any():
        raise ValueError(
            f"{key}: {int(bad.sum())} NaN/Inf pixel value(s) in the image: check the camera or the dataset's frames "
            "for this key."
        )
    lo, hi = float(images.min()), float(images.max())
    if hi > 1.5 or lo < -0.5:
        raise ValueError(
            f"{key}: pixel values span [{lo:.3g}, {hi:.3g}] but R&D expects raw images in [0, 1]: divide 0-255 "
            "images by 255, and keep normalization_mapping VISUAL=IDENTITY (R&D draws into the raw image)."
        )
    return images


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
        check_diffusion_space(config.diffusion_space, self.action_adapter)
        t = config.chunk_size
        self.action_dim = diffusion_dim(config.diffusion_space, self.action_adapter)  # D of the diffused variable
        self.action_stats = MinMaxStats((self.action_dim,))  # normalised jointly over the horizon
        self.displacement_stats = MinMaxStats((len(self.camera_keys), 3, 1, 1))

        self.patch_grid = (config.image_size[0] // config.patch_size, config.image_size[1] // config.patch_size)
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
            mlp_ratio=MLP_RATIO,
            dropout=config.dropout,
            predict_image=self.predict_image,
            predict_action=self.predict_action,
            use_point_map_input=config.use_point_map_input,
            gripper_patches=config.gripper_patches,
            patch_embed=config.patch_embed,
            n_tasks=len(config.tasks) if config.task_conditioning else 0,
            action_dim=self.action_dim,
        )
        # BCE weight of the "closed" class: open/closed ratio of the dataset's gripper targets.
        self.register_buffer("gripper_pos_weight", torch.ones(()))
        self._warned_invisible = False
        self.noise_scheduler = make_noise_scheduler(config.num_train_timesteps)
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
        """Estimate the min/max of the action-space and image-space targets from the dataset on disk (and, if
        the action adapter asks for it, the demos' gripper open/closed values first)."""
        cfg = self.config
        if self.action_adapter.gripper and self.action_adapter.gripper_from_data:
            episodes = load_episode_arrays(dataset_meta.root)
            grip = torch.cat([torch.from_numpy(action[:, -1]) for _, action in episodes])
            opened, closed = self.action_adapter.fit_gripper_range(grip)
            cfg.action_adapter = self.action_adapter.to_dict()  # saved with the checkpoint: fitted once
            logger.info(f"R&D gripper: the demos' gripper is open at {opened:g} and closed at {closed:g} "
                         f"(threshold {0.5 * (opened + closed):g}); the policy commands these values")  # fmt: skip
        stats = estimate_rnd_statistics(
            dataset_meta.root,
            n_obs_steps=cfg.n_obs_steps,
            chunk_size=cfg.chunk_size,
            num_samples=cfg.stats_num_samples,
            n_cameras=len(self.camera_keys),
            image_size=cfg.image_size,
            ee_pose=self.ee_reader.pose,
            gripper_state=self.ee_reader.gripper,
            to_rnd=self.action_adapter.to_rnd,
            diffusion_target=lambda action, T_ee_target, state_now: self.diffusion_space(state_now).target(
                action, T_ee_target
            ),
            noisy_sample_targets=self.noisy_sample_targets,
            device=self.action_stats.min.device,
            anchor=lambda state, previous, has: anchor_state(self.action_adapter, state, previous, has),
        )
        self.action_stats.set(stats["action_min"], stats["action_max"])
        self.displacement_stats.set(stats["displacement_min"], stats["displacement_max"])
        self.gripper_pos_weight.fill_(float(stats["gripper_pos_weight"]))

    def diffusion_space(self, state_now: Tensor | None, action_stats: MinMaxStats | None = None):
        """The space of the diffused variable (`lerobot_rnd.diffusion_space`) for a batch whose current state is
        state_now (B, S) (needed for "joints"), normalised by `action_stats` (default the model's own)."""
        stats = self.action_stats if action_stats is None else action_stats
        if self.config.diffusion_space == "joints":
            return JointSpace(stats, self.action_adapter, state_now)
        return EEPoseSpace(stats)

    def normalize_displacement(self, x: Tensor) -> Tensor:
        """Metric displacements (..., C, 3, N) on the predicted pixels -> normalised (per camera and axis)."""
        return self.displacement_stats.normalize(x[..., None]).squeeze(-1)

    def unnormalize_displacement(self, x: Tensor) -> Tensor:
        """Inverse of `normalize_displacement`."""
        return self.displacement_stats.unnormalize(x[..., None]).squeeze(-1)

    def _autocast(self, device_type: str):
        """bf16 autocast for the network when `autocast_bf16` and the device runs bf16 natively (precision.py)."""
        return bf16_autocast(self.config.autocast_bf16, device_type)

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

    def render_history(self, images: Tensor, T_world_ee: Tensor) -> dict:
        """The past/current frames' network inputs (they do not depend on the noisy actions: the sampler renders
        them once per chunk). images (B, H, C, 3, h, w), T_world_ee (B, H, 4, 4) -> {obs_rgb, obs_points}
        (B, H, C, 3, h, w): the images (with the gripper pasted over them when `history_rgb_overlay`) and the
        camera-frame point maps (metres) of the gripper at the past/current poses."""
        rgb_r, mask, points, _, _ = self.render_frames(T_world_ee, T_world_ee)
        obs_rgb = torch.where(mask[:, :, :, None], rgb_r, images) if self.config.history_rgb_overlay else images
        return {"obs_rgb": obs_rgb, "obs_points": points}

    def _network_inputs(
        self, images, T_world_ee, gripper, T_ee_future, full_composite: bool = False, history: dict | None = None
    ) -> dict:
        """Render the current noisy actions and build the network's inputs.

        images (B, H, C, 3, h, w), T_world_ee (B, H, 4, 4), T_ee_future (B, T, 4, 4) = T_ee_target; `history`:
        `render_history(images, T_world_ee)` if already computed.
        Returns a dict:
            obs_rgb, obs_points (B, H, C, 3, h, w); future_rgb, future_points (B, T, C, 3, h, w), or the selected
                patches' pixels (B, T, C, 3, N = K*p*p) with `gripper_patches` > 0: the network's inputs;
            patch_index (B, T, C, K) or None;
            target_points (B, T, C, 3, N) metric camera-frame points of the future renders at the pixels the
                network predicts (N = h*w without gripper patches), target_mask (B, T, C, N) where they are set;
            T_cam_obj, T_world_cam (B, T, C, 4, 4) of the future frames;
            composite (B, F, C, 3, h, w) the full images the network sees, only when `full_composite`.
        """
        cfg = self.config
        b = T_world_ee.shape[0]
        t = T_ee_future.shape[1]
        if history is None:
            history = self.render_history(images, T_world_ee)
        T_world_ee_now = T_world_ee[:, -1:]
        fut_rgb_r, fut_mask, fut_points, T_cam_obj, T_world_cam = self.render_frames(
            T_world_ee_now @ T_ee_future, T_world_ee_now.expand(b, t, 4, 4)
        )
        obs_rgb, obs_points = history["obs_rgb"], history["obs_points"]
        current = images[:, -1:].expand(-1, t, -1, -1, -1, -1)
        patch_index = None
        if cfg.gripper_patches:
            patch_index = select_gripper_patches(fut_mask, cfg.patch_size, cfg.gripper_patches)
            pixels = patch_pixel_index(patch_index, self.patch_grid, cfg.patch_size)  # (B, T, C, N)
            target_mask = gather_patch_pixels(fut_mask, pixels)
            target_points = gather_patch_pixels(fut_points, pixels)
            future_rgb = torch.where(
                target_mask[:, :, :, None], gather_patch_pixels(fut_rgb_r, pixels), gather_patch_pixels(current, pixels)
            )
            future_points = target_points
        else:
            future_rgb = torch.where(fut_mask[:, :, :, None], fut_rgb_r, current)
            future_points = fut_points
            target_mask = fut_mask.flatten(-2)
            target_points = fut_points.flatten(-2)
        out = {
            "obs_rgb": obs_rgb,
            "obs_points": obs_points,
            "obs_tokens": history.get("obs_tokens"),
            "future_rgb": future_rgb,
            "future_points": future_points,
            "patch_index": patch_index,
            "target_points": target_points,
            "target_mask": target_mask,
            "T_cam_obj": T_cam_obj,
            "T_world_cam": T_world_cam,
        }
        if full_composite:
            future_full = torch.where(fut_mask[:, :, :, None], fut_rgb_r, current)
            out["composite"] = torch.cat([obs_rgb, future_full], dim=1)
        return out

    def _run_network(
        self, network: nn.Module, inputs: dict, gripper: Tensor, timestep: Tensor, a: Tensor,
        task_index: Tensor | None = None,
    ):
        """The denoiser on rendered inputs (`task_index` (B,) when conditioning on tasks). Returns float32
        (displacement (B, T, C, 3, N) on the predicted pixels or None, action update (B, T, D) or None, gripper
        logits (B, T))."""
        extra = {} if task_index is None else {"task_index": task_index}
        with self._autocast(a.device.type):
            displacement, update, logits = network(
                inputs["obs_rgb"], inputs["obs_points"], inputs["future_rgb"], inputs["future_points"],
                gripper, timestep, a, patch_index=inputs["patch_index"], obs_tokens=inputs.get("obs_tokens"),
                **extra,
            )
        if displacement is not None:
            displacement = displacement.float().reshape(inputs["target_points"].shape)
        return displacement, None if update is None else update.float(), logits.float()

    def noisy_sample_targets(
        self, images: Tensor, T_world_ee: Tensor, gripper: Tensor, T_ee_target: Tensor, x_target: Tensor,
        state_now: Tensor | None = None, generator=None, action_stats: MinMaxStats | None = None,
    ) -> dict:
        """Noise a ground-truth chunk (Eq. 1), render it, and compute the training targets (Algorithm 1; used by
        training and by the statistics estimate).

        images (B, H, C, 3, h, w), T_world_ee (B, H, 4, 4), gripper (B, H), T_ee_target (B, T, 4, 4) the
        ground-truth poses and x_target (B, T, D) their unnormalised diffused variable (`diffusion_space(...)
        .target`); state_now (B, S): the current state (needed for "joints"); action_stats: the normalisation to
        noise in (default the model's own).
        Returns the `_network_inputs` dict plus k (B,), a_gt / a_noisy (B, T, D) normalised, and
        displacement (B, T, C, 3, N): the metric image-space target F_gt = T(a_gt, a_noisy) P - P (Eq. 6) at the
        predicted pixels (meaningful on `target_mask`).
        """
        cfg = self.config
        space = self.diffusion_space(state_now, action_stats)
        b = T_ee_target.shape[0]
        device = T_ee_target.device
        a_gt = space.normalize(x_target)
        k = torch.randint(0, cfg.num_train_timesteps, (b,), generator=generator, device="cpu").to(device)
        eps = torch.randn(a_gt.shape, generator=generator, device="cpu").to(device)
        a_noisy = self.noise_scheduler.add_noise(a_gt, eps, k).clamp(-1, 1)
        T_ee_noisy = space.to_pose(a_noisy)
        with torch.no_grad():
            inputs = self._network_inputs(images, T_world_ee, gripper, T_ee_noisy)
            T_world_cam = inputs["T_world_cam"]
            T_cam_target = invert_transform(T_world_cam) @ (T_world_ee[:, -1:, None] @ T_ee_target[:, :, None])
            displacement = displacement_target(inputs["target_points"], inputs["T_cam_obj"], T_cam_target)
        return {**inputs, "k": k, "a_gt": a_gt, "a_noisy": a_noisy, "displacement": displacement}

    # ------------------------------------------------------------------------------------------------
    # Training.
    def compute_loss(
        self, images: Tensor, state: Tensor, action: Tensor, action_is_pad: Tensor | None,
        task_index: Tensor | None = None,
    ) -> tuple[Tensor, dict]:
        """R&D training loss, Eq. (5): L1 image-space displacement + L1 action-space update + BCE gripper."""
        self.meshes.check_loaded()
        cfg = self.config
        if action.shape[1] != cfg.chunk_size:
            raise ValueError(f"Expected {cfg.chunk_size} future actions, got action {tuple(action.shape)}.")
        if not torch.isfinite(action).all():
            raise ValueError("The action batch contains NaN or inf.")
        images, T_world_ee, gripper = self.prepare_observation(images, state)
        b, t = action.shape[:2]
        state_now = state[:, -1]
        T_ee_target, gripper_target = self.action_adapter.to_rnd(action, T_world_ee[:, -1], state=state_now)
        x_target = self.diffusion_space(state_now).target(action, T_ee_target)
        sample = self.noisy_sample_targets(images, T_world_ee, gripper, T_ee_target, x_target, state_now)
        a_gt, a_noisy = sample["a_gt"], sample["a_noisy"]
        displacement, update, logits = self._run_network(
            self.network, sample, gripper, sample["k"], a_noisy, task_index
        )

        valid_step = torch.ones(b, t, dtype=torch.bool, device=action.device)
        if action_is_pad is not None:
            valid_step = ~action_is_pad
        valid_f = valid_step.float()
        loss_dict = {}
        loss = action.new_zeros(())
        if displacement is not None:
            target = self.normalize_displacement(sample["displacement"])
            pix = (sample["target_mask"] & valid_step[:, :, None, None]).unsqueeze(3).float()  # (B, T, C, 1, N)
            # Mean over each camera's rendered pixels, then sum over cameras: a near camera, whose gripper
            # covers many pixels, does not drown the others.
            per_cam_err = ((displacement - target).abs() * pix).sum((0, 1, 3, 4))  # (C,)
            per_cam_n = 3 * pix.sum((0, 1, 3, 4))
            image_loss = (per_cam_err / per_cam_n.clamp_min(1.0)).sum()
            loss = loss + image_loss
            loss_dict["image_loss"] = image_loss.item()
        if update is not None:
            action_loss = ((update - (a_gt - a_noisy)).abs().mean(-1) * valid_f).sum() / valid_f.sum().clamp_min(1)
            loss = loss + action_loss
            loss_dict["action_loss"] = action_loss.item()
        gripper_bce = F.binary_cross_entropy_with_logits(
            logits, (gripper_target > 0).float(), reduction="none", pos_weight=self.gripper_pos_weight
        )
        gripper_loss = (gripper_bce * valid_f).sum() / valid_f.sum().clamp_min(1)
        loss = loss + gripper_loss
        loss_dict["gripper_loss"] = gripper_loss.item()
        return loss, loss_dict

    # ------------------------------------------------------------------------------------------------
    # Inference.
    def denoiser(self, images, T_world_ee, gripper, history: dict | None = None, task_index: Tensor | None = None):
        """The callable the sampler (`lerobot_rnd.sampler`) denoises with: it renders the actions it is given
        into the observation and runs the network. images (B, H, C, 3, h, w), T_world_ee (B, H, 4, 4), gripper
        (B, H); `history`: `render_history(images, T_world_ee)` (with "obs_tokens") if already computed."""

        def denoise_fn(a: Tensor, T_ee_target: Tensor, timestep: Tensor, full_composite: bool) -> DenoiserOutput:
            inputs = self._network_inputs(
                images, T_world_ee, gripper, T_ee_target, full_composite=full_composite, history=history
            )
            displacement, update, logits = self._run_network(self.network, inputs, gripper, timestep, a, task_index)
            return DenoiserOutput(
                update=update,
                logits=logits,
                displacement=None if displacement is None else self.unnormalize_displacement(displacement),
                points=inputs["target_points"],
                mask=inputs["target_mask"],
                T_world_cam=inputs["T_world_cam"],
                composite=inputs.get("composite"),
            )

        return denoise_fn

    def denoise(
        self, images, T_world_ee, gripper, noise: Tensor, record: list | None = None, task_index: Tensor | None = None,
        state_now: Tensor | None = None,
    ):
        """Sample a chunk from `noise` (B, T, D) with `lerobot_rnd.sampler.sample_actions`: the past/current
        frames are rendered and tokenised once, every step renders the current actions. state_now (B, S): the
        current state (needed for "joints"). Returns (a_0 normalised (B, T, D), gripper logits (B, T)); `record`, a
        list, receives the composite images of every pass."""
        history = self.render_history(images, T_world_ee)  # the same for every step, and so are its tokens
        with self._autocast(images.device.type):
            history["obs_tokens"] = self.network.embed_observation(history["obs_rgb"], history["obs_points"])
        return sample_actions(
            self.denoiser(images, T_world_ee, gripper, history, task_index),
            noise,
            self.inference_timesteps,
            self.inference_alpha_bar,
            self.inference_alpha_bar_prev,
            self.diffusion_space(state_now),
            T_world_ee[:, -1:],
            point_update=self.config.point_update,
            final_action_step=self.config.final_action_step and self.predict_action,
            on_visibility=self._warn_if_never_visible,
            record=record,
        )

    def sampler_step(
        self, images, T_world_ee, gripper, a: Tensor, i: int, full_composite: bool = False,
        task_index: Tensor | None = None, state_now: Tensor | None = None,
    ):
        """Step i of the sampler alone (`lerobot_rnd.sampler.sampler_step`), for inspection: returns (a_next
        (B, T, D), gripper logits (B, T), composite images (B, F, C, 3, h, w) when `full_composite`, else None)."""
        a_next, logits, valid, composite = sampler_step(
            self.denoiser(images, T_world_ee, gripper, task_index=task_index),
            a,
            self.inference_timesteps[i],
            self.inference_alpha_bar[i],
            self.inference_alpha_bar_prev[i],
            self.diffusion_space(state_now),
            T_world_ee[:, -1:],
            self.config.point_update,
            full_composite=full_composite,
        )
        if valid is not None:
            self._warn_if_never_visible(valid)
        return a_next, logits, composite

    def _warn_if_never_visible(self, valid: Tensor) -> None:
        """Warn once when the gripper is invisible in every camera for a whole chunk (eager mode only)."""
        if self._warned_invisible or torch.compiler.is_compiling() or valid.device.type != "cpu":
            return
        if bool((~valid).all(dim=1).any()):
            self._warned_invisible = True
            warnings.warn(
                "R&D: for a whole chunk the rendered gripper is visible in none of the cameras; the image-space "
                "update falls back to the action space (variant I: the action stays as sampled). Check the camera "
                "calibration if this persists.",
                stacklevel=3,
            )

    def _denoise_compiled(self, images, T_world_ee, gripper, noise, task_index=None, state_now=None):
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
            a, logits = self._compiled_sampler(
                images, T_world_ee, gripper, noise, task_index=task_index, state_now=state_now
            )
            overflow = bool(self._render_overflow)
        finally:
            self._static_render = False
        if overflow:
            logger.warning("Static rendering overflowed its triangle capacity; recomputing this chunk eagerly.")
            a, logits = self.denoise(images, T_world_ee, gripper, noise, task_index=task_index, state_now=state_now)
        return a.clone(), logits.clone()

    @torch.no_grad()
    def generate_actions(
        self, images: Tensor, state: Tensor, noise: Tensor | None = None, task_index: Tensor | None = None
    ) -> Tensor:
        """images (B, H, C, 3, h0, w0), state (B, H, D), task_index (B,) when conditioning on tasks -> dataset
        actions (B, chunk_size, action_dim)."""
        self.meshes.check_loaded()
        images, T_world_ee, gripper = self.prepare_observation(images, state)
        b = images.shape[0]
        state_now = state[:, -1]
        if noise is None:
            noise = torch.randn(b, self.config.chunk_size, self.action_dim, device=images.device)
        if self.config.inference_compile and images.device.type == "cuda":
            a, logits = self._denoise_compiled(images, T_world_ee, gripper, noise, task_index, state_now)
        else:
            a, logits = self.denoise(images, T_world_ee, gripper, noise, task_index=task_index, state_now=state_now)
        gripper_action = torch.where(logits > 0, 1.0, -1.0)
        return self.diffusion_space(state_now).dataset_action(
            a, gripper_action, self.action_adapter, T_world_ee[:, -1], state_now
        )
