"""Binds an embodiment (cameras, gripper meshes, end-effector pose source) to the policy's tensors.

The embodiment is resolved once, when a policy is built from scratch, into plain JSON-able fields of the
config (`cameras`, `ee_pose`, `action_adapter`, `mesh_shapes`) and mesh buffers of the model, so a saved
checkpoint (config.json + model.safetensors) is self-contained. The policy's readers of those fields are
`CameraRig`, `MeshBuffers` and `EEPoseReader` (defined in `ee_pose_source.py`, imported here for the model).
"""

import logging
from pathlib import Path

import numpy as np
import torch
from torch import Tensor, nn

from lerobot_rnd.camera_calibration import CameraCalibration
from lerobot_rnd.ee_pose_source import EEPoseReader
from lerobot_rnd.embodiment import (
    EMBODIMENT_FILE_IN_DATASET,
    Embodiment,
    embodiment_preset_names,
    load_embodiment,
    missing_calibrations,
)
from lerobot_rnd.rendering import MeshBatch

__all__ = [
    "CameraRig",
    "EEPoseReader",
    "MESH_NAMES",
    "MeshBuffers",
    "camera_calibrations",
    "resolve_embodiment",
]

logger = logging.getLogger(__name__)

MESH_NAMES = ("full", "fingers")
#: RGB colours (0-1) of the two sides of the gripper's symmetry plane (the paper's texture), and of the whole gripper
#: when `render_texture` is off (its No-Texture ablation).
TEXTURE_COLORS = ((1.0, 0.1, 0.1), (0.1, 0.3, 1.0))
UNTEXTURED_COLOR = (0.6, 0.6, 0.6)


def resolve_embodiment(config, dataset_meta=None) -> dict | None:
    """Fill `config.cameras`, `config.ee_pose`, `config.action_adapter`, `config.mesh_shapes` from the
    embodiment source and return its meshes {"full": GripperMesh, "fingers": GripperMesh}.

    Source, in order: `config.embodiment` (preset name or JSON path), then the dataset's
    `meta/rnd_embodiment.json`. Returns None when no source is available but the config is already resolved
    (a checkpoint being loaded: its meshes come from model.safetensors).
    """
    source = config.embodiment
    if source is None and dataset_meta is not None:
        candidate = Path(dataset_meta.root) / EMBODIMENT_FILE_IN_DATASET
        if candidate.is_file():
            source = str(candidate)
            config.embodiment = source
    embodiment: Embodiment | None = None
    if source is not None:
        try:
            embodiment = load_embodiment(source)
        except FileNotFoundError:
            if not config.cameras:
                raise
            logger.info("Embodiment source %s not found; using the calibration stored in the config.", source)
    if embodiment is None:
        if not config.cameras or not config.mesh_shapes:
            raise ValueError(
                "R&D needs a camera calibration and gripper meshes but none was found: pass "
                "--policy.embodiment=<preset name or embodiment JSON> (presets: "
                f"{', '.join(embodiment_preset_names())}), or record the dataset with `lerobot-rnd-record`, which writes "
                f"{EMBODIMENT_FILE_IN_DATASET}. See docs/CALIBRATION.md."
            )
        _check_checkpoint_fits_inputs(config)
        _validate_cameras(config)
        return None

    missing = missing_calibrations(list(config.image_features), embodiment.cameras)
    if missing:
        raise ValueError(
            f"The embodiment {embodiment.name or source!r} calibrates cameras {sorted(embodiment.cameras)}, but the "
            f"policy's images are {sorted(config.image_features)} (no calibration for {missing}). The embodiment "
            "is probably for another robot or dataset: use the dataset's own embodiment file (recorded by "
            "lerobot-rnd-record) or a preset for this robot, calibrate these cameras (docs/CALIBRATION.md), or "
            "rename the dataset's cameras with --rename_map."
        )
    config.cameras = {
        key: {**cam.to_dict(), "mesh": embodiment.camera_mesh.get(key, "full")}
        for key, cam in embodiment.cameras.items()
        if key in config.image_features
    }
    config.ee_pose = embodiment.ee_pose_source.to_dict()
    if not config.action_adapter:
        if embodiment.action_adapter is None:
            raise ValueError(
                "The embodiment names no action adapter: pass --policy.action_adapter='{\"type\": ...}' "
                "(ee_position_delta, ee_delta, ee_absolute or joint_positions)."
            )
        config.action_adapter = dict(embodiment.action_adapter)
    meshes = {name: embodiment.meshes[name] for name in MESH_NAMES if name in embodiment.meshes}
    if "full" not in meshes:
        raise ValueError("The embodiment has no 'full' gripper mesh.")
    meshes.setdefault("fingers", meshes["full"])
    # Texturing may split faces on the symmetry plane: the buffers hold the textured meshes.
    meshes = {
        name: m.with_symmetry_texture(embodiment.symmetry_axis, colors=TEXTURE_COLORS)
        for name, m in meshes.items()
    }
    config.mesh_shapes = {name: [len(m.vertices), len(m.faces)] for name, m in meshes.items()}
    _validate_cameras(config)
    return meshes


def _check_checkpoint_fits_inputs(config) -> None:
    """A saved policy (calibration inside its config) must fit the inputs it is given (a dataset's or, at
    evaluation, an environment's features): same cameras and the action size of its action adapter."""
    from lerobot_rnd.action_adapters import ActionAdapter

    missing = missing_calibrations(list(config.image_features), config.cameras)
    action = config.action_feature
    try:
        adapter_dim = ActionAdapter.from_dict(config.action_adapter).action_dim if config.action_adapter else None
    except (ValueError, OSError, ImportError):  # e.g. a joint adapter whose URDF is not here: checked later
        adapter_dim = None
    wrong_action = action is not None and adapter_dim is not None and action.shape[0] != adapter_dim
    if missing or wrong_action:
        raise ValueError(
            f"This R&D checkpoint was trained for a robot with cameras {sorted(config.cameras)} and "
            f"{adapter_dim}-D actions ({config.action_adapter.get('type')!r}), but it is given cameras "
            f"{sorted(config.image_features)} and {action.shape[0] if action else '?'}-D actions: the checkpoint's "
            "robot and the environment's (or dataset's) robot differ. Evaluate it in the environment it was "
            "trained in (its train_config.json names it, e.g. --env.type=rnd_panda), or map camera names with "
            "--rename_map."
        )


def _validate_cameras(config) -> None:
    """Every image feature has a calibration whose size matches the feature's."""
    missing = missing_calibrations(list(config.image_features), config.cameras)
    if missing:
        raise ValueError(
            f"No camera calibration for {missing}; calibrated cameras: {sorted(config.cameras)}. Calibrate them "
            "in the embodiment JSON (docs/CALIBRATION.md) or rename the dataset's cameras to match."
        )
    for key, ft in config.image_features.items():
        h, w = ft.shape[-2:]
        ch, cw = config.cameras[key]["image_size"]
        if (h, w) != (ch, cw):
            raise ValueError(
                f"Camera {key!r}: images are {h}x{w} but its calibration is for {ch}x{cw}. Rescale the "
                f"calibration with CameraCalibration.resized({h}, {w}) (intrinsics scale with the image) or "
                "record at the calibrated size."
            )
    for key, cam in config.cameras.items():
        if (cam.get("T_world_cam") is None) == (cam.get("T_ee_cam") is None):
            raise ValueError(f"Camera {key!r} needs exactly one of T_world_cam (static) or T_ee_cam (on the EE).")
        if cam.get("mesh", "full") not in MESH_NAMES:
            raise ValueError(f"Camera {key!r}: mesh must be one of {MESH_NAMES}, got {cam.get('mesh')!r}.")


def camera_calibrations(config, camera_keys: list[str]):
    """`CameraCalibration`s of the policy's cameras, rescaled to the network's image size."""
    h, w = config.image_size
    cams = []
    for key in camera_keys:
        cam = {k: v for k, v in config.cameras[key].items() if k != "mesh"}
        cams.append(CameraCalibration.from_dict(cam).resized(h, w))
    return cams


class CameraRig(nn.Module):
    """Calibration of the policy's cameras as buffers, in the order of `camera_keys`.

    Buffers: K (C, 3, 3) at the network's image size, T_world_cam (C, 4, 4) for static cameras,
    T_ee_cam (C, 4, 4) for cameras on the end effector, mounted (C,) bool, follow_rotation (C,) bool (False:
    the camera follows the EE position only, MuJoCo "track" mode), mesh_index (C,) long.
    """

    def __init__(self, config, camera_keys: list[str]):
        super().__init__()
        _validate_cameras(config)
        cams = camera_calibrations(config, camera_keys)
        eye = np.eye(4)
        self.register_buffer("K", torch.tensor(np.stack([c.K for c in cams]), dtype=torch.float32), persistent=False)
        self.register_buffer(
            "T_world_cam_static",
            torch.tensor(np.stack([c.T_world_cam if c.is_static else eye for c in cams]), dtype=torch.float32),
            persistent=False,
        )
        self.register_buffer(
            "T_ee_cam",
            torch.tensor(np.stack([eye if c.is_static else c.T_ee_cam for c in cams]), dtype=torch.float32),
            persistent=False,
        )
        self.register_buffer("mounted", torch.tensor([not c.is_static for c in cams]), persistent=False)
        self.register_buffer(
            "follow_rotation", torch.tensor([c.ee_follow_rotation for c in cams]), persistent=False
        )
        mesh_index = [MESH_NAMES.index(config.cameras[key].get("mesh", "full")) for key in camera_keys]
        self.register_buffer("mesh_index", torch.tensor(mesh_index, dtype=torch.long), persistent=False)

    def T_world_cam(self, T_world_ee: Tensor) -> Tensor:
        """Camera poses for EE poses (..., 4, 4) -> T_world_cam (..., C, 4, 4).

        Static cameras ignore the EE pose; mounted cameras are at T_world_ee @ T_ee_cam, or at
        [I | p_world_ee] @ T_ee_cam when they follow the EE position only.
        """
        T_world_ee = T_world_ee[..., None, :, :]
        translation_only = torch.zeros_like(T_world_ee)
        translation_only[..., :3, :3] = torch.eye(3, device=T_world_ee.device, dtype=T_world_ee.dtype)
        translation_only[..., :, 3] = T_world_ee[..., :, 3]
        carrier = torch.where(self.follow_rotation[:, None, None], T_world_ee, translation_only)
        on_ee = carrier @ self.T_ee_cam
        return torch.where(self.mounted[:, None, None], on_ee, self.T_world_cam_static.expand_as(on_ee))


class MeshBuffers(nn.Module):
    """The gripper meshes ("full", "fingers") as buffers saved in model.safetensors.

    Built from the embodiment when training from scratch; allocated empty from `config.mesh_shapes` and
    filled by the state dict when a checkpoint is loaded.
    """

    def __init__(self, config, meshes: dict | None):
        super().__init__()
        shapes = config.mesh_shapes
        n_v = max(int(shapes[name][0]) for name in MESH_NAMES)
        n_f = max(int(shapes[name][1]) for name in MESH_NAMES)
        vertices = torch.zeros(len(MESH_NAMES), n_v, 3)
        faces = torch.zeros(len(MESH_NAMES), n_f, 3, dtype=torch.long)
        face_valid = torch.zeros(len(MESH_NAMES), n_f, dtype=torch.bool)
        colors = torch.zeros(len(MESH_NAMES), n_v, 3)
        plain = torch.zeros(len(MESH_NAMES), n_v, 3)
        loaded = torch.tensor(meshes is not None)
        if meshes is not None:
            for i, name in enumerate(MESH_NAMES):
                textured = meshes[name]  # already textured by `resolve_embodiment`
                v, f = len(textured.vertices), len(textured.faces)
                vertices[i, :v] = torch.as_tensor(textured.vertices, dtype=torch.float32)
                faces[i, :f] = torch.as_tensor(textured.faces, dtype=torch.long)
                face_valid[i, :f] = True
                colors[i, :v] = torch.as_tensor(textured.vertex_colors, dtype=torch.float32)
                plain[i, :v] = torch.tensor(UNTEXTURED_COLOR, dtype=torch.float32)
        self.register_buffer("vertices", vertices)
        self.register_buffer("faces", faces)
        self.register_buffer("face_valid", face_valid)
        self.register_buffer("colors_textured", colors)
        self.register_buffer("colors_plain", plain)
        self.register_buffer("loaded", loaded)
        self._batches: dict = {}

    def check_loaded(self) -> None:
        if not bool(self.loaded):
            raise RuntimeError(
                "The gripper meshes were never loaded: this policy was built without an embodiment and no "
                "checkpoint weights were loaded into it. Load it with RnDPolicy.from_pretrained(...)."
            )

    def mesh_batch(self, textured: bool) -> MeshBatch:
        colors = self.colors_textured if textured else self.colors_plain
        return MeshBatch(vertices=self.vertices, faces=self.faces, face_valid=self.face_valid, vertex_colors=colors)
