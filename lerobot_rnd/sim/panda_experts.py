"""Scripted experts for the Panda + Robotiq tasks of :mod:`lerobot_rnd.sim.panda_env`.

``PandaExpert(task).act(env) -> action (7,) float32`` in [-1, 1] for a
:class:`~lerobot_rnd.sim.panda_env.RnDPandaEnv` (or a wrapper of one). The experts read privileged
simulator state (object poses, the controller's target pose) and run a small state machine per task;
they move the target pose towards waypoints (straight lines, position and rotation scaled together), at
:data:`APPROACH_SPEED` to the first waypoint above the object and up to full speed after it and switch phases when the REAL end effector has arrived, so they also work
with the controller's lag. The state machine restarts whenever the env is at step 0.

- ``lift-cube``: above the cube with the gripper turned to the cube's yaw (modulo 90 degrees, so the
  fingers close on two opposite faces), descend, close, lift to 20 cm (re-grasps if the cube drops).
  ``lift-red-cube`` / ``lift-blue-cube`` do the same with the cube the task names.
- ``push-block`` and ``slide-block``: closed gripper turned so that the broad side of the finger pads faces the
  push direction, go behind the block on the block-target line, lower, push along the (re-planned every
  step) line; back off and re-approach when the block slips sideways.
- ``press-button``: close the gripper, go above the button (turned to the box's yaw modulo 90 degrees),
  press with the finger tips until the button is down, lift.
- ``pick-place``: grasp as in ``lift-cube``, lift to 12 cm, carry above the target, lower the cube onto
  it, open, move up.
"""

from __future__ import annotations

import math

import numpy as np

from lerobot_rnd.sim.panda_scene import (
    BLOCK_HALF,
    BLOCK_TASKS,
    BUTTON_HALF_HEIGHT,
    BUTTON_HOUSING_HALF,
    BUTTON_TRAVEL,
    CUBE_HALF,
    HOME_QUAT,
    PANDA_TASKS,
    TWO_CUBE_TASKS,
    placement_target_xy,
)
from lerobot_rnd.sim.quaternions import matrix_to_quat, quat_mul, quat_to_rotvec, yaw_quat

#: finger-pad tips below the EE (pinch) origin when the gripper is closed on nothing (m)
CLOSED_TIP_OFFSET = 0.018
LIFT_Z = 0.20
CARRY_Z = 0.12
HOVER = 0.10
#: fraction of the maximum step (0.02 m, 0.1 rad) for the approach to the point above the object, the only part of
#: each task that depends on where the object is: at full speed it took 5-8 steps, so one 8-step action chunk, planned
#: from the first frame, held all of it; at 0.4 it takes 10-19 steps (lift-cube), which a policy re-plans from new
#: images (benchmarks/results/panda_env_speed.json has the expert's steps per episode)
APPROACH_SPEED = 0.4
#: push-block: the block's half width + half the closed pads' thickness (EE from block centre at contact, m), and how
#: far behind that contact point the push starts
PUSH_CONTACT = max(BLOCK_HALF[:2]) + 0.008
PUSH_BACKOFF = 0.03
#: push-block: EE height while pushing (m)
PUSH_Z = 0.016 + CLOSED_TIP_OFFSET


def push_start_xy(block_xy: np.ndarray, target_xy: np.ndarray) -> np.ndarray:
    """(2,) world x, y (m) behind the block on the block-target line, where the push-block expert lowers its
    gripper before pushing."""
    d = np.asarray(target_xy, np.float64) - np.asarray(block_xy, np.float64)
    return np.asarray(block_xy, np.float64) - d / max(float(np.linalg.norm(d)), 1e-9) * (PUSH_CONTACT + PUSH_BACKOFF)


def first_contact_point(task: str, placement) -> np.ndarray:
    """(3,) world position (m) of the EE where the scripted expert of ``task`` first meets its object, from an
    episode's placement [x, y, yaw, ...]: lift-cube / pick-place / two cubes the (named) cube's centre (the grasp);
    push-block / slide-block the push start behind the block at pushing height; press-button the button's top."""
    p = np.asarray(placement, np.float64)
    if task in ("lift-cube", "pick-place", *TWO_CUBE_TASKS):
        return np.array([p[0], p[1], CUBE_HALF])
    if task in BLOCK_TASKS:
        return np.array([*push_start_xy(p[:2], placement_target_xy(task, p)), PUSH_Z])
    if task == "press-button":
        return np.array([p[0], p[1], 2 * (BUTTON_HOUSING_HALF[2] + BUTTON_HALF_HEIGHT)])
    raise ValueError(f"unknown Panda task {task!r}; known: {', '.join(PANDA_TASKS)}")


def _yaw_of(q: np.ndarray) -> float:
    w, x, y, z = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _wrap(a: float, period: float) -> float:
    """``a`` modulo ``period`` into [-period/2, period/2)."""
    return (a + period / 2) % period - period / 2


def nearest_equivalent_yaw(yaw: float, period: float, current: float, limit: float = 0.75 * math.pi) -> float:
    """The angle ``yaw + k * period`` nearest to ``current`` among those within ``[-limit, limit]``."""
    base = _wrap(yaw, period)
    cands = [base + k * period for k in range(-4, 5) if abs(base + k * period) <= limit]
    return min(cands, key=lambda c: abs(c - current))


def target_yaw(env) -> float:
    """Yaw of the controller's target orientation (angle of its x axis in the world xy plane)."""
    R = env.mocap_pose()[:3, :3]
    return math.atan2(R[1, 0], R[0, 0])


def ee_quat_for_yaw(yaw: float) -> np.ndarray:
    """EE orientation pointing down, turned by ``yaw`` about the world z axis from the home orientation."""
    return quat_mul(yaw_quat(yaw), HOME_QUAT)


class PandaExpert:
    """Scripted expert for one Panda task (see the module docstring).

    Args:
        task: one of :data:`~lerobot_rnd.sim.panda_env.PANDA_TASKS`.
        noise_std: std of Gaussian noise added to the 6 motion components (action units) for more diverse
            demonstrations (seeded by ``seed``).
    """

    def __init__(self, task: str, noise_std: float = 0.0, seed: int | None = None):
        if task not in PANDA_TASKS:
            raise ValueError(f"no Panda expert for task {task!r}; tasks: {', '.join(PANDA_TASKS)}")
        self.task = task
        self.noise_std = float(noise_std)
        self.rng = np.random.default_rng(seed)
        self.reset()

    def reset(self) -> None:
        self.phase = 0
        self.count = 0
        self.memory: dict = {}

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def move(env, pos, quat, grip: float, speed: float = 1.0) -> np.ndarray:
        """Action moving the controller's target towards (pos, quat) at up to ``speed`` (fraction of the
        maximum step), straight in position and rotation, with gripper command ``grip``."""
        T = env.mocap_pose()
        dpos = (np.asarray(pos, float) - T[:3, 3]) / env.pos_scale
        q_now = env.data.mocap_quat[env._mocap]
        q_rel = quat_mul(np.asarray(quat, float), q_now * np.array([1, -1, -1, -1]))
        drot = quat_to_rotvec(q_rel) / env.rot_scale
        m = max(np.abs(dpos).max() / speed, np.abs(drot).max() / speed, 1.0)
        a = np.zeros(7)
        a[:3], a[3:6] = dpos / m, drot / m
        a[6] = grip
        return a

    @staticmethod
    def ee_error(env, pos, quat) -> tuple[np.ndarray, float]:
        """(position error vector (m), rotation error (rad)) of the REAL EE pose from (pos, quat)."""
        T = env.ee_pose()
        q = matrix_to_quat(T[:3, :3])
        dq = quat_mul(np.asarray(quat, float), q * np.array([1, -1, -1, -1]))
        return np.asarray(pos, float) - T[:3, 3], float(np.linalg.norm(quat_to_rotvec(dq)))

    def _next(self, phase: int) -> None:
        self.phase, self.count = phase, 0

    # ------------------------------------------------------------------ tasks
    def _lift_cube(self, env, place: bool = False) -> np.ndarray:
        cube = env.object_pos()
        yaw = nearest_equivalent_yaw(_yaw_of(env.object_quat()), math.pi / 2, target_yaw(env))
        q = self.memory.get("quat", ee_quat_for_yaw(yaw))
        if self.phase in (0, 1):
            q = ee_quat_for_yaw(yaw)
            self.memory["quat"] = q
        if self.phase == 0:  # above the cube, turned to its yaw, open
            goal = np.array([cube[0], cube[1], cube[2] + HOVER])
            e, r = self.ee_error(env, goal, q)
            if np.linalg.norm(e[:2]) < 0.006 and abs(e[2]) < 0.015 and r < math.radians(3):
                self._next(1)
            return self.move(env, goal, q, -1.0, speed=APPROACH_SPEED)
        if self.phase == 1:  # descend
            goal = np.array([cube[0], cube[1], cube[2] + 0.004])
            e, _ = self.ee_error(env, goal, q)
            if np.linalg.norm(e) < 0.006:
                self.memory["grasp"] = goal
                self._next(2)
            return self.move(env, goal, q, -1.0, speed=0.6)
        if self.phase == 2:  # close
            self.count += 1
            if self.count >= 5:
                self._next(3)
            return self.move(env, self.memory["grasp"], q, 1.0)
        g = self.memory["grasp"]
        if self.phase == 3:  # lift
            self.count += 1
            if self.count > 8 and cube[2] < CUBE_HALF + 0.01:  # dropped: start over
                self._next(0)
                return self.move(env, env.mocap_pose()[:3, 3] + [0, 0, 0.02], q, -1.0)
            if not place:
                return self.move(env, [g[0], g[1], LIFT_Z], q, 1.0)
            goal = np.array([g[0], g[1], CARRY_Z])
            if env.ee_pose()[2, 3] > CARRY_Z - 0.03:
                self._next(4)
            return self.move(env, goal, q, 1.0)
        t = env.target_pos()
        if self.phase == 4:  # carry above the target
            goal = np.array([t[0], t[1], CARRY_Z])
            e, _ = self.ee_error(env, goal, q)
            if cube[2] < CUBE_HALF + 0.01:  # dropped on the way: start over
                self._next(0)
                return self.move(env, env.mocap_pose()[:3, 3] + [0, 0, 0.02], q, -1.0)
            if np.linalg.norm(e[:2]) < 0.008:
                self._next(5)
            return self.move(env, goal, q, 1.0)
        if self.phase == 5:  # put it down (pinch where it grasped the cube, cube on the table)
            goal = np.array([t[0], t[1], g[2] + 0.003])
            e, _ = self.ee_error(env, goal, q)
            self.count += 1
            if abs(e[2]) < 0.006 or self.count > 25:
                self._next(6)
            return self.move(env, goal, q, 1.0, speed=0.6)
        if self.phase == 6:  # open
            self.count += 1
            if self.count >= 4:
                self._next(7)
            return self.move(env, env.mocap_pose()[:3, 3], q, -1.0)
        return self.move(env, [t[0], t[1], HOVER], q, -1.0, speed=0.6)

    def _push_block(self, env) -> np.ndarray:
        b, t = env.object_pos(), env.target_pos()
        d = t[:2] - b[:2]
        dist = float(np.linalg.norm(d))
        u = d / max(dist, 1e-9)
        # finger-opening axis (EE y) along the push direction: EE y = (sin yaw, -cos yaw) in the world
        yaw = nearest_equivalent_yaw(math.atan2(u[1], u[0]) + math.pi / 2, math.pi, target_yaw(env))
        q = ee_quat_for_yaw(yaw)
        ee = env.ee_pose()[:3, 3]
        contact, push_z = PUSH_CONTACT, PUSH_Z
        behind = push_start_xy(b[:2], t[:2])
        if dist < 0.012 and self.phase == 2:
            self._next(3)
        if self.phase == 0:  # behind the block, above it, closed
            goal = np.array([*behind, HOVER])
            e, r = self.ee_error(env, goal, q)
            if np.linalg.norm(e[:2]) < 0.01 and abs(e[2]) < 0.02 and r < math.radians(5):
                self._next(1)
            return self.move(env, goal, q, 1.0, speed=APPROACH_SPEED)
        if self.phase == 1:  # lower
            goal = np.array([*behind, push_z])
            e, _ = self.ee_error(env, goal, q)
            if abs(e[2]) < 0.008 and np.linalg.norm(e[:2]) < 0.01:
                self._next(2)
            return self.move(env, goal, q, 1.0, speed=0.8)
        if self.phase == 2:  # push along the block-target line
            rel = ee[:2] - b[:2]
            lateral = abs(u[0] * rel[1] - u[1] * rel[0])
            along = float(u @ rel)
            if lateral > 0.015 or along > -contact + 0.01:
                self._next(4)
                return self.move(env, [*ee[:2], ee[2] + 0.03], q, 1.0)
            lead = min(0.03, dist + 0.005)
            goal = np.array([*(b[:2] - u * contact + u * lead), push_z])
            return self.move(env, goal, q, 1.0, speed=0.5)
        if self.phase == 3:  # done: back off upwards
            self.memory.setdefault("done_xy", ee[:2].copy())
            xy = self.memory["done_xy"] - u * 0.02
            return self.move(env, [*xy, HOVER], q, 1.0, speed=0.5)
        # 4: retreat upwards, then re-approach
        goal = np.array([*ee[:2], HOVER])
        if ee[2] > 0.07:
            self._next(0)
        return self.move(env, [*env.mocap_pose()[:2, 3], HOVER], q, 1.0)

    def _press_button(self, env) -> np.ndarray:
        top = env.object_pos()  # button top at rest
        yaw = _wrap(_yaw_of(env.object_quat()), math.pi / 2)
        q = ee_quat_for_yaw(yaw)
        if self.phase == 0:  # above the button, closed
            goal = np.array([top[0], top[1], top[2] + 0.06])
            e, r = self.ee_error(env, goal, q)
            if np.linalg.norm(e[:2]) < 0.006 and abs(e[2]) < 0.02 and r < math.radians(4):
                self._next(1)
            return self.move(env, goal, q, 1.0, speed=APPROACH_SPEED)
        if self.phase == 1:  # press with the finger tips
            self.count += 1
            goal = np.array([top[0], top[1], top[2] - (BUTTON_TRAVEL - 0.002) + CLOSED_TIP_OFFSET])
            if env.button_depth() > BUTTON_TRAVEL - 0.004 or self.count > 40:
                self._next(2)
            return self.move(env, goal, q, 1.0, speed=0.5)
        if self.phase == 2:  # hold briefly
            self.count += 1
            if self.count >= 2:
                self._next(3)
            return self.move(env, env.mocap_pose()[:3, 3], q, 1.0)
        return self.move(env, [top[0], top[1], top[2] + 0.06], q, 1.0, speed=0.5)

    # ------------------------------------------------------------------ API
    def act(self, env) -> np.ndarray:
        env = env.unwrapped
        if env.steps == 0 and self.memory.get("_last_step", None) != 0:
            self.reset()
        self.memory["_last_step"] = env.steps
        if self.task == "lift-cube" or self.task in TWO_CUBE_TASKS:
            a = self._lift_cube(env)
        elif self.task == "pick-place":
            a = self._lift_cube(env, place=True)
        elif self.task in BLOCK_TASKS:
            a = self._push_block(env)
        else:
            a = self._press_button(env)
        if self.noise_std > 0:
            a[:6] = a[:6] + self.rng.normal(0.0, self.noise_std, size=6)
        return np.clip(a, -1.0, 1.0).astype(np.float32)

    __call__ = act
