"""Where R&D reads the end-effector pose and the gripper state: :class:`EEPoseSource` (the embodiment's
description, JSON) and :class:`EEPoseReader` (the policy's reader of ``observation.state`` batches).

Formats: a position plus a fixed orientation, any rotation format of ``geometry.ROTATION_DIMS``
(quaternions, rotation vector, 6-D, Euler xyz, matrix), or joint positions through URDF forward kinematics.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor

from lerobot_rnd.arrays import as_matrix, as_rigid_transform, make_pose, tolist
from lerobot_rnd.geometry import ROTATION_DIMS, quat_wxyz_to_matrix, rotation_to_matrix

EE_POSE_FORMATS = ("none", *ROTATION_DIMS, "joints")


@dataclass
class EEPoseSource:
    """Where the world-from-EE pose and the gripper state live in ``observation.state``.

    ``format``:
      - "none": position from ``position_indices``, fixed orientation ``fixed_rotation``
        (3x3 R_world_ee or quaternion wxyz; identity by default);
      - "quat_wxyz" / "quat_xyzw" / "rotvec" / "rot6d" / "euler_xyz" (extrinsic xyz, scipy "xyz")
        / "matrix" (row-major 3x3): position from ``position_indices``, rotation from
        ``rotation_indices`` (4, 4, 3, 6, 3, 9 numbers);
      - "joints": joint positions ``joint_indices`` (times ``joint_scale``, the factor from the state's unit
        to the URDF's, e.g. pi/180 for degrees; default 1) -> forward kinematics of the URDF to ``ee_link``
        (pytorch_kinematics), then ``T_world_base @ T_base_link @ T_link_ee``. The URDF is ``urdf`` (its text,
        carried inline: a checkpoint that holds it works on any machine) or ``urdf_path`` (a file).
    ``gripper_index``: index of the gripper state; ``gripper_open_value`` / ``gripper_closed_value``:
    its values when fully open / closed.
    """

    format: str = "none"
    position_indices: list[int] | None = None
    rotation_indices: list[int] | None = None
    fixed_rotation: Any | None = None
    urdf_path: str | None = None
    urdf: str | None = None
    ee_link: str | None = None
    joint_indices: list[int] | None = None
    T_world_base: Any | None = None
    T_link_ee: Any | None = None
    gripper_index: int | None = None
    gripper_open_value: float = 1.0
    gripper_closed_value: float = 0.0
    state_key: str = "observation.state"
    joint_scale: list[float] | None = None

    def __post_init__(self) -> None:
        if self.format not in EE_POSE_FORMATS:
            raise ValueError(f"ee_pose_source.format must be one of {EE_POSE_FORMATS}, got {self.format!r}")
        if self.position_indices is not None:
            self.position_indices = [int(i) for i in self.position_indices]
        if self.rotation_indices is not None:
            self.rotation_indices = [int(i) for i in self.rotation_indices]
        if self.joint_indices is not None:
            self.joint_indices = [int(i) for i in self.joint_indices]
        if self.format == "joints":
            if not (self.urdf_path or self.urdf) or not self.ee_link or not self.joint_indices:
                raise ValueError("ee_pose_source 'joints' needs urdf (the URDF's text) or urdf_path, ee_link and "
                                 "joint_indices")  # fmt: skip
            if self.urdf_path and self.urdf:
                raise ValueError("ee_pose_source 'joints': give the URDF once, as urdf (text) or urdf_path")
            if self.joint_scale is not None:
                self.joint_scale = [float(v) for v in self.joint_scale]
                if len(self.joint_scale) != len(self.joint_indices) or not all(
                    math.isfinite(v) and v != 0 for v in self.joint_scale
                ):
                    raise ValueError(
                        f"ee_pose_source.joint_scale must be {len(self.joint_indices)} finite nonzero factors "
                        f"(one per joint index), got {self.joint_scale}"
                    )
        elif self.joint_scale is not None:
            raise ValueError("ee_pose_source.joint_scale is only for format 'joints'")
        else:
            if self.position_indices is None or len(self.position_indices) != 3:
                raise ValueError(
                    f"ee_pose_source '{self.format}' needs 3 position_indices, got {self.position_indices}"
                )
            need = ROTATION_DIMS.get(self.format, 0)
            if need and (self.rotation_indices is None or len(self.rotation_indices) != need):
                raise ValueError(
                    f"ee_pose_source '{self.format}' needs {need} rotation_indices, got {self.rotation_indices}"
                )
        if self.fixed_rotation is not None:
            fr = np.asarray(self.fixed_rotation, dtype=np.float64)
            if fr.shape == (4,):
                fr = quat_wxyz_to_matrix(torch.as_tensor(fr)).numpy()
            fr = as_matrix(fr, (3, 3), "ee_pose_source.fixed_rotation")
            as_rigid_transform(make_pose(fr, np.zeros(3)), "ee_pose_source.fixed_rotation")
            self.fixed_rotation = fr
        for attr in ("T_world_base", "T_link_ee"):
            val = getattr(self, attr)
            if val is not None:
                setattr(self, attr, as_rigid_transform(val, f"ee_pose_source.{attr}"))
        if self.gripper_index is not None:
            self.gripper_index = int(self.gripper_index)
        self._chain = None

    def used_indices(self) -> list[int]:
        idx = (
            list(self.position_indices or [])
            + list(self.rotation_indices or [])
            + list(self.joint_indices or [])
        )
        if self.gripper_index is not None:
            idx.append(self.gripper_index)
        return idx

    def min_state_dim(self) -> int:
        idx = self.used_indices()
        return max(idx) + 1 if idx else 0

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"format": self.format, "state_key": self.state_key}
        for k in (
            "position_indices",
            "rotation_indices",
            "urdf_path",
            "urdf",
            "ee_link",
            "joint_indices",
            "joint_scale",
            "gripper_index",
        ):
            if getattr(self, k) is not None:
                d[k] = getattr(self, k)
        for k in ("fixed_rotation", "T_world_base", "T_link_ee"):
            if getattr(self, k) is not None:
                d[k] = tolist(getattr(self, k))
        d["gripper_open_value"] = float(self.gripper_open_value)
        d["gripper_closed_value"] = float(self.gripper_closed_value)
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> EEPoseSource:
        known = {
            "format", "position_indices", "rotation_indices", "fixed_rotation", "urdf_path", "urdf", "ee_link",
            "joint_indices", "T_world_base", "T_link_ee", "gripper_index", "gripper_open_value",
            "gripper_closed_value", "state_key", "joint_scale",
        }  # fmt: skip
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"ee_pose_source: unknown keys {sorted(unknown)}")
        return cls(**dict(d))

    # ------------------------------------------------------------------ evaluation
    def _rotation(self, state: torch.Tensor) -> torch.Tensor:
        fmt = self.format
        if fmt == "none":
            R = (
                torch.eye(3, dtype=state.dtype, device=state.device)
                if self.fixed_rotation is None
                else (torch.as_tensor(self.fixed_rotation, dtype=state.dtype, device=state.device))
            )
            return R.expand(*state.shape[:-1], 3, 3)
        return rotation_to_matrix(state[..., self.rotation_indices], fmt)

    def ee_pose(self, state: torch.Tensor) -> torch.Tensor:
        """World-from-EE pose (..., 4, 4) from a state (..., D) (float tensor, any device)."""
        state = torch.as_tensor(state)
        if not state.is_floating_point():
            state = state.float()
        if state.shape[-1] < self.min_state_dim():
            raise ValueError(
                f"state has {state.shape[-1]} entries but the EE pose source reads index {self.min_state_dim() - 1}"
            )
        if self.format == "joints":
            return self._fk(state)
        R = self._rotation(state)
        T = torch.zeros(*state.shape[:-1], 4, 4, dtype=state.dtype, device=state.device)
        T[..., :3, :3] = R
        T[..., :3, 3] = state[..., self.position_indices]
        T[..., 3, 3] = 1.0
        return T

    def gripper(self, state: torch.Tensor) -> torch.Tensor | None:
        """Gripper closure in [0, 1] (0 open, 1 closed), or None without a gripper index."""
        if self.gripper_index is None:
            return None
        g = torch.as_tensor(state)[..., self.gripper_index]
        return ((g - self.gripper_open_value) / (self.gripper_closed_value - self.gripper_open_value)).clamp(
            0, 1
        )

    def _fk(self, state: torch.Tensor) -> torch.Tensor:
        import pytorch_kinematics as pk

        if self._chain is None:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                text = self.urdf.encode() if self.urdf else Path(self.urdf_path).read_bytes()
                self._chain = pk.build_serial_chain_from_urdf(text, self.ee_link)
        chain = self._chain.to(dtype=state.dtype, device=state.device)
        q = state[..., self.joint_indices]
        if self.joint_scale is not None:
            q = q * torch.as_tensor(self.joint_scale, dtype=q.dtype, device=q.device)
        lead = q.shape[:-1]
        T = chain.forward_kinematics(q.reshape(-1, q.shape[-1])).get_matrix().reshape(*lead, 4, 4)
        if self.T_world_base is not None:
            T = torch.as_tensor(self.T_world_base, dtype=state.dtype, device=state.device) @ T
        if self.T_link_ee is not None:
            T = T @ torch.as_tensor(self.T_link_ee, dtype=state.dtype, device=state.device)
        return T


class EEPoseReader:
    """Reads T_world_ee (..., 4, 4) and the gripper state in [-1 open, +1 closed] from observation.state
    (..., D), as the policy's config field ``ee_pose`` (an :meth:`EEPoseSource.to_dict`) describes."""

    def __init__(self, spec: dict, state_dim: int):
        if not spec:
            raise ValueError("config.ee_pose is empty: the embodiment must say where the EE pose is in the state.")
        self.source = EEPoseSource.from_dict(spec)
        if self.source.min_state_dim() > state_dim:
            raise ValueError(
                f"The EE pose source reads observation.state index {self.source.min_state_dim() - 1} but the state "
                f"has {state_dim} values: the embodiment does not match this dataset."
            )

    def pose(self, state: Tensor) -> Tensor:
        """state (..., D) -> T_world_ee (..., 4, 4)."""
        return self.source.ee_pose(state.float())

    def gripper(self, state: Tensor) -> Tensor:
        """state (..., D) -> gripper state (...) in [-1 open, +1 closed] (-1 without a gripper index)."""
        closure = self.source.gripper(state.float())
        if closure is None:
            return state.new_zeros(state.shape[:-1]).float() - 1.0
        return 2.0 * closure - 1.0
