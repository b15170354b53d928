#!/usr/bin/env python
"""Success against training steps: evaluate every saved checkpoint of one training run on VALIDATION seeds.

Training loss says when a policy stops fitting its demos, not when it stops getting better at the task. This
script evaluates each `checkpoints/<step>/pretrained_model` of a `lerobot-train` output folder with
`lerobot-eval --seed=<val seed>` (seeds 100-..., never the benchmark's evaluation seeds 1000-...) and writes

    <out>.json   one row per checkpoint: step, successes, episodes, Wilson 95% interval, per-episode success,
                 the training loss logged nearest that step, and the eval command
    <out>.png    success (with intervals) and training loss against the step

and keeps each evaluation's videos and log under outputs/validation_curve/<out name>/.

Finished checkpoints are skipped, so the script resumes; run it again as more checkpoints appear.

    python benchmarks/validation_curve.py \
        --train-dir outputs/benchmark/cpu_9000/runs/random/rnd_ai/reach-v3/n10/seed0/train \
        --out benchmarks/results/archive/validation_curve_cpu_9000
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from benchmarks.harness.reports import loss_curve_from_log, wilson_interval  # noqa: E402

WORK = REPO / "outputs" / "validation_curve"
FIRST_EVALUATION_SEED = 1000  # the benchmark's test seeds start here (run_benchmark.py --eval-seed)


def loss_near(losses: dict[int, float], step: int) -> float | None:
    """The loss logged at the last logging step <= `step` (None when nothing was logged by then)."""
    before = [s for s in losses if s <= step]
    return losses[max(before)] if before else None


def checkpoint_steps(train_dir: Path) -> list[int]:
    """Steps of the saved checkpoints that hold a pretrained_model folder, ascending."""
    ckpts = train_dir / "checkpoints"
    if not ckpts.is_dir():
        return []
    return sorted(
        int(d.name) for d in ckpts.iterdir() if d.name.isdigit() and (d / "pretrained_model").is_dir()
    )


def plot(res: dict, png: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = sorted(res["rows"], key=lambda r: r["step"])
    steps = [r["step"] for r in rows]
    rate = [100 * r["success_rate"] for r in rows]
    err = [
        [100 * (r["success_rate"] - r["ci95"][0]) for r in rows],
        [100 * (r["ci95"][1] - r["success_rate"]) for r in rows],
    ]
    fig, ax = plt.subplots(figsize=(6, 3.5))
    ax.errorbar(steps, rate, yerr=err, marker="o", capsize=3, label="validation success (Wilson 95%)")
    ax.set_xlabel("training step")
    ax.set_ylabel("success (%)")
    ax.set_ylim(0, 100)
    losses = {int(k): v for k, v in res.get("training_loss", {}).items()}
    if losses:
        ax2 = ax.twinx()
        ks = sorted(losses)
        ax2.plot(ks, [losses[k] for k in ks], color="tab:gray", alpha=0.6, lw=1, label="training loss")
        ax2.set_yscale("log")
        ax2.set_ylabel("training loss")
    ax.set_title(res["title"], fontsize=9)
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--train-dir", required=True, help="a lerobot-train --output_dir (holds checkpoints/ and, "
                   "from the harness, ../train.log)")  # fmt: skip
    p.add_argument("--out", required=True, help="output path without suffix (.json and .png are written)")
    p.add_argument("--task", default="reach-v3")
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--val-seed", type=int, default=100)
    p.add_argument("--steps", default="", help="comma-separated checkpoint steps (default: every saved one)")
    p.add_argument(
        "--eval-arg", action="append", default=[], help="extra lerobot-eval argument (sampler switch)"
    )
    a = p.parse_args(argv)
    if a.val_seed + a.episodes > FIRST_EVALUATION_SEED:
        p.error(f"validation seeds {a.val_seed}..{a.val_seed + a.episodes - 1} reach the benchmark's evaluation "
                f"seeds ({FIRST_EVALUATION_SEED}+): lower --val-seed or --episodes")  # fmt: skip
    train_dir = Path(a.train_dir).resolve()
    available = checkpoint_steps(train_dir)
    if not available:
        p.error(f"--train-dir {train_dir}: no checkpoints/<step>/pretrained_model folder (is it a lerobot-train "
                "--output_dir?)")  # fmt: skip
    wanted = [int(s) for s in a.steps.split(",") if s] or available
    missing = sorted(set(wanted) - set(available))
    if missing:
        p.error(f"--steps {missing} not saved in {train_dir / 'checkpoints'} (saved: {available})")
    out = Path(a.out).resolve()
    out_json, out_png = out.with_suffix(".json"), out.with_suffix(".png")
    res = json.loads(out_json.read_text()) if out_json.exists() else {"rows": []}
    if res.get("train_dir") not in (None, str(train_dir)) or res.get("eval_args", a.eval_arg) != a.eval_arg:
        p.error(f"{out_json} holds another run's curve ({res.get('train_dir')}, eval args {res.get('eval_args')}); "
                "give another --out")  # fmt: skip
    cfg = json.loads((train_dir / "checkpoints" / f"{available[-1]:06d}" / "pretrained_model" /
                      "train_config.json").read_text())  # fmt: skip
    from lerobot_rnd.sim.record import training_env_args  # the demos' cameras (imports lerobot: not at the top)

    try:
        env_args = training_env_args(cfg)
    except FileNotFoundError as e:
        p.error(str(e))
    train_log = next(
        (f for f in (train_dir / "train.log", train_dir.parent / "train.log") if f.exists()), None
    )
    losses = (
        dict(loss_curve_from_log(train_log.read_text(errors="replace"), cfg["log_freq"])) if train_log else {}
    )
    res.update({
        "benchmark": "validation_curve",
        "title": f"{cfg['policy']['type']} on {a.task}, {cfg['steps']} steps planned, validation seeds "
                 f"{a.val_seed}-{a.val_seed + a.episodes - 1}",
        "train_dir": str(train_dir), "train_steps_planned": cfg["steps"], "eval_args": a.eval_arg,
        "training_loss": {str(k): v for k, v in sorted(losses.items())},
        "note": "validation seeds only (never the benchmark's evaluation seeds 1000+); a checkpoint before the "
                "last is taken at a higher learning rate than a run that stops there (cosine schedule over "
                "train_steps_planned)",
    })  # fmt: skip
    command = shlex.join(
        ["python", "benchmarks/validation_curve.py", *(sys.argv[1:] if argv is None else argv)]
    )
    if "command" in res:  # a file written before the list held one call
        res["commands"] = [res.pop("command")]
    if command not in res.setdefault("commands", []):
        res["commands"].append(command)  # every distinct call, in order
    done = {r["step"] for r in res["rows"]}
    bindir = Path(sys.executable).parent
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"), "HF_HUB_OFFLINE": "1"}
    for step in wanted:
        if step in done:
            continue
        ckpt = train_dir / "checkpoints" / f"{step:06d}" / "pretrained_model"
        eval_dir = WORK / out.name / f"step_{step:06d}"  # videos and logs stay out of the results folder
        cmd = [str(bindir / "lerobot-eval"), f"--policy.path={ckpt}", "--env.type=rnd_mw", f"--env.task={a.task}",
               f"--eval.n_episodes={a.episodes}", "--eval.batch_size=10", "--policy.device=cpu",
               f"--seed={a.val_seed}", f"--output_dir={eval_dir}", *env_args, *a.eval_arg]  # fmt: skip
        print(f"[step {step}] evaluating on seeds {a.val_seed}-{a.val_seed + a.episodes - 1} ...", flush=True)
        t0 = time.time()
        log = eval_dir.parent / f"step_{step:06d}.log"
        log.parent.mkdir(parents=True, exist_ok=True)
        with open(log, "w") as f:
            rc = subprocess.run(
                cmd, check=False, stdout=f, stderr=subprocess.STDOUT, cwd=REPO, env=env
            ).returncode
        if rc != 0:
            raise SystemExit(f"lerobot-eval failed (rc {rc}) for step {step}; see {log}")
        info = json.loads((eval_dir / "eval_info.json").read_text())
        succ = [bool(s) for s in info["per_task"][0]["metrics"]["successes"]]
        lo, hi = wilson_interval(sum(succ), len(succ))
        res["rows"].append({
            "step": step, "successes": sum(succ), "episodes": len(succ), "success_rate": sum(succ) / len(succ),
            "ci95": [lo, hi], "val_seeds": [a.val_seed, a.val_seed + len(succ) - 1], "per_episode_success": succ,
            "training_loss_near_step": loss_near(losses, step), "eval_command": cmd,
            "eval_seconds": round(time.time() - t0, 1),
        })  # fmt: skip
        res["rows"].sort(key=lambda r: r["step"])
        out_json.write_text(json.dumps(res, indent=1))
        print(f"[step {step}] {sum(succ)}/{len(succ)}; wrote {out_json}", flush=True)
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(res, indent=1))
    if res["rows"]:
        plot(res, out_png)
        print(f"wrote {out_png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
