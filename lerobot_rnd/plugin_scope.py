"""Whether the plugin's changes to LeRobot (the column-first dataset query, the config-error hook) apply here.

LeRobot imports the plugin shim (`lerobot_policy_rnd`) in every `lerobot-train` / `lerobot-eval` run on a machine
where the plugin is installed, whatever the policy. Those changes apply by default only to `rnd` runs, recognised
from the command line the shim is imported under:

- ``--policy.type=rnd`` (or ``--policy.type rnd``);
- ``--policy.path=<checkpoint>`` whose ``config.json`` says ``"type": "rnd"``;
- ``--config_path=<file>`` whose ``policy.type`` (or ``type``, for a saved ``train_config.json``) is ``rnd``.

Other policies (ACT, Diffusion Policy, ...) keep LeRobot's own behaviour unless ``LEROBOT_RND_PATCH_ALL=1`` is
set (the benchmark harness sets it for every method, so they all read data the same way).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

PATCH_ALL_ENV = "LEROBOT_RND_PATCH_ALL"
POLICY_TYPE = "rnd"


def _flag_values(argv: Sequence[str], name: str) -> list[str]:
    """Values of ``--name=value`` and ``--name value`` in argv."""
    values = []
    for i, arg in enumerate(argv):
        if arg.startswith(name + "="):
            values.append(arg.split("=", 1)[1])
        elif arg == name and i + 1 < len(argv):
            values.append(argv[i + 1])
    return values


def _json_policy_type(path: Path, *keys: str) -> str | None:
    """The policy type found under the first of `keys` (a dotted path) that a JSON file holds, or None."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    for key in keys:
        node = data
        for part in key.split("."):
            node = node.get(part) if isinstance(node, Mapping) else None
        if isinstance(node, str):
            return node
    return None


def rnd_run_requested(argv: Sequence[str]) -> bool:
    """Whether a LeRobot command line asks for an `rnd` policy (see the module docstring)."""
    if POLICY_TYPE in _flag_values(argv, "--policy.type"):
        return True
    for path in _flag_values(argv, "--policy.path"):
        if _json_policy_type(Path(path) / "config.json", "type") == POLICY_TYPE:
            return True
    for path in _flag_values(argv, "--config_path"):
        if _json_policy_type(Path(path), "policy.type", "type") == POLICY_TYPE:
            return True
    return False


def patch_all_requested(environ: Mapping[str, str] | None = None) -> bool:
    """Whether ``LEROBOT_RND_PATCH_ALL`` asks for the plugin's changes for every policy."""
    value = (os.environ if environ is None else environ).get(PATCH_ALL_ENV, "")
    return value.strip().lower() in ("1", "true", "yes", "on")


def lerobot_patches_wanted(argv: Sequence[str], environ: Mapping[str, str] | None = None) -> bool:
    """Whether the shim should install its changes to LeRobot for this process."""
    return patch_all_requested(environ) or rnd_run_requested(argv)
