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
- ``slide-block``: push-block with the target rigid to the block, as RLBench's "slide block to target" (the
  paper's spatial-generalisation task, where block and target are placed as one): the disc lies
  ``panda_scene.SLIDE_DISTANCE`` (10 cm) along the block's local +y axis, so the push direction, and the gripper's yaw,
  turn with the block's yaw (+-45 degrees); the placement is the block's [x, y, yaw] only.
- ``lift-red-cube`` and ``lift-blue-cube``: a red and a blue 4 cm cube, each at a random position and yaw, at least
  :data:`CUBES_MIN_DISTANCE` (12 cm) apart; lift the cube the task names (success as ``lift-cube``, for that cube).
  Both tasks show the same scene, so only the task string tells them apart: the pair of issue 35's multi-task
  comparison, trained together with ``lerobot-rnd-record --suite panda --task lift-red-cube,lift-blue-cube``.

The scene (:mod:`lerobot_rnd.sim.panda_scene`) is gym-hil's Panda with the Robotiq 2F-85
(``gym_hil/assets/panda.xml``, gym-hil 0.1.14 is used only for its assets) plus a floor, lights, a static
``front`` camera, the task objects and a mocap body ``ee_target``. The arm is driven by gym-hil's
operational-space controller (:mod:`lerobot_rnd.sim.opspace`: torques on the 7 joints, a port that also runs
on MuJoCo 4) tracking the pose of ``ee_target``. The embodiment preset ``panda_robotiq`` is defined and
registered here.

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

Cameras: ``front`` (static, in front of the robot looking back at the workspace, fovy 42) and
``wrist`` (gym-hil's ``handcam_rgb`` on the arm's flange: rigid on the hand, fovy widened to 60, sees the finger
tips); ``panda_scene.FRONT_CAMERA_*`` and ``WRIST_CAMERA_FOVY`` say why. Fast rendering: no multisampling, shadows or reflections, decimated arm meshes.

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
cube / button box / slide-block's block; ``push-block`` / ``pick-place``: [block / cube x, y, yaw, target x, y]
(:func:`placement_target_xy` gives every task's target from its placement); ``lift-red-cube`` /
``lift-blue-cube``: [x, y, yaw of the cube to lift, x, y, yaw of the other cube], so the first three numbers are the
task's object in every task, and one seed puts the cube to lift at the same pose in both tasks.
``reset(options={"placement": vec})`` for an exact placement; otherwise ``placement="random"`` draws
from the range with the env's seeded RNG (``reset(seed=...)`` makes it reproducible), or
``placement="fixed"`` cycles through ``placements``.
Episodes start with the gripper open, pointing down, at :data:`START_POS`.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import torch
from gymnasium import spaces
from lerobot.envs.configs import EnvConfig

from lerobot_rnd.arrays import make_pose, mujoco_pose
from lerobot_rnd.embodiment import (
    CameraCalibration,
    EEPoseSource,
    Embodiment,
    GripperMesh,
    camera_from_mujoco,
    register_embodiment_preset,
)
from lerobot_rnd.geometry import quat_wxyz_to_matrix
from lerobot_rnd.sim.mujoco_env import RnDMuJoCoEnv, RnDSimEnvConfig, register_gym_envs
from lerobot_rnd.sim.opspace import OpSpaceController
from lerobot_rnd.sim.panda_scene import (
    BLOCK_HALF,
    BLOCK_TASKS,
    BUTTON_HALF_HEIGHT,
    BUTTON_HOUSING_HALF,
    CUBE_HALF,
    EE_SITE,
    FINGER_BODIES,
    GRIPPER_ROOT_BODY,
    GYM_HIL_VERSION,
    HOME_QUAT,
    MUJOCO_CAMERAS,
    PANDA_TASKS,
    PHYSICS_DT,
    START_POS,
    TWO_CUBE_TASKS,
    build_model,
    check_task,
    placement_target_xy,
)
from lerobot_rnd.sim.quaternions import matrix_to_quat, quat_from_rotvec, quat_mul, yaw_quat

logger = logging.getLogger(__name__)

GYM_NAMESPACE = "gym_rnd_panda"
TASK_DESCRIPTIONS = {
    "lift-cube": "Pick up the purple cube and lift it",
    "push-block": "Push the blue block onto the green target",
    "press-button": "Press the red button",
    "pick-place": "Put the purple cube on the green target",
    "slide-block": "Slide the blue block onto the green target",
    "lift-red-cube": "Pick up the red cube and lift it",
    "lift-blue-cube": "Pick up the blue cube and lift it",
}
DEFAULT_CAMERAS = ("front", "wrist")
STATE_NAMES = ["ee_x", "ee_y", "ee_z", "ee_qw", "ee_qx", "ee_qy", "ee_qz", "gripper_open"]
ACTION_NAMES = ["dx", "dy", "dz", "drx", "dry", "drz", "gripper"]

#: faces of the embodiment's gripper meshes. The Robotiq's thin links need more than the usual 1500
#: with the grid-clustering simplifier (mask IoU vs MuJoCo at 128 px, front "full" / wrist "fingers":
#: 1500 faces 0.82 / 0.91, 2000: 0.87 / 1.0, 4000: 0.96 / 1.0, unsimplified 0.99 / 1.0).
GRIPPER_MESH_FACES = 4000
#: Robotiq driver joint range (0 = open, 0.8 rad = closed)
DRIVER_CLOSED = 0.8
MAX_GRIPPER_COMMAND = 255.0

CONTROL_DT = 0.1
PANDA_FPS = 10
POS_SCALE = 0.02  # m per action unit and step
ROT_SCALE = 0.1  # rad per action unit and step
#: mocap target position limits (pinch site, metres, world)
WORKSPACE_BOUNDS = np.array([[0.2, -0.35, 0.005], [0.7, 0.35, 0.5]])
#: gym-hil's joint home (also the controller's null-space target)
PANDA_HOME = np.array([0.0, 0.195, 0.0, -2.43, 0.0, 2.62, 0.785])

LIFT_SUCCESS_HEIGHT = 0.08
PUSH_SUCCESS_RADIUS = 0.03
PLACE_SUCCESS_RADIUS = 0.03
BUTTON_SUCCESS_DEPTH = 0.01

# the yaw symmetry of every task's object (square from above): yaws 90 degrees apart show the same scene
OBJECT_YAW_PERIOD = math.pi / 2

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
    # block x, y, yaw (the target follows, SLIDE_DISTANCE along the block's +y: the range leans to -y so that the
    # target, 7-10 cm further to +y, stays inside the front camera's view, x 0.31-0.57, y -0.07-0.18)
    "slide-block": (np.array([0.38, -0.14, -math.pi / 4]), np.array([0.50, 0.08, math.pi / 4])),
    # x, y, yaw of the cube to lift, then of the other cube (each over lift-cube's range)
    **{t: (np.array([0.33, -0.15, -math.pi / 4] * 2), np.array([0.55, 0.15, math.pi / 4] * 2)) for t in TWO_CUBE_TASKS},
}
PLACE_MIN_DISTANCE = 0.10
PUSH_MIN_DISTANCE = 0.10
PUSH_MAX_DISTANCE = 0.22
#: lift-red-cube / lift-blue-cube: the least distance between the cube centres (m): the open Robotiq's pads stand
#: 4.25 cm either side of the grasped cube's centre (85 mm opening), plus their links; the other cube's corner lies up
#: to 2.8 cm from its own centre
CUBES_MIN_DISTANCE = 0.12


def canonical_ee_quat(q: np.ndarray) -> np.ndarray:
    """Unit quaternion with the sign that makes its dot product with :data:`HOME_QUAT` non-negative."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q)
    return -q if float(q @ HOME_QUAT) < 0 else q


# --------------------------------------------------------------------------------------------------
# The env
# --------------------------------------------------------------------------------------------------
class RnDPandaEnv(RnDMuJoCoEnv):
    """Panda + Robotiq tabletop task with multi-camera pixels + EE state (see the module docstring).

    Args:
        task: one of :data:`PANDA_TASKS`.
        camera_names: cameras to observe ("front", "wrist").
        episode_length: steps before truncation.
        control_dt: seconds per step (physics at 2 ms).
        pos_scale, rot_scale: metres / radians per action unit and step.
        simplify_meshes: draw decimated arm / gripper meshes (``panda_scene.MESH_FACE_CAPS``, 3-4x faster on
            software OpenGL); the gripper meshes of :meth:`embodiment` are taken from the same model.
        **settings: the other settings of :class:`~lerobot_rnd.sim.mujoco_env.RnDMuJoCoEnv` (image size,
            placements, rendering).
    """

    metadata: ClassVar[dict] = {"render_modes": ["rgb_array"], "render_fps": PANDA_FPS}

    def __init__(
        self,
        task: str = "lift-cube",
        camera_names: Sequence[str] = DEFAULT_CAMERAS,
        episode_length: int = 100,
        control_dt: float = CONTROL_DT,
        pos_scale: float = POS_SCALE,
        rot_scale: float = ROT_SCALE,
        simplify_meshes: bool = True,
        **settings: Any,
    ):
        super().__init__(camera_names=camera_names, episode_length=episode_length, **settings)
        import mujoco

        self.task = check_task(task)
        self.task_description = TASK_DESCRIPTIONS[self.task]
        self.state_names = list(STATE_NAMES)
        for c in self.camera_names:
            if c not in MUJOCO_CAMERAS:
                raise ValueError(f"unknown camera {c!r}; cameras: {list(MUJOCO_CAMERAS)}")
        if self.render_camera not in MUJOCO_CAMERAS:
            raise ValueError(f"unknown render camera {self.render_camera!r}; cameras: {list(MUJOCO_CAMERAS)}")
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
        self._ready = False
        self._object_z0 = 0.0
        self._start_qpos = self._settled_start_qpos()
        self._setup_spaces(state_dim=len(self.state_names), action_dim=7)

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

    def placement_periods(self) -> np.ndarray:
        """Per placement coordinate, the period after which the scene looks the same (0: none): the object's yaw
        repeats every 90 degrees (the cube, the 5 x 5 cm block and the square button box are square from above),
        so the two ends of its [-45, 45]-degree range are one pose. Furthest-point sampling of demos uses it.
        slide-block's yaw has none: its target turns with the block, 90 degrees apart it lies elsewhere."""
        periods = np.zeros(len(PLACEMENT_RANGES[self.task][0]))
        periods[2] = 0.0 if self.task == "slide-block" else OBJECT_YAW_PERIOD
        if self.task in TWO_CUBE_TASKS:
            periods[5] = OBJECT_YAW_PERIOD  # the other cube's yaw
        return periods

    def is_valid_placement(self, placement: Sequence[float]) -> bool:
        """Whether the placement has the right size, lies in the range (1 mm tolerance), and (push-block,
        slide-block) the target is 10-22 cm from the block with the pushing start point inside the workspace /
        (pick-place) at least 10 cm from the cube / (two cubes) the cubes at least 12 cm apart."""
        vec = np.asarray(placement, dtype=np.float64)
        low, high = PLACEMENT_RANGES[self.task]
        if vec.shape != low.shape or not np.all(np.isfinite(vec)):
            return False
        if np.any(vec < low - 1e-3) or np.any(vec > high + 1e-3):
            return False
        if self.task in BLOCK_TASKS:
            d = placement_target_xy(self.task, vec) - vec[0:2]
            dist = float(np.linalg.norm(d))
            if not PUSH_MIN_DISTANCE - 1e-6 <= dist <= PUSH_MAX_DISTANCE + 1e-6:
                return False
            start = vec[0:2] - d / dist * 0.08
            lo, hi = WORKSPACE_BOUNDS[0, :2] + 0.02, WORKSPACE_BOUNDS[1, :2] - 0.02
            if np.any(start < lo) or np.any(start > hi):
                return False
        if self.task == "pick-place" and np.linalg.norm(vec[3:5] - vec[0:2]) < PLACE_MIN_DISTANCE:
            return False
        if self.task in TWO_CUBE_TASKS and np.linalg.norm(vec[3:5] - vec[0:2]) < CUBES_MIN_DISTANCE:
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
                    **dict.fromkeys(TWO_CUBE_TASKS, f", cube-cube distance >= {CUBES_MIN_DISTANCE} m)"),
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
        elif self.task in BLOCK_TASKS:
            adr = m.joint("block").qposadr[0]
            d.qpos[adr : adr + 3] = [vec[0], vec[1], BLOCK_HALF[2]]
            d.qpos[adr + 3 : adr + 7] = yaw_quat(vec[2])
            m.body_pos[m.body("target_marker").id] = [*placement_target_xy(self.task, vec), 0.0]
        elif self.task in TWO_CUBE_TASKS:
            for name, pose in zip(TWO_CUBE_TASKS[self.task], (vec[0:3], vec[3:6]), strict=True):
                adr = m.joint(name).qposadr[0]
                d.qpos[adr : adr + 3] = [pose[0], pose[1], CUBE_HALF]
                d.qpos[adr + 3 : adr + 7] = yaw_quat(pose[2])
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
            vec = self._check_placement(self._next_fixed_placement())
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
        terminated, truncated = self._episode_end(is_success)
        obs = self._observation()
        return obs, float(is_success), terminated, truncated, {"is_success": is_success, "task": self.task}

    # ------------------------------------------------------------------ state and task quantities
    def ee_pose(self) -> np.ndarray:
        """World-from-EE (site ``pinch``) 4x4 pose."""
        return mujoco_pose(self.data.site_xmat[self._site], self.data.site_xpos[self._site])

    def mocap_pose(self) -> np.ndarray:
        """World-from-target 4x4 pose of the controller's target (what the actions move)."""
        R = quat_wxyz_to_matrix(torch.as_tensor(self.data.mocap_quat[self._mocap], dtype=torch.float64))
        return make_pose(R.numpy(), self.data.mocap_pos[self._mocap])

    def gripper_opening(self) -> float:
        q = float(np.mean(self.data.qpos[self._drivers]))
        return float(np.clip(1.0 - q / DRIVER_CLOSED, 0.0, 1.0))

    def state(self) -> np.ndarray:
        d = self.data
        pos = np.asarray(d.site_xpos[self._site], dtype=np.float64)
        q = canonical_ee_quat(matrix_to_quat(d.site_xmat[self._site]))
        return np.concatenate([pos, q, [self.gripper_opening()]]).astype(np.float32)

    def object_pos(self) -> np.ndarray:
        """Centre of the cube (two cubes: the one to lift) / block, or (press-button) the centre of the button's top
        face when not pressed, in the world."""
        d = self.data
        if self.task in ("lift-cube", "pick-place"):
            return d.body("cube").xpos.copy()
        if self.task in TWO_CUBE_TASKS:
            return d.body(TWO_CUBE_TASKS[self.task][0]).xpos.copy()
        if self.task in BLOCK_TASKS:
            return d.body("block").xpos.copy()
        top = 2 * (BUTTON_HOUSING_HALF[2] + BUTTON_HALF_HEIGHT)
        return d.body("button_box").xpos.copy() + np.array([0.0, 0.0, top])

    def object_quat(self) -> np.ndarray:
        d = self.data
        if self.task in TWO_CUBE_TASKS:
            return d.body(TWO_CUBE_TASKS[self.task][0]).xquat.copy()
        name = "block" if self.task in BLOCK_TASKS else {"press-button": "button_box"}.get(self.task, "cube")
        return d.body(name).xquat.copy()

    def target_pos(self) -> np.ndarray | None:
        """push-block / pick-place / slide-block: the target disc centre (on the table)."""
        if self.task not in ("push-block", "pick-place", "slide-block"):
            return None
        return self.data.body("target_marker").xpos.copy()

    def button_depth(self) -> float:
        """press-button: how far the button is pressed down (m, >= 0)."""
        if self.task != "press-button":
            return 0.0
        return float(-self.data.joint("button").qpos[0])

    @property
    def success_now(self) -> bool:
        if self.task == "lift-cube" or self.task in TWO_CUBE_TASKS:
            return bool(self.object_pos()[2] - self._object_z0 > LIFT_SUCCESS_HEIGHT)
        if self.task in BLOCK_TASKS:
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
    def mujoco_camera_name(self, camera: str) -> str:
        return MUJOCO_CAMERAS[camera]

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
def panda_ee_pose_source() -> EEPoseSource:
    """EE pose source for the 8-D state [ee xyz, ee quat wxyz, gripper opening (1 open, 0 closed)]."""
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


def panda_gripper_meshes(model=None, max_faces: int = GRIPPER_MESH_FACES) -> dict[str, GripperMesh]:
    """Robotiq 2F-85 meshes in the EE (``pinch`` site) frame, open gripper (qpos0 = open).

    "full": body ``base_mount`` subtree (mount, base, both finger linkages and pads); "fingers": the two
    fingers (follower links and pads, :data:`FINGER_BODIES`), drawn in the wrist camera, which sees the
    finger tips (the linkages next to the camera would cover much of its image when drawn at future
    poses)."""
    if model is None:
        model = build_model("lift-cube")
    full = GripperMesh.from_mjcf_body(model, GRIPPER_ROOT_BODY, ee_site=EE_SITE, name="full")
    fingers = GripperMesh.concatenate(
        [GripperMesh.from_mjcf_body(model, b, ee_site=EE_SITE) for b in FINGER_BODIES], name="fingers"
    )
    return {"full": full.simplified(max_faces), "fingers": fingers.simplified(max_faces)}


def panda_cameras(
    model, data, camera_names: Sequence[str], image_size: tuple[int, int]
) -> dict[str, CameraCalibration]:
    """Calibrations keyed ``observation.images.<name>``: ``front`` static, ``wrist`` rigid on the EE."""
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
) -> Embodiment:
    """Embodiment of the ``gym_rnd_panda`` envs / ``lerobot-rnd-record --suite panda`` datasets (identical for
    all tasks; preset ``panda_robotiq``): cameras ``front`` (static) and ``wrist`` (rigid on the hand,
    fingers-only mesh) from MuJoCo, EE frame = site ``pinch``, state [ee xyz, quat wxyz, gripper opening
    (1 open, 0 closed)], action adapter ``ee_delta`` (world frame, 0.02 m / 0.1 rad per unit, clipped to
    [-1, 1]). Needs gym-hil's assets."""
    import mujoco

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


register_embodiment_preset("panda_robotiq", panda_embodiment)  # this env / lerobot-rnd-record --suite panda


# --------------------------------------------------------------------------------------------------
# Gym registration and LeRobot EnvConfig
# --------------------------------------------------------------------------------------------------
register_gym_envs(GYM_NAMESPACE, PANDA_TASKS, "lerobot_rnd.sim.panda_env:RnDPandaEnv")


@EnvConfig.register_subclass("rnd_panda")
@dataclass
class RnDPandaEnvConfig(RnDSimEnvConfig):
    """``--env.type=rnd_panda``: Panda + Robotiq tabletop tasks (lerobot_rnd.sim.panda_env)."""

    task: str | None = "lift-cube"
    fps: int = PANDA_FPS
    episode_length: int = 100
    camera_names: list[str] = field(default_factory=lambda: list(DEFAULT_CAMERAS))

    gym_namespace: ClassVar[str] = GYM_NAMESPACE
    action_dim: ClassVar[int] = 7

    def state_dim(self) -> int:
        return len(STATE_NAMES)
