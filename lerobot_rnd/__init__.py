"""Render and Diffuse (R&D) for LeRobot.

Importing this package registers the `rnd` policy type with LeRobot. It imports no simulator: the MetaWorld and
Panda environments (`--env.type=rnd_mw` / `rnd_panda`) and their embodiment presets register when
`lerobot_rnd.sim` is imported, which LeRobot's plugin discovery does (`lerobot_policy_rnd.py`).
"""

from lerobot_rnd.configuration_rnd import RnDConfig

__all__ = ["RnDConfig"]
__version__ = "0.1.0"
