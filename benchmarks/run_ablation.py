#!/usr/bin/env python
"""R&D ablations on MetaWorld reach-v3 (CPU tier), evaluated on VALIDATION seeds (100-...), never on the
benchmark's evaluation seeds (1000-...): these runs choose defaults, so they must not see the test placements.

Each row trains `policies_config/metaworld/rnd_ai_cpu.json` with its training switches (or reuses another row's
checkpoint when only sampler switches differ), evaluates it with `lerobot-eval --seed=100` and its sampler
switches, and merges the row into `benchmarks/results/ablation_cpu.json`. Finished rows are skipped; a row
whose checkpoint exists is only evaluated.

    python benchmarks/run_ablation.py                       # every row (hours on 2 cores)
    python benchmarks/run_ablation.py --rows default,interpolate,ddim_points
    python benchmarks/write_benchmarks_md.py                # then rewrite docs/BENCHMARKS.md
    python benchmarks/run_ablation.py --steps 3000 --data data/mw_reach-v3_10_tcp \
        --out benchmarks/results/ablation_cpu_tcp_3000.json --rows default,shift_aug   # other demos / length

Data: `lerobot-rnd-record --task reach-v3 --episodes 10 --root data/mw_reach-v3_10 --repo-id local/mw_reach-v3_10
--seed 0` (recorded by this script when missing).
"""

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from benchmarks.harness.reports import wilson_interval  # noqa: E402
from lerobot_rnd.sim.record import recorded_setting  # noqa: E402

OUT_JSON = REPO / "benchmarks" / "results" / "ablation_cpu.json"
WORK = REPO / "outputs" / "ablation"
DATA = REPO / "data" / "mw_reach-v3_10"

# name -> (training overrides, checkpoint of (None: its own training), sampler overrides)
ROWS = {
    "default": ([], None, []),  # x0 point update, embeddings std 1, history RGB untouched (research code)
    "interpolate": ([], "default", ["--policy.point_update=interpolate"]),
    "ddim_points": ([], "default", ["--policy.point_update=ddim"]),  # the paper's equation on points
    "clean_jumps": ([], "default", ["--policy.denoise_step=clean"]),
    "embed_std_0.02": (["--policy.embedding_init_std=0.02"], None, []),
    "history_overlay": (["--policy.history_rgb_overlay=true"], None, []),
    "shift_aug": (["--policy.image_shift_augment=6"], None, []),  # +-6 px, principal point moved with them
    "legacy_like": (["--policy.embedding_init_std=0.02", "--policy.history_rgb_overlay=true"], None,
                    ["--policy.point_update=ddim"]),  # fmt: skip
}


def sh(argv: list[str], log: Path) -> None:
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "w") as f:
        r = subprocess.run(argv, stdout=f, stderr=subprocess.STDOUT, cwd=REPO)
    if r.returncode != 0:
        raise RuntimeError(f"{argv[0]} failed (rc {r.returncode}), see {log}")


def final_loss(log: Path) -> float | None:
    m = re.findall(r"loss:([0-9.]+)", log.read_text(errors="replace")) if log.exists() else []
    return float(m[-1]) if m else None


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rows", default=",".join(ROWS))
    p.add_argument("--steps", type=int, default=1500)
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--val-seed", type=int, default=100)
    p.add_argument("--data", default=str(DATA.relative_to(REPO)),
                   help="reach-v3 dataset (recorded with seed 0 when missing, by the current expert)")
    p.add_argument("--out", default=str(OUT_JSON.relative_to(REPO)),
                   help="results JSON; another file gets its own work folder outputs/ablation/<file stem>")
    a = p.parse_args(argv)
    data, out_json = (REPO / a.data).resolve(), (REPO / a.out).resolve()
    work = WORK if out_json == OUT_JSON else WORK / out_json.stem
    repo_id = "local/mw_reach-v3_10" if data == DATA else f"local/{data.name}"
    if a.val_seed + a.episodes > 1000:
        p.error("validation seeds must stay below the benchmark's evaluation seeds (1000+)")
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "HF_HUB_OFFLINE": "1"}
    os.environ.update(env)
    bindir = Path(sys.executable).parent
    if not data.exists():
        sh([str(bindir / "lerobot-rnd-record"), "--task", "reach-v3", "--episodes", "10", "--root", str(data),
            "--repo-id", repo_id, "--seed", "0"], work / "record.log")  # fmt: skip
    res = json.loads(out_json.read_text()) if out_json.exists() else {"rows": []}
    rec_settings = json.loads((data / "meta" / "rnd_recording.json").read_text())["settings"]
    expert = recorded_setting(rec_settings, "expert_reach_target")
    for row in res["rows"]:
        row.setdefault("demos_expert_reach_target", expert)
    done = {r["name"] for r in res["rows"]}
    res["description"] = (
        f"`python benchmarks/run_ablation.py{'' if out_json == OUT_JSON else ' --out ' + a.out}` (R&D-AI CPU tier, 10 demos of reach-v3 recorded with seed 0, "
        "validation seeds from 100: never the evaluation seeds). Rows sharing a checkpoint differ only in "
        "the sampler. `demos_expert_reach_target` says which expert recorded the demos: 'hand' is MetaWorld's "
        "own reach policy (demos end 3.4-4.9 cm from the goal), 'tcp' the corrected one."
    )
    out_json.write_text(json.dumps(res, indent=1))
    for name in a.rows.split(","):
        if name in done:
            continue
        train_args, ckpt_of, sampler_args = ROWS[name]
        run = work / (ckpt_of or name)
        ckpt = run / "train" / "checkpoints" / f"{a.steps:06d}" / "pretrained_model"
        train_cmd = [str(bindir / "lerobot-train"), "--config_path=policies_config/metaworld/rnd_ai_cpu.json",
                     f"--dataset.root={data}", f"--dataset.repo_id={repo_id}", f"--steps={a.steps}",
                     "--save_freq=500", "--log_freq=50", f"--output_dir={run / 'train'}", *ROWS[ckpt_of or name][0]]  # fmt: skip
        t0 = time.time()
        if not ckpt.exists():
            print(f"[{name}] training {run.name} ...", flush=True)
            sh(train_cmd, run / "train.log")
        eval_dir = work / name / f"val_{a.val_seed}"
        eval_cmd = [str(bindir / "lerobot-eval"), f"--policy.path={ckpt}", "--env.type=rnd_mw", "--env.task=reach-v3",
                    f"--eval.n_episodes={a.episodes}", "--eval.batch_size=10", "--policy.device=cpu",
                    f"--seed={a.val_seed}", f"--output_dir={eval_dir}", *sampler_args]  # fmt: skip
        if not (eval_dir / "eval_info.json").exists():
            print(f"[{name}] evaluating ...", flush=True)
            sh(eval_cmd, work / name / "eval.log")
        info = json.loads((eval_dir / "eval_info.json").read_text())
        succ = [bool(s) for s in info["per_task"][0]["metrics"]["successes"]]
        lo, hi = wilson_interval(sum(succ), len(succ))
        res["rows"].append({
            "name": name, "train": " ".join(train_args) or "(config defaults)",
            "sampler": " ".join(sampler_args) or "(config defaults)", "steps": a.steps,
            "final_loss": final_loss(run / "train.log"), "successes": sum(succ), "episodes": len(succ),
            "success_rate": sum(succ) / len(succ), "ci95": [lo, hi], "val_seeds": [a.val_seed, a.val_seed + len(succ) - 1],
            "per_episode_success": succ, "commands": {"train": train_cmd, "eval": eval_cmd},
            "demos_expert_reach_target": expert,
            "seconds": round(time.time() - t0, 1),
        })  # fmt: skip
        out_json.write_text(json.dumps(res, indent=1))
        print(f"[{name}] {sum(succ)}/{len(succ)}; wrote {out_json}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
