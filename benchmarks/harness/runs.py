"""The benchmark runs: datasets, evaluation placements, and per (method, task, demos, seed) training,
evaluation and resumption within the time budget; run.json / per-run result JSON files; results.json."""

from __future__ import annotations

import argparse
import datetime as dt
import hashlib
import json
import math
import os
import platform
import re
import shlex
import shutil
import sys
import time
from pathlib import Path

from . import REPO_ROOT, grid_eval
from .files import _read_json, _rel, _write_json
from .processes import OutOfTime, git_commit, run_logged, tool_argv
from .reports import loss_curve_from_log, median_logged, median_update_s_from_log, rnd_losses, wilson_interval, write_report_files
from .scales import COMMON_METHOD_ARGS, METHODS, SCALES, SUITES, method_family, suite_scale_defaults

HARNESS_VERSION = 1
EXIT_OK, EXIT_FAILED, EXIT_MORE = 0, 1, 3
#: how the spatial protocol's demos were placed (results.json settings.demo_placements), per recorder mode
DEMO_PLACEMENTS = {
    "fps": "lerobot-rnd-record --placements fps: furthest point sampling over every placement coordinate (scaled "
           "to the range) of a pool of 1000 valid placements drawn with the recording seed; the first is the pool "
           "point nearest the pool's mean",
    "fps-centre": "lerobot-rnd-record --placements fps-centre: furthest point sampling over the object's x, y and "
                  "yaw (scaled to their range; yaw compared modulo the object's 90-degree symmetry, except slide-block's, whose "
                  "target turns with the block), starting at the centre of the range; pool = the centre + 999 "
                  "uniform draws with the recording seed; the other coordinates (push-block / pick-place: the "
                  "target x, y) drawn uniformly from their range with the recording seed's generator until the "
                  "placement is valid (the target 10 cm or more from the object, push-block's 22 cm or less), as "
                  "the random protocol draws them; slide-block has no other coordinate (its target follows the block)",
}  # fmt: skip


def recorder_image_size() -> int:
    """lerobot-rnd-record's default --image-size (imported when needed: the recorder pulls in the simulators)."""
    from lerobot_rnd.sim.record import RecordSettings

    return RecordSettings.image_size


def recorder_extra_steps() -> int:
    """lerobot-rnd-record's default --extra-steps (frames after the expert's first success)."""
    from lerobot_rnd.sim.record import RecordSettings

    return RecordSettings.extra_steps


def put_train_slice(st: dict, entry: dict) -> None:
    """Append a training slice's record to ``st["train_slices"]``, replacing that slice's provisional record (the
    same start step, written at its last checkpoint) if there is one."""
    slices = st.setdefault("train_slices", [])
    if slices and slices[-1].get("provisional") and slices[-1]["start_step"] == entry["start_step"]:
        slices.pop()
    slices.append(entry)


def checkpoint_step(ckroot: Path) -> int:
    """The training step of a run's last checkpoint (``ckroot/last``; lerobot-train saves it in the training state
    beside the model), 0 without one."""
    state = _read_json(ckroot / "last" / "training_state" / "training_step.json", {}) or {}
    return int(state.get("step", 0))


def unit_tasks(unit: str) -> list[str]:
    """The tasks of a training unit: one task, or the comma-separated tasks of a --multitask run."""
    return [t for t in unit.split(",") if t]


def unit_name(unit: str) -> str:
    """A training unit in file names: the task, or the tasks joined by '+' (multi-task)."""
    return "+".join(unit_tasks(unit))


def override_flags(args: list[str]) -> list[str]:
    """Keep only the last `--key=value` of each key (later, more specific flags override earlier ones), in the
    position of that last occurrence. LeRobot's parser does not accept a flag twice."""
    last = {a.partition("=")[0]: i for i, a in enumerate(args)}
    return [a for i, a in enumerate(args) if last[a.partition("=")[0]] == i]


def _in_order(by_key: dict, order: list) -> dict:
    """`by_key` with the keys listed in `order` first, in that order (a report's tasks as it lists them), then the
    rest as they were: results.json stays in one order whichever call wrote it."""
    return {k: by_key[k] for k in sorted(by_key, key=lambda k: order.index(k) if k in order else len(order))}


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
        self.suite_name = getattr(a, "suite", "metaworld")
        self.suite = SUITES[self.suite_name]
        self.collect_from = [self._source_folder(Path(f)) for f in a.collect_from]
        #: what one training run covers: each task on its own, or (--multitask) all tasks together
        self.units = [",".join(a.tasks)] if getattr(a, "multitask", False) else list(a.tasks)

    # ------------------------------------------------------------------ budget
    def remaining(self) -> float:
        return math.inf if self.deadline is None else self.deadline - time.time()

    def need(self, seconds: float, what: str) -> None:
        if self.remaining() < seconds:
            raise OutOfTime(f"{what}: needs ~{seconds:.0f} s, {max(0, self.remaining()):.0f} s left")

    # ------------------------------------------------------------------ datasets
    def placements_mode(self) -> str:
        """The recorder's --placements: random, or the suite's furthest point sampling (spatial protocol)."""
        return self.suite["fps_mode"] if self.a.protocol == "spatial" else "random"

    def dataset_root(self, task: str, n: int) -> tuple[Path, str]:
        """The dataset of a unit (one task, or a --multitask unit's tasks: ``mt<k>-<hash of the task list>``, short
        enough for a repo id; its recording log names the tasks) and ``n`` demos (per task)."""
        a = self.a
        tasks = unit_tasks(task)
        if len(tasks) > 1:
            task = f"mt{len(tasks)}-{hashlib.sha1(','.join(tasks).encode()).hexdigest()[:8]}"
        other, extra = self.other_image_size(), self.other_extra_steps()
        name = (f"{self.suite['dataset_prefix']}_{task}_{self.placements_mode()}_s{a.record_seed}_n{n}"
                + (f"_img{other}" if other else "") + (f"_x{extra}" if extra is not None else ""))  # fmt: skip
        return self.data_dir / name, f"local/{name}"

    def image_size(self) -> int:
        """The side of the camera images in pixels: --image-size, else the recorder's default."""
        return self.a.image_size or recorder_image_size()

    def other_image_size(self) -> int | None:
        """--image-size where it differs from the recorder's default (it then names the datasets and reaches the
        recorder and R&D), else None: the datasets and commands of a run without the flag."""
        return None if self.image_size() == recorder_image_size() else self.image_size()

    def other_extra_steps(self) -> int | None:
        """--extra-steps where it differs from the recorder's default (it then names the datasets and reaches the
        recorder), else None."""
        x = getattr(self.a, "extra_steps", None)
        return None if x is None or x == recorder_extra_steps() else x

    def make_env(self, task: str):
        """The suite's env of ``task`` (placements and validity; nothing is rendered)."""
        if self.suite_name == "panda":
            from lerobot_rnd.sim.panda_env import RnDPandaEnv

            return RnDPandaEnv(task, episode_length=self.a.episode_length)
        if self.suite_name == "so101":
            from lerobot_rnd.sim.so101_env import RnDSO101Env

            return RnDSO101Env(task, episode_length=self.a.episode_length)
        from lerobot_rnd.sim.metaworld_env import RnDMetaWorldEnv

        return RnDMetaWorldEnv(task, episode_length=self.a.episode_length)

    def record(self, task: str) -> None:
        """Record (or reuse, or extend) one dataset per demo count; smaller sets are prefixes of larger."""
        a = self.a
        mode = self.placements_mode()
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
                    if a.dry_run:
                        print(f"$ cp -r {prev_root} {root}", flush=True)
                    else:
                        shutil.copytree(prev_root, root)
                    resume = True
                self.need(60 + 8.0 * (n - (have if resume else 0)), f"recording {root.name}")
                other = self.other_image_size()
                argv = tool_argv("lerobot-rnd-record", a.launcher) + list(self.suite["record_args"]) + [
                    "--task", task, "--episodes", str(n), "--root", str(root), "--repo-id", repo_id,
                    "--placements", mode, "--seed", str(a.record_seed),
                ] + (["--image-size", str(other)] if other else []) + (["--resume"] if resume else [])  # fmt: skip
                if self.other_extra_steps() is not None:
                    argv += ["--extra-steps", str(self.other_extra_steps())]
                r = run_logged(argv, self.work / "logs" / f"record_{root.name}.log", env=self.env(),
                               dry_run=a.dry_run)  # fmt: skip
                if r.rc != 0:
                    raise RuntimeError(f"recording {root} failed (rc {r.rc}):\n{r.tail}")
            from lerobot_rnd.sim.record import recorded_env_args, recorded_setting

            if have >= n and len(unit_tasks(task)) == 1 and not a.dry_run:
                self._check_reused_placements(task, root)
            if self.suite.get("calibration"):
                self.calibrate(root)
            rec = _read_json(root / "meta" / "rnd_recording.json", {}) or {}
            env_args = recorded_env_args(rec.get("settings") or {})
            if env_args:
                print(f"{root.name} was recorded with other observations than the env's defaults; its policies "
                      f"are evaluated with the same: {' '.join(env_args)}", flush=True)
            kept = [x for x in rec.get("attempts", []) if x.get("success")]
            kept.sort(key=lambda x: x["episode_index"])
            info = _read_json(root / "meta" / "info.json", {}) or {}
            self.datasets[task][n] = {
                "root": _rel(root), "repo_id": repo_id, "placements_mode": mode, "record_seed": a.record_seed,
                "expert_reach_target": recorded_setting(rec.get("settings") or {}, "expert_reach_target"),
                "episodes": info.get("total_episodes"), "frames": info.get("total_frames"),
                "placements": [x["placement"] for x in kept][:n],
                "placement_indices": [x["placement_index"] for x in kept][:n],
                "expert_failures": sum(1 for x in rec.get("attempts", []) if not x.get("success")),
                "eval_env_args": env_args,
            }  # fmt: skip
            if len(unit_tasks(task)) > 1:  # per task (the recorder writes the tasks one after the other)
                by_task = {t: [x for x in kept if x.get("task") == t][:n] for t in unit_tasks(task)}
                self.datasets[task][n].update(
                    tasks=unit_tasks(task), placements=None, placement_indices=None,
                    placements_by_task={t: [x["placement"] for x in v] for t, v in by_task.items()},
                    placement_indices_by_task={t: [x["placement_index"] for x in v] for t, v in by_task.items()})
            prev_root = root
        # check the nesting (smaller sets = first episodes of the larger ones)
        ns = sorted(self.datasets[task])
        for small, big in zip(ns, ns[1:], strict=False):
            s, b = self.datasets[task][small], self.datasets[task][big]
            if "placements_by_task" in s:  # multi-task: each task's demos are the first of the larger set's
                s["prefix_of_next"] = all(b["placements_by_task"][t][: len(v)] == v
                                          for t, v in s["placements_by_task"].items())  # fmt: skip
            else:
                s["prefix_of_next"] = bool(b["placements"][: len(s["placements"])] == s["placements"])
            if s["eval_env_args"] != b["eval_env_args"]:
                raise ValueError(
                    f"{task}: the {small}- and {big}-demo datasets were recorded with different observations "
                    f"({s['eval_env_args'] or 'the defaults'} against {b['eval_env_args'] or 'the defaults'}), so "
                    f"their policies would not see the same cameras; record {b['root']} again as an extension of "
                    f"{s['root']} (remove it and rerun: the benchmark copies the smaller set and resumes it)"
                )

    def _check_reused_placements(self, task: str, root: Path) -> None:
        """A complete dataset the benchmark reuses must hold the placements its recorder would draw today (else
        its runs would train on demos of another placement rule, e.g. push-block's former centre target): raises
        naming the dataset and the fix."""
        from lerobot_rnd.sim.placements import PlacementSequence
        from lerobot_rnd.sim.record import RecordSettings, attempt_task, check_same_placements

        log = _read_json(root / "meta" / "rnd_recording.json", {}) or {}
        st = log.get("settings") or {}
        s = RecordSettings(task=task, placements=st.get("placements", self.placements_mode()),
                           seed=int(st.get("seed", self.a.record_seed)),
                           fps_pool=int(st.get("fps_pool", RecordSettings.fps_pool)))  # fmt: skip
        if s.placements != self.placements_mode() or s.seed != self.a.record_seed:
            raise RuntimeError(f"{root} was recorded with --placements {s.placements} --seed {s.seed}, not "
                               f"{self.placements_mode()} / {self.a.record_seed}: remove it and rerun")  # fmt: skip
        attempts = [x for x in log.get("attempts", []) if attempt_task(x, st) == task]
        env = self.make_env(task)
        try:
            check_same_placements(attempts, PlacementSequence(env, s.placements, s.seed, s.fps_pool), root, s,
                                  context="benchmark, reusing a dataset",
                                  fix="remove it (archive the runs trained on it) and rerun: the benchmark records it "
                                      "again")  # fmt: skip
        except ValueError as e:  # SettingError
            raise RuntimeError(str(e)) from e
        finally:
            env.close()

    # ------------------------------------------------------------------ measured calibration (so101)
    def calibrate(self, root) -> None:
        """Puts the cameras R&D trains with into ``root``'s embodiment: measured by ``lerobot-rnd-calibrate`` on a
        simulated calibration session (recorded once per data folder; ``--calibration measured``) or MuJoCo's exact
        ones (``exact``, as recorded, kept as ``meta/rnd_embodiment_exact.json``)."""
        a = self.a
        meta = root / "meta"
        exact, used = meta / "rnd_embodiment_exact.json", meta / "rnd_embodiment.json"
        if not exact.exists() and not a.dry_run:
            shutil.copyfile(used, exact)
        if a.calibration == "exact":
            if not a.dry_run:
                shutil.copyfile(exact, used)
            return
        size = int((_read_json(meta / "info.json", {}) or {}).get("features", {}).get(
            "observation.images.front", {}).get("shape", [self.image_size()])[0])
        session = self.data_dir / "so101_calibration_session_s0"
        if not (session / "meta" / "info.json").exists():
            if session.exists():
                shutil.rmtree(session)
            argv = [sys.executable, "-m", "lerobot_rnd.sim.so101_calibration", "--root", str(session)]
            r = run_logged(argv, self.work / "logs" / "so101_calibration_session.log", env=self.env(), dry_run=a.dry_run)
            if r.rc != 0:
                raise RuntimeError(f"the calibration session failed (rc {r.rc}):\n{r.tail}")
        argv = [sys.executable, "-m", "lerobot_rnd.calibration.cli",
            "solve", "--dataset", str(session), "--board", str(session / "board.json"), "--robot", "so101",
            "--wrist", "observation.images.wrist", "--out", str(meta / "rnd_embodiment_measured.json"),
            "--image-size", f"{size}x{size}"]  # fmt: skip
        r = run_logged(argv, self.work / "logs" / f"calibrate_{root.name}.log", env=self.env(), dry_run=a.dry_run)
        if r.rc != 0:
            raise RuntimeError(f"calibrating {root.name} failed (rc {r.rc}):\n{r.tail}")
        if not a.dry_run:
            shutil.copyfile(meta / "rnd_embodiment_measured.json", used)

    def _reread_loss_curve(self, rdir: Path, st: dict, result_path: Path) -> None:
        """A finished run of this folder gets its loss curve read again from its train log, so a mended log parser
        reaches runs finished before it (result JSON and run.json rewritten only when the curve changed)."""
        log = rdir / "train.log"
        if st.get("collected_from") or not log.exists():
            return
        before = st.get("loss_curve")
        self._parse_train_log(log, st, self.a.log_freq)
        if [list(x) for x in st.get("loss_curve") or []] != [list(x) for x in before or []]:
            print(f"{_rel(result_path)}: loss curve read again from {_rel(log)}", flush=True)
            _write_json(result_path, st)
            if (rdir / "run.json").exists():
                _write_json(rdir / "run.json", st)

    # ------------------------------------------------------------------ evaluation placements
    def eval_set(self, task: str) -> dict:
        """Evaluation placements of ``task`` (random: one per seed; spatial: the grid) + held-out check."""
        if task in self.eval_sets:
            return self.eval_sets[task]
        import numpy as np

        a = self.a
        env = self.make_env(task)
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
                out.update(grid_eval.grid_placements(
                    env, task, low, high, a.grid, a.grid_dims or self.suite.get("grid_dims"), a.eval_seed,
                    n_third=getattr(a, "grid_yaws", 1), layout=self.suite["grid_layout"], others=self.suite["grid_others"]))
        finally:
            env.close()
        # held-out check against every training placement of this task (in its own or a multi-task dataset)
        train = [p for d in self.datasets.get(task, {}).values() for p in d["placements"]]
        train += [p for unit, ds in self.datasets.items() if unit != task for d in ds.values()
                  for p in (d.get("placements_by_task") or {}).get(task, [])]  # fmt: skip
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
        return self.work / "runs" / self.a.protocol / method / unit_name(task) / f"n{n}" / f"seed{seed}"

    def config_file(self, method: str) -> Path:
        files = suite_scale_defaults(self.suite_name, self.a.scale).get("config_files", {})
        return self.suite["config_dir"] / files.get(method, METHODS[method][0])

    def method_args(self, method: str) -> list[str]:
        fam = method_family(method)
        per_scale = SCALES[self.a.scale]["method_args"]
        args = list(COMMON_METHOD_ARGS[fam]) + list(per_scale[fam]) + list(per_scale.get(method, []))
        if fam == "rnd" and self.other_image_size():  # ACT and DP take the dataset's images as they are
            args.append(f"--policy.image_size=[{self.other_image_size()},{self.other_image_size()}]")
        for spec in self.a.train_arg or []:
            who, _, arg = spec.partition(":")
            if who in ("all", method, fam):
                args.append(arg)
        return override_flags(args)

    def train_argv(self, method: str, task: str, n: int, seed: int, out_dir: Path) -> list[str]:
        a = self.a
        root, repo_id = self.dataset_root(task, n)
        save_freq = a.save_freq if a.save_freq > 0 else a.steps
        return tool_argv("lerobot-train", a.launcher) + [
            f"--config_path={self.config_file(method)}",
            f"--dataset.repo_id={repo_id}", f"--dataset.root={root}", "--dataset.video_backend=pyav",
            f"--env.task={task}", f"--env.episode_length={a.episode_length}",
            f"--output_dir={out_dir}", f"--job_name={method}_{unit_name(task)}_n{n}_s{seed}",
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
            step = checkpoint_step(ckroot)
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
            marks: dict = {}
            poll = self._slice_recorder(self._checkpoint_poller(ckroot), ckroot, step, marks, st, rdir / "run.json")
            deadline = None if self.deadline is None else self.deadline - a.exit_margin_s
            r = run_logged(argv, log, deadline=deadline, poll=poll, env=self.env(), dry_run=a.dry_run, marks=marks)
            if a.dry_run:
                return
            end_step = checkpoint_step(ckroot)
            loop_s = (time.time() - r.marks["train_loop_start"]) if "train_loop_start" in r.marks else None
            if loop_s is not None:
                loop_s = min(loop_s, r.wall_s)
            put_train_slice(st, {
                "start_step": step, "end_step": end_step, "wall_s": round(r.wall_s, 2),
                "loop_s": None if loop_s is None else round(loop_s, 2), "rc": r.rc, "stopped": r.stopped,
            })  # fmt: skip
            self._parse_train_log(log, st, self.a.log_freq)
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

    @staticmethod
    def _slice_recorder(poll, ckroot: Path, start_step: int, marks: dict, st: dict, run_json: Path):
        """Wrap a training slice's ``poll`` so that each new checkpoint records the slice so far in ``run_json``
        (``provisional``: timed up to that checkpoint). A harness killed mid-slice (a session's end) then keeps
        the cost of the steps it trained, where the resumed run starts; a slice that ends replaces it."""
        t0 = time.time()
        seen = {"step": start_step}

        def recording_poll():
            step = checkpoint_step(ckroot)
            if step > seen["step"]:
                seen["step"] = step
                now = time.time()
                loop = now - marks["train_loop_start"] if "train_loop_start" in marks else None
                put_train_slice(st, {"start_step": start_step, "end_step": step, "wall_s": round(now - t0, 2),
                               "loop_s": None if loop is None else round(loop, 2), "rc": None,
                               "stopped": None, "provisional": True})  # fmt: skip
                _write_json(run_json, st)
            return poll()

        return recording_poll

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
    def _parse_train_log(log: Path, st: dict, log_freq: int) -> None:
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
            st["update_s_median_logged"] = median_update_s_from_log(text)
        if (data_s := median_logged(text, "data_s")) is not None:
            st["data_s_median_logged"] = data_s
        curve = loss_curve_from_log(text, log_freq)
        if curve:
            st["loss_curve"] = curve

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, method: str, task: str, n: int, seed: int, st: dict) -> None:
        a = self.a
        rdir = self.run_dir(method, task, n, seed)
        ckpt = (rdir / "train" / "checkpoints" / "last").resolve() / "pretrained_model"
        st["checkpoint"] = _rel(ckpt)
        tasks = unit_tasks(task)
        es = self.eval_set(tasks[0])  # a multi-task unit: the same seeds for every task, each task's placements
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
                    f"--env.type={self.suite['env_type']}", f"--env.task={task}", f"--env.episode_length={a.episode_length}",
                    f"--eval.n_episodes={k}", f"--eval.batch_size={bs}", f"--seed={a.eval_seed + start}",
                    f"--output_dir={edir}", *self.datasets[task][n]["eval_env_args"],
                ]  # fmt: skip
            else:
                pfile = rdir / "eval" / f"grid_{start}.json"
                _write_json(pfile, es["placements"][start : start + k])
                argv = grid_eval.grid_eval_argv(ckpt, a.device, task, a.episode_length, bs, a.eval_seed, pfile, edir,
                                                env_args=self.datasets[task][n]["eval_env_args"],
                                                env_type=self.suite["env_type"])  # fmt: skip
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
            if len(tasks) == 1:
                metrics = {task: info["per_task"][0]["metrics"]}
            else:  # lerobot-eval's per-task entries of --env.task=a,b,c: one group per task
                metrics = {e["task_group"]: e["metrics"] for e in info["per_task"]}
                if sorted(metrics) != sorted(tasks):
                    raise RuntimeError(f"eval_info.json has the tasks {sorted(metrics)}, expected {tasks}")
            succ = {t: [bool(x) for x in m["successes"]][:k] for t, m in metrics.items()}
            rewards = {t: [round(float(x), 6) for x in (m.get("max_rewards") or [])[:k]] for t, m in metrics.items()}
            short = {t: len(v) for t, v in succ.items() if len(v) != k}
            if short:
                raise RuntimeError(f"eval_info.json holds {short} episodes, expected {k} per task")
            if len(tasks) == 1:
                succ, rewards = succ[task], rewards[task]
            chunks[key] = {"successes": succ, "max_rewards": rewards, "wall_s": round(r.wall_s, 2),
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
        prev_size = (prev or {}).get("args", {}).get("image_size") or recorder_image_size()
        if prev is not None and a.resume and prev_size != self.image_size():
            raise SystemExit(
                f"{self.work} was run with --image-size {prev_size}, this call has {self.image_size()}: pass the same "
                "--image-size to --resume (one work dir, one image size)")  # fmt: skip
        prev_extra = (prev or {}).get("args", {}).get("extra_steps")
        prev_extra = recorder_extra_steps() if prev_extra is None else prev_extra
        this_extra = recorder_extra_steps() if self.other_extra_steps() is None else self.other_extra_steps()
        if prev is not None and a.resume and prev_extra != this_extra:
            raise SystemExit(f"{self.work} was run with --extra-steps {prev_extra}, this call has "
                             f"{getattr(a, 'extra_steps', None)}: pass the same --extra-steps to --resume (one work "
                             "dir, one set of demos)")  # fmt: skip
        if prev is not None and a.resume and (prev.get("args", {}).get("train_arg") or None) != (a.train_arg or None):
            raise SystemExit(
                f"{self.work} was run with --train-arg {prev['args'].get('train_arg')}, this call has "
                f"{a.train_arg}: pass the same --train-arg to --resume (one results folder, one training recipe)")  # fmt: skip
        if not a.dry_run:
            _write_json(self.state_path, {"args": vars(a), "started": self.started})
        print(f"benchmark: scale {a.scale}, protocol {a.protocol}, tasks {a.tasks}, demos {a.demos}, "
              f"methods {a.methods}, seeds {a.seeds}; work dir {self.work}", flush=True)  # fmt: skip
        try:
            for unit in self.units:
                self.record(unit)
            for task in a.tasks:
                self.eval_set(task)
            for task in self.units:
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

    def inputs_sha1(self, task: str, n: int) -> str:
        """Fingerprint of what a run of unit ``task`` with ``n`` demos trains and is evaluated on: its demos' placements
        and its tasks' evaluation placements (rounded to 1e-9), so a resumed or collected run is never mixed with
        re-recorded data or a changed grid."""
        import numpy as np

        def rounded(placements):
            return np.round(np.asarray(placements, dtype=np.float64), 9).tolist() if placements else placements

        d = self.datasets.get(task, {}).get(n, {})
        by_task = d.get("placements_by_task")
        demos = {t: rounded(v) for t, v in by_task.items()} if by_task else rounded(d.get("placements"))
        evals = {t: rounded(self.eval_set(t)["placements"]) for t in unit_tasks(task)}
        return hashlib.sha1(json.dumps([demos, evals], sort_keys=True).encode()).hexdigest()[:16]

    def result_path(self, method: str, task: str, n: int, seed: int) -> Path:
        """The committed JSON of one finished run (survives a fresh clone; the work dir does not)."""
        return self.out / "runs" / f"{method}__{unit_name(task)}__n{n}__seed{seed}.json"

    def run_state(self, method: str, task: str, n: int, seed: int) -> dict:
        """This folder's state of a run (its work dir's run.json, else its result JSON); a finished run in a
        --collect-from folder wins over one this folder started but did not finish (a budget stop leaves a
        'running' run.json behind, which must not hide the finished run another benchmark made since)."""
        st = _read_json(self.run_dir(method, task, n, seed) / "run.json")
        if st is None:
            st = _read_json(self.result_path(method, task, n, seed))
        if st is None or st.get("status") != "done":
            st = self.collected_state(method, task, n, seed) or st
        return st or {}

    # the settings a collected run must share with this benchmark: results.json's settings key -> this run's value
    _COLLECT_MATCH = {("matched", "steps"): "steps", ("matched", "batch_size"): "batch_size",
                      ("record_seed",): "record_seed", ("eval_seed",): "eval_seed",
                      ("episode_length",): "episode_length", ("eval_episodes_per_cell",): "eval_episodes"}  # fmt: skip

    def _source_folder(self, folder: Path) -> Path:
        """A --collect-from folder, checked against this benchmark's settings (SystemExit naming the mismatch)."""
        if not folder.exists() and not folder.is_absolute():
            folder = REPO_ROOT / folder  # a folder named from the repository root, e.g. benchmarks/results/cpu
        folder = folder.resolve()
        res = _read_json(folder / "results.json")
        if res is None or not (folder / "runs").is_dir():
            raise SystemExit(f"--collect-from {folder}: not a benchmark results folder (no results.json and runs/)")
        if res["benchmark"].get("suite", "metaworld") != self.suite_name:
            raise SystemExit(f"--collect-from {_rel(folder)}: suite {res['benchmark'].get('suite', 'metaworld')}, "
                             f"this benchmark's is {self.suite_name}")  # fmt: skip
        if res["benchmark"]["protocol"] != self.a.protocol:
            raise SystemExit(f"--collect-from {_rel(folder)}: protocol {res['benchmark']['protocol']}, this "
                             f"benchmark's is {self.a.protocol}")  # fmt: skip
        for keys, ours in self._COLLECT_MATCH.items():
            theirs = res["settings"]
            for k in keys:
                theirs = theirs[k]
            if theirs != getattr(self.a, ours):
                raise SystemExit(f"--collect-from {_rel(folder)}: its runs used {'.'.join(keys)}={theirs}, this "
                                 f"benchmark {ours.replace('_', '-')}={getattr(self.a, ours)}: pass --"
                                 f"{ours.replace('_', '-')} {theirs} or leave that folder out")  # fmt: skip
        return folder

    def collected_state(self, method: str, task: str, n: int, seed: int) -> dict | None:
        """The finished run from the first --collect-from folder that has it, marked with `collected_from`."""
        name = self.result_path(method, task, n, seed).name
        for folder in self.collect_from:
            st = _read_json(folder / "runs" / name)
            if st is not None and st.get("status") == "done":
                return {**st, "collected_from": _rel(folder / "runs" / name)}
        return None

    def run_one(self, method: str, task: str, n: int, seed: int) -> None:
        a = self.a
        rdir = self.run_dir(method, task, n, seed)
        st = self.run_state(method, task, n, seed)
        inputs = self.inputs_sha1(task, n)
        if st.get("inputs_sha1") not in (None, inputs) and not a.dry_run:
            raise SystemExit(
                f"{method} / {task} / n{n} / seed {seed} was trained or evaluated on other placements than its dataset "
                f"and evaluation set hold now (the dataset was recorded again, or the placement rule changed): move "
                f"{_rel(rdir)} and {_rel(self.result_path(method, task, n, seed))} away (archive the result) to run it "
                "again")  # fmt: skip
        if st.get("status") == "done" and not a.dry_run:
            self._reread_loss_curve(rdir, st, self.result_path(method, task, n, seed))
            return
        if st.get("status") == "failed" and not a.retry_failed:
            self.failed = True
            return
        if a.eval_only and (trained := checkpoint_step(rdir / "train" / "checkpoints")) < a.steps:
            # a run still training (or stopped part-way) must not be evaluated and marked done at its last checkpoint
            print(f"--eval-only: {method} / {task} / n{n} is trained to step {trained} of {a.steps}; left for a later "
                  "--resume", flush=True)  # fmt: skip
            return
        st.update(method=method, task=task, demos=n, seed=seed, protocol=a.protocol, scale=a.scale, suite=self.suite_name,
                  status="running", code_commit=st.get("code_commit") or git_commit(), inputs_sha1=inputs)  # fmt: skip
        if len(unit_tasks(task)) > 1:
            st["tasks"] = unit_tasks(task)  # one policy trained on all of them (--multitask), evaluated on each
        print(f"=== {method} / {task} / {n} demos / seed {seed}", flush=True)
        try:
            if not a.eval_only:
                self.train(method, task, n, seed, st)
            if a.train_only:
                print(f"trained {method} / {task} / n{n}; evaluation left for a later --resume", flush=True)
                return
            self.evaluate(method, task, n, seed, st)
            if not a.dry_run:
                st["status"] = "done"
                st.pop("error", None)
                self._parse_train_log(rdir / "train.log", st, self.a.log_freq)
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
        """One row per (method, task, demos, seed); a --multitask run gives one row per task, all with the same
        checkpoint, and its training and evaluation cost and loss curve on its first task's row only (so that sums
        over rows count each run once)."""
        units, demos, seeds, methods = self.report_axes()
        runs = []
        for unit in units:
            for n in demos:
                for seed in seeds:
                    for method in methods:
                        rdir = self.run_dir(method, unit, n, seed)
                        st = self.run_state(method, unit, n, seed)
                        for i, task in enumerate(unit_tasks(unit)):
                            runs.append(self._row(method, unit, task, n, seed, rdir, st, first=i == 0))
        return runs

    def previous_report(self) -> dict | None:
        """--out's results.json if an earlier call of the same benchmark (suite, protocol, scale, steps, batch size,
        training recipe, one- or multi-task) wrote it, else None."""
        a = self.a
        prev = _read_json(self.out / "results.json")
        if not prev or "benchmark" not in prev:
            return None
        b, matched = prev["benchmark"], prev.get("settings", {}).get("matched", {})
        same = (b.get("suite", "metaworld") == self.suite_name and b.get("protocol") == a.protocol
                and b.get("scale") == a.scale and bool(b.get("multitask")) == bool(getattr(a, "multitask", False))
                and matched.get("steps") == a.steps and matched.get("batch_size") == a.batch_size
                and (b.get("train_arg") or []) == (a.train_arg or []))  # fmt: skip
        return prev if same else None

    def report_axes(self) -> tuple[list[str], list[int], list[int], list[str]]:
        """The (units, demos, seeds, methods) results.json covers: this call's, joined with those of the report an
        earlier call of the same benchmark left in --out, so that resuming a subset (``--tasks push-block --demos
        4``) adds its runs to the report instead of replacing it. The earlier report's datasets and evaluation
        placements of units this call did not touch are kept with it."""
        a = self.a
        units, demos, seeds, methods = list(self.units), list(a.demos), list(a.seeds), list(a.methods)
        prev = self.previous_report()
        if prev is None:
            return units, demos, seeds, methods
        b = prev["benchmark"]
        prev_units = [",".join(b["tasks"])] if b.get("multitask") else list(b.get("tasks", []))
        units = prev_units + [u for u in units if u not in prev_units]
        methods = b.get("methods", []) + [m for m in methods if m not in b.get("methods", [])]
        demos, seeds = sorted({*b.get("demos", []), *demos}), sorted({*b.get("seeds", []), *seeds})
        for task, sets in prev.get("eval_sets", {}).items():
            self.eval_sets.setdefault(task, sets)
        for task, by_n in prev.get("datasets", {}).items():
            mine = self.datasets.setdefault(task, {})
            for n, d in by_n.items():
                mine.setdefault(int(n), d)
        return units, demos, seeds, methods

    def earlier_commands(self) -> list[str]:
        """The commands of the earlier calls whose runs the report joins (report_axes), oldest first."""
        prev = self.previous_report()
        if prev is None:
            return []
        now = shlex.join([sys.executable, *sys.argv])
        cmds = [*prev["benchmark"].get("earlier_commands", []), prev["benchmark"].get("command")]
        return [c for i, c in enumerate(cmds) if c and c != now and c not in cmds[:i]]

    def _row(self, method: str, unit: str, task: str, n: int, seed: int, rdir: Path, st: dict, first: bool) -> dict:
        """results.json's row of ``task`` in the run ``st`` of ``unit``."""
        a = self.a
        multitask = len(unit_tasks(unit)) > 1
        es = self.eval_sets.get(task, {})
        succ: list[bool] = []
        seeds: list = []
        for key, c in sorted(st.get("eval_chunks", {}).items(), key=lambda kv: int(kv[0].split(":")[0])):
            s0 = int(key.split(":")[0])
            chunk = c["successes"][task] if multitask else c["successes"]
            succ += chunk
            seeds += es.get("seeds", [])[s0 : s0 + len(chunk)]
        k, m = sum(succ), len(succ)
        lo, hi = wilson_interval(k, m)
        slices = st.get("train_slices", [])
        loop = [s["loop_s"] for s in slices if s.get("loop_s") is not None]
        cost = first or not multitask
        row = {
            "method": method, "label": METHODS[method][1], "task": task, "demos": n, "seed": seed,
            "protocol": a.protocol, "suite": self.suite_name, "status": st.get("status", "pending"),
            "steps": a.steps, "batch_size": a.batch_size,
            "steps_done": max((s["end_step"] for s in slices), default=0),
            "n_params": st.get("n_params"),
            "train_seconds": round(sum(loop), 2) if loop and cost else None,
            "train_wall_seconds": round(sum(s["wall_s"] for s in slices), 2) if slices and cost else None,
            "train_slices": slices,
            "eval_episodes": m, "eval_episodes_planned": len(es.get("placements", [])),
            "successes": k, "success_rate": (k / m) if m else None,
            "ci95": [lo, hi] if m else None,
            "eval_seconds": round(sum(c["wall_s"] for c in st.get("eval_chunks", {}).values()), 2) if cost else 0,
            "per_episode_success": succ,
            "eval_seeds": seeds if a.protocol == "random" else None,
            "checkpoint": st.get("checkpoint"),
            "loss_curve": st.get("loss_curve") if cost else None,
            "run_dir": None if st.get("collected_from") else _rel(rdir),
            "collected_from": st.get("collected_from"),
            "commands": st.get("commands", {}),
            "error": st.get("error"),
        }  # fmt: skip
        if multitask:
            row.update(trained_on=unit_tasks(unit), training="multi-task")
        return row

    def write_reports(self) -> None:
        a = self.a
        if a.dry_run:
            return
        units, demos, seeds, methods = self.report_axes()
        tasks = list(dict.fromkeys(t for u in units for t in unit_tasks(u)))
        runs = self.collect()
        import lerobot
        import torch

        complete = all(r["status"] == "done" for r in runs)
        settings = {
            "matched": {
                "observation_history": {"rnd": 2, "diffusion": 2, "act": "1 (LeRobot ACT accepts only 1)"},
                "action_chunk_executed": 8, "rnd_chunk": 8, "act_chunk": 8,
                "diffusion_horizon": next((x.split("=", 1)[1] for x in self.method_args("diffusion")
                                           if x.startswith("--policy.horizon=")), "the config's"),
                "batch_size": a.batch_size, "steps": a.steps, "seeds": seeds,
                "pretrained_weights": "none: ACT's ImageNet ResNet-18 cannot be downloaded here "
                                      "(--policy.pretrained_backbone_weights=null); DP and R&D use none",
                "optimiser": "each method's own preset in its config file (config_files below): R&D AdamW with "
                             "the config's optimizer_lr and cosine decay; ACT AdamW 1e-4; DP Adam 1e-4, cosine",
            },
            "method_args": {m: self.method_args(m) for m in methods},
            "config_files": {m: _rel(self.config_file(m)) for m in methods},
            "record_seed": a.record_seed, "eval_seed": a.eval_seed, "episode_length": a.episode_length,
            "image_size": self.image_size(),
            "demo_extra_steps": recorder_extra_steps() if self.other_extra_steps() is None else self.other_extra_steps(),
            "eval_episodes_per_cell": (a.eval_episodes if a.protocol == "random" else "one per valid grid point"),
            "ci": "Wilson score interval, 95%",
            "eval_placements": (
                f"lerobot-eval --seed=S: episode i resets {self.suite['env_type']} with seed S+i, whose first valid "
                "draw from the task's placement range is the placement" if a.protocol == "random" else
                grid_eval.grid_description(self.suite["grid_layout"], self.suite["grid_others"], a.eval_seed)),
            "env_type": self.suite["env_type"],
        }  # fmt: skip
        if a.protocol == "spatial":
            settings["demo_placements"] = DEMO_PLACEMENTS[self.placements_mode()]
        result = {
            "benchmark": {
                "scale": a.scale, "suite": self.suite_name, "protocol": a.protocol, "multitask": bool(getattr(a, "multitask", False)),
                "tasks": tasks, "demos": demos,
                "methods": methods, "seeds": seeds, "device": a.device, "complete": complete, "harness_version": HARNESS_VERSION,
                "started": self.started, "written": dt.datetime.now().isoformat(timespec="seconds"),
                "command": shlex.join([sys.executable, *sys.argv]), "train_arg": a.train_arg or [],
                "earlier_commands": self.earlier_commands(),
                "collect_from": [_rel(f) for f in self.collect_from],
                "host": {"platform": platform.platform(), "python": platform.python_version(),
                         "cpus": os.cpu_count(), "torch": torch.__version__, "lerobot": lerobot.__version__,
                         "cuda": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None},
                "work_dir": _rel(self.work),
            },
            "settings": settings,
            "datasets": {t: {str(n): d for n, d in sorted(v.items())} for t, v in _in_order(self.datasets, units).items()},
            "eval_sets": _in_order(self.eval_sets, tasks),
            "runs": runs,
            "rnd_losses": rnd_losses(runs),
        }  # fmt: skip
        _write_json(self.out / "results.json", result)
        write_report_files(result, self.out)
        print(f"wrote {self.out / 'results.json'}, results.md, success_vs_demos.png", flush=True)
