"""Simulated environments, scripted experts and the demonstration recorder.

Importing this package registers the gymnasium ids ``gym_rnd_metaworld/<task>`` (every MetaWorld V3
task) and LeRobot's ``--env.type=rnd_mw``, and the Panda suite's ``gym_rnd_panda/<task>`` and
``--env.type=rnd_panda`` (its scenes need gym-hil's assets: ``pip install --no-deps gym-hil==0.1.14``). MuJoCo / MetaWorld are imported only when an env is built.
Headless machines default to ``MUJOCO_GL=egl`` (set MUJOCO_GL=osmesa to override).
"""

import os

if "MUJOCO_GL" not in os.environ and not os.environ.get("DISPLAY"):
    os.environ["MUJOCO_GL"] = "egl"

from lerobot_rnd.sim.metaworld_env import (
    GYM_NAMESPACE,
    METAWORLD_V3_TASKS,
    RnDMetaWorldEnv,
    RnDMetaWorldEnvConfig,
    register_gym_envs,
)

register_gym_envs()

from lerobot_rnd.sim import panda_env  # noqa: E402,F401  (registers gym_rnd_panda/* and rnd_panda)

__all__ = [
    "GYM_NAMESPACE",
    "METAWORLD_V3_TASKS",
    "RnDMetaWorldEnv",
    "RnDMetaWorldEnvConfig",
    "register_gym_envs",
]
