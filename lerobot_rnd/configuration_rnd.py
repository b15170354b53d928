#!/usr/bin/env python
"""Configuration of the Render and Diffuse (R&D) policy."""

import functools
import logging
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from lerobot.configs.policies import PreTrainedConfig
from lerobot.configs.types import NormalizationMode
from lerobot.optim.optimizers import AdamWConfig
from lerobot.optim.schedulers import DiffuserSchedulerConfig

logger = logging.getLogger(__name__)

RND_VARIANTS = ("A", "I", "AI")
POINT_UPDATES = ("x0", "ddim")  # lerobot_rnd.sampler
DIFFUSION_SPACES = ("ee_pose", "joints")  # lerobot_rnd.diffusion_space
PATCH_EMBEDS = ("linear", "conv")  # lerobot_rnd.network.patch_embedding

#: Git tag of the last commit whose config still had the `RETIRED_FIELDS` switches (docs/BENCHMARKS.md).
RETIRED_FIELDS_TAG = "ablation-switches-2026-12"

#: Switches retired because the measurements showed they lost or changed nothing and no shipped config used
#: them (docs/BENCHMARKS.md, archived ablations), with the behaviour every policy now has, and whether a
#: different saved value would change what a trained checkpoint predicts. A saved config.json that still holds
#: one loads if its value is that behaviour, or if the switch only mattered while training (logged); otherwise
#: it is refused, naming the field and the tag of the code that can still run it (`drop_retired_fields`).
RETIRED_FIELDS: dict[str, tuple[Any, bool]] = {
    "texture_colors": (((1.0, 0.1, 0.1), (0.1, 0.3, 1.0)), True),
    "untextured_color": ((0.6, 0.6, 0.6), True),
    "render_history": (True, True),
    "point_map_scale": (1.0, True),
    "obs_encoder": ("patch", True),
    "per_horizon_action_normalization": (False, True),
    "min_visible_points": (3, True),
    "denoise_step": ("ddim", True),
    "beta_schedule": ("squaredcos_cap_v2", True),
    "use_ema": (False, True),
    "ema_decay": (0.999, False),
    "embedding_init_std": (1.0, False),
    "image_shift_augment": (0, False),
    "camera_dropout": (0.0, False),
    "train_first_step_fraction": (0.0, False),
    "action_stats_margin": (0.05, False),
    "image_loss_weight": (1.0, False),
    "action_loss_weight": (1.0, False),
    "gripper_loss_weight": (1.0, False),
    "scheduler_name": ("cosine", False),
    "mlp_ratio": (4.0, True),  # retired with issue 35 (task conditioning took its place in the field budget)
}

#: Fields added after checkpoints were already saved, whose default is not what those checkpoints did, with
#: the value that reproduces them. A saved config.json without the key gets this value on load
#: (`migrate_saved_config`, called by `RnDPolicy.from_pretrained`), not the new default.
LEGACY_FIELD_VALUES: dict[str, Any] = {
    # Until the method fixes (issue 13) the past/current renders were always pasted over the observed RGB.
    "history_rgb_overlay": True,
}


def _same(a: Any, b: Any) -> bool:
    """Equality of JSON-decoded and Python values (lists and tuples alike, floats to 1e-9)."""
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        return abs(float(a) - float(b)) <= 1e-9
    return a == b


def drop_retired_fields(saved: Mapping[str, Any], source: str = "the saved config") -> dict[str, Any]:
    """`saved` (a config.json as a dict) without its `RETIRED_FIELDS` keys.

    Raises ValueError, naming the field, its value and `RETIRED_FIELDS_TAG`, where a retired switch holds a value
    other than today's behaviour and that value would change the checkpoint's predictions (or its weights' shapes).
    A training-only switch with another value is dropped with a log line: the checkpoint predicts as it did.
    """
    kept = dict(saved)
    for name, (value, affects_inference) in RETIRED_FIELDS.items():
        if name not in kept:
            continue
        saved_value = kept.pop(name)
        if _same(saved_value, value):
            continue
        if name == "ema_decay" and not saved.get("use_ema", False):
            continue  # unused without EMA
        if affects_inference:
            raise ValueError(
                f"{source} sets `{name}={saved_value!r}`, a switch retired from lerobot_rnd (every policy now uses "
                f"{value!r}); it changes what this checkpoint predicts, so it cannot be loaded faithfully. Use the "
                f"code at git tag {RETIRED_FIELDS_TAG} (`git checkout {RETIRED_FIELDS_TAG}`) to run it."
            )
        logger.info("%s: ignoring the retired training-only switch %s=%r (now always %r)", source, name,
                    saved_value, value)  # fmt: skip
    if kept.get("point_update") == "interpolate":
        raise ValueError(
            f"{source} sets `point_update='interpolate'`, a retired option (kept: {POINT_UPDATES}): use the code at "
            f"git tag {RETIRED_FIELDS_TAG} to run it."
        )
    if kept.get("patch_embed") == "conv3x3":
        raise ValueError(
            f"{source} sets `patch_embed='conv3x3'`, a retired option (kept: {PATCH_EMBEDS}): use the code at git "
            f"tag {RETIRED_FIELDS_TAG} to run it."
        )
    return kept


def migrate_saved_config(config: "RnDConfig", saved: Mapping[str, Any]) -> list[str]:
    """Set on `config` the legacy value of every `LEGACY_FIELD_VALUES` field missing from `saved`.

    `saved` is the checkpoint's config.json as a dict. Returns the names of the fields set.
    """
    migrated = []
    for name, value in LEGACY_FIELD_VALUES.items():
        if name not in saved and getattr(config, name) != value:
            setattr(config, name, value)
            migrated.append(name)
    return migrated


@PreTrainedConfig.register_subclass("rnd")
@dataclass
class RnDConfig(PreTrainedConfig):
    """Configuration class for the Render and Diffuse policy (Vosylius et al., RSS 2024).

    R&D represents each candidate action by rendering the robot's gripper into every calibrated camera
    image at the pose the action would reach, and denoises the actions with a ViT that predicts, per
    camera and per future step, how every rendered pixel of the gripper should move (image space) and/or
    how the action itself should change (action space).

    Defaults are the paper's: 8 layers of width 1024 with 16 heads, patch 16, 128x128 images, H = 2
    observations, T = 8 future steps, 50 training diffusion steps and 4 DDIM steps at inference. For a
    model that trains in minutes on a CPU use `policies_config/metaworld/rnd_ai_cpu.json`.

    Notes on the inputs and outputs:
        - One or more keys starting with "observation.images." are required, each with a camera calibration
          (see `embodiment` and `cameras`).
        - "observation.state" is required: R&D reads the end-effector pose (and the gripper state) from it,
          as described by `ee_pose`. It is used raw (IDENTITY normalisation): R&D needs metric poses to
          render. The image-space and action-space targets are normalised inside the model by statistics
          estimated from the dataset and saved with the checkpoint.
        - "action" is required as an output key; `action_adapter` converts it to and from R&D's action
          chunk (the rigid transforms `T_ee_target` from the current end-effector pose plus a gripper bit).

    Args:
        n_obs_steps: Observations H (history, including the current one); the past gripper poses are rendered.
        chunk_size: Future steps T predicted per model call.
        n_action_steps: Predicted steps executed before the policy is queried again (<= chunk_size).
        normalization_mapping: LeRobot normaliser modes: IDENTITY for all (R&D normalises its own targets).
        variant: "AI" predicts in image and action space (the paper's best), "A" in action space only, "I" in
            image space only (actions recovered by SVD).
        embodiment: A preset name (`lerobot_rnd.embodiment.EMBODIMENT_PRESETS`) or an embodiment JSON path
            (docs/CALIBRATION.md); None uses the dataset's `meta/rnd_embodiment.json`. Resolved at construction
            into `cameras`, `ee_pose`, `action_adapter` and the mesh buffers, so a checkpoint needs nothing else.
        cameras: Calibration per image key (filled automatically; editable): `K`, `image_size` (H, W),
            `T_world_cam` (static camera) or `T_ee_cam` (on the end effector), and the mesh drawn in it.
        ee_pose: How "observation.state" gives the end-effector pose and gripper state (filled automatically).
        action_adapter: {"type": ..., **kwargs}: dataset actions <-> R&D's chunks (filled from the embodiment).
        mesh_shapes: Vertex and face counts of the gripper meshes (filled automatically).
        image_size: (H, W) rendered and fed to the network; same-aspect camera images are resized.
        render_texture: Colour the two sides of the gripper differently (False: the paper's No-Texture).
        history_rgb_overlay: Also paste the past/current gripper renders over the observed RGB images.
        use_point_map_input: Feed the rendered camera-frame point map as a second image per view.
        dim_model: Transformer width.
        n_layers: Self-attention layers.
        n_heads: Attention heads.
        patch_size: ViT patch size in pixels.
        patch_embed: "linear" (the ViT's) or "conv" (4x4, 2x2, (p/8)x(p/8) strided convolutions with GELU, still
            patch-local; needs patch_size divisible by 8).
        gripper_patches: 0 tokenises every patch of every frame (the paper); K > 0 only the K patches of each
            future frame and view that the rendered gripper covers most (image-space predictions there only).
        dropout: Dropout in the transformer blocks.
        task_conditioning: Condition on LeRobot's `task` string with one learned token per task (the paper's goal
            embedding). None: on when the training dataset has several tasks, off for one (stated in the log).
        tasks: The task vocabulary (filled from the dataset's meta/tasks when conditioning; saved in config.json).
            At inference the observation's `task` must be one of them.
        num_train_timesteps: Training diffusion steps K (squared-cosine DDIM schedule).
        num_inference_steps: DDIM steps at inference (the paper: 4; the CPU tier: 1).
        final_action_step: After the DDIM steps, one more pass whose action-space prediction is the final action.
        diffusion_space: What is diffused: "ee_pose" (the paper: each step's rigid motion from the current
            end-effector pose, 6-D) or "joints" (the dataset's joint targets, with the gripper drawn at FK(q): every
            candidate is reachable; for arms with fewer than 6 joints, such as the SO-101; needs the
            joint_positions action adapter).
        point_update: How the image-space prediction updates the action: "x0" (one SVD to the predicted clean
            points, then a DDIM step in action space) or "ddim" (the paper's Eq. applied to camera-frame points).
        stats_num_samples: Samples rendered to estimate the image-space target statistics when training.
        autocast_bf16: bf16 autocast for the network where the device runs bf16 natively (`precision.py`).
        inference_compile: CUDA only: compile the denoising loop with `torch.compile` (CUDA graphs).
        optimizer_lr, optimizer_betas, optimizer_eps, optimizer_weight_decay: AdamW preset (the paper: lr 1e-4,
            weight decay 1e-2).
        scheduler_warmup_steps: Warm-up steps of the cosine learning-rate schedule.
    """

    # Input / output structure.
    n_obs_steps: int = 2
    chunk_size: int = 8
    n_action_steps: int = 8

    normalization_mapping: dict[str, NormalizationMode] = field(
        default_factory=lambda: {
            "VISUAL": NormalizationMode.IDENTITY,
            "STATE": NormalizationMode.IDENTITY,
            "ACTION": NormalizationMode.IDENTITY,
        }
    )

    variant: str = "AI"

    # Embodiment (calibration, meshes, end-effector pose, action adapter).
    embodiment: str | None = None
    cameras: dict[str, Any] = field(default_factory=dict)
    ee_pose: dict[str, Any] = field(default_factory=dict)
    action_adapter: dict[str, Any] = field(default_factory=dict)
    mesh_shapes: dict[str, Any] = field(default_factory=dict)

    # Rendering.
    image_size: tuple[int, int] = (128, 128)
    render_texture: bool = True
    history_rgb_overlay: bool = False
    use_point_map_input: bool = True

    # Architecture (paper defaults).
    dim_model: int = 1024
    n_layers: int = 8
    n_heads: int = 16
    patch_size: int = 16
    patch_embed: str = "linear"
    gripper_patches: int = 0
    dropout: float = 0.0

    # Tasks.
    task_conditioning: bool | None = None
    tasks: list[str] = field(default_factory=list)

    # Diffusion.
    num_train_timesteps: int = 50
    num_inference_steps: int = 4
    final_action_step: bool = True
    diffusion_space: str = "ee_pose"
    point_update: str = "x0"
    stats_num_samples: int = 256

    # Speed.
    autocast_bf16: bool = False
    inference_compile: bool = False

    # Training preset.
    optimizer_lr: float = 1e-4
    optimizer_betas: tuple[float, float] = (0.9, 0.999)
    optimizer_eps: float = 1e-8
    optimizer_weight_decay: float = 1e-2
    scheduler_warmup_steps: int = 500

    def __post_init__(self):
        super().__post_init__()
        self._check_choices()
        self._check_sizes()
        for mode_name, mode in self.normalization_mapping.items():
            if NormalizationMode(mode) is not NormalizationMode.IDENTITY:
                raise ValueError(
                    f"R&D renders from metric poses and normalises its own targets: normalization_mapping must "
                    f"be IDENTITY for every feature type, got {mode_name}={mode}."
                )

    def _check_choices(self) -> None:
        for name, choices in (("variant", RND_VARIANTS), ("point_update", POINT_UPDATES),
                              ("patch_embed", PATCH_EMBEDS), ("diffusion_space", DIFFUSION_SPACES)):  # fmt: skip
            if getattr(self, name) not in choices:
                raise ValueError(f"`{name}` must be one of {choices}. Got {getattr(self, name)!r}.")
        if self.patch_embed == "conv" and self.patch_size % 8:
            raise ValueError(
                f"`patch_embed` 'conv' needs a `patch_size` divisible by 8 (4x4, 2x2 and p/8 strides). Got "
                f"{self.patch_size}."
            )

    def _check_sizes(self) -> None:
        for name in ("n_obs_steps", "chunk_size", "n_action_steps", "num_train_timesteps", "n_layers"):
            if getattr(self, name) < 1:
                raise ValueError(f"`{name}` must be >= 1. Got {getattr(self, name)}.")
        if self.n_action_steps > self.chunk_size:
            raise ValueError(
                f"`n_action_steps` ({self.n_action_steps}) must be <= `chunk_size` ({self.chunk_size}): the "
                "policy can only execute steps it predicted."
            )
        if not 1 <= self.num_inference_steps <= self.num_train_timesteps:
            raise ValueError(
                f"`num_inference_steps` must be in [1, num_train_timesteps={self.num_train_timesteps}]. "
                f"Got {self.num_inference_steps}."
            )
        if self.dim_model % self.n_heads != 0 or self.dim_model % 2 != 0:
            raise ValueError(
                f"`dim_model` ({self.dim_model}) must be even (two half-width patch embeddings) and divisible by "
                f"`n_heads` ({self.n_heads})."
            )
        self.image_size = tuple(int(s) for s in self.image_size)
        if len(self.image_size) != 2 or any(s % self.patch_size for s in self.image_size):
            raise ValueError(
                f"`image_size` {self.image_size} must be two sizes divisible by `patch_size` ({self.patch_size})."
            )
        n_patches = (self.image_size[0] // self.patch_size) * (self.image_size[1] // self.patch_size)
        if not 0 <= self.gripper_patches <= n_patches:
            raise ValueError(
                f"`gripper_patches` must be in [0, {n_patches}] (patches per image at image_size "
                f"{self.image_size}, patch_size {self.patch_size}). Got {self.gripper_patches}."
            )

    def get_optimizer_preset(self) -> AdamWConfig:
        return AdamWConfig(
            lr=self.optimizer_lr,
            betas=self.optimizer_betas,
            eps=self.optimizer_eps,
            weight_decay=self.optimizer_weight_decay,
        )

    def get_scheduler_preset(self) -> DiffuserSchedulerConfig:
        return DiffuserSchedulerConfig(name="cosine", num_warmup_steps=self.scheduler_warmup_steps)

    def validate_features(self) -> None:
        if not self.image_features:
            raise ValueError(
                "R&D needs at least one camera: no 'observation.images.*' feature among the inputs."
            )
        if self.robot_state_feature is None:
            raise ValueError(
                "R&D needs 'observation.state' to read the end-effector pose from; the inputs have none."
            )
        if self.action_feature is None:
            raise ValueError("R&D needs an 'action' output feature.")

    @property
    def observation_delta_indices(self) -> list:
        return list(range(1 - self.n_obs_steps, 1))

    @property
    def action_delta_indices(self) -> list:
        # from -1: the step before the chunk, where a chunk may start from (`lerobot_rnd.anchor`)
        return list(range(-1, self.chunk_size))

    @property
    def reward_delta_indices(self) -> None:
        return None


def _install_retired_field_decoding() -> None:
    """Let LeRobot's config parser (draccus) read a saved `rnd` config that still holds retired switches.

    draccus refuses unknown keys when it decodes a dataclass. Its `decode_dataclass` is wrapped so that, for
    `RnDConfig` only, the saved dict passes through `drop_retired_fields` first; every other class (every other
    policy's config included) decodes exactly as before. This covers `PreTrainedConfig.from_pretrained`,
    `--policy.path` and a resumed run's `--config_path=.../train_config.json`.
    """
    from draccus.parsers import decoding

    original = decoding.decode_dataclass
    if getattr(original, "_rnd_retired_fields", False):
        return

    @functools.wraps(original)
    def decode_dataclass(cls, d, path=()):
        if isinstance(cls, type) and issubclass(cls, RnDConfig) and isinstance(d, Mapping):
            d = drop_retired_fields(d, "This R&D config")
        return original(cls, d, path)

    decode_dataclass._rnd_retired_fields = True  # type: ignore[attr-defined]
    decoding.decode_dataclass = decode_dataclass
    if hasattr(decoding.get_decoding_fn, "cache_clear"):
        decoding.get_decoding_fn.cache_clear()


_install_retired_field_decoding()
