"""The last line of a command-line config error says what is wrong.

LeRobot's CLIs parse configs with draccus, which turns an error raised while building a config (for example
`RnDConfig.__post_init__` refusing `--policy.variant=X`) into "Couldn't instantiate class RnDConfig using the
given arguments." on the last line, with the real message tens of lines above it. `install_config_error_hook`
(called by the plugin shim `lerobot_policy_rnd`, not by importing `lerobot_rnd`) adds one line at the end of
such a traceback: ``error: <the message raised by this plugin>``.
"""

from __future__ import annotations

import sys
import traceback
from pathlib import Path
from types import TracebackType

_PACKAGE_DIR = Path(__file__).resolve().parent


def _raised_in_this_package(exc: BaseException) -> bool:
    return any(
        Path(frame.filename).resolve().is_relative_to(_PACKAGE_DIR)
        for frame in traceback.extract_tb(exc.__traceback__)
    )


def plugin_config_error(exc: BaseException) -> BaseException | None:
    """The error raised by this package that a draccus parsing/decoding error wraps, or None."""
    if type(exc).__module__.split(".")[0] != "draccus":
        return None
    seen: set[int] = set()
    cause = exc.__cause__ or exc.__context__
    while cause is not None and id(cause) not in seen:
        seen.add(id(cause))
        if _raised_in_this_package(cause) and type(cause).__module__.split(".")[0] != "draccus":
            return cause
        cause = cause.__cause__ or cause.__context__
    return None


def config_error_line(exc: BaseException) -> str | None:
    """``error: <message>`` for a draccus error that wraps an error of this package, else None."""
    cause = plugin_config_error(exc)
    return None if cause is None else f"error: {cause}"


def install_config_error_hook() -> None:
    """Chain a `sys.excepthook` that prints the usual traceback, then the plugin's message as the last line."""
    previous = sys.excepthook
    if getattr(previous, "_rnd_config_error_hook", False):
        return

    def hook(exc_type: type[BaseException], exc: BaseException, tb: TracebackType | None) -> None:
        previous(exc_type, exc, tb)
        line = config_error_line(exc)
        if line is not None:
            print(line, file=sys.stderr)

    hook._rnd_config_error_hook = True  # type: ignore[attr-defined]
    sys.excepthook = hook
