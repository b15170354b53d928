#!/usr/bin/env python
"""Episodes per minute of the Panda suite (``--env.type=rnd_panda``) on this machine, per task.

Two rollouts per task, with the observations the benchmark's policies get (two cameras, ``front`` and ``wrist``,
at the dataset size, 128 x 128 by default):

* ``expert``: the scripted expert as ``lerobot-rnd-record --suite panda`` runs it (until success + 10 extra
  frames, at most ``--max-steps``): what recording a demo costs, and how many steps the expert needs;
* ``random``: uniform random actions for ``--episode-length`` steps (no success end): the cost of the longest
  evaluation episode, without the policy.

Each control step (0.1 s) is split into its parts: the operational-space controller (Python, once per physics
step), MuJoCo's ``mj_step`` (``n_substeps`` = 50 per control step at 2 ms) and the camera renders; the JSON
holds the milliseconds per control step of each, so cheap speed-ups can be judged from it (fewer substeps,
fewer or smaller renders).

    python benchmarks/bench_panda_env.py --out benchmarks/results/panda_env_speed.json
    python benchmarks/bench_panda_env.py --tasks lift-cube --expert-episodes 1 --random-episodes 1   # quick
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

_REPO = Path(__file__).resolve().parents[1]
if str(_REPO) not in sys.path:
    sys.path.insert(0, str(_REPO))

from benchmarks.harness.scales import suite_scale_defaults  # noqa: E402


class _Timer:
    """Wraps a bound method of one object: calls and seconds spent in it."""

    def __init__(self, obj, name: str):
        self.fn, self.calls, self.s = getattr(obj, name), 0, 0.0
        setattr(obj, name, self)

    def __call__(self, *args, **kwargs):
        t = time.perf_counter()
        try:
            return self.fn(*args, **kwargs)
        finally:
            self.s += time.perf_counter() - t
            self.calls += 1


def _instrument(env) -> dict[str, _Timer]:
    import mujoco

    timers = {"render": _Timer(env, "_observation"), "controller": _Timer(env.controller, "torques")}
    step = mujoco.mj_step
    t = {"s": 0.0, "calls": 0}

    def timed_step(m, d, *a):
        t0 = time.perf_counter()
        step(m, d, *a)
        t["s"] += time.perf_counter() - t0
        t["calls"] += 1

    timers["_mj"] = t
    timers["_restore"] = lambda: setattr(mujoco, "mj_step", step)
    mujoco.mj_step = timed_step  # panda_env calls mujoco.mj_step through the module attribute
    return timers


def _breakdown(timers, steps: int, wall: float) -> dict:
    if steps == 0:
        return {}
    r, c, mj = timers["render"].s, timers["controller"].s, timers["_mj"]["s"]
    return {"ms_per_step": round(1e3 * wall / steps, 2), "render_ms": round(1e3 * r / steps, 2),
            "controller_ms": round(1e3 * c / steps, 2), "mj_step_ms": round(1e3 * mj / steps, 2),
            "other_ms": round(1e3 * (wall - r - c - mj) / steps, 2)}  # fmt: skip


def _reset_timers(timers) -> None:
    timers["render"].s = timers["controller"].s = timers["_mj"]["s"] = 0.0


def measure_task(task: str, a: argparse.Namespace) -> dict:
    import numpy as np

    from lerobot_rnd.sim.panda_env import RnDPandaEnv
    from lerobot_rnd.sim.panda_experts import PandaExpert
    from lerobot_rnd.sim.record import PlacementSequence, run_expert_episode

    t0 = time.perf_counter()
    env = RnDPandaEnv(task, camera_names=a.cameras, observation_height=a.image_size, observation_width=a.image_size,
                      episode_length=max(a.episode_length, a.max_steps + 10), terminate_on_success=False)  # fmt: skip
    build_s = time.perf_counter() - t0
    timers = _instrument(env)
    out: dict = {"task": task, "env_build_s": round(build_s, 2), "n_substeps": env.n_substeps}
    try:
        # expert, as the recorder runs it
        expert = PandaExpert(task, seed=a.seed)
        seq = PlacementSequence(env, "random", a.seed)
        eps = []
        _reset_timers(timers)
        t_all, steps_all = 0.0, 0
        for i in range(a.expert_episodes):
            t = time.perf_counter()
            frames, ok, steps = run_expert_episode(env, expert, seq[i], a.max_steps, 10)
            dt = time.perf_counter() - t
            t_all += dt
            steps_all += len(frames)
            eps.append({"success": bool(ok), "steps_to_success": steps, "frames": len(frames), "s": round(dt, 2)})
        out["expert"] = {"episodes": eps, "episodes_per_min": round(60 * len(eps) / t_all, 2) if t_all else None,
                         **_breakdown(timers, steps_all, t_all)}  # fmt: skip
        # random actions: an evaluation episode of --episode-length steps (measured over --random-steps steps
        # per episode, then scaled to the episode's length: the cost per step does not depend on the step)
        rng = np.random.default_rng(a.seed)
        n_steps = a.random_steps or a.episode_length
        t_all, steps_all, reset_s = 0.0, 0, 0.0
        parts = {"render": 0.0, "controller": 0.0, "_mj": 0.0}
        for i in range(a.random_episodes):
            t = time.perf_counter()
            env.reset(seed=a.seed + i)
            reset_s += time.perf_counter() - t
            _reset_timers(timers)  # the breakdown counts the steps only (the first reset builds the renderers)
            t = time.perf_counter()
            for _ in range(n_steps):
                env.step(rng.uniform(-1, 1, 7).astype(np.float32))
            t_all += time.perf_counter() - t
            steps_all += n_steps
            for k in parts:
                parts[k] += timers[k]["s"] if k == "_mj" else timers[k].s
        timers["render"].s, timers["controller"].s, timers["_mj"]["s"] = parts["render"], parts["controller"], parts["_mj"]
        step_s = t_all / max(1, steps_all)
        episode_s = reset_s / max(1, a.random_episodes) + a.episode_length * step_s
        out["random"] = {"episodes": a.random_episodes, "steps_measured_per_episode": n_steps,
                         "episode_length": a.episode_length, "reset_s": round(reset_s / max(1, a.random_episodes), 3),
                         "episode_s": round(episode_s, 2), "episodes_per_min": round(60 / episode_s, 2),
                         **_breakdown(timers, steps_all, t_all)}  # fmt: skip
        # one camera alone, at the dataset size and at half of it (is the render cost in the pixels?)
        probe = {}
        for cam in a.cameras:
            for size in (a.image_size, a.image_size // 2):
                env.render_camera_image(cam, (size, size))  # builds the renderer
                t = time.perf_counter()
                for _ in range(a.render_probe):
                    env.render_camera_image(cam, (size, size))
                probe[f"{cam}_{size}"] = round(1e3 * (time.perf_counter() - t) / max(1, a.render_probe), 2)
        out["render_ms_per_camera"] = probe
    finally:
        timers["_restore"]()
        env.close()
    return out


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("MUJOCO_GL", "egl")
    d = suite_scale_defaults("panda", "cpu")
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", default="lift-cube,push-block,press-button,pick-place,slide-block")
    p.add_argument("--expert-episodes", type=int, default=2)
    p.add_argument("--random-episodes", type=int, default=1)
    p.add_argument("--episode-length", type=int, default=d["episode_length"],
                   help="steps of a random-action episode (default: the benchmark's panda cpu scale)")  # fmt: skip
    p.add_argument("--random-steps", type=int, default=0,
                   help="steps measured per random episode (0: the whole --episode-length); the episode's time is "
                        "the reset plus --episode-length times the measured time per step")
    p.add_argument("--render-probe", type=int, default=10, help="renders per camera and size in the render probe")
    p.add_argument("--max-steps", type=int, default=120, help="expert step limit (the recorder's panda default)")
    p.add_argument("--image-size", type=int, default=128)
    p.add_argument("--cameras", default="front,wrist")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", help="JSON file to write")
    a = p.parse_args(argv)
    a.cameras = [c for c in a.cameras.split(",") if c]
    import mujoco
    import torch

    rows = []
    t0 = time.time()
    for task in [t for t in a.tasks.split(",") if t]:
        r = measure_task(task, a)
        rows.append(r)
        print(json.dumps(r), flush=True)
    hdr = (f"{'task':<13} {'expert ep/min':>13} {'expert steps':>12} {'random ep/min':>13} {'ms/step':>8} "
           f"{'render':>7} {'ctrl':>6} {'mj_step':>7} {'other':>6}")  # fmt: skip
    print(f"\n{len(a.cameras)} cameras at {a.image_size}x{a.image_size}, random episodes of {a.episode_length} steps "
          f"(ms per control step from the random rollouts)\n" + hdr)  # fmt: skip
    for r in rows:
        e, x = r["expert"], r["random"]
        steps = [ep["steps_to_success"] for ep in e["episodes"] if ep["steps_to_success"]]
        print(f"{r['task']:<13} {str(e['episodes_per_min']):>13} {str(steps):>12} {str(x['episodes_per_min']):>13} "
              f"{x['ms_per_step']:>8} {x['render_ms']:>7} {x['controller_ms']:>6} {x['mj_step_ms']:>7} "
              f"{x['other_ms']:>6}")  # fmt: skip
    for r in rows:
        print(f"{r['task']}: ms per render of one camera alone: " + ", ".join(
            f"{k} {v}" for k, v in r["render_ms_per_camera"].items()))  # fmt: skip
    res = {
        "what": "episodes per minute of the Panda suite (lerobot_rnd.sim.panda_env), scripted expert as recorded "
                "and uniform random actions for a full evaluation episode; ms per control step split into the "
                "camera renders, the Python operational-space controller and MuJoCo's mj_step",
        "command": " ".join([sys.executable, *sys.argv]),
        "settings": {k: v for k, v in vars(a).items() if k != "out"},
        "host": {"platform": platform.platform(), "cpus": os.cpu_count(), "python": platform.python_version(),
                 "mujoco": mujoco.__version__, "torch": torch.__version__,
                 "MUJOCO_GL": os.environ.get("MUJOCO_GL")},
        "load_average_at_end": [round(x, 2) for x in os.getloadavg()],  # other jobs on the machine slow it down
        "total_s": round(time.time() - t0, 1),
        "tasks": rows,
    }  # fmt: skip
    if a.out:
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        Path(a.out).write_text(json.dumps(res, indent=1) + "\n")
        print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
