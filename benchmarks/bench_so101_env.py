#!/usr/bin/env python
"""The simulated SO-101's scripted experts and speed (``--env.type=rnd_so101``), per task.

For each task, ``--episodes`` expert rollouts from placement seeds ``--seed`` .. ``--seed + episodes - 1`` (never
the benchmark's evaluation seeds, 1000 and up) with the observations the benchmark's policies get (front and wrist
cameras at 128 x 128), each until success or ``--episode-length`` steps (the harness's 150). Reported per task:
the expert's success rate (Wilson 95% interval), the steps it needs (median, max), episodes per minute, and the
milliseconds of one control step (1/30 s) split into physics (20 MuJoCo substeps) and the camera renders.

    python benchmarks/bench_so101_env.py --out benchmarks/results/so101_env_speed.json
    python benchmarks/bench_so101_env.py --tasks reach-target --episodes 2     # quick
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
_REPO = Path(__file__).resolve().parents[1]
if str(_REPO) not in sys.path:
    sys.path.insert(0, str(_REPO))

from benchmarks.harness.files import write_result_json
from benchmarks.harness.reports import wilson_interval


def run_task(task: str, episodes: int, seed: int, episode_length: int, image_size: int) -> dict:
    """Expert rollouts of one task: successes, steps, and where a control step's time goes."""
    from lerobot_rnd.sim.so101_env import RnDSO101Env
    from lerobot_rnd.sim.so101_experts import SO101Expert

    env = RnDSO101Env(task, episode_length=episode_length, observation_height=image_size, observation_width=image_size)
    observe = env._observation
    render_s = [0.0]

    def timed_observation(*args, **kwargs):
        t = time.perf_counter()
        try:
            return observe(*args, **kwargs)
        finally:
            render_s[0] += time.perf_counter() - t

    env._observation = timed_observation
    successes, steps_needed, wall = [], [], 0.0
    step_s = render_in_steps = 0.0
    n_steps = 0
    for ep in range(episodes):
        t0 = time.perf_counter()
        env.reset(seed=seed + ep)
        expert = SO101Expert(task)
        ok = False
        for _ in range(episode_length):
            action = expert.act(env)
            before = render_s[0]
            t = time.perf_counter()
            _, _, terminated, truncated, info = env.step(action)
            step_s += time.perf_counter() - t
            render_in_steps += render_s[0] - before
            n_steps += 1
            if info["is_success"]:
                ok = True
                break
            if terminated or truncated:
                break
        wall += time.perf_counter() - t0
        successes.append(ok)
        steps_needed.append(env.steps)
        print(f"{task} episode {ep + 1}/{episodes}: {'success' if ok else 'failure'} after {env.steps} steps",
              flush=True)
    env.close()
    k = sum(successes)
    return {
        "task": task,
        "episodes": episodes,
        "successes": k,
        "success_rate": k / episodes,
        "wilson95": wilson_interval(k, episodes),
        "failed_seeds": [seed + i for i, s in enumerate(successes) if not s],
        "steps_median": statistics.median(steps_needed),
        "steps_max": max(steps_needed),
        "episodes_per_minute": 60.0 * episodes / wall,
        "ms_per_control_step": {"total": 1e3 * step_s / n_steps,
                                "render": 1e3 * render_in_steps / n_steps,
                                "physics_and_rest": 1e3 * (step_s - render_in_steps) / n_steps},
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--tasks", default="reach-target,pick-cube")
    p.add_argument("--episodes", type=int, default=30)
    p.add_argument("--seed", type=int, default=0, help="first placement seed (keep clear of evaluation seeds)")
    p.add_argument("--episode-length", type=int, default=150, help="the harness's so101 episode length")
    p.add_argument("--image-size", type=int, default=128)
    p.add_argument("--out", help="JSON file to write")
    a = p.parse_args(argv)
    if a.episodes < 1:
        p.error("--episodes must be at least 1")
    if a.seed + a.episodes > 1000:
        p.error(f"--seed {a.seed} with {a.episodes} episodes reaches the evaluation seeds (1000 and up)")
    import torch

    rows = [run_task(t, a.episodes, a.seed, a.episode_length, a.image_size) for t in a.tasks.split(",") if t]
    print(f"\n{'task':<14}{'expert success':>18}{'steps (med/max)':>17}{'episodes/min':>14}"
          f"{'ms/step':>9}{'render':>8}{'physics':>9}")
    for r in rows:
        lo, hi = r["wilson95"]
        ms = r["ms_per_control_step"]
        print(f"{r['task']:<14}{r['successes']:>5}/{r['episodes']:<3}({lo:.0%}-{hi:.0%})"
              f"{r['steps_median']:>9.0f}/{r['steps_max']:<7}{r['episodes_per_minute']:>14.1f}"
              f"{ms['total']:>9.1f}{ms['render']:>8.1f}{ms['physics_and_rest']:>9.1f}")
    if a.out:
        out = {
            "benchmark": "so101_env",
            "settings": {"episodes": a.episodes, "seed": a.seed, "episode_length": a.episode_length,
                         "image_size": a.image_size, "cameras": ["front", "wrist"]},
            "machine": {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
                        "torch": torch.__version__, "mujoco_gl": os.environ.get("MUJOCO_GL"),
                        # other work on the machine scales the times (not the success rates)
                        "load_average_1_5_15min": [round(x, 2) for x in os.getloadavg()]},
            "results": rows,
        }
        write_result_json(a.out, out, argv, script="benchmarks/bench_so101_env.py")
    return 0


if __name__ == "__main__":
    sys.exit(main())
