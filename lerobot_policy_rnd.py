"""Discovery shim: LeRobot imports distributions named `lerobot_policy_*` by that name."""

import lerobot_rnd  # noqa: F401  (registers the `rnd` policy and the `rnd_mw` environment)
