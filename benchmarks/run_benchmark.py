#!/usr/bin/env python
"""Success-rate benchmark: R&D (A, I, AI) against LeRobot's ACT and Diffusion Policy on MetaWorld.

One command records (or reuses) scripted demonstrations for every task and demo count, trains every
method on the same demos with matched settings through ``lerobot-train``, evaluates every checkpoint on the
same held-out placements through ``lerobot-eval`` and writes, in ``--out``:

    results.json          every run: method, task, demos, seed, steps, training time, parameters, evaluation
                          episodes and seeds, successes, success rate, Wilson 95% interval, checkpoint and the
                          exact commands; the datasets (placements) and the held-out check
    results.md            success table (rows: methods, columns: task x demos, plus the average), training
                          time / size table, and where R&D loses
    success_vs_demos.png  success rate against the number of demos, per task and averaged, Wilson bars
    heatmap_<task>.png    (--protocol spatial) success over the placement grid, training placements marked

    python benchmarks/run_benchmark.py --scale smoke --out benchmarks/results/smoke           # CPU, minutes
    python benchmarks/run_benchmark.py --scale gpu --tasks reach-v3,push-v3 --demos 10,20 \\
        --out benchmarks/results/gpu --resume --max-minutes 9                                # one GPU slice

Scales (every value can be overridden on the command line; see benchmarks/README.md):
  smoke  CPU, tiny models (R&D 1 x 64, ACT 64-wide, DP [32, 64]), 2 steps of batch 2, 2 evaluation
         episodes of 16 steps: proves the pipeline, says nothing about the methods.
  gpu    CUDA, ~100M parameters each (R&D paper size 8 x 1024: 107M; ACT 768-wide, 6 encoder layers: 92M;
         DP U-Net [640, 1280]: 107M), batch 32 x 25k steps (= the paper's 8 x 100k samples), 50 evaluation
         episodes per task and demo count, 300-step episodes.

Matched settings: every method trains on the same recorded demos (the n-demo set is the first n episodes of
the larger sets: recorded once, then extended with the recorder's --resume), with the same seed, batch size,
number of steps and checkpoint schedule, no pretrained weights (nothing is downloaded: ACT's ImageNet
backbone is switched off), observation history 2 (ACT: 1, the only value LeRobot's ACT accepts) and an
8-step action chunk executed open loop (DP: horizon 12 = 1 past + 8 executed + 3 for the U-Net's 4x
downsampling, of which 8 are executed). Each method keeps its own optimiser preset (learning rate, schedule).

Held-out placements: demos are recorded with placements drawn from ``numpy.random.default_rng(record_seed)``
(--protocol random) or by furthest point sampling (spatial). ``lerobot-eval --seed=S --eval.n_episodes=N``
resets episode i's env with ``seed=S+i``; the ``rnd_mw`` env then draws its placement from a generator
seeded with S+i (the same PCG64 stream a recorder with ``--seed S+i`` would start with), so the evaluation
seeds must not include the recording seed. The harness computes every evaluation placement and stores its
distance to the nearest training placement in results.json. The spatial protocol evaluates one episode on
every valid point of a grid over two placement coordinates (the others at the centre of their range), with
an in-process copy of lerobot-eval's loop (``rnd_mw`` takes no placement list on the command line).

Time budget and resumption: with ``--max-minutes M`` the harness stops starting work that would not fit,
stops training cleanly (right after a checkpoint when the next one would not fit, otherwise at the deadline,
losing the steps since the last checkpoint) and exits with code 3; run the same command again with
``--resume`` to continue: training resumes from ``checkpoints/last`` with ``lerobot-train --resume=true``
(same total --steps, so learning-rate schedules are unchanged), evaluation continues chunk by chunk, finished
runs are skipped. Exit codes: 0 complete, 3 work remains, 1 some run failed (its log tail is in
results.json).
"""

from __future__ import annotations

import argparse
import contextlib
import datetime as dt
import importlib.metadata
import json
import math
import os
import platform
import re
import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
CONFIG_DIR = REPO_ROOT / "policies_config" / "metaworld"
HARNESS_VERSION = 1
EXIT_OK, EXIT_FAILED, EXIT_MORE = 0, 1, 3

METHODS = {  # name -> (config file, label)
    "rnd_ai": ("rnd_ai.json", "R&D-AI"),
    "rnd_a": ("rnd_a.json", "R&D-A"),
    "rnd_i": ("rnd_i.json", "R&D-I"),
    "act": ("act.json", "ACT"),
    "diffusion": ("diffusion.json", "Diffusion Policy"),
}
RND_METHODS = ("rnd_ai", "rnd_a", "rnd_i")

# Per-scale defaults (CLI flags override) and per-method lerobot-train overrides.
SCALES: dict[str, dict] = {
    "smoke": dict(
        tasks="reach-v3", demos="3", device="cpu", steps=2, batch_size=2, save_freq=0, log_freq=1,
        num_workers=0, eval_episodes=2, eval_chunk=0, eval_batch_size=2, episode_length=16, grid=3,
        min_train_slice_s=30,
        method_args={
            "rnd": ["--policy.dim_model=64", "--policy.n_layers=1", "--policy.n_heads=4",
                    "--policy.stats_num_samples=16"],
            "act": ["--policy.dim_model=64", "--policy.n_heads=4", "--policy.dim_feedforward=128",
                    "--policy.n_encoder_layers=1", "--policy.n_decoder_layers=1",
                    "--policy.n_vae_encoder_layers=1", "--policy.latent_dim=8"],
            "diffusion": ["--policy.down_dims=[32,64]", "--policy.diffusion_step_embed_dim=32",
                          "--policy.spatial_softmax_num_keypoints=8"],
        },
    ),
    "gpu": dict(
        tasks="reach-v3,push-v3", demos="10,20", device="cuda", steps=25000, batch_size=32, save_freq=1000,
        log_freq=200, num_workers=4, eval_episodes=50, eval_chunk=10, eval_batch_size=10, episode_length=300,
        grid=8, min_train_slice_s=180,
        method_args={
            "rnd": [],  # paper size from the config: 8 layers x 1024, 16 heads (107M)
            "act": ["--policy.dim_model=768", "--policy.n_heads=12", "--policy.dim_feedforward=3072",
                    "--policy.n_encoder_layers=6"],  # 92M
            "diffusion": ["--policy.down_dims=[640,1280]"],  # 107M
        },
    ),
}
SCALES["cpu"] = dict(
    tasks="reach-v3,button-press-topdown-v3,drawer-close-v3", demos="10", device="cpu", steps=2000, batch_size=8,
    save_freq=250, log_freq=50, num_workers=2, eval_episodes=50, eval_chunk=10, eval_batch_size=10,
    episode_length=300, grid=5, min_train_slice_s=120,
    # Each method at its own CPU size (policies_config/metaworld/*_cpu.json): R&D's CPU tier (patch 32,
    # 4 gripper patches per future frame, width 256 x 4 layers, bf16 autocast: 6.5M), ACT as configured for
    # MetaWorld (51.6M, mostly its ResNet-18), DP with a [128, 256, 512] U-Net (29.5M incl. its ResNet-18).
    config_files={"rnd_ai": "rnd_ai_cpu.json", "rnd_a": "rnd_ai_cpu.json", "rnd_i": "rnd_ai_cpu.json",
                  "act": "act_cpu.json", "diffusion": "diffusion_cpu.json"},
    method_args={"rnd": [], "act": [], "diffusion": [],
                 "rnd_a": ["--policy.variant=A"], "rnd_i": ["--policy.variant=I"]},
)
# Applied at every scale: matched horizons, no downloads, no Hub.
COMMON_METHOD_ARGS = {
    "rnd": ["--policy.n_obs_steps=2", "--policy.chunk_size=8", "--policy.n_action_steps=8"],
    "act": ["--policy.n_obs_steps=1", "--policy.chunk_size=8", "--policy.n_action_steps=8",
            "--policy.pretrained_backbone_weights=null"],
    "diffusion": ["--policy.n_obs_steps=2", "--policy.horizon=12", "--policy.n_action_steps=8",
                  "--policy.pretrained_backbone_weights=null"],
}  # fmt: skip
GRID_DIMS = {"reach-v3": (3, 4), "reach-wall-v3": (3, 4)}  # goal x, y; other tasks: object x, y


def method_family(method: str) -> str:
    return "rnd" if method in RND_METHODS else method


# --------------------------------------------------------------------------------------------------
# statistics
# --------------------------------------------------------------------------------------------------
def wilson_interval(successes: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion (95% by default); (nan, nan) for n = 0."""
    if n <= 0:
        return (float("nan"), float("nan"))
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


def git_commit() -> str | None:
    """The repository's commit (with "+dirty" when lerobot_rnd/ or benchmarks/ have local changes), or None."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO_ROOT, capture_output=True,
                              text=True, check=True, timeout=10).stdout.strip()  # fmt: skip
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "lerobot_rnd", "benchmarks/run_benchmark.py"],
                               cwd=REPO_ROOT, capture_output=True, text=True, check=True, timeout=10).stdout  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return None
    return head + ("+dirty" if dirty.strip() else "")


# --------------------------------------------------------------------------------------------------
# subprocesses
# --------------------------------------------------------------------------------------------------
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
    return [sys.executable, str(Path(__file__).resolve()), f"_{tool}"]


@dataclass
class ProcResult:
    rc: int | None
    wall_s: float
    stopped: str | None = None  # "deadline" | "checkpoint" | None
    marks: dict = field(default_factory=dict)
    tail: str = ""


def run_logged(argv: list[str], log_path: Path, deadline: float | None = None, poll=None,
               env: dict | None = None, dry_run: bool = False) -> ProcResult:  # fmt: skip
    """Run ``argv`` in its own process group, stdout+stderr appended to ``log_path``.

    Stops it (SIGTERM, then SIGKILL) at ``deadline`` or when ``poll()`` returns a reason. ``marks`` holds
    the wall-clock time of the first "Start offline training" line (the start of LeRobot's training loop).
    """
    log_path.parent.mkdir(parents=True, exist_ok=True)
    print(f"$ {shlex.join(argv)}", flush=True)
    if dry_run:
        return ProcResult(rc=0, wall_s=0.0)
    t0 = time.time()
    marks: dict = {}
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


# --------------------------------------------------------------------------------------------------
# the harness
# --------------------------------------------------------------------------------------------------
def _csv(s: str, cast=str) -> list:
    return [cast(x.strip()) for x in str(s).split(",") if x.strip()]


def _read_json(path: Path, default=None):
    try:
        return json.loads(Path(path).read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return default


def _write_json(path: Path, obj) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(obj, indent=1, default=_json_default))
    os.replace(tmp, path)


def _json_default(o):
    if isinstance(o, Path):
        return str(o)
    try:
        import numpy as np

        if isinstance(o, np.generic):
            return o.item()
        if isinstance(o, np.ndarray):
            return o.tolist()
    except ImportError:  # pragma: no cover
        pass
    raise TypeError(f"not JSON serialisable: {type(o)}")


def _rel(p: Path) -> str:
    p = Path(p).resolve()
    try:
        return str(p.relative_to(REPO_ROOT))
    except ValueError:
        return str(p)


class Benchmark:
    def __init__(self, a: argparse.Namespace):
        self.a = a
        self.out = Path(a.out).resolve()
        self.work = Path(a.work_dir).resolve()
        self.data_dir = Path(a.data_dir).resolve()
        self.deadline = None if a.max_minutes is None else time.time() + 60.0 * a.max_minutes
        self.state_path = self.work / "state.json"
        self.started = dt.datetime.now().isoformat(timespec="seconds")
        self.datasets: dict = {}
        self.eval_sets: dict = {}
        self.more_work = False
        self.failed = False

    # ------------------------------------------------------------------ budget
    def remaining(self) -> float:
        return math.inf if self.deadline is None else self.deadline - time.time()

    def need(self, seconds: float, what: str) -> None:
        if self.remaining() < seconds:
            raise OutOfTime(f"{what}: needs ~{seconds:.0f} s, {max(0, self.remaining()):.0f} s left")

    # ------------------------------------------------------------------ datasets
    def dataset_root(self, task: str, n: int) -> tuple[Path, str]:
        a = self.a
        mode = "fps" if a.protocol == "spatial" else "random"
        name = f"mw_{task}_{mode}_s{a.record_seed}_n{n}"
        return self.data_dir / name, f"local/{name}"

    def record(self, task: str) -> None:
        """Record (or reuse, or extend) one dataset per demo count; smaller sets are prefixes of larger."""
        a = self.a
        mode = "fps" if a.protocol == "spatial" else "random"
        prev_root = None
        self.datasets[task] = {}
        for n in sorted(a.demos):
            root, repo_id = self.dataset_root(task, n)
            info = _read_json(root / "meta" / "info.json")
            have = int(info.get("total_episodes", 0)) if info else 0
            if have < n:
                if root.exists() and info is None:
                    shutil.rmtree(root)
                resume = root.exists()
                if not root.exists() and prev_root is not None:  # extend the previous (smaller) set
                    shutil.copytree(prev_root, root)
                    resume = True
                self.need(60 + 8.0 * (n - (have if resume else 0)), f"recording {root.name}")
                argv = tool_argv("lerobot-rnd-record", a.launcher) + [
                    "--task", task, "--episodes", str(n), "--root", str(root), "--repo-id", repo_id,
                    "--placements", mode, "--seed", str(a.record_seed),
                ] + (["--resume"] if resume else [])  # fmt: skip
                r = run_logged(argv, self.work / "logs" / f"record_{root.name}.log", env=self.env(),
                               dry_run=a.dry_run)  # fmt: skip
                if r.rc != 0:
                    raise RuntimeError(f"recording {root} failed (rc {r.rc}):\n{r.tail}")
            rec = _read_json(root / "meta" / "rnd_recording.json", {}) or {}
            kept = [x for x in rec.get("attempts", []) if x.get("success")]
            kept.sort(key=lambda x: x["episode_index"])
            info = _read_json(root / "meta" / "info.json", {}) or {}
            self.datasets[task][n] = {
                "root": _rel(root), "repo_id": repo_id, "placements_mode": mode, "record_seed": a.record_seed,
                "episodes": info.get("total_episodes"), "frames": info.get("total_frames"),
                "placements": [x["placement"] for x in kept][:n],
                "placement_indices": [x["placement_index"] for x in kept][:n],
                "expert_failures": sum(1 for x in rec.get("attempts", []) if not x.get("success")),
            }  # fmt: skip
            prev_root = root
        # check the nesting (smaller sets = first episodes of the larger ones)
        ns = sorted(self.datasets[task])
        for small, big in zip(ns, ns[1:], strict=False):
            s, b = self.datasets[task][small], self.datasets[task][big]
            s["prefix_of_next"] = bool(b["placements"][: len(s["placements"])] == s["placements"])

    # ------------------------------------------------------------------ evaluation placements
    def eval_set(self, task: str) -> dict:
        """Evaluation placements of ``task`` (random: one per seed; spatial: the grid) + held-out check."""
        if task in self.eval_sets:
            return self.eval_sets[task]
        import numpy as np

        from lerobot_rnd.sim.metaworld_env import RnDMetaWorldEnv

        a = self.a
        env = RnDMetaWorldEnv(task, episode_length=a.episode_length)
        sp = env.placement_space
        low, high = np.asarray(sp.low, float), np.asarray(sp.high, float)
        span = np.where(high - low > 0, high - low, 1.0)
        out: dict = {"protocol": a.protocol}
        try:
            if a.protocol == "random":
                seeds = list(range(a.eval_seed, a.eval_seed + a.eval_episodes))
                placements = []
                for s in seeds:
                    env.reset(seed=s)
                    placements.append([float(v) for v in env.placement])
                out.update(seeds=seeds, placements=placements)
            else:
                dims = tuple(a.grid_dims) if a.grid_dims else GRID_DIMS.get(task)
                if dims is None:
                    varying = [i for i in range(len(low)) if high[i] > low[i]]
                    dims = tuple(varying[:2])
                centre = (low + high) / 2
                xs = np.linspace(low[dims[0]], high[dims[0]], a.grid)
                ys = np.linspace(low[dims[1]], high[dims[1]], a.grid)
                points, cells = [], []
                for iy, y in enumerate(ys):
                    for ix, x in enumerate(xs):
                        p = centre.copy()
                        p[dims[0]], p[dims[1]] = x, y
                        if env.is_valid_placement(p):
                            points.append([float(v) for v in p])
                            cells.append([iy, ix])
                out.update(grid_dims=list(dims), grid_x=xs.tolist(), grid_y=ys.tolist(), placements=points,
                           cells=cells, n_invalid=a.grid * a.grid - len(points),
                           seeds=[a.eval_seed] * len(points))  # fmt: skip
        finally:
            env.close()
        # held-out check against every training placement of this task
        train = [p for d in self.datasets.get(task, {}).values() for p in d["placements"]]
        if train and out["placements"]:
            P = (np.asarray(out["placements"]) - low) / span
            T = (np.asarray(train) - low) / span
            d = np.linalg.norm(P[:, None, :] - T[None, :, :], axis=-1).min(axis=1)
            out["min_normalised_distance_to_train"] = float(d.min())
            out["median_normalised_distance_to_train"] = float(np.median(d))
            out["n_equal_to_a_train_placement"] = int((d < 1e-9).sum())
        if a.protocol == "random" and a.record_seed in out.get("seeds", []):
            raise ValueError(
                f"evaluation seeds {a.eval_seed}..{a.eval_seed + a.eval_episodes - 1} include the recording "
                f"seed {a.record_seed}: the first evaluation placement of that seed is a training placement"
            )
        self.eval_sets[task] = out
        return out

    # ------------------------------------------------------------------ runs
    def env(self) -> dict:
        e = dict(os.environ)
        e.setdefault("MUJOCO_GL", "egl")
        e["HF_HUB_OFFLINE"] = "1"
        e["PYTHONUNBUFFERED"] = "1"
        e["WANDB_MODE"] = "disabled"
        pp = e.get("PYTHONPATH", "")
        if str(REPO_ROOT) not in pp.split(os.pathsep):
            e["PYTHONPATH"] = str(REPO_ROOT) + (os.pathsep + pp if pp else "")
        return e

    def run_dir(self, method: str, task: str, n: int, seed: int) -> Path:
        return self.work / "runs" / self.a.protocol / method / task / f"n{n}" / f"seed{seed}"

    def config_file(self, method: str) -> Path:
        files = SCALES[self.a.scale].get("config_files", {})
        return CONFIG_DIR / files.get(method, METHODS[method][0])

    def method_args(self, method: str) -> list[str]:
        fam = method_family(method)
        per_scale = SCALES[self.a.scale]["method_args"]
        args = list(COMMON_METHOD_ARGS[fam]) + list(per_scale[fam]) + list(per_scale.get(method, []))
        for spec in self.a.train_arg or []:
            who, _, arg = spec.partition(":")
            if who in ("all", method, fam):
                args.append(arg)
        return args

    def train_argv(self, method: str, task: str, n: int, seed: int, out_dir: Path) -> list[str]:
        a = self.a
        root, repo_id = self.dataset_root(task, n)
        save_freq = a.save_freq if a.save_freq > 0 else a.steps
        return tool_argv("lerobot-train", a.launcher) + [
            f"--config_path={self.config_file(method)}",
            f"--dataset.repo_id={repo_id}", f"--dataset.root={root}", "--dataset.video_backend=pyav",
            f"--env.task={task}", f"--env.episode_length={a.episode_length}",
            f"--output_dir={out_dir}", f"--job_name={method}_{task}_n{n}_s{seed}",
            f"--seed={seed}", f"--steps={a.steps}", f"--batch_size={a.batch_size}",
            f"--num_workers={a.num_workers}", f"--save_freq={save_freq}", f"--log_freq={a.log_freq}",
            "--eval_freq=0", "--wandb.enable=false",
            f"--policy.device={a.device}", "--policy.push_to_hub=false",
        ] + self.method_args(method)  # fmt: skip

    def train(self, method: str, task: str, n: int, seed: int, st: dict) -> None:
        """Train (or resume) one run until it has ``--steps`` steps, within the time budget."""
        a = self.a
        rdir = self.run_dir(method, task, n, seed)
        tdir = rdir / "train"
        log = rdir / "train.log"
        ckroot = tdir / "checkpoints"
        while True:
            last = ckroot / "last"
            step = 0
            if last.exists():
                step = int((_read_json(last / "training_state" / "training_step.json", {}) or {}).get("step", 0))
            if step >= a.steps:
                break
            self._prune_checkpoints(ckroot)
            self.need(a.min_train_slice_s, f"training {method} {task} n{n}")
            if step > 0:
                argv = tool_argv("lerobot-train", a.launcher) + [
                    f"--config_path={last / 'pretrained_model' / 'train_config.json'}", "--resume=true",
                ]
                st.setdefault("commands", {})["train_resume"] = argv
            else:
                if tdir.exists():
                    shutil.rmtree(tdir)  # a start that never reached a checkpoint
                argv = self.train_argv(method, task, n, seed, tdir)
                st.setdefault("commands", {})["train"] = argv
            poll = self._checkpoint_poller(ckroot)
            deadline = None if self.deadline is None else self.deadline - a.exit_margin_s
            r = run_logged(argv, log, deadline=deadline, poll=poll, env=self.env(), dry_run=a.dry_run)
            if a.dry_run:
                return
            end_step = 0
            if (ckroot / "last").exists():
                end_step = int((_read_json(ckroot / "last" / "training_state" / "training_step.json", {}) or {}).get("step", 0))
            loop_s = (time.time() - r.marks["train_loop_start"]) if "train_loop_start" in r.marks else None
            if loop_s is not None:
                loop_s = min(loop_s, r.wall_s)
            st.setdefault("train_slices", []).append({
                "start_step": step, "end_step": end_step, "wall_s": round(r.wall_s, 2),
                "loop_s": None if loop_s is None else round(loop_s, 2), "rc": r.rc, "stopped": r.stopped,
            })  # fmt: skip
            self._parse_train_log(log, st)
            _write_json(rdir / "run.json", st)
            if r.stopped:
                hint = ("" if end_step > step else
                        f"; no checkpoint was reached in this slice: lower --save-freq ({a.save_freq})")
                raise OutOfTime(f"training {method} {task} n{n} stopped at step {end_step} / {a.steps}{hint}")
            if r.rc != 0:
                raise RuntimeError(f"lerobot-train failed (rc {r.rc}); log {log}:\n{r.tail}")
            if end_step <= step:
                raise RuntimeError(f"lerobot-train made no progress (step {step}); log {log}:\n{r.tail}")
        self._prune_checkpoints(ckroot)

    def _checkpoint_poller(self, ckroot: Path):
        """Stop training right after a checkpoint when the next one would not fit in the budget."""
        a = self.a
        seen = {"target": self._last_target(ckroot), "t": time.time(), "interval": None, "count": 0}

        def poll():
            tgt = self._last_target(ckroot)
            if tgt is None or tgt == seen["target"]:
                return None
            now = time.time()
            if seen["count"] > 0:
                iv = now - seen["t"]
                seen["interval"] = iv if seen["interval"] is None else max(seen["interval"], iv)
            seen.update(target=tgt, t=now, count=seen["count"] + 1)
            if a.stop_after_checkpoints and seen["count"] >= a.stop_after_checkpoints:
                return "checkpoint"
            if self.deadline is not None and seen["interval"] is not None:
                if now + 1.2 * seen["interval"] > self.deadline - a.exit_margin_s:
                    return "checkpoint"
            return None

        return poll

    @staticmethod
    def _last_target(ckroot: Path) -> str | None:
        last = ckroot / "last"
        try:
            return os.readlink(last) if last.is_symlink() else (str(last) if last.exists() else None)
        except OSError:
            return None

    def _prune_checkpoints(self, ckroot: Path) -> None:
        """Keep only the checkpoint that ``last`` points to (unless --keep-checkpoints)."""
        if self.a.keep_checkpoints or not ckroot.is_dir():
            return
        last = ckroot / "last"
        keep = last.resolve() if last.exists() else None
        for d in ckroot.iterdir():
            if d.name == "last" or not d.is_dir() or d.is_symlink():
                continue
            if keep is None or d.resolve() != keep:
                shutil.rmtree(d, ignore_errors=True)

    @staticmethod
    def _parse_train_log(log: Path, st: dict) -> None:
        try:
            text = log.read_text(errors="replace")
        except FileNotFoundError:
            return
        m = re.findall(r"num_learnable_params=(\d+)", text)
        if m:
            st["n_params"] = int(m[-1])
        m = re.findall(r"num_total_params=(\d+)", text)
        if m:
            st["n_params_total"] = int(m[-1])
        m = re.findall(r"updt_s:([0-9.]+)", text)
        if m:
            st["update_s_last_logged"] = float(m[-1])
            st["update_s_median_logged"] = sorted(float(x) for x in m)[len(m) // 2]
        m = re.findall(r"data_s:([0-9.]+)", text)
        if m:
            st["data_s_median_logged"] = sorted(float(x) for x in m)[len(m) // 2]
        curve = {}
        for step, loss in re.findall(r"step:([0-9.]+K?) .*?loss:([0-9.]+)", text):
            k = int(float(step[:-1]) * 1000) if step.endswith("K") else int(step)
            curve[k] = float(loss)  # a resumed run logs its steps again: the last value wins
        if curve:
            st["loss_curve"] = sorted(curve.items())

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, method: str, task: str, n: int, seed: int, st: dict) -> None:
        a = self.a
        rdir = self.run_dir(method, task, n, seed)
        ckpt = (rdir / "train" / "checkpoints" / "last").resolve() / "pretrained_model"
        st["checkpoint"] = _rel(ckpt)
        es = self.eval_set(task)
        total = len(es["placements"])
        chunk = a.eval_chunk if a.eval_chunk > 0 else total
        chunks = st.setdefault("eval_chunks", {})
        for start in range(0, total, chunk):
            k = min(chunk, total - start)
            key = f"{start}:{start + k}"
            if key in chunks:
                continue
            est = max((c["wall_s"] for c in chunks.values()), default=a.eval_chunk_estimate_s)
            self.need(1.1 * est + a.exit_margin_s, f"evaluating {method} {task} n{n} episodes {key}")
            edir = rdir / "eval" / f"ep{start:04d}-{start + k - 1:04d}"
            if edir.exists():
                shutil.rmtree(edir)
            bs = max(1, min(a.eval_batch_size, k))
            if a.protocol == "random":
                argv = tool_argv("lerobot-eval", a.launcher) + [
                    f"--policy.path={ckpt}", f"--policy.device={a.device}",
                    "--env.type=rnd_mw", f"--env.task={task}", f"--env.episode_length={a.episode_length}",
                    f"--eval.n_episodes={k}", f"--eval.batch_size={bs}", f"--seed={a.eval_seed + start}",
                    f"--output_dir={edir}",
                ]  # fmt: skip
            else:
                pfile = rdir / "eval" / f"grid_{start}.json"
                _write_json(pfile, es["placements"][start : start + k])
                argv = [sys.executable, str(Path(__file__).resolve()), "_grid_eval",
                        f"--policy-path={ckpt}", f"--device={a.device}", f"--task={task}",
                        f"--episode-length={a.episode_length}", f"--batch-size={bs}",
                        f"--seed={a.eval_seed}", f"--placements={pfile}", f"--output-dir={edir}"]  # fmt: skip
            st.setdefault("commands", {}).setdefault("eval", []).append(argv)
            deadline = None if self.deadline is None else self.deadline - a.exit_margin_s
            r = run_logged(argv, rdir / "eval.log", deadline=deadline, env=self.env(), dry_run=a.dry_run)
            if a.dry_run:
                continue
            if r.stopped:
                raise OutOfTime(f"evaluation of {method} {task} n{n} stopped")
            info = _read_json(edir / "eval_info.json")
            if r.rc != 0 or info is None:
                raise RuntimeError(f"evaluation failed (rc {r.rc}); log {rdir / 'eval.log'}:\n{r.tail}")
            succ = [bool(x) for x in info["per_task"][0]["metrics"]["successes"]][:k]
            if len(succ) != k:
                raise RuntimeError(f"eval_info.json holds {len(succ)} episodes, expected {k}")
            chunks[key] = {"successes": succ, "wall_s": round(r.wall_s, 2),
                           "eval_s": info.get("overall", {}).get("eval_s"), "dir": _rel(edir)}  # fmt: skip
            _write_json(rdir / "run.json", st)

    # ------------------------------------------------------------------ driver
    def run(self) -> int:
        a = self.a
        self.out.mkdir(parents=True, exist_ok=True)
        self.work.mkdir(parents=True, exist_ok=True)
        prev = _read_json(self.state_path)
        if prev is not None and not a.resume and not a.dry_run:
            raise SystemExit(f"{self.work} holds an earlier benchmark: pass --resume to continue it, "
                             f"or choose another --out / --work-dir")  # fmt: skip
        if not a.dry_run:
            _write_json(self.state_path, {"args": vars(a), "started": self.started})
        print(f"benchmark: scale {a.scale}, protocol {a.protocol}, tasks {a.tasks}, demos {a.demos}, "
              f"methods {a.methods}, seeds {a.seeds}; work dir {self.work}", flush=True)  # fmt: skip
        try:
            for task in a.tasks:
                self.record(task)
            for task in a.tasks:
                self.eval_set(task)
            for task in a.tasks:
                for n in a.demos:
                    for seed in a.seeds:
                        for method in a.methods:
                            self.run_one(method, task, n, seed)
        except OutOfTime as e:
            print(f"time budget: {e}; run again with --resume to continue", flush=True)
            self.more_work = True
        self.write_reports()
        if self.more_work:
            return EXIT_MORE
        return EXIT_FAILED if self.failed else EXIT_OK

    def result_path(self, method: str, task: str, n: int, seed: int) -> Path:
        """The committed JSON of one finished run (survives a fresh clone; the work dir does not)."""
        return self.out / "runs" / f"{method}__{task}__n{n}__seed{seed}.json"

    def run_state(self, method: str, task: str, n: int, seed: int) -> dict:
        st = _read_json(self.run_dir(method, task, n, seed) / "run.json")
        if st is None:
            st = _read_json(self.result_path(method, task, n, seed))
        return st or {}

    def run_one(self, method: str, task: str, n: int, seed: int) -> None:
        a = self.a
        rdir = self.run_dir(method, task, n, seed)
        st = self.run_state(method, task, n, seed)
        if st.get("status") == "done" and not a.dry_run:
            return
        if st.get("status") == "failed" and not a.retry_failed:
            self.failed = True
            return
        st.update(method=method, task=task, demos=n, seed=seed, protocol=a.protocol, scale=a.scale,
                  status="running", code_commit=st.get("code_commit") or git_commit())  # fmt: skip
        print(f"=== {method} / {task} / {n} demos / seed {seed}", flush=True)
        try:
            if not a.eval_only:
                self.train(method, task, n, seed, st)
            self.evaluate(method, task, n, seed, st)
            if not a.dry_run:
                st["status"] = "done"
                st.pop("error", None)
                self._parse_train_log(rdir / "train.log", st)
                _write_json(self.result_path(method, task, n, seed), st)
                print(f"wrote {self.result_path(method, task, n, seed)}", flush=True)
                if a.prune_optimizer:
                    ts = (rdir / "train" / "checkpoints" / "last").resolve() / "training_state"
                    if ts.is_dir():
                        shutil.rmtree(ts)
                        st["optimizer_state_pruned"] = True
        except OutOfTime:
            raise
        except Exception as e:  # noqa: BLE001 - record the failure and go on with the other runs
            st["status"] = "failed"
            st["error"] = f"{type(e).__name__}: {e}"[-6000:]
            self.failed = True
            print(f"FAILED {method} / {task} / n{n}: {st['error'][-2000:]}", flush=True)
        finally:
            if not a.dry_run:
                _write_json(rdir / "run.json", st)

    # ------------------------------------------------------------------ reports
    def collect(self) -> list[dict]:
        a = self.a
        runs = []
        for task in a.tasks:
            for n in a.demos:
                for seed in a.seeds:
                    for method in a.methods:
                        rdir = self.run_dir(method, task, n, seed)
                        st = self.run_state(method, task, n, seed)
                        es = self.eval_sets.get(task, {})
                        succ: list[bool] = []
                        seeds: list = []
                        for key, c in sorted(st.get("eval_chunks", {}).items(), key=lambda kv: int(kv[0].split(":")[0])):
                            s0 = int(key.split(":")[0])
                            succ += c["successes"]
                            seeds += es.get("seeds", [])[s0 : s0 + len(c["successes"])]
                        k, m = sum(succ), len(succ)
                        lo, hi = wilson_interval(k, m)
                        slices = st.get("train_slices", [])
                        loop = [s["loop_s"] for s in slices if s.get("loop_s") is not None]
                        runs.append({
                            "method": method, "label": METHODS[method][1], "task": task, "demos": n, "seed": seed,
                            "protocol": a.protocol, "status": st.get("status", "pending"),
                            "steps": a.steps, "batch_size": a.batch_size,
                            "steps_done": max((s["end_step"] for s in slices), default=0),
                            "n_params": st.get("n_params"),
                            "train_seconds": round(sum(loop), 2) if loop else None,
                            "train_wall_seconds": round(sum(s["wall_s"] for s in slices), 2) if slices else None,
                            "train_slices": slices,
                            "eval_episodes": m, "eval_episodes_planned": len(es.get("placements", [])),
                            "successes": k, "success_rate": (k / m) if m else None,
                            "ci95": [lo, hi] if m else None,
                            "eval_seconds": round(sum(c["wall_s"] for c in st.get("eval_chunks", {}).values()), 2),
                            "per_episode_success": succ,
                            "eval_seeds": seeds if a.protocol == "random" else None,
                            "checkpoint": st.get("checkpoint"),
                            "loss_curve": st.get("loss_curve"),
                            "run_dir": _rel(rdir),
                            "commands": st.get("commands", {}),
                            "error": st.get("error"),
                        })  # fmt: skip
        return runs

    def write_reports(self) -> None:
        a = self.a
        if a.dry_run:
            return
        runs = self.collect()
        import lerobot
        import torch

        complete = all(r["status"] == "done" for r in runs)
        settings = {
            "matched": {
                "observation_history": {"rnd": 2, "diffusion": 2, "act": "1 (LeRobot ACT accepts only 1)"},
                "action_chunk_executed": 8, "rnd_chunk": 8, "act_chunk": 8,
                "diffusion_horizon": "12 (1 past + 8 executed + 3 padding for the U-Net's 4x downsampling)",
                "batch_size": a.batch_size, "steps": a.steps, "seeds": a.seeds,
                "pretrained_weights": "none: ACT's ImageNet ResNet-18 cannot be downloaded here "
                                      "(--policy.pretrained_backbone_weights=null); DP and R&D use none",
                "optimiser": "each method's own LeRobot preset (R&D: AdamW 1e-4, cosine; ACT: AdamW 1e-4 as in "
                             "policies_config/metaworld/act.json; DP: Adam 1e-4, cosine, 500 warm-up)",
            },
            "method_args": {m: self.method_args(m) for m in a.methods},
            "config_files": {m: _rel(self.config_file(m)) for m in a.methods},
            "record_seed": a.record_seed, "eval_seed": a.eval_seed, "episode_length": a.episode_length,
            "eval_episodes_per_cell": (a.eval_episodes if a.protocol == "random" else "one per valid grid point"),
            "ci": "Wilson score interval, 95%",
            "eval_placements": (
                "lerobot-eval --seed=S: episode i resets rnd_mw with seed S+i, whose first valid draw from the "
                "task's placement range is the placement" if a.protocol == "random" else
                "grid over placement coordinates (see eval_sets), others at the range centre; one episode each"),
        }  # fmt: skip
        result = {
            "benchmark": {
                "scale": a.scale, "protocol": a.protocol, "tasks": a.tasks, "demos": a.demos, "methods": a.methods,
                "seeds": a.seeds, "device": a.device, "complete": complete, "harness_version": HARNESS_VERSION,
                "started": self.started, "written": dt.datetime.now().isoformat(timespec="seconds"),
                "command": shlex.join([sys.executable, *sys.argv]),
                "host": {"platform": platform.platform(), "python": platform.python_version(),
                         "cpus": os.cpu_count(), "torch": torch.__version__, "lerobot": lerobot.__version__,
                         "cuda": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None},
                "work_dir": _rel(self.work),
            },
            "settings": settings,
            "datasets": {t: {str(n): d for n, d in v.items()} for t, v in self.datasets.items()},
            "eval_sets": self.eval_sets,
            "runs": runs,
            "rnd_losses": rnd_losses(runs),
        }  # fmt: skip
        _write_json(self.out / "results.json", result)
        (self.out / "results.md").write_text(markdown_report(result))
        plot_success_vs_demos(result, self.out / "success_vs_demos.png")
        plot_success_per_task(result, self.out / "success_per_task.png")
        plot_loss_curves(result, self.out / "loss_curves.png")
        if a.protocol == "spatial":
            for task in a.tasks:
                plot_heatmap(result, task, self.out / f"heatmap_{task}.png")
        print(f"wrote {self.out / 'results.json'}, results.md, success_vs_demos.png", flush=True)


# --------------------------------------------------------------------------------------------------
# reports (pure functions of results.json)
# --------------------------------------------------------------------------------------------------
def _pool(runs: list[dict]) -> tuple[int, int]:
    return sum(r["successes"] for r in runs), sum(r["eval_episodes"] for r in runs)


def cell_stats(runs: list[dict], method: str, task: str | None, demos: int | None) -> dict | None:
    sel = [r for r in runs if r["method"] == method and r["eval_episodes"] > 0
           and (task is None or r["task"] == task) and (demos is None or r["demos"] == demos)]  # fmt: skip
    if not sel:
        return None
    k, n = _pool(sel)
    lo, hi = wilson_interval(k, n)
    return {"k": k, "n": n, "rate": k / n, "lo": lo, "hi": hi}


def rnd_losses(runs: list[dict]) -> list[dict]:
    """Every (task, demos) cell where a baseline's success rate beats an R&D variant's."""
    out = []
    cells = sorted({(r["task"], r["demos"]) for r in runs})
    methods = sorted({r["method"] for r in runs})
    for task, n in cells:
        for rv in [m for m in methods if m in RND_METHODS]:
            s = cell_stats(runs, rv, task, n)
            if s is None:
                continue
            for b in [m for m in methods if m not in RND_METHODS]:
                t = cell_stats(runs, b, task, n)
                if t is None or t["rate"] <= s["rate"]:
                    continue
                out.append({"task": task, "demos": n, "rnd": rv, "baseline": b,
                            "rnd_rate": s["rate"], "baseline_rate": t["rate"],
                            "significant": bool(t["lo"] > s["hi"])})  # fmt: skip
    return out


def _fmt_cell(s: dict | None) -> str:
    if s is None:
        return "–"
    return f"{100 * s['rate']:.0f}% [{100 * s['lo']:.0f}–{100 * s['hi']:.0f}] ({s['k']}/{s['n']})"


def _fmt_s(x) -> str:
    if x is None:
        return "–"
    return f"{x:.0f} s" if x < 600 else f"{x / 60:.1f} min"


def markdown_report(res: dict) -> str:
    b, runs, st = res["benchmark"], res["runs"], res["settings"]
    cells = [(t, n) for t in b["tasks"] for n in b["demos"]]
    lines = [
        f"# Benchmark: {b['scale']} scale, {b['protocol']} protocol",
        "",
        f"{'Complete' if b['complete'] else '**Incomplete** (run again with `--resume`)'}; written "
        f"{b['written']} on {b['host']['platform']} ({b['host']['cpus']} CPUs"
        f"{', ' + b['host']['cuda'] if b['host']['cuda'] else ''}), torch {b['host']['torch']}, "
        f"lerobot {b['host']['lerobot']}.",
        "",
        f"Success rate, Wilson 95% interval, (successes / episodes). Training seeds {b['seeds']}; "
        f"{st['matched']['steps']} steps of batch {st['matched']['batch_size']}; demos recorded with seed "
        f"{st['record_seed']}; evaluation seeds from {st['eval_seed']} ({st['eval_episodes_per_cell']} episodes "
        f"per cell, {st['episode_length']}-step episodes).",
    ]
    if b["scale"] == "smoke":
        lines += ["", "**Smoke scale: tiny models trained for a few steps. These numbers test the pipeline; "
                  "they say nothing about the methods.**"]  # fmt: skip
    lines += ["", "| method | " + " | ".join(f"{t} / {n} demos" for t, n in cells) + " | average |",
              "| --- |" + " --- |" * (len(cells) + 1)]  # fmt: skip
    for m in b["methods"]:
        row = [_fmt_cell(cell_stats(runs, m, t, n)) for t, n in cells]
        row.append(_fmt_cell(cell_stats(runs, m, None, None)))
        lines.append(f"| {METHODS[m][1]} | " + " | ".join(row) + " |")
    lines += ["", "## Training and evaluation cost", "",
              "| method | parameters | training loop (sum over runs) | training wall incl. start-up | "
              "evaluation wall | runs done |", "| --- | --- | --- | --- | --- | --- |"]  # fmt: skip
    for m in b["methods"]:
        rs = [r for r in runs if r["method"] == m]
        params = sorted({r["n_params"] for r in rs if r["n_params"]})
        ptxt = ", ".join(f"{p / 1e6:.2f}M" for p in params) or "–"
        tl = [r["train_seconds"] for r in rs if r["train_seconds"] is not None]
        tw = [r["train_wall_seconds"] for r in rs if r["train_wall_seconds"] is not None]
        ev = [r["eval_seconds"] for r in rs if r["eval_seconds"]]
        done = sum(r["status"] == "done" for r in rs)
        lines.append(f"| {METHODS[m][1]} | {ptxt} | {_fmt_s(sum(tl)) if tl else '–'} | "
                     f"{_fmt_s(sum(tw)) if tw else '–'} | {_fmt_s(sum(ev)) if ev else '–'} | {done}/{len(rs)} |")  # fmt: skip
    lines += ["", "## Where R&D loses", ""]
    losses = res.get("rnd_losses", [])
    if not losses:
        lines.append("No cell where a baseline's success rate is above an R&D variant's.")
    else:
        lines.append("Cells where a baseline's success rate is above an R&D variant's; *significant* = the "
                     "baseline's Wilson interval lies entirely above R&D's.")  # fmt: skip
        lines.append("")
        for x in losses:
            lines.append(f"- {x['task']} / {x['demos']} demos: {METHODS[x['baseline']][1]} "
                         f"{100 * x['baseline_rate']:.0f}% > {METHODS[x['rnd']][1]} {100 * x['rnd_rate']:.0f}%"
                         f"{' (significant)' if x['significant'] else ' (within the intervals)'}")  # fmt: skip
    failed = [r for r in runs if r["status"] == "failed"]
    pending = [r for r in runs if r["status"] not in ("done", "failed")]
    if failed or pending:
        lines += ["", "## Not done", ""]
        for r in failed:
            err = (r.get("error") or "").strip().splitlines()
            lines.append(f"- FAILED {r['method']} / {r['task']} / {r['demos']} demos / seed {r['seed']}: "
                         f"`{err[0][:200] if err else '?'}` (full log tail in results.json)")  # fmt: skip
        for r in pending:
            lines.append(f"- pending {r['method']} / {r['task']} / {r['demos']} demos / seed {r['seed']} "
                         f"({r['steps_done']}/{r['steps']} steps, {r['eval_episodes']} episodes evaluated)")
    lines += ["", "## Settings", ""]
    for k, v in st["matched"].items():
        lines.append(f"- {k}: {v}")
    lines.append(f"- evaluation placements: {st['eval_placements']}")
    for t, es in res.get("eval_sets", {}).items():
        if "min_normalised_distance_to_train" in es:
            lines.append(f"- {t}: {len(es['placements'])} evaluation placements, none equal to a training one "
                         f"({es['n_equal_to_a_train_placement']} equal); nearest training placement at normalised "
                         f"distance {es['min_normalised_distance_to_train']:.3f} (median "
                         f"{es['median_normalised_distance_to_train']:.3f})")  # fmt: skip
    for t, ds in res.get("datasets", {}).items():
        for n, d in ds.items():
            pre = d.get("prefix_of_next")
            lines.append(f"- data {t} / {n} demos: `{d['root']}`, {d['frames']} frames"
                         f"{'; first episodes of the next larger set' if pre else ''}"
                         f"{'; NOT a prefix of the next larger set' if pre is False else ''}")  # fmt: skip
    lines.append("- per-method lerobot-train overrides (besides the config file):")
    for m, args in st["method_args"].items():
        lines.append(f"  - {METHODS[m][1]} (`{st['config_files'][m]}`): `{' '.join(args)}`")
    lines += ["", "Every command, per-episode outcome and seed is in `results.json`.", ""]
    return "\n".join(lines)


def _mpl():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_success_vs_demos(res: dict, path: Path) -> None:
    plt = _mpl()
    b, runs = res["benchmark"], res["runs"]
    panels = list(b["tasks"]) + (["average"] if len(b["tasks"]) > 1 else [])
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.6), squeeze=False)
    for ax, panel in zip(axes[0], panels, strict=True):
        for j, m in enumerate(b["methods"]):
            xs, ys, lo, hi = [], [], [], []
            for n in sorted(b["demos"]):
                s = cell_stats(runs, m, None if panel == "average" else panel, n)
                if s is None:
                    continue
                xs.append(n + (j - (len(b["methods"]) - 1) / 2) * 0.15 * (1 if len(b["demos"]) == 1 else 1))
                ys.append(100 * s["rate"])
                lo.append(100 * (s["rate"] - s["lo"]))
                hi.append(100 * (s["hi"] - s["rate"]))
            if xs:
                ax.errorbar(xs, ys, yerr=[lo, hi], marker="o", capsize=3, label=METHODS[m][1],
                            linestyle="-" if len(xs) > 1 else "none")  # fmt: skip
        ax.set_title(panel)
        ax.set_xlabel("demonstrations")
        ax.set_xticks(sorted(b["demos"]))
        ax.set_ylim(-5, 105)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("success rate (%), Wilson 95%")
    if axes[0][-1].get_legend_handles_labels()[0]:
        axes[0][-1].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    title = f"{b['scale']} scale, {b['protocol']} protocol"
    if b["scale"] == "smoke":
        title += " (pipeline check, not a result)"
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_success_per_task(res: dict, path: Path) -> None:
    """Bars: success per task (and the mean over tasks) per method, Wilson 95% intervals, all demo counts pooled."""
    plt = _mpl()
    b, runs = res["benchmark"], res["runs"]
    panels = list(b["tasks"]) + (["mean over tasks"] if len(b["tasks"]) > 1 else [])
    fig, ax = plt.subplots(figsize=(1.6 + 1.5 * len(panels) * max(1, len(b["methods"])) / 3, 3.6))
    width = 0.8 / max(1, len(b["methods"]))
    for j, m in enumerate(b["methods"]):
        xs, ys, lo, hi = [], [], [], []
        for i, panel in enumerate(panels):
            if panel == "mean over tasks":
                cells = [cell_stats(runs, m, t, None) for t in b["tasks"]]
                if any(c is None for c in cells):
                    continue
                rate = sum(c["rate"] for c in cells) / len(cells)
                s = {"rate": rate, "lo": rate, "hi": rate}
            else:
                s = cell_stats(runs, m, panel, None)
            if s is None:
                continue
            xs.append(i + (j - (len(b["methods"]) - 1) / 2) * width)
            ys.append(100 * s["rate"])
            lo.append(100 * (s["rate"] - s["lo"]))
            hi.append(100 * (s["hi"] - s["rate"]))
        if xs:
            ax.bar(xs, ys, width=width, yerr=[lo, hi], capsize=3, label=METHODS[m][1])
    ax.set_xticks(range(len(panels)))
    ax.set_xticklabels(panels, fontsize=8)
    ax.set_ylim(0, 105)
    ax.set_ylabel("success rate (%), Wilson 95%")
    ax.grid(axis="y", alpha=0.3)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    ax.set_title(f"{b['scale']} scale: {', '.join(str(n) for n in b['demos'])} demos, "
                 f"{b['protocol']} placements", fontsize=9)  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_loss_curves(res: dict, path: Path) -> None:
    """Training loss against step, one panel per task, one line per method (each method's own loss)."""
    plt = _mpl()
    b, runs = res["benchmark"], res["runs"]
    tasks = [t for t in b["tasks"] if any(r.get("loss_curve") and r["task"] == t for r in runs)]
    if not tasks:
        return
    fig, axes = plt.subplots(1, len(tasks), figsize=(4.2 * len(tasks), 3.4), squeeze=False)
    for ax, task in zip(axes[0], tasks, strict=True):
        for r in runs:
            if r["task"] != task or not r.get("loss_curve"):
                continue
            steps, losses = zip(*r["loss_curve"])
            ax.plot(steps, losses, label=f"{METHODS[r['method']][1]} (n{r['demos']}, s{r['seed']})")
        ax.set_yscale("log")
        ax.set_title(task, fontsize=9)
        ax.set_xlabel("training step")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("training loss (each method's own)")
    axes[0][-1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_heatmap(res: dict, task: str, path: Path) -> None:
    """Success over the evaluation grid (rows: methods, columns: demo counts), training placements marked."""
    import numpy as np

    plt = _mpl()
    b, runs = res["benchmark"], res["runs"]
    es = res["eval_sets"].get(task)
    if not es or "cells" not in es:
        return
    G = len(es["grid_x"])
    dims = es["grid_dims"]
    ms, ns = b["methods"], sorted(b["demos"])
    fig, axes = plt.subplots(len(ms), len(ns), figsize=(max(5.0, 3.0 * len(ns) + 1.2), 2.7 * len(ms) + 0.6),
                             squeeze=False)  # fmt: skip
    gx, gy = es["grid_x"], es["grid_y"]
    hx = (gx[-1] - gx[0]) / max(1, G - 1) / 2
    hy = (gy[-1] - gy[0]) / max(1, G - 1) / 2
    ext = [gx[0] - hx, gx[-1] + hx, gy[0] - hy, gy[-1] + hy]  # cell centres on the grid points
    for i, m in enumerate(ms):
        for j, n in enumerate(ns):
            ax = axes[i][j]
            grid = np.full((G, G), np.nan)
            sel = [r for r in runs if r["method"] == m and r["task"] == task and r["demos"] == n]
            if sel and all(len(r["per_episode_success"]) == len(es["cells"]) for r in sel):
                acc = np.mean([r["per_episode_success"] for r in sel], axis=0)
                for (iy, ix), v in zip(es["cells"], acc, strict=True):
                    grid[iy, ix] = v
            im = ax.imshow(grid, origin="lower", extent=ext, vmin=0, vmax=1, cmap="RdYlGn", aspect="auto")
            tr = res["datasets"].get(task, {}).get(str(n), {}).get("placements", [])
            if tr:
                tr = np.asarray(tr)
                ax.scatter(tr[:, dims[0]], tr[:, dims[1]], marker="x", c="k", s=18, label="demos")
            s = cell_stats(runs, m, task, n)
            ax.set_title(f"{METHODS[m][1]}, {n} demos: {_fmt_cell(s).split(' (')[0]}", fontsize=7)
            ax.tick_params(labelsize=6)
            ax.set_xlabel(f"placement[{dims[0]}] (m)", fontsize=7)
            ax.set_ylabel(f"placement[{dims[1]}] (m)", fontsize=7)
    fig.subplots_adjust(top=1.0 - 0.85 / fig.get_figheight(), hspace=0.45, wspace=0.35)
    fig.colorbar(im, ax=axes, shrink=0.6, label="success")
    fig.suptitle(f"{task}: success per evaluation placement\n(x: training placements; grid over placement "
                 f"coordinates {dims[0]}, {dims[1]})", fontsize=8)  # fmt: skip
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --------------------------------------------------------------------------------------------------
# wrappers run as subprocesses: lerobot tools with the plugin imported first, and the grid evaluation
# --------------------------------------------------------------------------------------------------
def _exec_tool(tool: str, args: list[str]) -> int:
    sys.path.insert(0, str(REPO_ROOT))
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


def _grid_eval(argv: list[str]) -> int:
    """lerobot-eval's loop over an explicit list of placements (one episode each); writes eval_info.json
    in lerobot-eval's layout (per_task[0].metrics.successes)."""
    p = argparse.ArgumentParser(prog="run_benchmark.py _grid_eval")
    p.add_argument("--policy-path", required=True)
    p.add_argument("--device", default="cpu")
    p.add_argument("--task", required=True)
    p.add_argument("--episode-length", type=int, default=300)
    p.add_argument("--batch-size", type=int, default=1)
    p.add_argument("--seed", type=int, default=1000)
    p.add_argument("--placements", required=True)
    p.add_argument("--output-dir", required=True)
    a = p.parse_args(argv)
    sys.path.insert(0, str(REPO_ROOT))
    import gymnasium as gym
    import torch
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.envs.factory import make_env_pre_post_processors
    from lerobot.policies.factory import make_policy, make_pre_post_processors
    from lerobot.scripts.lerobot_eval import eval_policy
    from lerobot.utils.random_utils import set_seed

    import lerobot_policy_rnd  # noqa: F401
    from lerobot_rnd.sim.metaworld_env import RnDMetaWorldEnvConfig

    placements = json.loads(Path(a.placements).read_text())
    set_seed(a.seed)
    env_cfg = RnDMetaWorldEnvConfig(task=a.task, episode_length=a.episode_length)
    pcfg = PreTrainedConfig.from_pretrained(a.policy_path)
    pcfg.pretrained_path = Path(a.policy_path)
    pcfg.device = a.device
    policy = make_policy(cfg=pcfg, env_cfg=env_cfg)
    policy.eval()
    pre, post = make_pre_post_processors(
        policy_cfg=pcfg, pretrained_path=a.policy_path,
        preprocessor_overrides={"device_processor": {"device": str(policy.config.device)},
                                "rename_observations_processor": {"rename_map": {}}},
    )  # fmt: skip
    env_pre, env_post = make_env_pre_post_processors(env_cfg=env_cfg, policy_cfg=pcfg)
    t0 = time.time()
    successes, rewards = [], []
    for i in range(0, len(placements), a.batch_size):
        batch = placements[i : i + a.batch_size]
        fns = [
            (lambda pl=pl: gym.make(env_cfg.gym_id, disable_env_checker=True,
                                    **{**env_cfg.gym_kwargs, "placement": "fixed", "placements": [pl]}))
            for pl in batch
        ]  # fmt: skip
        vec = gym.vector.SyncVectorEnv(fns, autoreset_mode=gym.vector.AutoresetMode.SAME_STEP)
        try:
            with torch.no_grad():
                info = eval_policy(vec, policy, env_pre, env_post, pre, post, n_episodes=len(batch),
                                   start_seed=a.seed + i)  # fmt: skip
        finally:
            vec.close()
        successes += [bool(e["success"]) for e in info["per_episode"]]
        rewards += [e["max_reward"] for e in info["per_episode"]]
        print(f"grid eval: {len(successes)}/{len(placements)} episodes, {sum(successes)} successes", flush=True)
    out = Path(a.output_dir)
    out.mkdir(parents=True, exist_ok=True)
    n = max(1, len(successes))
    _write_json(out / "eval_info.json", {
        "per_task": [{"task_group": "rnd_mw", "task_id": 0,
                      "metrics": {"successes": successes, "max_rewards": rewards, "placements": placements}}],
        "overall": {"pc_success": 100.0 * sum(successes) / n, "n_episodes": len(successes),
                    "eval_s": time.time() - t0},
    })  # fmt: skip
    return 0


# --------------------------------------------------------------------------------------------------
# command line
# --------------------------------------------------------------------------------------------------
def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scale", choices=sorted(SCALES), required=True)
    p.add_argument("--tasks", help="comma-separated MetaWorld V3 tasks (scale default)")
    p.add_argument("--demos", help="comma-separated demo counts (scale default)")
    p.add_argument("--methods", default=",".join(METHODS), help=f"subset of {','.join(METHODS)}")
    p.add_argument("--out", help="results folder (default benchmarks/results/<scale>)")
    p.add_argument("--work-dir", help="datasets-free working folder: checkpoints, logs, eval outputs "
                                      "(default outputs/benchmark/<name of --out>)")  # fmt: skip
    p.add_argument("--data-dir", default=str(REPO_ROOT / "outputs" / "benchmark" / "data"),
                   help="recorded datasets, shared between benchmarks")  # fmt: skip
    p.add_argument("--protocol", choices=["random", "spatial"], default="random",
                   help="random: uniform placements, seeded evaluation; spatial: furthest-point-sampled demos, "
                        "evaluation on a grid, heat maps")  # fmt: skip
    p.add_argument("--seed", default="0", help="training seed(s), comma-separated (one run per seed)")
    p.add_argument("--record-seed", type=int, default=0, help="placement seed of the recorded demos")
    p.add_argument("--eval-seed", type=int, default=1000, help="first evaluation seed (episode i: seed + i)")
    p.add_argument("--eval-episodes", type=int, help="evaluation episodes per task and demo count")
    p.add_argument("--eval-chunk", type=int, help="episodes per lerobot-eval call (0: all in one)")
    p.add_argument("--eval-batch-size", type=int, help="parallel envs per lerobot-eval call")
    p.add_argument("--episode-length", type=int, help="env steps before an episode fails")
    p.add_argument("--grid", type=int, help="spatial protocol: G x G evaluation grid")
    p.add_argument("--grid-dims", help="spatial protocol: two placement coordinates, e.g. 0,1 (object x, y)")
    p.add_argument("--steps", type=int, help="training steps (same for every method)")
    p.add_argument("--batch-size", type=int)
    p.add_argument("--save-freq", type=int, help="checkpoint every N steps (0: only at the end)")
    p.add_argument("--log-freq", type=int)
    p.add_argument("--num-workers", type=int)
    p.add_argument("--device")
    p.add_argument("--train-arg", action="append",
                   help="extra lerobot-train argument for some methods: 'METHOD:--x=y', 'rnd:--x=y' (all R&D "
                        "variants) or 'all:--x=y'; repeatable")  # fmt: skip
    p.add_argument("--resume", action="store_true", help="continue the benchmark in --work-dir")
    p.add_argument("--retry-failed", action="store_true", help="with --resume: run failed runs again")
    p.add_argument("--eval-only", action="store_true", help="evaluate existing checkpoints, train nothing")
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
    d = SCALES[a.scale]
    for k in ("tasks", "demos", "eval_episodes", "eval_chunk", "eval_batch_size", "episode_length", "grid",
              "steps", "batch_size", "save_freq", "log_freq", "num_workers", "device", "min_train_slice_s"):  # fmt: skip
        if getattr(a, k) is None:
            setattr(a, k, d[k])
    a.tasks = _csv(a.tasks)
    a.demos = sorted(_csv(a.demos, int))
    a.methods = _csv(a.methods)
    bad = [m for m in a.methods if m not in METHODS]
    if bad:
        p.error(f"unknown methods {bad}; choose from {list(METHODS)}")
    a.seeds = _csv(a.seed, int)
    a.grid_dims = _csv(a.grid_dims, int) if a.grid_dims else None
    if a.grid_dims is not None and len(a.grid_dims) != 2:
        p.error("--grid-dims takes two coordinates")
    if a.prune_optimizer is None:
        a.prune_optimizer = a.scale == "gpu"
    a.out = a.out or str(REPO_ROOT / "benchmarks" / "results" / a.scale)
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
        (Path(a.out) / "results.md").write_text(markdown_report(res))
        plot_success_vs_demos(res, Path(a.out) / "success_vs_demos.png")
        plot_success_per_task(res, Path(a.out) / "success_per_task.png")
        plot_loss_curves(res, Path(a.out) / "loss_curves.png")
        if res["benchmark"]["protocol"] == "spatial":
            for task in res["benchmark"]["tasks"]:
                plot_heatmap(res, task, Path(a.out) / f"heatmap_{task}.png")
        return EXIT_OK
    return Benchmark(a).run()


if __name__ == "__main__":
    sys.exit(main())
