"""Render and Diffuse (R&D) for LeRobot.

Importing this package registers the `rnd` policy type with LeRobot (and the `rnd_mw` environment type
when the simulation extras are importable).
"""

from lerobot_rnd.configuration_rnd import RnDConfig

__all__ = ["RnDConfig"]
__version__ = "0.1.0"

try:  # environments are optional for policy-only use
    import lerobot_rnd.sim  # noqa: F401
except ImportError as _err:  # pragma: no cover - depends on the installed simulators
    import logging as _logging

    _logging.getLogger(__name__).debug("lerobot_rnd.sim not available: %s", _err)
