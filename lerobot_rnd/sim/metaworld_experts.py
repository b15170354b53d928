"""Scripted MetaWorld experts: MetaWorld's per-task heuristic policies behind a small common interface."""

from __future__ import annotations

import numpy as np

from lerobot_rnd.sim.metaworld_env import lerobot_metaworld_config


def metaworld_policy_class_name(task: str) -> str:
    """Name of MetaWorld's scripted policy class for a V3 task ("reach-v3" -> "SawyerReachV3Policy")."""
    mapping = lerobot_metaworld_config().get("TASK_POLICY_MAPPING", {})
    if task in mapping:
        return mapping[task]
    base, _, version = task.rpartition("-")
    special = {"peg-insert-side": "PegInsertionSide"}
    camel = special.get(base) or "".join(p.capitalize() for p in base.split("-"))
    return f"Sawyer{camel}{version.upper()}Policy"


#: tasks whose MetaWorld policy drives the hand body (observation[:3]) to the goal while success is measured
#: from the gripper's centre (`tcp_center`, about 4.5 cm below the hand): with reach_target="tcp" the expert
#: aims the gripper's centre at the goal instead
HAND_TO_GOAL_TASKS = frozenset({"reach-v3", "reach-wall-v3"})
REACH_TARGETS = ("tcp", "hand")


class MetaWorldExpert:
    """MetaWorld scripted policy acting on the raw 39-D MetaWorld observation.

    ``expert(raw_obs) -> action (4,) float32`` in [-1, 1]; ``noise_std`` adds Gaussian noise to the
    xyz part (seeded by ``seed``) for more diverse demonstrations.

    ``reach_target`` (tasks in :data:`HAND_TO_GOAL_TASKS`, with :meth:`act`): "tcp" (default) moves the
    gripper's centre onto the goal, where MetaWorld measures success; "hand" is MetaWorld's own policy, which
    parks the hand on the goal and so ends with the gripper's centre about 4.5 cm from it, just inside the 5 cm
    success radius: demos that succeed by a few millimetres, which an imitating policy misses half the time.
    """

    def __init__(self, task: str, noise_std: float = 0.0, seed: int | None = None, reach_target: str = "tcp"):
        from metaworld import policies

        name = metaworld_policy_class_name(task)
        if not hasattr(policies, name):
            raise ValueError(f"MetaWorld has no scripted policy '{name}' for task '{task}'")
        if reach_target not in REACH_TARGETS:
            raise ValueError(f"reach_target must be one of {REACH_TARGETS}, got {reach_target!r}")
        self.task = task
        self.reach_target = reach_target
        self.policy = getattr(policies, name)()
        self.noise_std = float(noise_std)
        self.rng = np.random.default_rng(seed)

    def __call__(self, raw_obs: np.ndarray) -> np.ndarray:
        import warnings

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "Constant(s) may be too high" from MetaWorld's policies
            a = np.asarray(self.policy.get_action(raw_obs), dtype=np.float64)
        if self.noise_std > 0:
            a[:3] = a[:3] + self.rng.normal(0.0, self.noise_std, size=3)
        return np.clip(a, -1.0, 1.0).astype(np.float32)

    def act(self, env) -> np.ndarray:
        """Action for a :class:`~lerobot_rnd.sim.metaworld_env.RnDMetaWorldEnv` (reads its raw observation)."""
        env = env.unwrapped
        raw = env.raw_observation
        if self.reach_target == "tcp" and self.task in HAND_TO_GOAL_TASKS:
            raw = raw.copy()  # goal moved by (hand - tcp): the policy brings the hand there, the tcp onto the goal
            raw[-3:] = raw[-3:] + (raw[:3] - env.tcp_center)
        return self(raw)
