"""Scripted experts of the SO-101 suite, in joint space: at the first step of an episode they plan waypoints as
gripper poses, turn them into LeRobot joint targets by the robot's IK (:func:`ik_position_first`) and play
minimum-jerk joint trajectories between them (the action is the next joint target, as a leader arm gives).

- ``reach-target``: the gripper moves to the ball, pointing down with the jaws facing the base as in the start pose
  (so the wrist barely rolls, as a teleoperator would reach), and holds.
- ``pick-cube``: above the cube (top-down, the jaws across the pair of faces that needs the least wrist roll),
  down, close, lift 8 cm.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from lerobot_rnd import so101
from lerobot_rnd.sim.so101_scene import CUBE_HALF, SO101_TASKS

GRIPPER_OPEN = 60.0  # LeRobot units; about 55 degrees of jaw opening, room for the 3 cm cube
GRIPPER_CLOSED = 0.0  # the servo keeps squeezing towards it
#: where the cube's centre is in the EE frame when the jaws come down around it: 6 mm in front of the static
#: jaw's inner face (x < 0; the moving jaw then pushes it against that face), a little behind the tips
GRASP_CUBE_IN_EE = np.array([-CUBE_HALF - 0.006, 0.0, -0.004])
#: heights above the grasp pose of the descent's waypoints (the joints move straight between them, so the jaws
#: stay near the vertical line)
DESCENT_HEIGHTS = (0.06, 0.04, 0.02, 0.0)


def _top_down(yaw: float) -> np.ndarray:
    """R_world_ee (3, 3) pointing the jaws straight down (EE z = -world z), EE x at angle ``yaw`` in the table plane."""
    x = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    z = np.array([0.0, 0.0, -1.0])
    return np.stack([x, np.cross(z, x), z], axis=1)


def ik_position_first(T_world_ee: np.ndarray, q_seed: np.ndarray, iterations: int = 60) -> tuple[np.ndarray, float]:
    """LeRobot joint vector (6,) reaching ``T_world_ee`` (4, 4) with the body joints, and its position error (m).

    The arm has 5 body joints, so not every pose can be reached: a pose IK (position and rotation alike) comes
    first, then damped least squares on the position alone from there, which keeps the rotation close while the
    position becomes exact. The gripper entry is copied from ``q_seed``."""
    kin = so101._kinematics()
    seed = so101.lerobot_to_urdf(torch.as_tensor(q_seed, dtype=torch.float64))[: so101.ARM_JOINTS]
    T = torch.as_tensor(T_world_ee, dtype=torch.float64)
    q, _ = kin.inverse_kinematics(T, seed)
    chain = kin.chain("cpu", torch.float64)
    low, high = (torch.as_tensor(v, dtype=torch.float64) for v in chain.get_joint_limits())
    for _ in range(iterations):
        p = chain.forward_kinematics(q[None]).get_matrix()[0, :3, 3]
        err = T[:3, 3] - p
        if err.norm() < 1e-5:
            break
        J = chain.jacobian(q[None])[0, :3]  # (3, 5) linear part
        dq = J.T @ torch.linalg.solve(J @ J.T + 1e-4 * torch.eye(3, dtype=J.dtype), err)
        q = torch.clamp(q + dq, low, high)
    p = chain.forward_kinematics(q[None]).get_matrix()[0, :3, 3]
    full = torch.cat([q, so101.lerobot_to_urdf(torch.as_tensor(q_seed, dtype=torch.float64))[so101.ARM_JOINTS:]])
    return so101.urdf_to_lerobot(full).numpy(), float((T[:3, 3] - p).norm())


def min_jerk(q0: np.ndarray, q1: np.ndarray, steps: int) -> np.ndarray:
    """(steps, D) joint targets from ``q0`` (excluded) to ``q1`` (included) along a minimum-jerk profile."""
    s = np.arange(1, steps + 1) / steps
    s = 10 * s**3 - 15 * s**4 + 6 * s**5
    return q0[None] + s[:, None] * (q1 - q0)[None]


class SO101Expert:
    """Scripted expert for one SO-101 task. ``noise_std``: std (degrees) of Gaussian noise on the body joints'
    waypoints, for more diverse demonstrations (seeded by ``seed``)."""

    def __init__(self, task: str, noise_std: float = 0.0, seed: int | None = None):
        if task not in SO101_TASKS:
            raise ValueError(f"no SO-101 expert for task {task!r}; tasks: {', '.join(SO101_TASKS)}")
        self.task = task
        self.noise_std = float(noise_std)
        self.rng = np.random.default_rng(seed)
        self.plan: np.ndarray | None = None
        self.max_ik_error = 0.0

    def _waypoints(self, env) -> list[tuple[np.ndarray, int]]:
        """[(LeRobot joint target (6,), steps to get there)] for the current episode."""
        q = env.joints()
        out = []
        if self.task == "reach-target":
            t = env.target_pos()
            # EE x back towards the base, as in the start pose: the ball is round, so any yaw reaches it, and this
            # one needs no wrist roll. (Pointing it out from the base made every demo roll the wrist about 160
            # degrees, one way or the other by the side of the ball: a discontinuous motion no policy learned.)
            R = _top_down(math.atan2(t[1], t[0]) + math.pi)
            goal, err = ik_position_first(_pose(R, t), np.r_[q[:5], GRIPPER_OPEN])
            self.max_ik_error = err
            return [(goal, 45)]
        cube = env.cube_pos()
        yaw = env.placement[2]
        # the jaws close along EE x: across the pair of faces whose normal is nearest the direction back to the
        # base, where EE x points in the start pose (the least wrist roll)
        back = math.atan2(cube[1], cube[0]) + math.pi
        k = round((back - yaw) / (math.pi / 2))
        R = _top_down(yaw + k * math.pi / 2)
        grasp = cube - R @ GRASP_CUBE_IN_EE
        targets, seed = [], np.r_[q[:5], GRIPPER_OPEN]
        for h in DESCENT_HEIGHTS:
            seed, err = ik_position_first(_pose(R, grasp + [0, 0, h]), seed)
            targets.append((seed, err))
        down = targets[-1][0]
        lift, e_lift = ik_position_first(_pose(R, grasp + [0, 0, 0.08]), np.r_[down[:5], GRIPPER_CLOSED])
        self.max_ik_error = max([e for _, e in targets] + [e_lift])
        closed = np.r_[down[:5], GRIPPER_CLOSED]
        out = [(targets[0][0], 36)] + [(t, 8) for t, _ in targets[1:]] + [(closed, 12), (closed, 6), (lift, 30)]
        return out

    def _make_plan(self, env) -> np.ndarray:
        q = env.joints()
        rows = []
        for target, steps in self._waypoints(env):
            target = target.copy()
            if self.noise_std > 0:
                target[:5] += self.rng.normal(0.0, self.noise_std, size=5)
            rows.append(min_jerk(q, target, steps))
            q = target
        return np.concatenate(rows, axis=0)

    def act(self, env) -> np.ndarray:
        env = env.unwrapped
        if env.steps == 0 or self.plan is None:
            self.plan = self._make_plan(env)
        i = min(env.steps, len(self.plan) - 1)
        return self.plan[i].astype(np.float32)

    __call__ = act


def _pose(R: np.ndarray, p) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = p
    return T
