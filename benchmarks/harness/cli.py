"""The command line of benchmarks/run_benchmark.py: flags and per-scale defaults, and main (the benchmark, the
reports alone, or one of the wrappers the harness runs as subprocesses)."""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from . import REPO_ROOT
from . import __doc__ as OVERVIEW  # the --help text
from .grid_eval import main as _grid_eval
from .processes import _exec_tool
from .reports import rnd_losses, write_report_files
from .runs import EXIT_OK, Benchmark
from .scales import METHODS, SCALES, SUITES, suite_scale_defaults


def _csv(s: str, cast=str) -> list:
    return [cast(x.strip()) for x in str(s).split(",") if x.strip()]


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=OVERVIEW, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scale", choices=sorted(SCALES), required=True)
    p.add_argument("--suite", choices=list(SUITES), default="metaworld",
                   help="metaworld (--env.type=rnd_mw, policies_config/metaworld/), panda (--env.type=rnd_panda, "
                        "policies_config/panda/) or so101 (--env.type=rnd_so101, policies_config/so101/); the last "
                        "two: smoke and cpu scales")  # fmt: skip
    p.add_argument("--calibration", choices=["measured", "exact"], default="measured",
                   help="so101: the demos' cameras, measured by lerobot-rnd-calibrate on a simulated calibration "
                        "session (default) or MuJoCo's exact ones")  # fmt: skip
    p.add_argument("--tasks", help="comma-separated tasks of the suite: MetaWorld V3 or Panda (scale default)")
    p.add_argument("--demos", help="comma-separated demo counts (scale default)")
    p.add_argument("--methods", default=",".join(METHODS), help=f"subset of {','.join(METHODS)}")
    p.add_argument("--out", help="results folder (default benchmarks/results/<scale>, Panda: panda_<scale>)")
    p.add_argument("--work-dir", help="datasets-free working folder: checkpoints, logs, eval outputs "
                                      "(default outputs/benchmark/<name of --out>)")  # fmt: skip
    p.add_argument("--data-dir", default=str(REPO_ROOT / "outputs" / "benchmark" / "data"),
                   help="recorded datasets, shared between benchmarks")  # fmt: skip
    p.add_argument("--protocol", choices=["random", "spatial"], default="random",
                   help="random: uniform placements, seeded evaluation; spatial: furthest-point-sampled demos, "
                        "evaluation on a grid, heat maps")  # fmt: skip
    p.add_argument("--multitask", action="store_true",
                   help="one policy per method and demo count trained on all --tasks together (one dataset with "
                        "--demos of each task, every frame with its task's description) and evaluated on each task "
                        "(lerobot-eval --env.task=a,b,c); random protocol only")  # fmt: skip
    p.add_argument("--seed", default="0", help="training seed(s), comma-separated (one run per seed)")
    p.add_argument("--record-seed", type=int, default=0, help="placement seed of the recorded demos")
    p.add_argument("--eval-seed", type=int, default=1000, help="first evaluation seed (episode i: seed + i)")
    p.add_argument("--eval-episodes", type=int, help="evaluation episodes per task and demo count")
    p.add_argument("--eval-chunk", type=int, help="episodes per lerobot-eval call (0: all in one)")
    p.add_argument("--eval-batch-size", type=int, help="parallel envs per lerobot-eval call")
    p.add_argument("--episode-length", type=int, help="env steps before an episode fails")
    p.add_argument("--grid", type=int, help="spatial protocol: G x G evaluation grid (over the first two grid dims)")
    p.add_argument("--grid-dims", help="spatial protocol: two or three placement coordinates, e.g. 0,1 (object x, y; "
                                       "MetaWorld default) or 0,1,2 (object x, y, yaw; Panda default)")  # fmt: skip
    p.add_argument("--grid-yaws", type=int,
                   help="spatial protocol, three grid dims: points on the third (Panda: yaw; scale default 3, so a "
                        "3 x 3 grid has 27 cells)")  # fmt: skip
    p.add_argument("--steps", type=int, help="training steps (same for every method)")
    p.add_argument("--batch-size", type=int)
    p.add_argument("--save-freq", type=int, help="checkpoint every N steps (0: only at the end)")
    p.add_argument("--log-freq", type=int)
    p.add_argument("--num-workers", type=int)
    p.add_argument("--device")
    p.add_argument("--image-size", type=int,
                   help="camera images' side in pixels, for the demos (the recorder's --image-size), R&D's "
                        "--policy.image_size and the evaluation (default: the recorder's 128); the datasets of "
                        "another size are named with _img<N>")  # fmt: skip
    p.add_argument("--extra-steps", type=int,
                   help="frames the demos go on after the expert's first success (the recorder's --extra-steps, "
                        "default 10; e.g. 40 for demos that hold at the goal); the datasets of another value are "
                        "named with _x<N>")  # fmt: skip
    p.add_argument("--train-arg", action="append",
                   help="extra lerobot-train argument for some methods: 'METHOD:--x=y', 'rnd:--x=y' (all R&D "
                        "variants) or 'all:--x=y'; repeatable")  # fmt: skip
    p.add_argument("--collect-from", default="",
                   help="comma-separated results folders of other benchmarks: a run this one has not done is taken "
                        "from the first of them whose runs/ holds it finished (nothing is copied; the report names "
                        "each run's source). Their steps, batch, seeds and episodes must match this benchmark's")  # fmt: skip
    p.add_argument("--resume", action="store_true", help="continue the benchmark in --work-dir")
    p.add_argument("--retry-failed", action="store_true", help="with --resume: run failed runs again")
    p.add_argument("--eval-only", action="store_true", help="evaluate existing checkpoints, train nothing")
    p.add_argument("--train-only", action="store_true",
                   help="train (or finish training), evaluate nothing: e.g. to validate a checkpoint on other "
                        "seeds first; a later --resume evaluates it")  # fmt: skip
    p.add_argument("--max-minutes", type=float, help="time budget of this invocation (exit 3 if work remains)")
    p.add_argument("--min-train-slice-s", type=float,
                   help="do not start a training slice with less time left (smoke 30, gpu 180); keep "
                        "--save-freq steps well inside one slice, or no slice ever reaches a checkpoint")  # fmt: skip
    p.add_argument("--eval-chunk-estimate-s", type=float, default=150.0,
                   help="assumed duration of the first evaluation chunk")  # fmt: skip
    p.add_argument("--exit-margin-s", type=float, default=20.0)
    p.add_argument("--keep-checkpoints", action="store_true", help="keep every checkpoint, not only the last")
    p.add_argument("--prune-optimizer", action=argparse.BooleanOptionalAction, default=None,
                   help="delete the optimiser state of a finished run (default: on at gpu scale)")  # fmt: skip
    p.add_argument("--launcher", choices=["auto", "cli", "module"], default="auto")
    p.add_argument("--stop-after-checkpoints", type=int, default=0, help=argparse.SUPPRESS)  # resume tests
    p.add_argument("--dry-run", action="store_true", help="print the commands, run nothing")
    p.add_argument("--reports-only", action="store_true",
                   help="rewrite results.md and the plots from --out/results.json, run nothing")  # fmt: skip
    a = p.parse_args(argv)
    try:
        d = suite_scale_defaults(a.suite, a.scale)
    except ValueError as e:
        p.error(str(e))
    for k in ("tasks", "demos", "eval_episodes", "eval_chunk", "eval_batch_size", "episode_length", "grid",
              "grid_yaws", "steps", "batch_size", "save_freq", "log_freq", "num_workers", "device",
              "min_train_slice_s"):  # fmt: skip
        if getattr(a, k) is None:
            setattr(a, k, d[k])
    a.tasks = _csv(a.tasks)
    a.demos = sorted(_csv(a.demos, int))
    a.methods = _csv(a.methods)
    bad = [m for m in a.methods if m not in METHODS]
    if bad:
        p.error(f"unknown methods {bad}; choose from {list(METHODS)}")
    a.seeds = _csv(a.seed, int)
    a.collect_from = _csv(a.collect_from)
    a.grid_dims = _csv(a.grid_dims, int) if a.grid_dims else None
    if a.image_size is not None and a.image_size <= 0:
        p.error(f"--image-size must be a positive number of pixels, got {a.image_size}")
    if a.extra_steps is not None and a.extra_steps < 0:
        p.error(f"--extra-steps must be >= 0 frames, got {a.extra_steps}")
    if a.grid_dims is not None and len(a.grid_dims) not in (2, 3):
        p.error("--grid-dims takes two or three coordinates")
    if a.suite != "metaworld":
        from lerobot_rnd.sim.record import SUITE_NAMES, suite_tasks

        bad = [t for t in a.tasks if t not in suite_tasks(a.suite)]
        if bad:
            p.error(f"--suite {a.suite}: {bad} are not {SUITE_NAMES[a.suite]} tasks; tasks: "
                    f"{', '.join(suite_tasks(a.suite))}")  # fmt: skip
    if a.calibration == "exact" and a.suite != "so101":
        p.error("--calibration applies to --suite so101 (the other suites' demos carry MuJoCo's cameras)")
    if a.multitask and len(a.tasks) < 2:
        p.error("--multitask trains one policy on several tasks: name two or more with --tasks")
    if a.multitask and a.protocol != "random":
        p.error("--multitask evaluates with lerobot-eval's seeded placements: use --protocol random")
    if a.train_only and a.eval_only:
        p.error("--train-only and --eval-only exclude each other")
    if a.prune_optimizer is None:
        a.prune_optimizer = a.scale == "gpu"
    a.out = a.out or str(REPO_ROOT / "benchmarks" / "results" / (a.scale if a.suite == "metaworld" else f"{a.suite}_{a.scale}"))
    a.work_dir = a.work_dir or str(REPO_ROOT / "outputs" / "benchmark" / Path(a.out).name)
    return a


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] in ("_lerobot-train", "_lerobot-eval", "_lerobot-rnd-record"):
        return _exec_tool(argv[0][1:], argv[1:])
    if argv and argv[0] == "_grid_eval":
        return _grid_eval(argv[1:])
    os.environ.setdefault("MUJOCO_GL", "egl")
    os.environ["HF_HUB_OFFLINE"] = "1"
    sys.path.insert(0, str(REPO_ROOT))
    a = parse_args(argv)
    if a.reports_only:
        res = json.loads((Path(a.out) / "results.json").read_text())
        res["rnd_losses"] = rnd_losses(res["runs"])
        write_report_files(res, Path(a.out))
        return EXIT_OK
    return Benchmark(a).run()
