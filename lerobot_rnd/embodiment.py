"""The embodiment of R&D: everything it needs to know about a robot to render "where the gripper would be".

:class:`Embodiment` holds the cameras (:class:`~lerobot_rnd.camera_calibration.CameraCalibration`, keyed by
LeRobot image feature key), the gripper meshes (:class:`~lerobot_rnd.gripper_mesh.GripperMesh`), which mesh
each camera draws, the EE pose source (:class:`~lerobot_rnd.ee_pose_source.EEPoseSource`), the action adapter
spec and the symmetry axis; it round-trips through JSON (layout: docs/CALIBRATION.md) and validates against a
dataset's / policy's features. Named presets come from a registry (:func:`register_embodiment_preset`); the
MetaWorld and Panda presets live in ``lerobot_rnd.sim`` next to their environments.
"""

from __future__ import annotations

import difflib
import importlib
import json
import logging
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from lerobot_rnd.arrays import tolist
from lerobot_rnd.camera_calibration import CameraCalibration, camera_from_mujoco
from lerobot_rnd.ee_pose_source import EEPoseSource
from lerobot_rnd.gripper_mesh import GripperMesh

__all__ = [
    "EMBODIMENT_FILE_IN_DATASET",
    "EMBODIMENT_PRESETS",
    "CameraCalibration",
    "EEPoseSource",
    "Embodiment",
    "GripperMesh",
    "camera_from_mujoco",
    "embodiment_preset_names",
    "load_embodiment",
    "register_embodiment_preset",
]

logger = logging.getLogger(__name__)

EMBODIMENT_FORMAT = "lerobot_rnd.embodiment"
EMBODIMENT_VERSION = 1
#: Top-level keys of an embodiment JSON (`Embodiment.to_dict`); any other key is an error (a misspelling).
EMBODIMENT_KEYS = frozenset({
    "format", "version", "name", "notes", "cameras", "camera_mesh", "ee_pose_source", "action_adapter",
    "symmetry_axis", "meshes",
})  # fmt: skip
#: Where a dataset keeps its embodiment, relative to the dataset root (written by lerobot-rnd-record).
EMBODIMENT_FILE_IN_DATASET = "meta/rnd_embodiment.json"


def missing_calibrations(image_keys: Sequence[str], calibrated: Mapping[str, Any] | Sequence[str]) -> list[str]:
    """The image keys (in order) that have no camera calibration among `calibrated` (keys or a key -> calibration
    mapping): the one check that every camera R&D renders into is calibrated."""
    return [key for key in image_keys if key not in calibrated]


def _image_hw(feature: Any) -> tuple[int, int] | None:
    """(H, W) of an image feature given as a PolicyFeature (C,H,W) or a dataset feature dict (H,W,C)."""
    ftype = getattr(feature, "type", None)
    if ftype is not None:  # PolicyFeature
        if getattr(ftype, "name", str(ftype)) != "VISUAL":
            return None
        shape = tuple(feature.shape)
    elif isinstance(feature, Mapping):
        if feature.get("dtype") not in ("image", "video"):
            return None
        shape = tuple(feature["shape"])
        names = feature.get("names")
        if names and len(names) == 3 and names[0] in ("channels", "channel", "c"):
            return int(shape[1]), int(shape[2])
        if shape[-1] in (1, 3, 4):
            return int(shape[0]), int(shape[1])
    else:
        return None
    if len(shape) != 3:
        return None
    if shape[0] in (1, 3, 4) and shape[-1] not in (1, 3, 4):
        return int(shape[1]), int(shape[2])
    if shape[-1] in (1, 3, 4) and shape[0] not in (1, 3, 4):
        return int(shape[0]), int(shape[1])
    return int(shape[1]), int(shape[2])  # ambiguous: LeRobot policy features are channel-first


def _state_dim(feature: Any) -> int | None:
    shape = getattr(feature, "shape", None)
    if shape is None and isinstance(feature, Mapping):
        shape = feature.get("shape")
    if shape is None or len(tuple(shape)) == 0:
        return None
    return int(tuple(shape)[-1])


@dataclass
class Embodiment:
    """Cameras (keyed by LeRobot image feature key), gripper meshes and the EE pose source."""

    cameras: dict[str, CameraCalibration]
    meshes: dict[str, GripperMesh]
    camera_mesh: dict[str, str] = field(default_factory=dict)
    ee_pose_source: EEPoseSource = field(default_factory=lambda: EEPoseSource(position_indices=[0, 1, 2]))
    action_adapter: dict[str, Any] | None = None
    symmetry_axis: int = 1
    name: str = ""
    notes: str = ""

    def __post_init__(self) -> None:
        if self.action_adapter is not None:
            if not isinstance(self.action_adapter, Mapping) or "type" not in self.action_adapter:
                raise ValueError(
                    "action_adapter must be a dict with a 'type' key (ee_position_delta, ee_delta, ee_absolute, "
                    f"joint_positions) and the adapter's arguments, got {self.action_adapter!r}"
                )
            self.action_adapter = dict(self.action_adapter)
        if self.symmetry_axis not in (0, 1, 2):
            raise ValueError(f"symmetry_axis must be 0, 1 or 2, got {self.symmetry_axis}")
        if not self.cameras:
            raise ValueError("an embodiment needs at least one camera")
        if not self.meshes:
            raise ValueError("an embodiment needs at least one gripper mesh")
        for k, c in self.cameras.items():
            if not isinstance(c, CameraCalibration):
                raise TypeError(f"cameras['{k}'] must be a CameraCalibration, got {type(c).__name__}")
        for k, m in self.meshes.items():
            if not isinstance(m, GripperMesh):
                raise TypeError(f"meshes['{k}'] must be a GripperMesh, got {type(m).__name__}")
            if m.num_faces == 0:
                raise ValueError(
                    f"meshes['{k}'] has no faces, so the gripper would never be drawn: check the mesh file or "
                    "the MJCF/URDF body it was loaded from"
                )
        self.camera_mesh = dict(self.camera_mesh)
        default_mesh = "full" if "full" in self.meshes else next(iter(self.meshes))
        for k in self.cameras:
            self.camera_mesh.setdefault(k, default_mesh)
        for k, mname in self.camera_mesh.items():
            if k not in self.cameras:
                raise ValueError(
                    f"camera_mesh names camera '{k}', which has no calibration; cameras: {list(self.cameras)}"
                )
            if mname not in self.meshes:
                raise ValueError(f"camera_mesh['{k}'] = '{mname}' is not a mesh; meshes: {list(self.meshes)}")

    # ------------------------------------------------------------------ access helpers
    @property
    def camera_keys(self) -> list[str]:
        return list(self.cameras)

    @property
    def mesh_names(self) -> list[str]:
        return list(self.meshes)

    def mesh_index(self, camera_key: str) -> int:
        """Index of the camera's mesh in :attr:`mesh_names` (the order of :meth:`mesh_batch`)."""
        return self.mesh_names.index(self.camera_mesh[camera_key])

    def mesh_batch(self, device=None, textured: bool = False, colors=((1.0, 0.0, 0.0), (0.0, 0.0, 1.0))):
        """All meshes as one padded ``rendering.MeshBatch`` in :attr:`mesh_names` order."""
        from lerobot_rnd.rendering import MeshBatch

        ms = [self.meshes[n] for n in self.mesh_names]
        if textured:
            ms = [m.with_symmetry_texture(self.symmetry_axis, colors) for m in ms]
        return MeshBatch.from_meshes([(m.vertices, m.faces, m.vertex_colors) for m in ms], device=device)

    def with_image_size(self, height: int, width: int, keys: Sequence[str] | None = None) -> Embodiment:
        """A copy with the given cameras (default all) resized to (height, width)."""
        cams = {
            k: (c.resized(height, width) if keys is None or k in keys else c) for k, c in self.cameras.items()
        }
        return self._replace(cameras=cams)

    def _replace(self, **changes) -> Embodiment:
        kw = {
            "cameras": dict(self.cameras), "meshes": dict(self.meshes), "camera_mesh": dict(self.camera_mesh),
            "ee_pose_source": self.ee_pose_source, "action_adapter": self.action_adapter,
            "symmetry_axis": self.symmetry_axis, "name": self.name, "notes": self.notes,
        }  # fmt: skip
        kw.update(changes)
        return Embodiment(**kw)

    def subset(self, camera_keys: Sequence[str]) -> Embodiment:
        missing = missing_calibrations(camera_keys, self.cameras)
        if missing:
            raise ValueError(f"unknown camera keys {missing}; cameras: {list(self.cameras)}")
        return self._replace(
            cameras={k: self.cameras[k] for k in camera_keys},
            camera_mesh={k: self.camera_mesh[k] for k in camera_keys},
        )

    def textured(self, colors: Sequence[Sequence[float]] = ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0))) -> Embodiment:
        """A copy whose meshes carry the symmetry texture about :attr:`symmetry_axis`."""
        return self._replace(
            meshes={k: m.with_symmetry_texture(self.symmetry_axis, colors) for k, m in self.meshes.items()}
        )

    def ee_pose_dict(self) -> dict[str, Any]:
        """The EE pose source in the policy config's ``ee_pose`` layout (see embodiment_binding.py)."""
        src = self.ee_pose_source
        if src.format not in ("none", "quat_wxyz", "quat_xyzw", "rotvec", "rot6d"):
            raise ValueError(
                f"the policy reads EE poses as fixed/quat_wxyz/quat_xyzw/rotvec/rot6d; convert the dataset's "
                f"'{src.format}' state (e.g. forward kinematics) into one of these first"
            )
        return {
            "position_indices": list(src.position_indices),
            "rotation": "fixed" if src.format == "none" else src.format,
            "rotation_indices": list(src.rotation_indices or []),
            "fixed_rotation": tolist(src.fixed_rotation if src.fixed_rotation is not None else np.eye(3)),
            "gripper_index": src.gripper_index,
            "gripper_open_value": float(src.gripper_open_value),
            "gripper_closed_value": float(src.gripper_closed_value),
            "state_key": src.state_key,
        }

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        return {
            "format": EMBODIMENT_FORMAT,
            "version": EMBODIMENT_VERSION,
            "name": self.name,
            "notes": self.notes,
            "cameras": {k: c.to_dict() for k, c in self.cameras.items()},
            "camera_mesh": dict(self.camera_mesh),
            "ee_pose_source": self.ee_pose_source.to_dict(),
            "action_adapter": self.action_adapter,
            "symmetry_axis": self.symmetry_axis,
            "meshes": {k: m.to_dict() for k, m in self.meshes.items()},
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Embodiment:
        fmt = d.get("format", EMBODIMENT_FORMAT)
        if fmt != EMBODIMENT_FORMAT:
            raise ValueError(
                f"not an embodiment description (format={fmt!r}, expected {EMBODIMENT_FORMAT!r})"
            )
        if int(d.get("version", EMBODIMENT_VERSION)) > EMBODIMENT_VERSION:
            raise ValueError(
                f"embodiment version {d.get('version')} is newer than supported ({EMBODIMENT_VERSION})"
            )
        unknown = sorted(set(d) - EMBODIMENT_KEYS)
        if unknown:
            hints = [
                f"{k!r} (did you mean {close[0]!r}?)" if (close := difflib.get_close_matches(k, EMBODIMENT_KEYS, 1))
                else repr(k)
                for k in unknown
            ]
            raise ValueError(
                f"embodiment description: unknown key(s) {', '.join(hints)}; valid keys: {sorted(EMBODIMENT_KEYS)}"
            )
        for req in ("cameras", "meshes"):
            if req not in d:
                raise ValueError(f"embodiment description has no '{req}'")
        return cls(
            cameras={k: CameraCalibration.from_dict(c) for k, c in d["cameras"].items()},
            meshes={k: GripperMesh.from_dict(m) for k, m in d["meshes"].items()},
            camera_mesh=dict(d.get("camera_mesh", {})),
            ee_pose_source=EEPoseSource.from_dict(
                d.get("ee_pose_source", {"format": "none", "position_indices": [0, 1, 2]})
            ),
            action_adapter=d.get("action_adapter"),
            symmetry_axis=int(d.get("symmetry_axis", 1)),
            name=d.get("name", ""),
            notes=d.get("notes", ""),
        )

    def save_json(self, path: str | os.PathLike) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.to_dict(), separators=(",", ":")))
        return path

    @classmethod
    def load_json(cls, path: str | os.PathLike) -> Embodiment:
        """Read an embodiment JSON; errors name the file (and the line, for invalid JSON)."""
        path = Path(path)
        try:
            d = json.loads(path.read_text())
        except json.JSONDecodeError as err:
            raise ValueError(
                f"{path}: not valid JSON ({err.msg} at line {err.lineno}, column {err.colno}); fix the file or "
                "write it again with Embodiment.save_json"
            ) from err
        if not isinstance(d, Mapping):
            raise TypeError(f"{path}: an embodiment JSON holds an object ({{...}}), got {type(d).__name__}")
        try:
            return cls.from_dict(d)
        except (ValueError, TypeError, KeyError) as err:
            raise type(err)(f"{path}: {err}") from err

    # ------------------------------------------------------------------ validation
    def validate_against(self, features: Mapping[str, Any], require_all_cameras: bool = True) -> None:
        """Check the embodiment fits a dataset's or policy's features; raise ValueError naming the fix.

        ``features``: ``{key: PolicyFeature}`` (policy input features, images channel-first) or a
        LeRobot dataset ``meta.features`` dict (images ``{"dtype": "image", "shape": (H, W, C)}``).
        """
        image_feats = {k: hw for k, f in features.items() if (hw := _image_hw(f)) is not None}
        for k in self.cameras:
            if k not in features:
                raise ValueError(
                    f"embodiment camera '{k}' is not a feature; image features are {sorted(image_feats)}. "
                    "Rename the calibration key to the dataset's image key (or map the key with --rename_map)."
                )
            if k not in image_feats:
                raise ValueError(f"embodiment camera '{k}' is a feature but not an image feature")
        if require_all_cameras:
            missing = missing_calibrations(list(image_feats), self.cameras)
            if missing:
                raise ValueError(
                    f"no camera calibration for image feature(s) {missing}; add a CameraCalibration for each "
                    "(e.g. camera_from_mujoco or a calibration JSON) or drop these cameras from the inputs"
                )
        for k, cam in self.cameras.items():
            if image_feats[k] != tuple(cam.image_size):
                H, W = image_feats[k]
                raise ValueError(
                    f"camera '{k}': calibration is for {cam.image_size[0]}x{cam.image_size[1]} images but the "
                    f"feature is {H}x{W}; use embodiment.with_image_size({H}, {W}) or "
                    f"CameraCalibration.resized({H}, {W}) (crops need a new calibration)"
                )
        skey = self.ee_pose_source.state_key
        need = self.ee_pose_source.min_state_dim()
        if need:
            if skey not in features:
                raise ValueError(f"the EE pose source reads '{skey}', which is not a feature")
            dim = _state_dim(features[skey])
            if dim is not None and dim < need:
                raise ValueError(
                    f"'{skey}' has {dim} entries but the EE pose source reads index {need - 1}; "
                    "fix ee_pose_source indices to the dataset's state layout"
                )


# --------------------------------------------------------------------------------------------------
# Presets
# --------------------------------------------------------------------------------------------------
#: Named embodiments for ``--policy.embodiment=<name>``: name -> factory building the :class:`Embodiment`.
#: Filled by :func:`register_embodiment_preset`.
EMBODIMENT_PRESETS: dict[str, Callable[[], Embodiment]] = {}
#: Modules that register presets when imported (``lerobot_rnd.sim``: "metaworld_sawyer",
#: "metaworld_sawyer_lerobot", "panda_robotiq"). LeRobot's plugin discovery imports them; otherwise they are
#: imported by name the first time a preset name is not found (this module has no import of them).
PRESET_MODULES = ("lerobot_rnd.sim",)


def register_embodiment_preset(name: str, factory: Callable[[], Embodiment]) -> None:
    """Make ``factory()`` available as ``--policy.embodiment=<name>`` / ``load_embodiment(name)``.

    Registering the same factory again is a no-op; another factory under a taken name is an error."""
    if not callable(factory):
        raise TypeError(f"embodiment preset {name!r}: factory must be callable, got {factory!r}")
    existing = EMBODIMENT_PRESETS.get(name)
    if existing is not None and _qualified_name(existing) != _qualified_name(factory):
        raise ValueError(
            f"embodiment preset {name!r} is already registered (by {_qualified_name(existing)}): "
            "pick another name"
        )
    EMBODIMENT_PRESETS[name] = factory


def _qualified_name(fn: Callable) -> str:
    return f"{getattr(fn, '__module__', '?')}.{getattr(fn, '__qualname__', repr(fn))}"


def _import_preset_modules() -> None:
    for module in PRESET_MODULES:
        try:
            importlib.import_module(module)
        except ImportError as e:  # optional simulators missing: their presets are simply not offered
            logger.debug("embodiment presets of %s not available: %s", module, e)


def embodiment_preset_names() -> list[str]:
    """Names of all presets, after importing :data:`PRESET_MODULES`."""
    _import_preset_modules()
    return sorted(EMBODIMENT_PRESETS)


def load_embodiment(source: str | os.PathLike | Mapping[str, Any] | Embodiment) -> Embodiment:
    """An embodiment from a preset name (:data:`EMBODIMENT_PRESETS`), a JSON path, a dataset root
    (reads :data:`EMBODIMENT_FILE_IN_DATASET`), a dict or an :class:`Embodiment`."""
    if isinstance(source, Embodiment):
        return source
    if isinstance(source, Mapping):
        return Embodiment.from_dict(source)
    if isinstance(source, str) and source not in EMBODIMENT_PRESETS and not Path(source).exists():
        _import_preset_modules()
    if isinstance(source, str) and source in EMBODIMENT_PRESETS:
        return EMBODIMENT_PRESETS[source]()
    path = Path(source)
    if path.is_dir():
        path = path / EMBODIMENT_FILE_IN_DATASET
    if not path.is_file():
        raise FileNotFoundError(
            f"embodiment source {str(source)!r} is neither a preset ({', '.join(embodiment_preset_names())}) "
            f"nor an existing JSON file / dataset folder with {EMBODIMENT_FILE_IN_DATASET}"
        )
    return Embodiment.load_json(path)
