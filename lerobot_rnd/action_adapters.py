"""Dataset ``action`` <-> R&D action chunk.

An R&D action chunk for one sample (see ``docs/DESIGN.md``) is

* ``T_ee_target`` ``(..., T, 4, 4)``: for each future step k = 1..T the rigid transform from
  the current EE pose (time t) to the EE pose at t+k, expressed in the current EE frame
  (cumulative, not step-to-step), and
* ``gripper`` ``(..., T)``: -1 (open) or +1 (closed).

The policy works on the 7-D vector form ``[t(3), rotvec(3), gripper(1)]`` per step
(:func:`chunk_to_vector` / :func:`vector_to_chunk`).

An :class:`ActionAdapter` converts a dataset's ``action`` tensor ``(..., T, A)`` plus the
current EE pose ``T_world_ee`` ``(..., 4, 4)`` (and, for joint-space datasets, the current
joint positions as ``state``) into that chunk (:meth:`ActionAdapter.to_rnd`) and back
(:meth:`ActionAdapter.from_rnd`). All conversions are batched over any leading shape
(``action``'s leading dims and ``T_world_ee``'s leading dims broadcast) and run on CPU and CUDA
without Python loops over batch or horizon (the chunk compositions use a log2(T)-step
parallel prefix scan).

Gripper convention shared by all adapters (``gripper=True``): the dataset's last action
column is the gripper command. ``to_rnd`` maps it to +1 (closed) when it lies on the
``gripper_closed`` side of ``gripper_threshold`` (default: the midpoint of ``gripper_open``
and ``gripper_closed``, i.e. 0 for the default -1/+1) and to -1 otherwise (a value exactly at
the threshold counts as open). ``from_rnd`` maps the R&D gripper value g linearly,
``open + (g + 1) / 2 * (closed - open)``: with the default -1/+1 values the R&D gripper value
is passed through unchanged. With ``gripper=False`` the dataset action has no gripper column;
``to_rnd`` reports -1 (open) and ``from_rnd`` drops the gripper.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, ClassVar

import torch
from torch import Tensor

from lerobot_rnd.geometry import (
    action_from_pose,
    check_finite,
    check_rigid,
    invert_transform,
    make_transform,
    matrix_to_rotation,
    pose_from_action,
    rotation_to_matrix,
    so3_exp,
    so3_log,
)

__all__ = [
    "ActionAdapter",
    "EEPositionDeltaAdapter",
    "EEDeltaAdapter",
    "AbsoluteEEPoseAdapter",
    "JointPositionAdapter",
    "ACTION_ADAPTERS",
    "make_action_adapter",
    "chunk_to_vector",
    "vector_to_chunk",
]


# ---- small helpers -------------------------------------------------------------------


def _as_float(x: Tensor, name: str) -> Tensor:
    if not isinstance(x, Tensor):
        x = torch.as_tensor(x)
    if not torch.is_floating_point(x):
        x = x.to(torch.get_default_dtype())
    return x


def _cumulative_matmul(M: Tensor, reverse_order: bool = False) -> Tensor:
    """Prefix products over dim -3 of ``M`` (..., T, n, n).

    ``P_k = M_1 @ M_2 @ ... @ M_k`` (or ``M_k @ ... @ M_1`` with ``reverse_order``), by a
    Hillis-Steele scan: ceil(log2 T) batched matmuls, no loop over the horizon.
    """
    T = M.shape[-3]
    P = M
    d = 1
    while d < T:
        if reverse_order:
            tail = P[..., d:, :, :] @ P[..., :-d, :, :]
        else:
            tail = P[..., :-d, :, :] @ P[..., d:, :, :]
        P = torch.cat([P[..., :d, :, :], tail], dim=-3)
        d *= 2
    return P


def _prev_steps(T_ee_target: Tensor) -> Tensor:
    """Chunk shifted by one step with the identity (step 0 = current pose) in front."""
    eye = torch.eye(4, dtype=T_ee_target.dtype, device=T_ee_target.device)
    first = eye.expand(*T_ee_target.shape[:-3], 1, 4, 4)
    return torch.cat([first, T_ee_target[..., :-1, :, :]], dim=-3)


def _rotate(R: Tensor, v: Tensor) -> Tensor:
    """R (..., 3, 3) applied to v (..., 3) with broadcasting."""
    return (R @ v.unsqueeze(-1)).squeeze(-1)


def _rotate_inv(R: Tensor, v: Tensor) -> Tensor:
    """R^T (..., 3, 3) applied to v (..., 3) with broadcasting."""
    return (v.unsqueeze(-2) @ R).squeeze(-2)


def _matrix_or_none(m: Any, name: str) -> Tensor | None:
    if m is None:
        return None
    t = torch.as_tensor(m, dtype=torch.float64)
    if tuple(t.shape) != (4, 4):
        raise ValueError(f"{name} must be a 4x4 matrix, got shape {tuple(t.shape)}")
    check_rigid(t, name, 1e-6)
    return t


def _matrix_to_list(m: Tensor | None) -> list | None:
    return None if m is None else m.tolist()


# ---- chunk <-> 7-D vector ------------------------------------------------------------


def chunk_to_vector(T_ee_target: Tensor, gripper: Tensor) -> Tensor:
    """(T_ee_target (..., T, 4, 4), gripper (..., T)) -> (..., T, 7) = [t(3), rotvec(3), gripper]."""
    a6 = action_from_pose(T_ee_target)
    g = gripper.to(a6.dtype)
    lead = torch.broadcast_shapes(a6.shape[:-1], g.shape)
    return torch.cat([a6.expand(*lead, 6), g.expand(lead).unsqueeze(-1)], dim=-1)


def vector_to_chunk(vector: Tensor) -> tuple[Tensor, Tensor]:
    """(..., T, 7) -> (T_ee_target (..., T, 4, 4), gripper (..., T))."""
    if vector.shape[-1] != 7:
        raise ValueError(f"R&D action vectors have 7 values per step, got shape {tuple(vector.shape)}")
    return pose_from_action(vector[..., :6]), vector[..., 6]


# ---- base class ----------------------------------------------------------------------


class ActionAdapter:
    """Converts a dataset's action chunk to the R&D chunk and back.

    Subclasses define ``name`` (factory key), ``motion_names`` (dataset columns before the
    gripper), ``_to_rnd_motion`` and ``_from_rnd_motion``.

    Args:
        gripper: whether the dataset action ends with one gripper column.
        gripper_open / gripper_closed: the dataset's gripper values for open / closed.
        gripper_threshold: dataset value separating open from closed (default: midpoint).
        gripper_from_data: replace ``gripper_open`` / ``gripper_closed`` by the values the training demos use
            (their action gripper column's 2nd and 98th percentiles, on the sides given here; threshold midway),
            once, when training starts (:meth:`fit_gripper_range`); the saved config holds the fitted values. For
            teleoperated grippers (the SO-101's 0-100) whose demos never reach the nominal ends.
        validate: check shapes, NaN/Inf and rigidity of the poses (costs a device sync on CUDA).
        rigid_atol: tolerance of the rigidity check of ``T_world_ee``.
    """

    name: ClassVar[str] = ""

    def __init__(
        self,
        gripper: bool = True,
        gripper_open: float = -1.0,
        gripper_closed: float = 1.0,
        gripper_threshold: float | None = None,
        gripper_from_data: bool = False,
        validate: bool = True,
        rigid_atol: float = 1e-3,
    ):
        if gripper_open == gripper_closed:
            raise ValueError("gripper_open and gripper_closed must differ")
        self.gripper = bool(gripper)
        self.gripper_open = float(gripper_open)
        self.gripper_closed = float(gripper_closed)
        self.gripper_threshold = None if gripper_threshold is None else float(gripper_threshold)
        self.gripper_from_data = bool(gripper_from_data)
        self.validate = bool(validate)
        self.rigid_atol = float(rigid_atol)

    # ---- layout ---------------------------------------------------------------------
    @property
    def motion_names(self) -> list[str]:
        raise NotImplementedError

    @property
    def action_names(self) -> list[str]:
        """Names of the dataset action columns, in order."""
        return list(self.motion_names) + (["gripper"] if self.gripper else [])

    @property
    def action_dim(self) -> int:
        """Dataset-side action dimension A."""
        return len(self.action_names)

    @property
    def motion_dim(self) -> int:
        return len(self.motion_names)

    # ---- gripper --------------------------------------------------------------------
    @property
    def _threshold(self) -> float:
        if self.gripper_threshold is not None:
            return self.gripper_threshold
        return 0.5 * (self.gripper_open + self.gripper_closed)

    def fit_gripper_range(self, gripper_actions: Tensor) -> tuple[float, float] | None:
        """With ``gripper_from_data``: set ``gripper_open`` / ``gripper_closed`` to the demos' gripper values
        (``gripper_actions``: every action's gripper column, any shape; 2nd / 98th percentiles on the configured
        sides), the threshold midway, and turn ``gripper_from_data`` off. Returns (open, closed), or None when
        nothing is fitted (not asked, no gripper column)."""
        if not (self.gripper and self.gripper_from_data):
            return None
        g = torch.as_tensor(gripper_actions, dtype=torch.float64).flatten()
        g = g[torch.isfinite(g)]
        if g.numel() == 0:
            raise ValueError("gripper_from_data: the dataset's action has no finite gripper values")
        low, high = (float(v) for v in torch.quantile(g, torch.tensor([0.02, 0.98], dtype=torch.float64)))
        if high - low < 1e-6 * max(1.0, abs(self.gripper_open - self.gripper_closed)):
            raise ValueError(
                f"gripper_from_data: the demos' gripper never moves (always {low:g}); record demos that open and "
                "close it, or set gripper_from_data=false with gripper_open / gripper_closed in the embodiment"
            )
        opens_high = self.gripper_open > self.gripper_closed
        self.gripper_open, self.gripper_closed = (high, low) if opens_high else (low, high)
        self.gripper_threshold = None
        self.gripper_from_data = False
        return self.gripper_open, self.gripper_closed

    def gripper_to_rnd(self, g: Tensor) -> Tensor:
        """Dataset gripper values -> {-1 (open), +1 (closed)}."""
        side = (g - self._threshold) * math.copysign(1.0, self.gripper_closed - self.gripper_open)
        return torch.where(side > 0, torch.ones_like(g), -torch.ones_like(g))

    def gripper_from_rnd(self, g: Tensor) -> Tensor:
        """R&D gripper values (-1 open .. +1 closed) -> dataset gripper values (linear map)."""
        return self.gripper_open + (g + 1.0) * 0.5 * (self.gripper_closed - self.gripper_open)

    # ---- validation -----------------------------------------------------------------
    def _check_action(self, action: Tensor) -> Tensor:
        action = _as_float(action, "action")
        if action.ndim < 2:
            raise ValueError(
                f"{self.name} adapter expects an action chunk of shape (..., T, {self.action_dim}), "
                f"got shape {tuple(action.shape)}"
            )
        if action.shape[-1] != self.action_dim:
            raise ValueError(
                f"{self.name} adapter expects action dimension {self.action_dim} "
                f"({', '.join(self.action_names)}), but the dataset action has dimension "
                f"{action.shape[-1]} (shape {tuple(action.shape)})"
            )
        if self.validate:
            check_finite(action, "action")
        return action

    def _check_pose(self, T_world_ee: Tensor, like: Tensor) -> Tensor:
        T_world_ee = _as_float(T_world_ee, "T_world_ee").to(device=like.device, dtype=like.dtype)
        if T_world_ee.ndim < 2 or tuple(T_world_ee.shape[-2:]) != (4, 4):
            raise ValueError(f"T_world_ee must have shape (..., 4, 4), got {tuple(T_world_ee.shape)}")
        if self.validate:
            check_rigid(T_world_ee, "T_world_ee", self.rigid_atol)
        return T_world_ee

    def _check_chunk(self, T_ee_target: Tensor, gripper: Tensor | None) -> tuple[Tensor, Tensor | None]:
        T_ee_target = _as_float(T_ee_target, "T_ee_target")
        if T_ee_target.ndim < 3 or tuple(T_ee_target.shape[-2:]) != (4, 4):
            raise ValueError(f"T_ee_target must have shape (..., T, 4, 4), got {tuple(T_ee_target.shape)}")
        if self.validate:
            check_finite(T_ee_target, "T_ee_target")
        if gripper is not None:
            gripper = _as_float(gripper, "gripper").to(device=T_ee_target.device, dtype=T_ee_target.dtype)
            if self.validate:
                check_finite(gripper, "gripper")
        return T_ee_target, gripper

    # ---- public API -----------------------------------------------------------------
    def to_rnd(
        self, action: Tensor, T_world_ee: Tensor, state: Tensor | None = None
    ) -> tuple[Tensor, Tensor]:
        """Dataset action chunk (..., T, A) -> (T_ee_target (..., T, 4, 4), gripper (..., T))."""
        action = self._check_action(action)
        T_world_ee = self._check_pose(T_world_ee, action)
        motion = action[..., : self.motion_dim]
        T_ee_target = self._to_rnd_motion(motion, T_world_ee, state)
        lead = T_ee_target.shape[:-2]
        if self.gripper:
            g = self.gripper_to_rnd(action[..., -1])
        else:
            g = -torch.ones(action.shape[:-1], dtype=action.dtype, device=action.device)
        return T_ee_target, g.expand(lead)

    def from_rnd(
        self, T_ee_target: Tensor, gripper: Tensor | None, T_world_ee: Tensor, state: Tensor | None = None
    ) -> Tensor:
        """(T_ee_target (..., T, 4, 4), gripper (..., T)) -> dataset action chunk (..., T, A)."""
        T_ee_target, gripper = self._check_chunk(T_ee_target, gripper)
        T_world_ee = self._check_pose(T_world_ee, T_ee_target)
        return self.compose_action(self._from_rnd_motion(T_ee_target, T_world_ee, state), gripper)

    def compose_action(self, motion: Tensor, gripper: Tensor | None) -> Tensor:
        """(motion columns (..., T, M) in the dataset's units, R&D gripper (..., T) in [-1 open, +1 closed]) ->
        dataset action chunk (..., T, A)."""
        if not self.gripper:
            return motion
        if gripper is None:
            raise ValueError(f"{self.name} adapter has a gripper column: pass the R&D gripper values")
        g = self.gripper_from_rnd(gripper)
        lead = torch.broadcast_shapes(motion.shape[:-1], g.shape)
        return torch.cat([motion.expand(*lead, motion.shape[-1]), g.expand(lead).unsqueeze(-1)], dim=-1)

    def _to_rnd_motion(self, motion: Tensor, T_world_ee: Tensor, state: Tensor | None) -> Tensor:
        raise NotImplementedError

    def _from_rnd_motion(self, T_ee_target: Tensor, T_world_ee: Tensor, state: Tensor | None) -> Tensor:
        raise NotImplementedError

    # ---- serialisation ----------------------------------------------------------------
    def _base_config(self) -> dict[str, Any]:
        return {
            "gripper": self.gripper,
            "gripper_open": self.gripper_open,
            "gripper_closed": self.gripper_closed,
            "gripper_threshold": self.gripper_threshold,
            "gripper_from_data": self.gripper_from_data,
            "validate": self.validate,
            "rigid_atol": self.rigid_atol,
        }

    def _config(self) -> dict[str, Any]:
        return {}

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable description; ``ActionAdapter.from_dict`` rebuilds the adapter."""
        return {"type": self.name, **self._base_config(), **self._config()}

    @staticmethod
    def from_dict(d: Mapping[str, Any]) -> ActionAdapter:
        d = dict(d)
        if "type" not in d:
            raise ValueError(f"action adapter dict needs a 'type' key (one of {sorted(ACTION_ADAPTERS)})")
        return make_action_adapter(d.pop("type"), **d)

    def __repr__(self) -> str:
        cfg = {k: v for k, v in self.to_dict().items() if k not in ("type", "urdf")}
        return f"{type(self).__name__}({', '.join(f'{k}={v!r}' for k, v in cfg.items())})"


# ---- 1. MetaWorld-style world-frame position deltas ----------------------------------


class EEPositionDeltaAdapter(ActionAdapter):
    """Dataset action ``[dx, dy, dz, gripper]`` (MetaWorld): world-frame position deltas.

    Each step the mocap target moves by ``scale * d`` in the world frame (MetaWorld:
    ``action_scale = 1/100``); the orientation is fixed. ASSUMPTION: at time t the mocap
    target equals the current EE position, so target k is ``p_ee + scale * sum_{j<=k} d_j``.
    The R&D rotation is the identity (``to_rnd``) and ignored (``from_rnd``).
    ``from_rnd`` divides the per-step world displacement by ``scale`` and clips to
    ``[-clip_limit, clip_limit]`` when ``clip`` (MetaWorld clips actions to [-1, 1]).
    """

    name = "ee_position_delta"

    def __init__(
        self,
        scale: float | Sequence[float] = 0.01,
        clip: bool = True,
        clip_limit: float = 1.0,
        **kwargs: Any,
    ):
        super().__init__(**kwargs)
        s = torch.as_tensor(scale, dtype=torch.float64).flatten()
        if s.numel() not in (1, 3) or bool((s == 0).any()):
            raise ValueError(f"scale must be one nonzero number or three, got {scale!r}")
        self.scale = [float(v) for v in s.expand(3)]
        self.clip = bool(clip)
        self.clip_limit = float(clip_limit)

    @property
    def motion_names(self) -> list[str]:
        return ["dx", "dy", "dz"]

    def _scale(self, like: Tensor) -> Tensor:
        return torch.tensor(self.scale, dtype=like.dtype, device=like.device)

    def _to_rnd_motion(self, motion, T_world_ee, state):
        disp_world = torch.cumsum(motion * self._scale(motion), dim=-2)  # (..., T, 3)
        R = T_world_ee[..., :3, :3].unsqueeze(-3)  # (..., 1, 3, 3)
        t = _rotate_inv(R, disp_world)
        eye = torch.eye(3, dtype=t.dtype, device=t.device).expand(*t.shape[:-1], 3, 3)
        return make_transform(eye, t)

    def _from_rnd_motion(self, T_ee_target, T_world_ee, state):
        R = T_world_ee[..., :3, :3].unsqueeze(-3)
        disp_world = _rotate(R, T_ee_target[..., :3, 3])  # (..., T, 3)
        prev = torch.cat([torch.zeros_like(disp_world[..., :1, :]), disp_world[..., :-1, :]], dim=-2)
        d = (disp_world - prev) / self._scale(disp_world)
        if self.clip:
            d = d.clamp(-self.clip_limit, self.clip_limit)
        return d

    def _config(self):
        return {"scale": self.scale, "clip": self.clip, "clip_limit": self.clip_limit}


# ---- 2. step-to-step pose deltas -----------------------------------------------------


class EEDeltaAdapter(ActionAdapter):
    """Dataset action ``[dpos(3), drot(3) rotation vector, gripper]``: step-to-step deltas.

    ``frame="ee"``: body-frame deltas, ``T_world_ee(k) = T_world_ee(k-1) @ [exp(rot_scale*drot) |
    pos_scale*dpos]`` (translation in the previous EE frame, rotation about its own axes).
    ``frame="world"``: world-frame deltas, ``p(k) = p(k-1) + pos_scale*dpos`` and
    ``R(k) = exp(rot_scale*drot) @ R(k-1)`` (world axes, about the EE origin).
    Step 0 is the current EE pose. Exactly invertible for per-step rotations below pi;
    ``clip`` (None or a limit) clips ``from_rnd``'s output.
    """

    name = "ee_delta"

    def __init__(
        self,
        pos_scale: float = 1.0,
        rot_scale: float = 1.0,
        frame: str = "ee",
        clip: float | None = None,
        **kwargs: Any,
    ):
        super().__init__(**kwargs)
        if frame not in ("ee", "world"):
            raise ValueError(f"frame must be 'ee' or 'world', got {frame!r}")
        if pos_scale == 0 or rot_scale == 0:
            raise ValueError("pos_scale and rot_scale must be nonzero")
        self.pos_scale = float(pos_scale)
        self.rot_scale = float(rot_scale)
        self.frame = frame
        self.clip = None if clip is None else float(clip)

    @property
    def motion_names(self) -> list[str]:
        return ["dx", "dy", "dz", "drx", "dry", "drz"]

    def _to_rnd_motion(self, motion, T_world_ee, state):
        dpos = motion[..., :3] * self.pos_scale
        E = so3_exp(motion[..., 3:6] * self.rot_scale)  # (..., T, 3, 3)
        if self.frame == "ee":
            T = _cumulative_matmul(make_transform(E, dpos))
            lead = torch.broadcast_shapes(T.shape[:-3], T_world_ee.shape[:-2])
            return T.expand(*lead, *T.shape[-3:])
        R0 = T_world_ee[..., :3, :3].unsqueeze(-3)  # (..., 1, 3, 3)
        Rw = _cumulative_matmul(E, reverse_order=True)  # E_k ... E_1
        R = R0.transpose(-1, -2) @ Rw @ R0
        t = _rotate_inv(R0, torch.cumsum(dpos, dim=-2))
        return make_transform(R, t)

    def _from_rnd_motion(self, T_ee_target, T_world_ee, state):
        prev = _prev_steps(T_ee_target)
        if self.frame == "ee":
            D = invert_transform(prev) @ T_ee_target
            dpos = D[..., :3, 3]
            drot = so3_log(D[..., :3, :3])
            lead = torch.broadcast_shapes(T_ee_target.shape[:-3], T_world_ee.shape[:-2])
            out = torch.cat([dpos / self.pos_scale, drot / self.rot_scale], dim=-1)
            out = out.expand(*lead, *out.shape[-2:])
        else:
            R0 = T_world_ee[..., :3, :3].unsqueeze(-3)
            dpos = _rotate(R0, T_ee_target[..., :3, 3] - prev[..., :3, 3])
            R_rel = T_ee_target[..., :3, :3] @ prev[..., :3, :3].transpose(-1, -2)
            drot = so3_log(R0 @ R_rel @ R0.transpose(-1, -2))
            out = torch.cat([dpos / self.pos_scale, drot / self.rot_scale], dim=-1)
        if self.clip is not None:
            out = out.clamp(-self.clip, self.clip)
        return out

    def _config(self):
        return {
            "pos_scale": self.pos_scale,
            "rot_scale": self.rot_scale,
            "frame": self.frame,
            "clip": self.clip,
        }


# ---- 3. absolute EE poses ------------------------------------------------------------

#: the rotation formats (``geometry.ROTATION_DIMS``) an absolute-pose action may use, with their column names
_ROT_NAMES = {
    "quat_wxyz": ["qw", "qx", "qy", "qz"],
    "quat_xyzw": ["qx", "qy", "qz", "qw"],
    "rotvec": ["rx", "ry", "rz"],
    "rot6d": [f"r6d_{i}" for i in range(6)],
}


class AbsoluteEEPoseAdapter(ActionAdapter):
    """Dataset action ``[pos(3), rotation, gripper]``: absolute EE target pose per step.

    ``rotation_format``: ``quat_wxyz`` | ``quat_xyzw`` | ``rotvec`` | ``rot6d`` (the 6-D
    convention of ``geometry.matrix_to_rotation_6d``). The poses are given in a frame ``F``
    with ``T_world_frame`` (4x4, default identity: the world frame), so
    ``T_ee_target = inv(T_world_ee) @ T_world_frame @ T_frame_target``. Quaternions are
    normalised on input; on output they have a non-negative scalar part.
    """

    name = "ee_absolute"

    def __init__(self, rotation_format: str = "quat_wxyz", T_world_frame: Any = None, **kwargs: Any):
        super().__init__(**kwargs)
        if rotation_format not in _ROT_NAMES:
            raise ValueError(f"rotation_format must be one of {sorted(_ROT_NAMES)}, got {rotation_format!r}")
        self.rotation_format = rotation_format
        self.T_world_frame = _matrix_or_none(T_world_frame, "T_world_frame")

    @property
    def motion_names(self) -> list[str]:
        return ["x", "y", "z", *_ROT_NAMES[self.rotation_format]]

    def _to_rnd_motion(self, motion, T_world_ee, state):
        r = motion[..., 3:]
        if self.validate and self.rotation_format.startswith("quat") and r.numel():
            if float(r.norm(dim=-1).min()) < 1e-6:
                raise ValueError("action contains a zero-norm quaternion")
        T_f_target = make_transform(rotation_to_matrix(r, self.rotation_format), motion[..., :3])
        if self.T_world_frame is not None:
            T_f_target = self.T_world_frame.to(T_f_target) @ T_f_target
        return invert_transform(T_world_ee).unsqueeze(-3) @ T_f_target

    def _from_rnd_motion(self, T_ee_target, T_world_ee, state):
        T = T_world_ee.unsqueeze(-3) @ T_ee_target
        if self.T_world_frame is not None:
            T = invert_transform(self.T_world_frame.to(T)) @ T
        return torch.cat([T[..., :3, 3], matrix_to_rotation(T[..., :3, :3], self.rotation_format)], dim=-1)

    def _config(self):
        return {"rotation_format": self.rotation_format, "T_world_frame": _matrix_to_list(self.T_world_frame)}


# ---- 4. absolute joint positions (URDF forward / inverse kinematics) -----------------

ANCHORS = ("measured", "last_command")  # JointPositionAdapter.anchor


class JointPositionAdapter(ActionAdapter):
    """Dataset action ``[q_1..q_n, gripper]``: absolute joint position targets per step.

    Kinematics come from a URDF serial chain (``pytorch_kinematics``) from ``root_link`` (default:
    the URDF root, called ``base``) to ``ee_link``; ``T_link_ee`` (4x4, default identity) is the
    R&D EE frame in ``ee_link``'s frame, ``T_world_base`` (default identity) the robot base pose.

    ``state``: current joint positions (..., S); the joints are ``state[..., state_joint_indices]``
    or, by default, the first n entries. ``joint_scale`` (one factor, or one per joint): the dataset's joint
    unit in the URDF's (radians / metres), e.g. pi/180 for degrees; ``forward_kinematics`` and
    ``inverse_kinematics`` work in URDF units, ``to_rnd`` / ``from_rnd`` in the dataset's.

    * ``to_rnd``: ``T_ee_target = inv(FK(q_now)) @ FK(q_target)`` when ``state`` is given (the
      calibration ``T_world_base`` cancels); without ``state`` the current pose is
      ``inv(T_world_base) @ T_world_ee``.
    * ``from_rnd`` (needs ``state``): targets ``FK(q_now) @ T_ee_target`` are solved by batched
      damped least-squares IK (``pk.PseudoInverseIK``), every step seeded from ``q_now`` (plus
      ``ik_num_retries - 1`` Gaussian perturbations of ``ik_retry_std``); among converged retries
      the one closest to ``q_now`` wins, else the one with the smallest error. Per-step errors are
      in ``self.last_ik_info`` (``converged``, ``err_pos`` [m], ``err_rot`` [rad]).

    ``anchor``: the joints a chunk starts from, ``"measured"`` (the state's) or ``"last_command"`` (the last targets
    sent, put into ``state`` by the policy: ``lerobot_rnd.anchor``; for position servos that sag under gravity).

    ``ik_orientation_weight`` (metres per radian in the least-squares objective, default 1): below 1 the IK
    keeps the position and gives up the rotation an arm with fewer than 6 joints cannot reach (the SO-101's
    five); at 1 a rotation error of 1 rad weighs as much as a position error of 1 m.
    """

    name = "joint_positions"

    def __init__(
        self,
        urdf: str | None = None,
        urdf_path: str | None = None,
        ee_link: str = "",
        root_link: str = "",
        T_link_ee: Any = None,
        T_world_base: Any = None,
        state_joint_indices: Sequence[int] | None = None,
        ik_max_iterations: int = 100,
        ik_pos_tolerance: float = 1e-4,
        ik_rot_tolerance: float = 1e-3,
        ik_num_retries: int = 1,
        ik_retry_std: float = 0.1,
        ik_lm_damping: float = 0.1,
        ik_enforce_joint_limits: bool = True,
        ik_orientation_weight: float = 1.0,
        anchor: str = "measured",
        joint_scale: float | Sequence[float] | None = None,
        **kwargs: Any,
    ):
        super().__init__(**kwargs)
        if (urdf is None) == (urdf_path is None):
            raise ValueError("give exactly one of urdf (URDF text) or urdf_path")
        if not ee_link:
            raise ValueError("ee_link (name of the URDF link carrying the end effector) is required")
        self.urdf = urdf
        self.urdf_path = urdf_path
        self._urdf_text = urdf if urdf is not None else Path(urdf_path).read_text()
        self.ee_link = ee_link
        self.root_link = root_link
        self.T_link_ee = _matrix_or_none(T_link_ee, "T_link_ee")
        self.T_world_base = _matrix_or_none(T_world_base, "T_world_base")
        self.state_joint_indices = (
            None if state_joint_indices is None else [int(i) for i in state_joint_indices]
        )
        self.ik_max_iterations = int(ik_max_iterations)
        self.ik_pos_tolerance = float(ik_pos_tolerance)
        self.ik_rot_tolerance = float(ik_rot_tolerance)
        self.ik_num_retries = int(ik_num_retries)
        if self.ik_num_retries < 1:
            raise ValueError("ik_num_retries must be >= 1")
        self.ik_retry_std = float(ik_retry_std)
        self.ik_lm_damping = float(ik_lm_damping)
        self.ik_enforce_joint_limits = bool(ik_enforce_joint_limits)
        self.ik_orientation_weight = float(ik_orientation_weight)
        if not (math.isfinite(self.ik_orientation_weight) and self.ik_orientation_weight > 0):
            raise ValueError(f"ik_orientation_weight must be a finite number > 0, got {ik_orientation_weight!r}")
        if anchor not in ANCHORS:
            raise ValueError(f"anchor must be one of {ANCHORS}, got {anchor!r}")
        self.anchor = anchor
        self._chains: dict[tuple[str, torch.dtype], Any] = {}
        chain = self.chain(torch.device("cpu"), torch.float64)
        self.joint_names: list[str] = list(chain.get_joint_parameter_names(exclude_fixed=True))
        self.last_ik_info: dict[str, Tensor] = {}
        self.joint_scale = None
        if joint_scale is not None:
            s = torch.as_tensor(joint_scale, dtype=torch.float64).flatten()
            if s.numel() not in (1, self.n_joints) or not bool(torch.isfinite(s).all() and (s != 0).all()):
                raise ValueError(
                    f"joint_scale must be one finite nonzero factor or {self.n_joints}, got {joint_scale!r}"
                )
            self.joint_scale = [float(v) for v in s.expand(self.n_joints)]

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def motion_names(self) -> list[str]:
        return list(self.joint_names)

    def chain(self, device: torch.device | str = "cpu", dtype: torch.dtype = torch.float32):
        """The pytorch_kinematics SerialChain on ``device`` / ``dtype`` (cached)."""
        import pytorch_kinematics as pk

        device = torch.device(device)
        key = (str(device), dtype)
        if key not in self._chains:
            # Built outside inference mode even when first asked for under it, so that training can use it too.
            with torch.inference_mode(False):
                try:
                    ch = pk.build_serial_chain_from_urdf(self._urdf_text, self.ee_link, self.root_link)
                except Exception as e:  # pk raises assorted errors for unknown links
                    raise ValueError(
                        f"cannot build a serial chain to link {self.ee_link!r} from the URDF: {e}"
                    ) from e
                self._chains[key] = ch.to(dtype=dtype, device=device)
        return self._chains[key]

    def _joints_from_state(self, state: Tensor | None, like: Tensor) -> Tensor:
        if state is None:
            raise ValueError("joint_positions adapter needs the current joint positions as `state`")
        state = _as_float(state, "state").to(device=like.device, dtype=like.dtype)
        if self.state_joint_indices is not None:
            idx = torch.tensor(self.state_joint_indices, device=state.device)
            if state.shape[-1] <= max(self.state_joint_indices):
                raise ValueError(
                    f"state has {state.shape[-1]} values; state_joint_indices={self.state_joint_indices}"
                )
            q = state.index_select(-1, idx)
        else:
            if state.shape[-1] < self.n_joints:
                raise ValueError(
                    f"state must hold the {self.n_joints} joint positions ({', '.join(self.joint_names)}), "
                    f"got last dim {state.shape[-1]}"
                )
            q = state[..., : self.n_joints]
        if q.shape[-1] != self.n_joints:
            raise ValueError(f"expected {self.n_joints} joint positions from state, got {q.shape[-1]}")
        if self.validate:
            check_finite(q, "state")
        return q

    def joints_from_state(self, state: Tensor) -> Tensor:
        """The current joint positions (..., n) in the dataset's units, from the robot state (..., S)."""
        return self._joints_from_state(state, _as_float(state, "state"))

    def to_urdf_units(self, q: Tensor) -> Tensor:
        """Dataset joint positions (..., n) -> URDF units (times ``joint_scale``)."""
        if self.joint_scale is None:
            return q
        return q * torch.tensor(self.joint_scale, dtype=q.dtype, device=q.device)

    def from_urdf_units(self, q: Tensor) -> Tensor:
        """URDF joint positions (..., n) -> the dataset's units."""
        if self.joint_scale is None:
            return q
        return q / torch.tensor(self.joint_scale, dtype=q.dtype, device=q.device)

    def forward_kinematics(self, q: Tensor) -> Tensor:
        """Joint positions (..., n) in URDF units -> T_base_ee (..., 4, 4) (including ``T_link_ee``)."""
        q = _as_float(q, "q")
        if q.shape[-1] != self.n_joints:
            raise ValueError(f"expected {self.n_joints} joint positions, got shape {tuple(q.shape)}")
        lead = q.shape[:-1]
        flat = q.reshape(-1, self.n_joints)
        if flat.shape[0] == 0:
            return q.new_zeros(*lead, 4, 4)
        T = self.chain(q.device, q.dtype).forward_kinematics(flat).get_matrix()
        T = T.reshape(*lead, 4, 4)
        if self.T_link_ee is not None:
            T = T @ self.T_link_ee.to(T)
        return T

    def inverse_kinematics(self, T_base_ee: Tensor, q_seed: Tensor) -> tuple[Tensor, dict[str, Tensor]]:
        """Batched IK: targets (..., 4, 4) and seeds (..., n) (broadcast) -> q (..., n), info."""
        import pytorch_kinematics as pk

        lead = torch.broadcast_shapes(T_base_ee.shape[:-2], q_seed.shape[:-1])
        T_link = T_base_ee
        if self.T_link_ee is not None:
            T_link = T_link @ invert_transform(self.T_link_ee.to(T_link))
        n, R = self.n_joints, self.ik_num_retries
        out_dtype = torch.promote_types(T_base_ee.dtype, q_seed.dtype)
        # Solved in float64: on an arm with fewer than 6 joints J J^T is singular and pytorch-kinematics' damping
        # vanishes with the error, so float32 fails ("the input matrix is singular") near a reached target.
        work = torch.float32 if T_base_ee.device.type == "mps" else torch.float64
        T_flat = T_link.expand(*lead, 4, 4).reshape(-1, 4, 4).to(work)
        seed = q_seed.expand(*lead, n).reshape(-1, n).to(work)
        M = T_flat.shape[0]
        if M == 0:
            empty = torch.zeros(*lead, dtype=torch.bool, device=T_base_ee.device)
            info = {"converged": empty, "err_pos": empty.float(), "err_rot": empty.float()}
            return q_seed.new_zeros(*lead, n, dtype=out_dtype), info
        seeds = seed.unsqueeze(1).repeat(1, R, 1)  # (M, R, n)
        if R > 1:
            gen = torch.Generator(device=seed.device).manual_seed(0)
            noise = torch.randn(M, R - 1, n, generator=gen, device=seed.device, dtype=seed.dtype)
            seeds[:, 1:] += self.ik_retry_std * noise
        chain = self.chain(T_flat.device, T_flat.dtype)
        ik = pk.PseudoInverseIK(
            chain,
            pos_tolerance=self.ik_pos_tolerance,
            rot_tolerance=self.ik_rot_tolerance,
            retry_configs=seeds[0],  # fixes num_retries = R; the per-problem seeds are set below
            max_iterations=self.ik_max_iterations,
            lm_damping=self.ik_lm_damping,
            early_stopping_any_converged=True,
            early_stopping_no_improvement=None,
            enforce_joint_limits=self.ik_enforce_joint_limits,
            **self._ik_weights(),
        )
        ik.initial_config = seeds.reshape(M * R, n)  # solve() accepts (M*R, n) problem-major seeds
        sol = ik.solve(pk.Transform3d(matrix=T_flat, dtype=T_flat.dtype, device=T_flat.device))
        q_all = sol.solutions.reshape(M, R, n)
        dist = (q_all - seed.unsqueeze(1)).norm(dim=-1)
        err = sol.err_pos / self.ik_pos_tolerance + self.ik_orientation_weight * sol.err_rot / self.ik_rot_tolerance
        cost = torch.where(sol.converged, dist, 1e6 + err)
        best = cost.argmin(dim=1)
        ar = torch.arange(M, device=best.device)
        q = q_all[ar, best].reshape(*lead, n).to(out_dtype)
        info = {
            "converged": sol.converged[ar, best].reshape(lead),
            "err_pos": sol.err_pos[ar, best].reshape(lead),
            "err_rot": sol.err_rot[ar, best].reshape(lead),
        }
        return q, info

    def _ik_weights(self) -> dict[str, float]:
        """pytorch_kinematics' objective weights (its ``orientation_weight`` needs pytorch-kinematics >= 0.10)."""
        if self.ik_orientation_weight == 1.0:
            return {}
        import inspect

        import pytorch_kinematics as pk

        if "orientation_weight" not in inspect.signature(pk.InverseKinematics.__init__).parameters:
            raise RuntimeError("ik_orientation_weight needs pytorch-kinematics >= 0.10: "
                               "pip install 'pytorch-kinematics>=0.10'")  # fmt: skip
        return {"orientation_weight": self.ik_orientation_weight}

    def _current_T_base_ee(self, T_world_ee: Tensor, state: Tensor | None, like: Tensor) -> Tensor:
        if state is not None:
            return self.forward_kinematics(self.to_urdf_units(self._joints_from_state(state, like)))
        if self.T_world_base is not None:
            return invert_transform(self.T_world_base.to(T_world_ee)) @ T_world_ee
        return T_world_ee

    def _to_rnd_motion(self, motion, T_world_ee, state):
        T_base_target = self.forward_kinematics(self.to_urdf_units(motion))  # (..., T, 4, 4)
        T_base_ee = self._current_T_base_ee(T_world_ee, state, motion)
        return invert_transform(T_base_ee).unsqueeze(-3) @ T_base_target

    def _from_rnd_motion(self, T_ee_target, T_world_ee, state):
        q_now = self.to_urdf_units(self._joints_from_state(state, T_ee_target))
        T_base_target = self.forward_kinematics(q_now).unsqueeze(-3) @ T_ee_target
        q, info = self.inverse_kinematics(T_base_target, q_now.unsqueeze(-2))
        lead = torch.broadcast_shapes(q.shape[:-1], T_world_ee.shape[:-2] + (1,))
        self.last_ik_info = info
        return self.from_urdf_units(q.expand(*lead, self.n_joints))

    def _config(self):
        return {
            "urdf": self.urdf,
            "urdf_path": self.urdf_path,
            "ee_link": self.ee_link,
            "root_link": self.root_link,
            "T_link_ee": _matrix_to_list(self.T_link_ee),
            "T_world_base": _matrix_to_list(self.T_world_base),
            "state_joint_indices": self.state_joint_indices,
            "ik_max_iterations": self.ik_max_iterations,
            "ik_pos_tolerance": self.ik_pos_tolerance,
            "ik_rot_tolerance": self.ik_rot_tolerance,
            "ik_num_retries": self.ik_num_retries,
            "ik_retry_std": self.ik_retry_std,
            "ik_lm_damping": self.ik_lm_damping,
            "ik_enforce_joint_limits": self.ik_enforce_joint_limits,
            "ik_orientation_weight": self.ik_orientation_weight,
            "anchor": self.anchor,
            "joint_scale": self.joint_scale,
        }


# ---- factory -------------------------------------------------------------------------

ACTION_ADAPTERS: dict[str, type[ActionAdapter]] = {
    cls.name: cls
    for cls in (EEPositionDeltaAdapter, EEDeltaAdapter, AbsoluteEEPoseAdapter, JointPositionAdapter)
}


def make_action_adapter(name: str, **kwargs: Any) -> ActionAdapter:
    """Build an adapter by name: ee_position_delta | ee_delta | ee_absolute | joint_positions."""
    if name not in ACTION_ADAPTERS:
        raise ValueError(f"unknown action adapter {name!r}; choose one of {sorted(ACTION_ADAPTERS)}")
    return ACTION_ADAPTERS[name](**kwargs)
