"""Subprocesses: the lerobot tools' command lines, running one with its log, time budget and signals, and the
wrappers that run the tools with the plugin imported first."""

from __future__ import annotations

import contextlib
import datetime as dt
import importlib.metadata
import os
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from . import ENTRY_POINT, REPO_ROOT


def git_commit() -> str | None:
    """The repository's commit (with "+dirty" when lerobot_rnd/ or benchmarks/ have local changes), or None."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO_ROOT, capture_output=True,
                              text=True, check=True, timeout=10).stdout.strip()  # fmt: skip
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "lerobot_rnd", "benchmarks/run_benchmark.py",
                                "benchmarks/harness"],
                               cwd=REPO_ROOT, capture_output=True, text=True, check=True, timeout=10).stdout  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return None
    return head + ("+dirty" if dirty.strip() else "")


def _plugin_installed() -> bool:
    try:
        importlib.metadata.distribution("lerobot_policy_rnd")
        return True
    except importlib.metadata.PackageNotFoundError:
        return False


def tool_argv(tool: str, launcher: str) -> list[str]:
    """argv prefix for lerobot-train / lerobot-eval / lerobot-rnd-record.

    ``cli`` runs the console scripts (LeRobot finds the plugin by its installed distribution); ``module``
    runs this file's thin wrappers, which import ``lerobot_rnd`` first (for machines where the project is
    on PYTHONPATH but not pip-installed, such as the offline GPU machine); ``auto`` picks ``cli`` when the
    scripts and the plugin distribution are installed.
    """
    if launcher == "auto":
        bindir = Path(sys.executable).parent
        found = all((bindir / t).exists() or shutil.which(t) for t in ("lerobot-train", "lerobot-eval"))
        launcher = "cli" if found and _plugin_installed() else "module"
    if launcher == "cli":
        bindir = Path(sys.executable).parent
        exe = bindir / tool
        return [str(exe) if exe.exists() else tool]
    return [sys.executable, str(ENTRY_POINT), f"_{tool}"]


@dataclass
class ProcResult:
    rc: int | None
    wall_s: float
    stopped: str | None = None  # "deadline" | "checkpoint" | None
    marks: dict = field(default_factory=dict)
    tail: str = ""


def run_logged(argv: list[str], log_path: Path, deadline: float | None = None, poll=None,
               env: dict | None = None, dry_run: bool = False, marks: dict | None = None) -> ProcResult:  # fmt: skip
    """Run ``argv`` in its own process group, stdout+stderr appended to ``log_path``.

    Stops it (SIGTERM, then SIGKILL) at ``deadline`` or when ``poll()`` returns a reason. ``marks`` (the
    caller's dict, filled while the command runs, so that ``poll`` can read it; a new one when None) holds
    the wall-clock time of the first "Start offline training" line (the start of LeRobot's training loop).
    """
    log_path.parent.mkdir(parents=True, exist_ok=True)
    print(f"$ {shlex.join(argv)}", flush=True)
    if dry_run:
        return ProcResult(rc=0, wall_s=0.0)
    t0 = time.time()
    marks = {} if marks is None else marks
    tail: list[bytes] = []
    with open(log_path, "ab") as log:
        log.write(f"\n# {dt.datetime.now().isoformat(timespec='seconds')}\n$ {shlex.join(argv)}\n".encode())
        log.flush()
        proc = subprocess.Popen(
            argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True, env=env,
            cwd=str(REPO_ROOT),
        )  # fmt: skip

        def reader():
            for line in iter(proc.stdout.readline, b""):
                log.write(line)
                log.flush()
                tail.append(line[-2000:])
                del tail[:-60]
                if b"Start offline training" in line and "train_loop_start" not in marks:
                    marks["train_loop_start"] = time.time()

        th = threading.Thread(target=reader, daemon=True)
        th.start()
        stopped = None
        while proc.poll() is None:
            time.sleep(0.5)
            if deadline is not None and time.time() >= deadline:
                stopped = "deadline"
            elif poll is not None:
                stopped = poll()
            if stopped:
                print(f"  stopping ({stopped})", flush=True)
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGTERM)
                try:
                    proc.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    with contextlib.suppress(ProcessLookupError):
                        os.killpg(proc.pid, signal.SIGKILL)
                    proc.wait()
                break
        th.join(timeout=10)
        end = time.time()
        log.write(f"# exit {proc.returncode} after {end - t0:.1f} s{' (' + stopped + ')' if stopped else ''}\n".encode())
    text = b"".join(tail).decode(errors="replace")
    text = "\n".join(s.split("\r")[-1] for s in text.splitlines())  # drop progress-bar redraws
    return ProcResult(rc=proc.returncode, wall_s=end - t0, stopped=stopped, marks=marks, tail=text[-4000:])


class OutOfTime(Exception):
    """The --max-minutes budget does not leave room for the next piece of work."""


# wrappers run as subprocesses (``run_benchmark.py _lerobot-train ...``): the lerobot tools with the plugin
# imported first
def _exec_tool(tool: str, args: list[str]) -> int:
    sys.path.insert(0, str(REPO_ROOT))
    # Every method reads the dataset the same way (the plugin's column-first query), so the comparison is fair.
    os.environ.setdefault("LEROBOT_RND_PATCH_ALL", "1")
    import lerobot_policy_rnd  # noqa: F401  (registers --policy.type=rnd and --env.type=rnd_mw)

    sys.argv = [tool, *args]
    if tool == "lerobot-train":
        from lerobot.scripts.lerobot_train import main
    elif tool == "lerobot-eval":
        from lerobot.scripts.lerobot_eval import main
    elif tool == "lerobot-rnd-record":
        from lerobot_rnd.sim.record import main

        return main(args) or 0
    else:
        raise SystemExit(f"unknown tool {tool}")
    main()
    return 0
