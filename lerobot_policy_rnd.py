"""Discovery shim: LeRobot imports distributions named `lerobot_policy_*` by that name.

Registers the `rnd` policy and, when the simulators are importable, the `rnd_mw` / `rnd_panda` environment
types and the MetaWorld / Panda embodiment presets.
"""

import logging

import lerobot_rnd  # noqa: F401  (registers the `rnd` policy)

try:  # environments are optional for policy-only use
    import lerobot_rnd.sim  # noqa: F401
except ImportError as err:  # pragma: no cover - depends on the installed simulators
    logging.getLogger(__name__).debug("lerobot_rnd.sim not available: %s", err)
