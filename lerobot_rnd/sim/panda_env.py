"""Franka Panda + Robotiq 2F-85 tabletop tasks (gym-hil's assets) as a gymnasium env for LeRobot.

``gym.make("gym_rnd_panda/lift-cube")`` (registered when this module is imported), or
``lerobot-eval --env.type=rnd_panda --env.task=lift-cube``. Tasks (:data:`PANDA_TASKS`):

- ``lift-cube``: a 4 cm cube at a random position and yaw; success = cube centre more than
  :data:`LIFT_SUCCESS_HEIGHT` (8 cm) above its initial height.
- ``push-block``: push a 5 x 5 x 4 cm block (random position and yaw) into a green target disc on the
  table; success = block centre within :data:`PUSH_SUCCESS_RADIUS` (3 cm, horizontally) of the disc centre.
- ``press-button``: a red push button (spring-loaded, 15 mm travel) on a grey box at a random position
  and yaw; success = button pressed down by more than :data:`BUTTON_SUCCESS_DEPTH` (1 cm).
- ``pick-place``: pick the 4 cm cube (random position and yaw) and put it down on a green target disc;
  success = cube resting on the table (centre below 2.5 cm) within :data:`PLACE_SUCCESS_RADIUS` (3 cm)
  of the disc centre with the gripper opened (opening > 0.5).

The scene is gym-hil's Panda with the Robotiq 2F-85 (``gym_hil/assets/panda.xml``, gym-hil 0.1.14 is used
only for its assets) plus a floor, lights, a static ``front`` camera, the task objects and a mocap body
``ee_target``. The arm is driven by gym-hil's operational-space controller (torques on the 7 joints, a
port that also runs on MuJoCo 4) tracking the pose of ``ee_target``.

Observation (LeRobot's ``preprocess_observation`` maps it to ``observation.images.<cam>`` and
``observation.state``)::

    {"pixels": {"front": uint8 (H, W, 3), "wrist": uint8 (H, W, 3)},
     "agent_pos": float32 (8,) = [ee x, y, z (m, world), ee quat w, x, y, z, gripper opening]}

- EE frame = MuJoCo site ``pinch`` of the Robotiq (between the finger pads, about 4 mm above the pad
  tips when open, 18 mm when closed; z along the fingers, the fingers open along y; pointing down:
  quat (0, 1, 0, 0)). This is the
  frame the controller drives to the ``ee_target`` mocap pose.
- quaternion: wxyz, unit, sign chosen so that its dot product with the home orientation (0, 1, 0, 0) is
  >= 0 (continuous for every yaw within +-180 degrees of home).
- gripper opening: 1 - (mean Robotiq driver joint angle) / 0.8 rad, clipped to [0, 1]: 1 = fully open
  (85 mm), 0 = fully closed (about 0.42 when closed on the 4 cm cube).

Cameras: ``front`` (static, in front of the robot looking back at the workspace, fovy 50) and
``wrist`` (gym-hil's ``handcam_rgb`` on the arm's flange: rigid on the hand, fovy 42.5, sees the finger
tips). Fast rendering: no multisampling, shadows or reflections, decimated arm meshes.

Action (7,), clipped to [-1, 1], one control step = ``control_dt`` = 0.1 s (10 Hz, 50 physics steps)::

    [dx, dy, dz, drx, dry, drz, gripper]

- ``dx, dy, dz``: the mocap target moves by ``pos_scale * d`` (:data:`POS_SCALE` = 0.02 m per unit) in the
  WORLD frame (then clipped to :data:`WORKSPACE_BOUNDS`);
- ``drx, dry, drz``: rotation vector in the WORLD frame, ``rot_scale`` (:data:`ROT_SCALE` = 0.1 rad per
  unit), applied to the target orientation about the target point: ``R <- exp(rot_scale * drot) @ R``;
- ``gripper``: absolute command, -1 = open, +1 = closed (linear in between: Robotiq ctrl
  ``255 * (g + 1) / 2``).

This is exactly ``lerobot_rnd.action_adapters.EEDeltaAdapter(pos_scale=0.02, rot_scale=0.1,
frame="world", clip=1.0)`` (:func:`panda_action_adapter`) for the controller's target pose; the real EE
follows it with the controller's lag (below 1 mm / 0.1 degree at rest, about 18 mm / 7 degrees behind
while moving at full speed: the EE poses reached k steps later match the adapter's prediction to 3 mm
(k=1) ... 14 mm (k=8) on average on expert demonstrations).

Placement (:meth:`RnDPandaEnv.placement_space`): ``lift-cube`` / ``press-button``: [x, y, yaw] of the
cube / button box; ``push-block`` / ``pick-place``: [block / cube x, y, yaw, target x, y].
``reset(options={"placement": vec})`` for an exact placement; otherwise ``placement="random"`` draws
from the range with the env's seeded RNG (``reset(seed=...)`` makes it reproducible), or
``placement="fixed"`` cycles through ``placements``.
Episodes start with the gripper open, pointing down, at :data:`START_POS`.
"""

from __future__ import annotations

import copy
import importlib.util
import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_IMAGES, OBS_STATE

logger = logging.getLogger(__name__)

GYM_NAMESPACE = "gym_rnd_panda"
PANDA_TASKS = ("lift-cube", "push-block", "press-button", "pick-place")
TASK_DESCRIPTIONS = {
    "lift-cube": "Pick up the purple cube and lift it",
    "push-block": "Push the blue block onto the green target",
    "press-button": "Press the red button",
    "pick-place": "Put the purple cube on the green target",
}
GYM_HIL_VERSION = "0.1.14"
INSTALL_HINT = f"pip install --no-deps gym-hil=={GYM_HIL_VERSION}  (only its MuJoCo assets are used)"

DEFAULT_CAMERAS = ("front", "wrist")
#: observation camera name -> MuJoCo camera name
MUJOCO_CAMERAS = {"front": "front", "wrist": "handcam_rgb"}
STATE_NAMES = ["ee_x", "ee_y", "ee_z", "ee_qw", "ee_qx", "ee_qy", "ee_qz", "gripper_open"]
ACTION_NAMES = ["dx", "dy", "dz", "drx", "dry", "drz", "gripper"]

EE_SITE = "pinch"
GRIPPER_ROOT_BODY = "base_mount"
#: the Robotiq's fingers (follower links with their pads): the "fingers" mesh drawn in the wrist camera
FINGER_BODIES = ("right_follower", "left_follower")
#: faces of the embodiment's gripper meshes. The Robotiq's thin links need more than the usual 1500
#: with the grid-clustering simplifier (mask IoU vs MuJoCo at 128 px, front "full" / wrist "fingers":
#: 1500 faces 0.82 / 0.91, 2000: 0.87 / 1.0, 4000: 0.96 / 1.0, unsimplified 0.99 / 1.0).
GRIPPER_MESH_FACES = 4000
#: Robotiq driver joint range (0 = open, 0.8 rad = closed)
DRIVER_CLOSED = 0.8
MAX_GRIPPER_COMMAND = 255.0

CONTROL_DT = 0.1
PHYSICS_DT = 0.002
PANDA_FPS = 10
POS_SCALE = 0.02  # m per action unit and step
ROT_SCALE = 0.1  # rad per action unit and step
#: mocap target position limits (pinch site, metres, world)
WORKSPACE_BOUNDS = np.array([[0.2, -0.35, 0.005], [0.7, 0.35, 0.5]])
#: home orientation of the EE (pointing down, fingers opening along world -y)
HOME_QUAT = np.array([0.0, 1.0, 0.0, 0.0])
#: EE (pinch) position at the start of every episode
START_POS = np.array([0.45, 0.0, 0.22])
#: gym-hil's joint home (also the controller's null-space target)
PANDA_HOME = np.array([0.0, 0.195, 0.0, -2.43, 0.0, 2.62, 0.785])
#: static front camera: position and the point it looks at
FRONT_CAMERA_POS = (0.95, 0.0, 0.55)
FRONT_CAMERA_LOOKAT = (0.42, 0.0, 0.08)
FRONT_CAMERA_FOVY = 50.0

CUBE_HALF = 0.02
BLOCK_HALF = (0.025, 0.025, 0.02)
TARGET_RADIUS = 0.03
BUTTON_HOUSING_HALF = (0.04, 0.04, 0.025)
BUTTON_RADIUS = 0.02
BUTTON_HALF_HEIGHT = 0.008
BUTTON_TRAVEL = 0.015

LIFT_SUCCESS_HEIGHT = 0.08
PUSH_SUCCESS_RADIUS = 0.03
PLACE_SUCCESS_RADIUS = 0.03
BUTTON_SUCCESS_DEPTH = 0.01

PLACEMENT_RANGES = {
    # x, y, yaw
    "lift-cube": (np.array([0.33, -0.15, -math.pi / 4]), np.array([0.55, 0.15, math.pi / 4])),
    # block x, y, yaw, target x, y
    "push-block": (
        np.array([0.36, -0.12, -math.pi / 4, 0.32, -0.2]),
        np.array([0.54, 0.12, math.pi / 4, 0.58, 0.2]),
    ),
    "press-button": (np.array([0.33, -0.15, -math.pi / 4]), np.array([0.55, 0.15, math.pi / 4])),
    # cube x, y, yaw, target x, y
    "pick-place": (
        np.array([0.35, -0.15, -math.pi / 4, 0.33, -0.18]),
        np.array([0.55, 0.15, math.pi / 4, 0.57, 0.18]),
    ),
}
PLACE_MIN_DISTANCE = 0.10
PUSH_MIN_DISTANCE = 0.10
PUSH_MAX_DISTANCE = 0.22


# --------------------------------------------------------------------------------------------------
# small rotation helpers (numpy, quaternions wxyz)
# --------------------------------------------------------------------------------------------------
def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def quat_from_rotvec(r: np.ndarray) -> np.ndarray:
    r = np.asarray(r, dtype=np.float64)
    angle = float(np.linalg.norm(r))
    if angle < 1e-12:
        return np.array([1.0, 0.5 * r[0], 0.5 * r[1], 0.5 * r[2]]) / np.sqrt(1 + 0.25 * angle**2)
    axis = r / angle
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * axis])


def quat_to_rotvec(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q)
    if q[0] < 0:
        q = -q
    s = float(np.linalg.norm(q[1:]))
    if s < 1e-12:
        return 2.0 * q[1:]
    return 2.0 * math.atan2(s, q[0]) * q[1:] / s


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    import mujoco

    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, np.asarray(q, dtype=np.float64) / np.linalg.norm(q))
    return m.reshape(3, 3)


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    import mujoco

    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.asarray(R, dtype=np.float64).reshape(9))
    return q


def yaw_quat(yaw: float) -> np.ndarray:
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def canonical_ee_quat(q: np.ndarray) -> np.ndarray:
    """Unit quaternion with the sign that makes its dot product with :data:`HOME_QUAT` non-negative."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q)
    return -q if float(q @ HOME_QUAT) < 0 else q


def _lookat_xyaxes(pos: Sequence[float], target: Sequence[float]) -> list[float]:
    f = np.asarray(target, float) - np.asarray(pos, float)
    f /= np.linalg.norm(f)
    right = np.cross(f, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, f)
    return [*right.tolist(), *up.tolist()]


# --------------------------------------------------------------------------------------------------
# operational-space controller (port of gym_hil.controllers.opspace, MuJoCo 3 and 4)
# --------------------------------------------------------------------------------------------------
def full_inertia(model, data, out: np.ndarray) -> np.ndarray:
    """Dense joint-space inertia matrix (MuJoCo >= 3.5 / 4: ``mj_fullM(m, d, dst)``; older:
    ``mj_fullM(m, dst, d.qM)``)."""
    import mujoco

    if hasattr(data, "qM"):
        mujoco.mj_fullM(model, out, data.qM)
    else:
        mujoco.mj_fullM(model, data, out)
    return out


def _quat_err_axisangle(quat: np.ndarray, quat_des: np.ndarray) -> np.ndarray:
    """Rotation vector of quat * quat_des^-1 (gym-hil's ``quat_to_axisangle(quat_diff_active(...))``)."""
    conj = np.array([quat_des[0], -quat_des[1], -quat_des[2], -quat_des[3]])
    qe = quat_mul(quat, conj)
    n = np.linalg.norm(qe)
    if n < 1e-10:
        return np.zeros(3)
    qe = qe / n
    angle = 2.0 * math.acos(min(1.0, max(-1.0, qe[0])))
    s = math.sqrt(max(0.0, 1.0 - qe[0] * qe[0]))
    if s < 1e-10:
        return angle * qe[1:]
    return angle * qe[1:] / s


def opspace(
    model,
    data,
    site_id: int,
    dof_ids: np.ndarray,
    pos: np.ndarray | None = None,
    ori: np.ndarray | None = None,
    joint: np.ndarray | None = None,
    pos_gains=(200.0, 200.0, 200.0),
    ori_gains=(200.0, 200.0, 200.0),
    damping_ratio: float = 1.0,
    nullspace_stiffness: float = 0.5,
    max_pos_acceleration: float | None = None,
    max_ori_acceleration: float | None = None,
    gravity_comp: bool = True,
    _buffers: dict | None = None,
) -> np.ndarray:
    """Joint torques of gym-hil's operational-space controller (``gym_hil.controllers.opspace.opspace``:
    same signature, gains and equations: task-space PD on the site pose, critically damped, null-space PD
    towards ``joint``, gravity compensation), for MuJoCo 3 and 4 (gym-hil 0.1.14 reads ``data.qM``,
    which MuJoCo 4 removed). ``ori``: wxyz quaternion or 3x3 matrix."""
    import mujoco

    dof_ids = np.asarray(dof_ids)
    x_des = data.site_xpos[site_id] if pos is None else np.asarray(pos)
    if ori is None:
        quat_des = matrix_to_quat(data.site_xmat[site_id])
    else:
        ori = np.asarray(ori, dtype=np.float64)
        quat_des = matrix_to_quat(ori) if ori.shape == (3, 3) else ori
    q_des = data.qpos[dof_ids] if joint is None else np.asarray(joint)
    kp_p = np.asarray(pos_gains, dtype=np.float64)
    kd_p = damping_ratio * 2 * np.sqrt(kp_p)
    kp_o = np.asarray(ori_gains, dtype=np.float64)
    kd_o = damping_ratio * 2 * np.sqrt(kp_o)
    kp_j = nullspace_stiffness
    kd_j = damping_ratio * 2 * math.sqrt(nullspace_stiffness)
    b = _buffers if _buffers is not None else {}
    if "Jv" not in b:
        b["Jv"], b["Jw"] = np.zeros((3, model.nv)), np.zeros((3, model.nv))
        b["M"], b["ix"] = np.zeros((model.nv, model.nv)), np.ix_(dof_ids, dof_ids)

    q, dq = data.qpos[dof_ids], data.qvel[dof_ids]
    mujoco.mj_jacSite(model, data, b["Jv"], b["Jw"], site_id)
    J_v, J_w = b["Jv"][:, dof_ids], b["Jw"][:, dof_ids]
    J = np.concatenate([J_v, J_w], axis=0)
    ddx = -kp_p * (data.site_xpos[site_id] - x_des)
    if max_pos_acceleration and np.linalg.norm(ddx) > max_pos_acceleration:
        ddx *= max_pos_acceleration / np.linalg.norm(ddx)
    ddx -= kd_p * (J_v @ dq)
    cur = matrix_to_quat(data.site_xmat[site_id])
    if cur @ quat_des < 0.0:
        cur = -cur
    dw = -kp_o * _quat_err_axisangle(cur, quat_des)
    if max_ori_acceleration and np.linalg.norm(dw) > max_ori_acceleration:
        dw *= max_ori_acceleration / np.linalg.norm(dw)
    dw -= kd_o * (J_w @ dq)
    M = full_inertia(model, data, b["M"])[b["ix"]]
    M_inv = np.linalg.inv(M)
    Mx_inv = J @ M_inv @ J.T
    Mx = np.linalg.inv(Mx_inv) if abs(np.linalg.det(Mx_inv)) >= 1e-2 else np.linalg.pinv(Mx_inv, rcond=1e-2)
    tau = J.T @ Mx @ np.concatenate([ddx, dw])
    ddq = -kp_j * (q - q_des) - kd_j * dq
    Jnull = M_inv @ J.T @ Mx
    tau += (np.eye(len(dof_ids)) - J.T @ Jnull.T) @ ddq
    if gravity_comp:
        tau += data.qfrc_bias[dof_ids]
    return tau


class OpSpaceController:
    """:func:`opspace` with gym-hil's default gains for one site, null-space target ``home``."""

    def __init__(self, model, site_id: int, dof_ids: np.ndarray, home: np.ndarray):
        self.model, self.site_id = model, int(site_id)
        self.dof_ids, self.home = np.asarray(dof_ids), np.asarray(home, dtype=np.float64)
        self._buffers: dict = {}

    def torques(self, data, pos: np.ndarray, quat: np.ndarray) -> np.ndarray:
        return opspace(
            self.model, data, self.site_id, self.dof_ids, pos=pos, ori=quat, joint=self.home,
            _buffers=self._buffers,
        )  # fmt: skip


_GYM_HIL_PATCHED = False


def patch_gym_hil_for_mujoco() -> None:
    """Make gym-hil 0.1.14's own envs (``gym_hil/PandaPickCube*``, LeRobot's ``gym_manipulator``) step on
    MuJoCo 4, where ``MjData.qM`` is gone: its ``opspace`` is replaced by :func:`opspace` (same
    signature and result). Idempotent; a no-op without gym-hil or on MuJoCo versions that have ``qM``."""
    global _GYM_HIL_PATCHED
    if _GYM_HIL_PATCHED or importlib.util.find_spec("gym_hil") is None:
        return
    import mujoco

    if hasattr(mujoco.MjData(mujoco.MjModel.from_xml_string("<mujoco/>")), "qM"):
        _GYM_HIL_PATCHED = True
        return
    import sys

    import gym_hil.controllers
    import gym_hil.mujoco_gym_env

    sys.modules["gym_hil.controllers.opspace"].opspace = opspace  # the package attribute is the function
    gym_hil.controllers.opspace = opspace
    gym_hil.mujoco_gym_env.opspace = opspace
    _GYM_HIL_PATCHED = True


# --------------------------------------------------------------------------------------------------
# scene
# --------------------------------------------------------------------------------------------------
def gym_hil_assets_dir() -> Path:
    spec = importlib.util.find_spec("gym_hil")
    if spec is None or spec.origin is None:
        raise ImportError(f"the Panda suite needs gym-hil's MuJoCo assets: {INSTALL_HINT}")
    d = Path(spec.origin).parent / "assets"
    if not (d / "panda.xml").exists():
        raise FileNotFoundError(f"{d / 'panda.xml'} not found: reinstall gym-hil ({INSTALL_HINT})")
    return d


#: face caps of the visual meshes (software OpenGL draws gym-hil's 190k-face arm at about 40 ms per
#: 128x128 image on a CPU; with these caps, 35k faces, about 12 ms). None keeps the original meshes.
MESH_FACE_CAPS = {"robotiq_2f85": 3000, "franka_emika_panda": 1000}
_ASSETS: dict[bool, dict[str, bytes]] = {}
_MODEL_CACHE: dict[tuple, Any] = {}


def decimate_mesh(v: np.ndarray, f: np.ndarray, max_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertex clustering on a grid whose cell grows until the mesh has at most ``max_faces`` faces
    (deterministic, numpy only)."""
    v = np.asarray(v, np.float64)
    f = np.asarray(f, np.int64)
    if len(f) <= max_faces:
        return v, f
    e1, e2 = v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
    area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1).sum()
    cell = math.sqrt(2.0 * area / max_faces)
    lo = v.min(0)
    for _ in range(60):
        k = np.floor((v - lo) / cell).astype(np.int64)
        dims = k.max(0) + 1
        uniq, inv = np.unique((k[:, 0] * dims[1] + k[:, 1]) * dims[2] + k[:, 2], return_inverse=True)
        inv = inv.reshape(-1)
        n = len(uniq)
        nf = inv[f]
        nf = nf[(nf[:, 0] != nf[:, 1]) & (nf[:, 1] != nf[:, 2]) & (nf[:, 0] != nf[:, 2])]
        srt = np.sort(nf, axis=1)
        _, first = np.unique((srt[:, 0] * n + srt[:, 1]) * n + srt[:, 2], return_index=True)
        nf = nf[np.sort(first)]
        if len(nf) <= max_faces:
            break
        cell *= 1.15
    cnt = np.bincount(inv, minlength=n).astype(np.float64)
    nv = np.stack([np.bincount(inv, weights=v[:, i], minlength=n) for i in range(3)], 1) / cnt[:, None]
    used = np.unique(nf)
    remap = -np.ones(n, np.int64)
    remap[used] = np.arange(len(used))
    return nv[used], remap[nf]


def _assets(simplify: bool = True) -> dict[str, bytes]:
    """gym-hil's asset files (``panda.xml`` and meshes) by relative path; with ``simplify`` the visual
    meshes (Panda ``.obj`` parts, Robotiq ``.stl`` parts) are decimated to :data:`MESH_FACE_CAPS`."""
    if simplify not in _ASSETS:
        root = gym_hil_assets_dir()
        assets = {
            p.relative_to(root).as_posix(): p.read_bytes()
            for p in root.rglob("*")
            if p.is_file() and p.suffix.lower() in (".xml", ".stl", ".obj", ".png")
        }
        if simplify:
            import io

            import trimesh

            for key, raw in list(assets.items()):
                folder, ext = key.split("/", 1)[0], key.rsplit(".", 1)[-1].lower()
                cap = MESH_FACE_CAPS.get(folder)
                panda_collision = folder == "franka_emika_panda" and ext == "stl"  # never drawn
                if cap is None or ext not in ("obj", "stl") or panda_collision:
                    continue
                tm = trimesh.load(io.BytesIO(raw), file_type=ext, force="mesh", process=False)
                if len(tm.faces) <= cap:
                    continue
                v, f = decimate_mesh(tm.vertices, tm.faces, cap)
                out = trimesh.Trimesh(v, f, process=False).export(file_type=ext)
                assets[key] = out.encode() if isinstance(out, str) else out
        _ASSETS[simplify] = assets
    return _ASSETS[simplify]


def _task_xml(task: str) -> str:
    if task in ("lift-cube", "pick-place"):
        h = CUBE_HALF
        target = "" if task == "lift-cube" else f"""
    <body name="target_marker" pos="0.45 0.1 0">
      <geom name="target_marker" type="cylinder" size="{TARGET_RADIUS + 0.01} 0.0005" pos="0 0 0.0005"
            contype="0" conaffinity="0" rgba=".1 .8 .2 1"/>
    </body>"""
        return target + f"""
    <body name="cube" pos="0.45 0 {h}">
      <freejoint name="cube"/>
      <geom name="cube" type="box" size="{h} {h} {h}" mass="0.1" rgba=".6 .3 .6 1"/>
    </body>"""
    if task == "push-block":
        bx, by, bz = BLOCK_HALF
        return f"""
    <body name="target_marker" pos="0.45 0.1 0">
      <geom name="target_marker" type="cylinder" size="{TARGET_RADIUS} 0.0005" pos="0 0 0.0005"
            contype="0" conaffinity="0" rgba=".1 .8 .2 1"/>
    </body>
    <body name="block" pos="0.45 0 {bz}">
      <freejoint name="block"/>
      <geom name="block" type="box" size="{bx} {by} {bz}" mass="0.15" rgba=".15 .35 .85 1"/>
    </body>"""
    if task == "press-button":
        hx, hy, hz = BUTTON_HOUSING_HALF
        return f"""
    <body name="button_box" pos="0.45 0 0">
      <geom name="button_box" type="box" size="{hx} {hy} {hz}" pos="0 0 {hz}" rgba=".35 .35 .38 1"/>
      <body name="button" pos="0 0 {2 * hz}">
        <joint name="button" type="slide" axis="0 0 1" range="-{BUTTON_TRAVEL} 0" limited="true"
               stiffness="40" springref="0.01" damping="2"/>
        <geom name="button" type="cylinder" size="{BUTTON_RADIUS} {BUTTON_HALF_HEIGHT}"
              pos="0 0 {BUTTON_HALF_HEIGHT}" mass="0.02" rgba=".85 .1 .1 1"/>
      </body>
    </body>"""
    raise ValueError(task)


def _task_contact_xml(task: str) -> str:
    if task == "press-button":  # the housing is static (part of the world): not filtered as a parent
        return '<contact><exclude body1="button_box" body2="button"/></contact>'
    return ""


def scene_xml(
    task: str, offscreen_size: int = 640, front_pos=FRONT_CAMERA_POS, front_lookat=FRONT_CAMERA_LOOKAT
) -> str:
    """MJCF of a task scene (includes gym-hil's ``panda.xml``; load with :func:`build_model`)."""
    xy = " ".join(f"{v:.6f}" for v in _lookat_xyaxes(front_pos, front_lookat))
    fp = " ".join(f"{v:.6f}" for v in front_pos)
    return f"""<mujoco model="rnd_panda_{task}">
  <include file="panda.xml"/>
  <option timestep="{PHYSICS_DT}" noslip_iterations="5" noslip_tolerance="0"/>
  <statistic center="0.4 0 0.2" extent="0.8"/>
  <visual>
    <headlight diffuse=".4 .4 .4" ambient=".4 .4 .4"/>
    <global azimuth="160" elevation="-20" offwidth="{offscreen_size}" offheight="{offscreen_size}"/>
    <quality offsamples="0"/>
  </visual>
  <asset>
    <texture type="skybox" builtin="gradient" rgb1=".3 .5 .7" rgb2="0 0 0" width="32" height="512"/>
    <texture name="grid" type="2d" builtin="checker" width="512" height="512"
             rgb1=".1 .2 .3" rgb2=".2 .3 .4"/>
    <material name="grid" texture="grid" texrepeat="2 2" texuniform="true" reflectance="0"/>
  </asset>
  <worldbody>
    <camera name="front" pos="{fp}" xyaxes="{xy}" fovy="{FRONT_CAMERA_FOVY}"/>
    <light pos="0 0 3" dir="0 0 -1" diffuse=".6 .6 .6" specular=".3 .3 .3"/>
    <light pos="1.2 -0.5 1.0" dir="-0.7 0.4 -0.6" diffuse=".6 .6 .6" specular=".2 .2 .2"/>
    <geom name="floor" size="3 3 0.01" type="plane" material="grid"/>
    <body name="ee_target" pos="{START_POS[0]} {START_POS[1]} {START_POS[2]}" quat="0 1 0 0" mocap="true"/>
    {_task_xml(task)}
  </worldbody>
  {_task_contact_xml(task)}
</mujoco>
"""


def build_model(task: str = "lift-cube", offscreen_size: int = 640, simplify_meshes: bool = True):
    """A fresh ``mujoco.MjModel`` of the task scene (compiled once per process, then copied)."""
    import mujoco

    task = _check_task(task)
    key = (task, int(offscreen_size), bool(simplify_meshes))
    if key not in _MODEL_CACHE:
        _MODEL_CACHE[key] = mujoco.MjModel.from_xml_string(
            scene_xml(task, offscreen_size), _assets(bool(simplify_meshes))
        )
    return copy.deepcopy(_MODEL_CACHE[key])


def _check_task(task: str) -> str:
    if task not in PANDA_TASKS:
        raise ValueError(f"unknown Panda task {task!r}; tasks: {', '.join(PANDA_TASKS)}")
    return task


# --------------------------------------------------------------------------------------------------
# The env
# --------------------------------------------------------------------------------------------------
class RnDPandaEnv(gym.Env):
    """Panda + Robotiq tabletop task with multi-camera pixels + EE state (see the module docstring).

    Args:
        task: one of :data:`PANDA_TASKS`.
        camera_names: cameras to observe ("front", "wrist").
        observation_height, observation_width: image size.
        episode_length: steps before truncation.
        placement: "random" (seeded, from the task's range) or "fixed" (cycle through ``placements``).
        placements: list of placement vectors for "fixed".
        terminate_on_success: end the episode at the first success.
        fast_render: no multisampling, shadows or reflections.
        render_mode: "rgb_array"; ``render()`` returns the last observation's images side by side, or a
            ``visualization_height`` x ``visualization_width`` render of ``render_camera`` when set.
        control_dt: seconds per step (physics at 2 ms).
        pos_scale, rot_scale: metres / radians per action unit and step.
        simplify_meshes: draw decimated arm / gripper meshes (:data:`MESH_FACE_CAPS`, 3-4x faster on
            software OpenGL); the gripper meshes of :meth:`embodiment` are taken from the same model.
    """

    metadata: ClassVar[dict] = {"render_modes": ["rgb_array"], "render_fps": PANDA_FPS}

    def __init__(
        self,
        task: str = "lift-cube",
        camera_names: Sequence[str] = DEFAULT_CAMERAS,
        observation_height: int = 128,
        observation_width: int = 128,
        episode_length: int = 100,
        placement: str = "random",
        placements: Sequence[Sequence[float]] | None = None,
        terminate_on_success: bool = True,
        fast_render: bool = True,
        render_mode: str | None = "rgb_array",
        render_camera: str | None = None,
        visualization_height: int | None = None,
        visualization_width: int | None = None,
        obs_type: str = "pixels_agent_pos",
        control_dt: float = CONTROL_DT,
        pos_scale: float = POS_SCALE,
        rot_scale: float = ROT_SCALE,
        simplify_meshes: bool = True,
    ):
        super().__init__()
        import mujoco

        self.task = _check_task(task)
        self.task_description = TASK_DESCRIPTIONS[self.task]
        if obs_type != "pixels_agent_pos":
            raise ValueError(f"obs_type must be 'pixels_agent_pos', got {obs_type!r}")
        self.obs_type = obs_type
        self.state_names = list(STATE_NAMES)
        self.camera_names = tuple(camera_names)
        if not self.camera_names:
            raise ValueError("camera_names is empty")
        for c in self.camera_names:
            if c not in MUJOCO_CAMERAS:
                raise ValueError(f"unknown camera {c!r}; cameras: {list(MUJOCO_CAMERAS)}")
        self.image_size = (int(observation_height), int(observation_width))
        if int(episode_length) <= 0:
            raise ValueError(f"episode_length must be positive, got {episode_length}")
        self._max_episode_steps = int(episode_length)
        if placement not in ("random", "fixed"):
            raise ValueError(f"placement must be 'random' or 'fixed', got {placement!r}")
        self.placement_mode = placement
        self.placements = (
            None if placements is None else [np.asarray(p, dtype=np.float64) for p in placements]
        )
        if placement == "fixed" and not self.placements:
            raise ValueError("placement='fixed' needs a non-empty list of placements")
        self.terminate_on_success = bool(terminate_on_success)
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be 'rgb_array' or None, got {render_mode!r}")
        self.render_mode = render_mode
        self.render_camera = render_camera or self.camera_names[0]
        if self.render_camera not in MUJOCO_CAMERAS:
            raise ValueError(f"unknown render camera {self.render_camera!r}; cameras: {list(MUJOCO_CAMERAS)}")
        self.visualization_size = (
            None if visualization_height is None or visualization_width is None
            else (int(visualization_height), int(visualization_width))
        )  # fmt: skip
        self.control_dt = float(control_dt)
        self.n_substeps = max(1, int(round(self.control_dt / PHYSICS_DT)))
        self.pos_scale, self.rot_scale = float(pos_scale), float(rot_scale)
        self.metadata = {**self.metadata, "render_fps": int(round(1.0 / self.control_dt))}

        sizes = [*self.image_size, *(self.visualization_size or ())]
        self.simplify_meshes = bool(simplify_meshes)
        self.model = build_model(
            self.task, offscreen_size=max(640, *sizes), simplify_meshes=self.simplify_meshes
        )
        self.data = mujoco.MjData(self.model)
        self.fast_render = bool(fast_render)
        if self.fast_render:
            self.model.vis.quality.offsamples = 0
        m = self.model
        self._site = m.site(EE_SITE).id
        self._dof = np.array([m.joint(f"joint{i}").dofadr[0] for i in range(1, 8)])
        self._qadr = np.array([m.joint(f"joint{i}").qposadr[0] for i in range(1, 8)])
        self._arm_act = np.array([m.actuator(f"actuator{i}").id for i in range(1, 8)])
        self._grip_act = m.actuator("fingers_actuator").id
        self._drivers = np.array([m.joint(n).qposadr[0] for n in ("right_driver_joint", "left_driver_joint")])
        self._mocap = int(m.body_mocapid[m.body("ee_target").id])
        self.controller = OpSpaceController(m, self._site, self._dof, PANDA_HOME)
        self._renderers: dict[tuple[int, int], Any] = {}
        self._fixed_cursor = 0
        self._steps = 0
        self._ready = False
        self._last_pixels: dict[str, np.ndarray] | None = None
        self._placement: np.ndarray | None = None
        self._object_z0 = 0.0
        self._start_qpos = self._settled_start_qpos()

        H, W = self.image_size
        self.observation_space = spaces.Dict(
            {
                "pixels": spaces.Dict(
                    {c: spaces.Box(0, 255, shape=(H, W, 3), dtype=np.uint8) for c in self.camera_names}
                ),
                "agent_pos": spaces.Box(-np.inf, np.inf, shape=(len(self.state_names),), dtype=np.float32),
            }
        )
        self.action_space = spaces.Box(-1.0, 1.0, shape=(7,), dtype=np.float32)

    # ------------------------------------------------------------------ start pose
    def _settled_start_qpos(self) -> np.ndarray:
        """Joint positions with the EE at rest at START_POS / HOME_QUAT, gripper open (computed once by
        running the controller from gym-hil's home for 1.5 s)."""
        import mujoco

        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[self._qadr] = PANDA_HOME
        d.mocap_pos[self._mocap] = START_POS
        d.mocap_quat[self._mocap] = HOME_QUAT
        mujoco.mj_forward(m, d)
        for _ in range(int(1.5 / PHYSICS_DT)):
            self._control_substep()
        q = d.qpos.copy()
        return q

    # ------------------------------------------------------------------ placements
    @property
    def placement_space(self) -> spaces.Box:
        low, high = PLACEMENT_RANGES[self.task]
        return spaces.Box(low, high, dtype=np.float64)

    @property
    def placement(self) -> np.ndarray | None:
        return None if self._placement is None else self._placement.copy()

    def sample_placement(self, rng: np.random.Generator | None = None) -> np.ndarray:
        """A uniform placement from the task's range (not checked; see :meth:`is_valid_placement`)."""
        rng = self.np_random if rng is None else rng
        low, high = PLACEMENT_RANGES[self.task]
        return rng.uniform(low, high).astype(np.float64)

    def is_valid_placement(self, placement: Sequence[float]) -> bool:
        """Whether the placement has the right size, lies in the range (1 mm tolerance), and (push-block)
        the target is 10-22 cm from the block with the pushing start point inside the workspace /
        (pick-place) at least 10 cm from the cube."""
        vec = np.asarray(placement, dtype=np.float64)
        low, high = PLACEMENT_RANGES[self.task]
        if vec.shape != low.shape or not np.all(np.isfinite(vec)):
            return False
        if np.any(vec < low - 1e-3) or np.any(vec > high + 1e-3):
            return False
        if self.task == "push-block":
            d = vec[3:5] - vec[0:2]
            dist = float(np.linalg.norm(d))
            if not PUSH_MIN_DISTANCE <= dist <= PUSH_MAX_DISTANCE:
                return False
            start = vec[0:2] - d / dist * 0.08
            lo, hi = WORKSPACE_BOUNDS[0, :2] + 0.02, WORKSPACE_BOUNDS[1, :2] - 0.02
            if np.any(start < lo) or np.any(start > hi):
                return False
        if self.task == "pick-place" and np.linalg.norm(vec[3:5] - vec[0:2]) < PLACE_MIN_DISTANCE:
            return False
        return True

    def _check_placement(self, vec: np.ndarray) -> np.ndarray:
        low = PLACEMENT_RANGES[self.task][0]
        if vec.shape != low.shape:
            raise ValueError(
                f"{self.task}: placement must have {low.shape[0]} numbers, got shape {vec.shape}"
            )
        if not self.is_valid_placement(vec):
            low, high = PLACEMENT_RANGES[self.task]
            raise ValueError(
                f"{self.task}: invalid placement {vec.tolist()} (range {low.tolist()} .. {high.tolist()}"
                + {
                    "push-block": f", block-target distance {PUSH_MIN_DISTANCE}-{PUSH_MAX_DISTANCE} m)",
                    "pick-place": f", cube-target distance >= {PLACE_MIN_DISTANCE} m)",
                }.get(self.task, ")")
            )
        return vec

    def _apply_placement(self, vec: np.ndarray) -> None:
        m, d = self.model, self.data
        if self.task in ("lift-cube", "pick-place"):
            adr = m.joint("cube").qposadr[0]
            d.qpos[adr : adr + 3] = [vec[0], vec[1], CUBE_HALF]
            d.qpos[adr + 3 : adr + 7] = yaw_quat(vec[2])
            if self.task == "pick-place":
                m.body_pos[m.body("target_marker").id] = [vec[3], vec[4], 0.0]
        elif self.task == "push-block":
            adr = m.joint("block").qposadr[0]
            d.qpos[adr : adr + 3] = [vec[0], vec[1], BLOCK_HALF[2]]
            d.qpos[adr + 3 : adr + 7] = yaw_quat(vec[2])
            m.body_pos[m.body("target_marker").id] = [vec[3], vec[4], 0.0]
        elif self.task == "press-button":
            b = m.body("button_box").id
            m.body_pos[b] = [vec[0], vec[1], 0.0]
            m.body_quat[b] = yaw_quat(vec[2])

    # ------------------------------------------------------------------ gym API
    def reset(self, seed: int | None = None, options: dict | None = None):
        import mujoco

        super().reset(seed=seed)
        options = options or {}
        explicit = options.get("placement")
        if explicit is not None:
            vec = self._check_placement(np.asarray(explicit, dtype=np.float64))
        elif self.placement_mode == "fixed":
            vec = self._check_placement(self.placements[self._fixed_cursor % len(self.placements)])
            self._fixed_cursor += 1
        else:
            for _ in range(10000):
                vec = self.sample_placement()
                if self.is_valid_placement(vec):
                    break
            else:  # pragma: no cover
                raise RuntimeError(f"{self.task}: no valid placement found")
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qpos[:] = self._start_qpos
        d.mocap_pos[self._mocap] = START_POS
        d.mocap_quat[self._mocap] = HOME_QUAT
        d.ctrl[self._grip_act] = 0.0
        self._apply_placement(vec)
        mujoco.mj_forward(m, d)
        for _ in range(int(0.1 / PHYSICS_DT)):  # let contacts settle
            self._control_substep()
        self._placement = vec.copy()
        self._object_z0 = float(self.object_pos()[2]) if self.task != "press-button" else 0.0
        self._steps = 0
        self._ready = True
        return self._observation(), {"is_success": False, "task": self.task}

    def _control_substep(self) -> None:
        import mujoco

        d = self.data
        tau = self.controller.torques(d, d.mocap_pos[self._mocap], d.mocap_quat[self._mocap])
        d.ctrl[self._arm_act] = tau
        mujoco.mj_step(self.model, d)

    def apply_action(self, action: np.ndarray) -> None:
        """Move the mocap target and set the gripper command (see the module docstring), no stepping."""
        a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        d = self.data
        d.mocap_pos[self._mocap] = np.clip(
            d.mocap_pos[self._mocap] + self.pos_scale * a[:3], WORKSPACE_BOUNDS[0], WORKSPACE_BOUNDS[1]
        )
        q = quat_mul(quat_from_rotvec(self.rot_scale * a[3:6]), d.mocap_quat[self._mocap])
        d.mocap_quat[self._mocap] = q / np.linalg.norm(q)
        d.ctrl[self._grip_act] = MAX_GRIPPER_COMMAND * 0.5 * (a[6] + 1.0)

    def step(self, action):
        action = np.asarray(action, dtype=np.float32)
        if action.shape != (7,):
            raise ValueError(f"expected a (7,) action, got shape {action.shape}")
        if not self._ready:
            raise RuntimeError("call reset() before step()")
        self.apply_action(action)
        for _ in range(self.n_substeps):
            self._control_substep()
        self._steps += 1
        is_success = self.success_now
        terminated = is_success and self.terminate_on_success
        truncated = (not terminated) and self._steps >= self._max_episode_steps
        obs = self._observation()
        return obs, float(is_success), terminated, truncated, {"is_success": is_success, "task": self.task}

    def render(self):
        if self.render_mode is None:
            return None
        if self.visualization_size is None:
            if self._last_pixels is None:
                return np.zeros((*self.image_size, 3), dtype=np.uint8)
            return np.concatenate([self._last_pixels[c] for c in self.camera_names], axis=1)
        return self.render_camera_image(self.render_camera, self.visualization_size)

    def close(self):
        for r in self._renderers.values():
            try:
                r.close()
            except Exception as e:  # noqa: BLE001
                logger.debug("closing a MuJoCo renderer failed: %s", e)
        self._renderers.clear()

    # ------------------------------------------------------------------ state and task quantities
    @property
    def steps(self) -> int:
        """Steps taken since the last reset."""
        return self._steps

    def ee_pose(self) -> np.ndarray:
        """World-from-EE (site ``pinch``) 4x4 pose."""
        T = np.eye(4)
        T[:3, :3] = np.asarray(self.data.site_xmat[self._site]).reshape(3, 3)
        T[:3, 3] = self.data.site_xpos[self._site]
        return T

    def mocap_pose(self) -> np.ndarray:
        """World-from-target 4x4 pose of the controller's target (what the actions move)."""
        T = np.eye(4)
        T[:3, :3] = quat_to_matrix(self.data.mocap_quat[self._mocap])
        T[:3, 3] = self.data.mocap_pos[self._mocap]
        return T

    def gripper_opening(self) -> float:
        q = float(np.mean(self.data.qpos[self._drivers]))
        return float(np.clip(1.0 - q / DRIVER_CLOSED, 0.0, 1.0))

    def state(self) -> np.ndarray:
        d = self.data
        pos = np.asarray(d.site_xpos[self._site], dtype=np.float64)
        q = canonical_ee_quat(matrix_to_quat(d.site_xmat[self._site]))
        return np.concatenate([pos, q, [self.gripper_opening()]]).astype(np.float32)

    def object_pos(self) -> np.ndarray:
        """Centre of the cube / block, or (press-button) the centre of the button's top face when not
        pressed, in the world."""
        d = self.data
        if self.task in ("lift-cube", "pick-place"):
            return d.body("cube").xpos.copy()
        if self.task == "push-block":
            return d.body("block").xpos.copy()
        top = 2 * (BUTTON_HOUSING_HALF[2] + BUTTON_HALF_HEIGHT)
        return d.body("button_box").xpos.copy() + np.array([0.0, 0.0, top])

    def object_quat(self) -> np.ndarray:
        d = self.data
        name = {"push-block": "block", "press-button": "button_box"}.get(self.task, "cube")
        return d.body(name).xquat.copy()

    def target_pos(self) -> np.ndarray | None:
        """push-block / pick-place: the target disc centre (on the table)."""
        if self.task not in ("push-block", "pick-place"):
            return None
        return self.data.body("target_marker").xpos.copy()

    def button_depth(self) -> float:
        """press-button: how far the button is pressed down (m, >= 0)."""
        if self.task != "press-button":
            return 0.0
        return float(-self.data.joint("button").qpos[0])

    @property
    def success_now(self) -> bool:
        if self.task == "lift-cube":
            return bool(self.object_pos()[2] - self._object_z0 > LIFT_SUCCESS_HEIGHT)
        if self.task == "push-block":
            return bool(np.linalg.norm(self.object_pos()[:2] - self.target_pos()[:2]) < PUSH_SUCCESS_RADIUS)
        if self.task == "pick-place":
            p = self.object_pos()
            return bool(
                np.linalg.norm(p[:2] - self.target_pos()[:2]) < PLACE_SUCCESS_RADIUS
                and p[2] < CUBE_HALF + 0.005
                and self.gripper_opening() > 0.5
            )
        return self.button_depth() > BUTTON_SUCCESS_DEPTH

    # ------------------------------------------------------------------ rendering
    def _renderer(self, size: tuple[int, int]):
        r = self._renderers.get(size)
        if r is None:
            import mujoco

            r = mujoco.Renderer(self.model, height=size[0], width=size[1])
            if self.fast_render:
                r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = 0
                r.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = 0
            self._renderers[size] = r
        return r

    def render_camera_image(self, camera: str, size: tuple[int, int] | None = None) -> np.ndarray:
        """uint8 (H, W, 3) image of camera ``front`` or ``wrist``."""
        r = self._renderer(tuple(size) if size is not None else self.image_size)
        r.update_scene(self.data, camera=MUJOCO_CAMERAS[camera])
        return r.render()

    def _observation(self) -> dict[str, Any]:
        pixels = {c: self.render_camera_image(c) for c in self.camera_names}
        self._last_pixels = pixels
        return {"pixels": pixels, "agent_pos": self.state()}

    # ------------------------------------------------------------------ calibration
    def embodiment(self, max_faces: int = GRIPPER_MESH_FACES):
        """The :class:`~lerobot_rnd.embodiment.Embodiment` matching this env's cameras, state and action."""
        return panda_embodiment(
            self.camera_names, self.image_size, max_faces=max_faces, model=self.model,
            pos_scale=self.pos_scale, rot_scale=self.rot_scale,
            notes_extra=f"{GYM_NAMESPACE}/{self.task}, control_dt {self.control_dt} s",
        )  # fmt: skip


# --------------------------------------------------------------------------------------------------
# embodiment
# --------------------------------------------------------------------------------------------------
def panda_ee_pose_source():
    """EE pose source for the 8-D state [ee xyz, ee quat wxyz, gripper opening (1 open, 0 closed)]."""
    from lerobot_rnd.embodiment import EEPoseSource

    return EEPoseSource(
        format="quat_wxyz", position_indices=[0, 1, 2], rotation_indices=[3, 4, 5, 6], gripper_index=7,
        gripper_open_value=1.0, gripper_closed_value=0.0,
    )  # fmt: skip


def panda_action_adapter(pos_scale: float = POS_SCALE, rot_scale: float = ROT_SCALE) -> dict[str, Any]:
    """Action adapter spec of the 7-D action: world-frame step deltas of the EE target, gripper -1 open /
    +1 closed, clipped to [-1, 1]."""
    from lerobot_rnd.action_adapters import EEDeltaAdapter

    return EEDeltaAdapter(
        pos_scale=pos_scale, rot_scale=rot_scale, frame="world", clip=1.0, gripper_open=-1.0,
        gripper_closed=1.0,
    ).to_dict()  # fmt: skip


def panda_gripper_meshes(model=None, max_faces: int = GRIPPER_MESH_FACES) -> dict:
    """Robotiq 2F-85 meshes in the EE (``pinch`` site) frame, open gripper (qpos0 = open).

    "full": body ``base_mount`` subtree (mount, base, both finger linkages and pads); "fingers": the two
    fingers (follower links and pads, :data:`FINGER_BODIES`), drawn in the wrist camera, which sees the
    finger tips (the linkages next to the camera would cover much of its image when drawn at future
    poses)."""
    from lerobot_rnd.embodiment import GripperMesh

    if model is None:
        model = build_model("lift-cube")
    full = GripperMesh.from_mjcf_body(model, GRIPPER_ROOT_BODY, ee_site=EE_SITE, name="full")
    fingers = GripperMesh.concatenate(
        [GripperMesh.from_mjcf_body(model, b, ee_site=EE_SITE) for b in FINGER_BODIES], name="fingers"
    )
    return {"full": full.simplified(max_faces), "fingers": fingers.simplified(max_faces)}


def panda_cameras(model, data, camera_names: Sequence[str], image_size: tuple[int, int]) -> dict:
    """Calibrations keyed ``observation.images.<name>``: ``front`` static, ``wrist`` rigid on the EE."""
    from lerobot_rnd.embodiment import camera_from_mujoco

    cams = {}
    for c in camera_names:
        mj = MUJOCO_CAMERAS[c]
        cams[f"observation.images.{c}"] = camera_from_mujoco(
            model, data, mj, image_size, mounted_on_site=EE_SITE if c == "wrist" else None, name=c
        )
    return cams


def panda_embodiment(
    camera_names: Sequence[str] = DEFAULT_CAMERAS,
    image_size: tuple[int, int] = (128, 128),
    max_faces: int = GRIPPER_MESH_FACES,
    model=None,
    pos_scale: float = POS_SCALE,
    rot_scale: float = ROT_SCALE,
    notes_extra: str = "",
):
    """Embodiment of the ``gym_rnd_panda`` envs (identical for all tasks)."""
    import mujoco

    from lerobot_rnd.embodiment import Embodiment

    if model is None:
        model = build_model("lift-cube")
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    cams = panda_cameras(model, data, camera_names, tuple(image_size))
    return Embodiment(
        cameras=cams,
        meshes=panda_gripper_meshes(model, max_faces=max_faces),
        camera_mesh={k: ("fingers" if c.name == "wrist" else "full") for k, c in cams.items()},
        ee_pose_source=panda_ee_pose_source(),
        action_adapter=panda_action_adapter(pos_scale, rot_scale),
        symmetry_axis=1,
        name="panda_robotiq",
        notes=(
            f"Franka Panda + Robotiq 2F-85 (gym-hil {GYM_HIL_VERSION} assets); EE frame = site 'pinch' "
            "(z along the fingers, fingers open along y); state [ee xyz, quat wxyz, gripper opening]; "
            f"cameras {list(camera_names)} at {image_size[0]}x{image_size[1]}; action = world-frame "
            f"EE target deltas ({pos_scale} m, {rot_scale} rad per unit) + gripper (-1 open, +1 closed)"
            + (f"; {notes_extra}" if notes_extra else "")
        ),
    )


# --------------------------------------------------------------------------------------------------
# registration and LeRobot EnvConfig
# --------------------------------------------------------------------------------------------------
def register_gym_envs() -> None:
    """Register ``gym_rnd_panda/<task>`` for every task (idempotent)."""
    from gymnasium.envs.registration import registry

    for task in PANDA_TASKS:
        env_id = f"{GYM_NAMESPACE}/{task}"
        if env_id not in registry:
            gym.register(
                id=env_id, entry_point="lerobot_rnd.sim.panda_env:RnDPandaEnv", kwargs={"task": task}
            )


@EnvConfig.register_subclass("rnd_panda")
@dataclass
class RnDPandaEnvConfig(EnvConfig):
    """``--env.type=rnd_panda``: Panda + Robotiq tabletop tasks (lerobot_rnd.sim.panda_env)."""

    task: str | None = "lift-cube"
    fps: int = PANDA_FPS
    episode_length: int = 100
    obs_type: str = "pixels_agent_pos"
    render_mode: str = "rgb_array"
    camera_names: list[str] = field(default_factory=lambda: list(DEFAULT_CAMERAS))
    observation_height: int = 128
    observation_width: int = 128
    placement: str = "random"
    terminate_on_success: bool = True
    features: dict[str, PolicyFeature] = field(
        default_factory=lambda: {ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(7,))}
    )
    features_map: dict[str, str] = field(default_factory=lambda: {ACTION: ACTION, "agent_pos": OBS_STATE})

    def __post_init__(self):
        self.features["agent_pos"] = PolicyFeature(type=FeatureType.STATE, shape=(len(STATE_NAMES),))
        for cam in self.camera_names:
            self.features[f"pixels/{cam}"] = PolicyFeature(
                type=FeatureType.VISUAL, shape=(self.observation_height, self.observation_width, 3)
            )
            self.features_map[f"pixels/{cam}"] = f"{OBS_IMAGES}.{cam}"

    @property
    def package_name(self) -> str:
        return "lerobot_rnd.sim.panda_env"

    @property
    def gym_id(self) -> str:
        return f"{GYM_NAMESPACE}/{self.task}"

    @property
    def gym_kwargs(self) -> dict:
        return {
            "camera_names": list(self.camera_names),
            "observation_height": self.observation_height,
            "observation_width": self.observation_width,
            "episode_length": self.episode_length,
            "placement": self.placement,
            "terminate_on_success": self.terminate_on_success,
            "render_mode": self.render_mode,
            "obs_type": self.obs_type,
        }


register_gym_envs()
