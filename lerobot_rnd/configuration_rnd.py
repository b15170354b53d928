#!/usr/bin/env python
"""Configuration of the Render and Diffuse (R&D) policy."""

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from lerobot.configs.policies import PreTrainedConfig
from lerobot.configs.types import NormalizationMode
from lerobot.optim.optimizers import AdamWConfig
from lerobot.optim.schedulers import DiffuserSchedulerConfig

RND_VARIANTS = ("A", "I", "AI")
POINT_UPDATES = ("x0", "interpolate", "ddim")
PATCH_EMBEDS = ("linear", "conv", "conv3x3")  # lerobot_rnd.network.patch_embedding
OBS_ENCODERS = ("patch", "resnet18")  # lerobot_rnd.network.ResNetObservationEncoder
DENOISE_STEPS = ("ddim", "clean", "refine")

#: Fields added after checkpoints were already saved, whose default is not what those checkpoints did, with
#: the value that reproduces them. A saved config.json without the key gets this value on load
#: (`migrate_saved_config`, called by `RnDPolicy.from_pretrained`), not the new default.
LEGACY_FIELD_VALUES: dict[str, Any] = {
    # Until the method fixes (issue 13) the past/current renders were always pasted over the observed RGB.
    "history_rgb_overlay": True,
}


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
    model that trains in minutes on a CPU use `policies_config/metaworld/rnd_ai_cpu.json` (patch 32, width 256,
    4 layers, only the gripper's patches of the future frames as tokens, bf16 autocast).

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
        n_obs_steps: Number of observations (history H, including the current one). The past end-effector
            poses are rendered into their frames too, so the model sees where the gripper was.
        chunk_size: Number of future steps T predicted per model invocation.
        n_action_steps: Number of predicted steps executed before the policy is queried again
            (<= chunk_size).
        normalization_mapping: LeRobot normaliser modes. R&D keeps images, state and action raw (IDENTITY)
            and normalises its own targets; do not change this unless you know why.
        variant: "A" predicts in action space only, "I" in image space only (actions recovered by SVD),
            "AI" both (the paper's best, the default).
        embodiment: Where the camera calibration, gripper meshes, end-effector pose source and action
            adapter come from: a preset name (see `lerobot_rnd.embodiment.EMBODIMENT_PRESETS`) or the path
            of an embodiment JSON file (docs/CALIBRATION.md). When None, the dataset's
            `meta/rnd_embodiment.json` is used if it exists. Resolved once at construction into `cameras`,
            `ee_pose`, `action_adapter` and mesh buffers, so a checkpoint needs nothing else.
        cameras: Resolved calibration per image feature key (filled automatically; editable): intrinsics
            `K`, `image_size` (H, W), `T_world_cam` (static camera) or `T_ee_cam` (camera mounted on the end
            effector), and the mesh rendered in it ("full" or "fingers").
        ee_pose: Resolved description of how to read the end-effector pose and gripper state from
            "observation.state" (filled automatically).
        action_adapter: Resolved action adapter spec: {"type": ..., **kwargs} (filled automatically from the
            embodiment unless given).
        mesh_shapes: Number of vertices and faces of each gripper mesh (filled automatically; the meshes
            themselves are buffers in model.safetensors).
        image_size: (H, W) at which images are rendered and fed to the network. Camera images of another
            size with the same aspect ratio are resized, and the calibration rescaled accordingly.
        render_texture: Colour the two sides of the gripper's symmetry plane differently (False = the
            paper's No-Texture ablation).
        texture_colors: RGB colours (0-1) of the two sides.
        untextured_color: RGB colour of the gripper when `render_texture` is False.
        render_history: Render the past end-effector poses into the past frames (the paper does).
        history_rgb_overlay: Paste the renders of the past/current gripper poses over the observed past/current
            RGB images (the paper's figures). False keeps the observed RGB untouched, as the research code does:
            the network then sees the real gripper, and the history poses only through the point map.
        use_point_map_input: Feed the rendered camera-frame point map as a second image per view.
        point_map_scale: Metres mapped to 1 in the point-map input.
        dim_model: Transformer width.
        n_layers: Number of self-attention layers.
        n_heads: Number of attention heads.
        mlp_ratio: Hidden width of the MLP blocks relative to `dim_model`.
        patch_size: ViT patch size in pixels.
        patch_embed: How RGB patches become tokens: "linear" (the ViT's and the paper's) or "conv" (4x4, 2x2 and
            (p/8)x(p/8) strided convolutions with GELU, still patch-local; needs patch_size divisible by 8), which
            sees small features such as a goal marker at 4-px resolution inside a coarse patch. "conv3x3":
            three overlapping 3x3 stride-2 convolutions and a (p/8)x(p/8) one, run on each patch alone (a
            convolutional stem, Xiao et al. 2021; also needs patch_size divisible by 8).
        obs_encoder: How the observed (past/current) RGB frames become tokens: "patch" (`patch_embed`, the
            paper's) or "resnet18" (a ResNet-18 trunk from scratch with GroupNorm, as Diffusion Policy uses without
            pretrained weights, shared by the cameras; its stride-32 feature map gives one token per 32-px patch,
            so it needs patch_size=32; the rendered future patches keep `patch_embed`). The paper reports that
            ResNet encoders did worse at its scale; this switch measures it with few demos on a CPU.
        gripper_patches: 0 tokenises every patch of every frame (the paper). K > 0 tokenises only the K patches
            of each future frame and view that the rendered gripper covers most (the rest of a future frame is
            the current image, already tokenised): far fewer tokens, static shapes. Image-space predictions
            (and their loss and SVD) then cover those patches only.
        embedding_init_std: Standard deviation of the initial frame, view, future-step and register embeddings
            (the authors use 1 and report that small values work much worse).
        dropout: Dropout in the transformer blocks.
        image_shift_augment: Training only: shift each camera's images by a random offset of up to this many
            pixels (at `image_size`; border replicated) and its principal point with them, so the renders stay on
            the real gripper (`lerobot_rnd.augmentation`). 0 = off.
        camera_dropout: Training only: the probability that a sample loses one of its cameras (chosen uniformly;
            never the last one): that view's RGB and point maps become 0 and its image-space loss is dropped, so
            the network does not rely on one view. The authors' research code offers this off by default
            (`camera_masking_ratio`: it removes one view's tokens for a whole batch; a per-sample blank view
            keeps shapes static). 0 = off.
        num_train_timesteps: Diffusion steps K used in training.
        train_first_step_fraction: Training only: the fraction of samples noised at the sampler's first
            timestep (the pure-noise start, where the network must read the whole action from the images)
            instead of at a uniform timestep. 0 = uniform over [0, num_train_timesteps) (DDPM).
        beta_schedule: Noise schedule of the DDIM scheduler (diffusers names).
        num_inference_steps: DDIM steps at inference (the paper: 4). The CPU tier (rnd_ai_cpu.json) uses 1: on
            the CPU benchmark's three tasks it solved as many test episodes as 4 or one more (docs/REACH.md).
        final_action_step: After the DDIM steps, run one more pass and take its action-space prediction as
            the final, precise action (variants A and AI).
        per_horizon_action_normalization: Normalise each horizon step's 6-D action with its own min/max
            instead of all steps jointly.
        action_stats_margin: The action min/max are taken over every window of the dataset, then widened by
            this fraction of the range on each side, so that no training target is clamped.
        stats_num_samples: Number of dataset samples used to estimate the image-space target statistics (which
            need rendering) when training from scratch.
        min_visible_points: Fewer visible rendered points than this (over all cameras) for a step makes the
            image-space update fall back to the action-space one.
        point_update: How the image-space prediction becomes an action update. "x0": one SVD from the rendered
            points to the predicted clean points gives a clean action estimate, then the DDIM step is taken in
            normalised action space (as diffusers does for sample prediction; independent of where the cameras
            are). "interpolate": the points move towards the predicted clean points by DDIM's fraction, then an
            SVD. "ddim": the paper's equation applied literally to camera-frame points (it rescales the cloud
            about each camera centre; kept for ablation).
        denoise_step: "ddim" takes deterministic DDIM steps from the clean estimate; "clean" jumps to the clean
            estimate at every step, re-rendering it for the next one; "refine" jumps to the clean estimate too but
            tells the network the noise level of what it now sees: the first step at the schedule's first
            timestep, then timesteps num_inference_steps - 2, ..., 0 (nearly clean), as the research code does.
        image_loss_weight, action_loss_weight, gripper_loss_weight: Weights of the three loss terms
            (L1 image-space displacement, averaged per camera then summed over cameras; L1 action-space update;
            BCE gripper, with the positive class weighted by the dataset's open/closed ratio).
        use_ema: Keep an exponential moving average of the network weights (updated after every optimiser
            step) and sample with it at evaluation.
        ema_decay: Maximum EMA decay; the decay warms up as min(ema_decay, (1 + n) / (10 + n)) after n updates.
        autocast_bf16: Run the network under bfloat16 autocast (rendering, SVD and losses stay float32). About
            1.7x faster on CPUs with AVX-512 bf16 and on GPUs. Ignored (float32, one warning) on CPUs without
            native bf16, where emulated bf16 is ~19x slower: `lerobot_rnd.precision`.
        inference_compile: On CUDA, compile the denoising loop with `torch.compile` ("reduce-overhead": CUDA
            graphs over static-shape rendering) for fast inference; same actions as eager up to floating-point
            error. Ignored on CPU, where tracing takes longer than it saves.
        optimizer_*, scheduler_warmup_steps: Training preset (the paper: AdamW, lr 1e-4, weight decay 1e-2,
            cosine schedule).
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
    texture_colors: tuple[tuple[float, float, float], tuple[float, float, float]] = (
        (1.0, 0.1, 0.1),
        (0.1, 0.3, 1.0),
    )
    untextured_color: tuple[float, float, float] = (0.6, 0.6, 0.6)
    render_history: bool = True
    history_rgb_overlay: bool = False
    use_point_map_input: bool = True
    point_map_scale: float = 1.0

    # Architecture (paper defaults).
    dim_model: int = 1024
    n_layers: int = 8
    n_heads: int = 16
    mlp_ratio: float = 4.0
    patch_size: int = 16
    patch_embed: str = "linear"
    obs_encoder: str = "patch"
    gripper_patches: int = 0
    embedding_init_std: float = 1.0
    dropout: float = 0.0
    image_shift_augment: int = 0
    camera_dropout: float = 0.0

    # Diffusion.
    num_train_timesteps: int = 50
    train_first_step_fraction: float = 0.0
    beta_schedule: str = "squaredcos_cap_v2"
    num_inference_steps: int = 4
    final_action_step: bool = True
    per_horizon_action_normalization: bool = False
    action_stats_margin: float = 0.05
    stats_num_samples: int = 256
    min_visible_points: int = 3
    point_update: str = "x0"
    denoise_step: str = "ddim"

    # Loss.
    image_loss_weight: float = 1.0
    action_loss_weight: float = 1.0
    gripper_loss_weight: float = 1.0
    use_ema: bool = False
    ema_decay: float = 0.999

    # Speed.
    autocast_bf16: bool = False
    inference_compile: bool = False

    # Training preset.
    optimizer_lr: float = 1e-4
    optimizer_betas: tuple[float, float] = (0.9, 0.999)
    optimizer_eps: float = 1e-8
    optimizer_weight_decay: float = 1e-2
    scheduler_name: str = "cosine"
    scheduler_warmup_steps: int = 500

    def __post_init__(self):
        super().__post_init__()
        if self.variant not in RND_VARIANTS:
            raise ValueError(f"`variant` must be one of {RND_VARIANTS}. Got {self.variant!r}.")
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
        if self.dim_model % self.n_heads != 0:
            raise ValueError(
                f"`dim_model` ({self.dim_model}) must be divisible by `n_heads` ({self.n_heads})."
            )
        if self.dim_model % 2 != 0:
            raise ValueError(f"`dim_model` must be even (two half-width patch embeddings). Got {self.dim_model}.")
        self.image_size = tuple(int(s) for s in self.image_size)
        if len(self.image_size) != 2 or any(s % self.patch_size for s in self.image_size):
            raise ValueError(
                f"`image_size` {self.image_size} must be two sizes divisible by `patch_size` ({self.patch_size})."
            )
        if not 0 <= self.image_shift_augment < min(self.image_size) // 2:
            raise ValueError(
                f"`image_shift_augment` must be in [0, {min(self.image_size) // 2}) pixels (image_size "
                f"{self.image_size}). Got {self.image_shift_augment}."
            )
        if not 0.0 <= self.train_first_step_fraction <= 1.0:
            raise ValueError(
                "`train_first_step_fraction` is a fraction of the training samples, in [0, 1] (0 = uniform "
                f"timesteps). Got {self.train_first_step_fraction}."
            )
        if not 0.0 <= self.camera_dropout <= 1.0:
            raise ValueError(
                f"`camera_dropout` is a probability, in [0, 1] (0 = off). Got {self.camera_dropout}."
            )
        if self.point_map_scale <= 0:
            raise ValueError(f"`point_map_scale` must be > 0. Got {self.point_map_scale}.")
        if self.min_visible_points < 3:
            raise ValueError(
                f"`min_visible_points` must be >= 3 (a rigid transform needs 3 points). "
                f"Got {self.min_visible_points}."
            )
        if self.patch_embed not in PATCH_EMBEDS or (self.patch_embed != "linear" and self.patch_size % 8):
            raise ValueError(
                f"`patch_embed` must be one of {PATCH_EMBEDS}, and the conv ones need a `patch_size` divisible "
                "by 8. "
                f"Got {self.patch_embed!r} with patch_size {self.patch_size}."
            )
        if self.obs_encoder not in OBS_ENCODERS or (self.obs_encoder == "resnet18" and self.patch_size != 32):
            raise ValueError(
                f"`obs_encoder` must be one of {OBS_ENCODERS}, and 'resnet18' needs `patch_size=32` (one token per "
                f"cell of its stride-32 feature map). Got {self.obs_encoder!r} with patch_size {self.patch_size}."
            )
        if self.point_update not in POINT_UPDATES:
            raise ValueError(f"`point_update` must be one of {POINT_UPDATES}. Got {self.point_update!r}.")
        if self.denoise_step not in DENOISE_STEPS:
            raise ValueError(f"`denoise_step` must be one of {DENOISE_STEPS}. Got {self.denoise_step!r}.")
        n_patches = (self.image_size[0] // self.patch_size) * (self.image_size[1] // self.patch_size)
        if not 0 <= self.gripper_patches <= n_patches:
            raise ValueError(
                f"`gripper_patches` must be in [0, {n_patches}] (patches per image at image_size "
                f"{self.image_size}, patch_size {self.patch_size}). Got {self.gripper_patches}."
            )
        if self.action_stats_margin < 0:
            raise ValueError(f"`action_stats_margin` must be >= 0. Got {self.action_stats_margin}.")
        if not 0.0 <= self.ema_decay < 1.0:
            raise ValueError(f"`ema_decay` must be in [0, 1). Got {self.ema_decay}.")
        for mode_name, mode in self.normalization_mapping.items():
            if NormalizationMode(mode) is not NormalizationMode.IDENTITY:
                raise ValueError(
                    f"R&D renders from metric poses and normalises its own targets: normalization_mapping must "
                    f"be IDENTITY for every feature type, got {mode_name}={mode}."
                )

    def get_optimizer_preset(self) -> AdamWConfig:
        return AdamWConfig(
            lr=self.optimizer_lr,
            betas=self.optimizer_betas,
            eps=self.optimizer_eps,
            weight_decay=self.optimizer_weight_decay,
        )

    def get_scheduler_preset(self) -> DiffuserSchedulerConfig:
        return DiffuserSchedulerConfig(name=self.scheduler_name, num_warmup_steps=self.scheduler_warmup_steps)

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
        return list(range(self.chunk_size))

    @property
    def reward_delta_indices(self) -> None:
        return None
