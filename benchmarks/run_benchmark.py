#!/usr/bin/env python
"""Success-rate benchmark: R&D (A, I, AI) against LeRobot's ACT and Diffusion Policy on MetaWorld.

The command line of the harness in ``benchmarks/harness/`` (one module per concept; docs/DESIGN.md lists
them). ``python benchmarks/run_benchmark.py --help`` prints what it does and every flag; benchmarks/README.md
has the commands. The harness also runs this file for its subprocess wrappers (``_lerobot-train``,
``_lerobot-eval``, ``_lerobot-rnd-record``, ``_grid_eval``). The names below are re-exported for scripts and
tests that imported them from here; new code imports them from ``benchmarks.harness``.
"""

from __future__ import annotations

import sys
from pathlib import Path

_REPO = str(Path(__file__).resolve().parents[1])
if _REPO not in sys.path:  # run as a script, sys.path[0] is benchmarks/
    sys.path.insert(0, _REPO)

from benchmarks.harness.cli import main, parse_args
from benchmarks.harness.grid_eval import GRID_DIMS
from benchmarks.harness.processes import OutOfTime, ProcResult, git_commit, run_logged, tool_argv
from benchmarks.harness.reports import (
    cell_stats,
    markdown_report,
    plot_heatmap,
    plot_loss_curves,
    plot_success_per_task,
    plot_success_vs_demos,
    rnd_losses,
    wilson_interval,
)
from benchmarks.harness.runs import EXIT_FAILED, EXIT_MORE, EXIT_OK, HARNESS_VERSION, Benchmark
from benchmarks.harness.scales import COMMON_METHOD_ARGS, METHODS, RND_METHODS, SCALES, method_family

__all__ = [
    "COMMON_METHOD_ARGS", "EXIT_FAILED", "EXIT_MORE", "EXIT_OK", "GRID_DIMS", "HARNESS_VERSION", "METHODS",
    "RND_METHODS", "SCALES", "Benchmark", "OutOfTime", "ProcResult", "cell_stats", "git_commit", "main",
    "markdown_report", "method_family", "parse_args", "plot_heatmap", "plot_loss_curves", "plot_success_per_task",
    "plot_success_vs_demos", "rnd_losses", "run_logged", "tool_argv", "wilson_interval",
]  # fmt: skip

if __name__ == "__main__":
    sys.exit(main())
