"""Discovery shim: LeRobot imports distributions named `lerobot_policy_*` by that name.

Registers the `rnd` policy and, when the simulators are importable, the `rnd_mw` / `rnd_panda` environment
types and the MetaWorld / Panda embodiment presets. For `rnd` runs (`--policy.type=rnd`, an `rnd` checkpoint or
config file; `lerobot_rnd.plugin_scope`) it also makes the last line of a config error raised by the plugin say
what is wrong (`lerobot_rnd.cli_errors`) and makes LeRobot 0.4.4's image-dataset frame queries decode only the
queried column (`lerobot_rnd.dataset_query`: the same samples, several times fewer PNG decodes). Other policies
keep LeRobot's own behaviour unless `LEROBOT_RND_PATCH_ALL=1` is set.
"""

import logging
import sys

import lerobot_rnd  # noqa: F401  (registers the `rnd` policy)
from lerobot_rnd.cli_errors import install_config_error_hook
from lerobot_rnd.dataset_query import install_column_first_queries
from lerobot_rnd.plugin_scope import lerobot_patches_wanted

if lerobot_patches_wanted(sys.argv):
    install_config_error_hook()  # a CLI config error ends with the plugin's own message
    install_column_first_queries()  # LEROBOT_RND_DATASET_QUERY=upstream keeps LeRobot's own query

try:  # environments are optional for policy-only use
    import lerobot_rnd.sim  # noqa: F401
except ImportError as err:  # pragma: no cover - depends on the installed simulators
    logging.getLogger(__name__).debug("lerobot_rnd.sim not available: %s", err)
