#!/usr/bin/env python
"""Does a trained benchmark policy reproduce its own demonstrations? Evaluate it on its training placements.

A policy that fails on new placements may generalise badly (few demos) or may not even fit its demos
(underfitting, or a mismatch between training and inference). This script tells the two apart: it replays the
placements of the run's recorded demos (the successful attempts in the dataset's `meta/rnd_recording.json`, in
episode order) with `run_benchmark.py _grid_eval` (lerobot-eval's loop, one episode per placement) and writes
success and MetaWorld's max reward per episode. It also replays the demos' own recorded actions, so the policy can be
compared with how close the demonstrator itself came (MetaWorld's `obj_to_target` at the demo's last frame). These are training placements, not evaluation seeds: nothing is
tuned on the benchmark's test set.

    python benchmarks/eval_train_placements.py --methods rnd_ai,act --tasks reach-v3 \
        --out benchmarks/results/cpu/train_placements.json
    python benchmarks/eval_train_placements.py --suite panda --protocol spatial --tasks lift-cube --demos 8 \
        --work outputs/benchmark/panda_spatial --out benchmarks/results/panda_spatial/train_placements_lift-cube_n8.json

Runs are read from a benchmark's work dir (default `outputs/benchmark/cpu`, random protocol, 10 demos, seed 0);
an evaluation whose `eval_info.json` exists is not repeated. The demos' own actions are replayed on MetaWorld only
(the Panda recorder keeps only attempts whose expert succeeded). MetaWorld's reach reward is 10 inside the 5 cm
success radius and falls off with the distance beyond it, so a max reward of 9-9.99 means "came close".
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from benchmarks.harness.files import _read_json, _rel, _write_json  # noqa: E402
from benchmarks.harness.grid_eval import grid_eval_argv  # noqa: E402
from benchmarks.harness.reports import wilson_interval  # noqa: E402
from benchmarks.harness.scales import SUITES
from lerobot_rnd.sim.record import recorded_env_args  # noqa: E402


def training_placements(dataset_root: Path) -> list[list[float]]:
    """The placements of the dataset's episodes, in episode order (from the recorder's log)."""
    rec = _read_json(dataset_root / "meta" / "rnd_recording.json")
    if rec is None:
        raise FileNotFoundError(f"{dataset_root}/meta/rnd_recording.json: record the dataset with lerobot-rnd-record")
    kept = sorted((a for a in rec["attempts"] if a.get("success")), key=lambda a: a["episode_index"])
    return [a["placement"] for a in kept]


def replay_demos(dataset_root: Path, task: str) -> list[dict]:
    """Replay each recorded demo's actions from its placement (MetaWorld is deterministic) and measure how
    close the demonstrator itself came: per episode the max reward, and MetaWorld's ``obj_to_target`` (for
    reach: the distance from the gripper's centre to the goal, m) at the last frame and its minimum."""
    import numpy as np
    import pyarrow.parquet as pq

    from lerobot_rnd.sim.metaworld_env import RnDMetaWorldEnv

    table = pq.read_table(sorted((dataset_root / "data").glob("*/*.parquet")), columns=["episode_index", "action"])
    episodes = np.asarray(table.column("episode_index").to_pylist())
    actions = np.asarray(table.column("action").to_pylist(), dtype=np.float32)
    env = RnDMetaWorldEnv(task, observation_height=32, observation_width=32, episode_length=500,
                          terminate_on_success=False)  # fmt: skip
    out = []
    try:
        for ep, placement in enumerate(training_placements(dataset_root)):
            env.reset(options={"placement": placement})
            rewards, dist = [], []
            for action in actions[episodes == ep]:
                _, reward, _, _, _ = env.step(action)
                rewards.append(reward)
                dist.append(float(env.metaworld_info.get("obj_to_target", float("nan"))))
            out.append({"episode_index": ep, "frames": len(rewards), "max_reward": max(rewards),
                        "final_obj_to_target_m": dist[-1], "min_obj_to_target_m": min(dist)})  # fmt: skip
    finally:
        env.close()
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--suite", default="metaworld", choices=["metaworld", "panda", "so101"])
    p.add_argument("--protocol", default="random", choices=["random", "spatial"],
                   help="the benchmark's protocol: its datasets' placements and its work dir's runs/<protocol>")
    p.add_argument("--episode-length", type=int, default=None,
                   help="default: the suite's CPU-scale episode length (MetaWorld 300, Panda 120), as the benchmark")
    p.add_argument("--methods", default="rnd_ai,act")
    p.add_argument("--tasks", default="reach-v3")
    p.add_argument("--work", default="outputs/benchmark/cpu", help="the CPU benchmark's work dir")
    p.add_argument("--data", default="outputs/benchmark/data", help="where the benchmark recorded its datasets")
    p.add_argument("--demos", type=int, default=10)
    p.add_argument("--seed", type=int, default=0, help="training seed of the run")
    p.add_argument("--record-seed", type=int, default=0)
    p.add_argument("--checkpoint", default="last", help="checkpoint folder name (last, 001000, ...)")
    p.add_argument("--extra", action="append", default=[], metavar="NAME=CHECKPOINT",
                   help="also evaluate this pretrained_model folder (e.g. an ablation run on the same demos)")
    p.add_argument("--out", default="benchmarks/results/cpu/train_placements.json")
    a = p.parse_args(argv)
    work, data = (REPO / a.work).resolve(), (REPO / a.data).resolve()
    suite = SUITES[a.suite]
    episode_length = a.episode_length or suite["scales"].get("cpu", {}).get("episode_length", 300)
    placements_mode = suite["fps_mode"] if a.protocol == "spatial" else "random"
    rows, demos = [], {}
    for task in a.tasks.split(","):
        root = data / f"{suite['dataset_prefix']}_{task}_{placements_mode}_s{a.record_seed}_n{a.demos}"
        placements = training_placements(root)
        env_args = recorded_env_args((_read_json(root / "meta" / "rnd_recording.json") or {}).get("settings") or {})
        if a.suite == "metaworld":
            demos[task] = replay_demos(root, task)
        runs = []
        for method in a.methods.split(","):
            run = work / "runs" / a.protocol / method / task / f"n{a.demos}" / f"seed{a.seed}"
            ckpt = run / "train" / "checkpoints" / a.checkpoint / "pretrained_model"
            runs.append((method, ckpt, run / f"train_placements_{a.checkpoint}"))
        for spec in a.extra:
            name, _, path = spec.partition("=")
            ckpt = (REPO / path).resolve()
            runs.append((name, ckpt, ckpt.parents[2] / f"train_placements_{task}_{ckpt.parent.name}"))
        for method, ckpt, out_dir in runs:
            if not ckpt.exists():
                print(f"skip {method} / {task}: no checkpoint at {_rel(ckpt)}")
                continue
            pl_file = out_dir / "placements.json"
            argv_eval = grid_eval_argv(ckpt, "cpu", task, episode_length, 10, 0, pl_file, out_dir, env_args=env_args,
                                       env_type=suite["env_type"])  # fmt: skip
            if not (out_dir / "eval_info.json").exists():
                _write_json(pl_file, placements)
                print(f"evaluating {method} / {task} on its {len(placements)} training placements ...", flush=True)
                subprocess.run(argv_eval, check=True, cwd=REPO)
            m = _read_json(out_dir / "eval_info.json")["per_task"][0]["metrics"]
            k, n = sum(m["successes"]), len(m["successes"])
            lo, hi = wilson_interval(k, n)
            rows.append({"method": method, "task": task, "checkpoint": _rel(ckpt), "successes": k, "episodes": n,
                         "success_rate": k / n, "ci95": [lo, hi], "per_episode_success": m["successes"],
                         "max_rewards": m["max_rewards"], "placements": placements,
                         "command": [str(x).replace(f"{REPO}/", "") for x in argv_eval]})  # fmt: skip
    for task, eps in demos.items():
        print(f"\n{task}: the demos themselves (recorded actions replayed), final gripper-goal distance (cm): "
              + " ".join(f"{100 * e['final_obj_to_target_m']:.1f}" for e in eps))
        print("  max rewards: " + " ".join(f"{e['max_reward']:.2f}" for e in eps))
    w = max([len("method")] + [len(r["method"]) for r in rows]) + 2  # --extra names can be long
    print(f"\n{'method':<{w}}{'task':<28}{'success on training placements':>32}  max rewards")
    for r in rows:
        print(f"{r['method']:<{w}}{r['task']:<28}{r['successes']:>4}/{r['episodes']:<3} ({r['ci95'][0]:.0%}-"
              f"{r['ci95'][1]:.0%})".ljust(w + 60) + " ".join(f"{x:.2f}" for x in r["max_rewards"]))
    out = {"description": __doc__.strip().splitlines()[0],
           "command": "python benchmarks/eval_train_placements.py " + " ".join(argv if argv is not None else sys.argv[1:]),
           "rows": rows, "demos": demos}  # fmt: skip
    _write_json(REPO / a.out, out)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
