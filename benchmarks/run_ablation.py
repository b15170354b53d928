#!/usr/bin/env python
"""R&D ablations on MetaWorld reach-v3 (CPU tier), evaluated on VALIDATION seeds (100-...), never on the
benchmark's evaluation seeds (1000-...): these runs choose defaults, so they must not see the test placements.

Each row trains `policies_config/metaworld/rnd_ai_cpu.json` with its training switches (or reuses another row's
checkpoint when only sampler switches differ), evaluates it with `lerobot-eval --seed=100` and its sampler
switches, and merges the row into `benchmarks/results/ablation_cpu.json`. Finished rows are skipped; a row
whose checkpoint exists is only evaluated.

    python benchmarks/run_ablation.py                       # every row (hours on 2 cores)
    python benchmarks/run_ablation.py --rows default,ddim_points
    python benchmarks/write_benchmarks_md.py                # then rewrite docs/BENCHMARKS.md
    python benchmarks/run_ablation.py --steps 3000 --data data/mw_reach-v3_10_tcp \
        --out benchmarks/results/ablation_cpu_tcp_3000.json --rows default,dropout_0.1   # other demos / length

A training row can reuse a checkpoint trained elsewhere with the same switches, steps and demos (e.g. by
`run_benchmark.py --train-only --train-arg rnd:--policy.dim_model=384`), so one training serves both the
validation here and, once chosen, the benchmark's test seeds: `--checkpoint width_384=<pretrained_model dir>`.
A checkpoint whose train_config.json differs from its row is refused.

The evaluation env is built with the demos' cameras (and flips, image size, state layout), read from the
dataset's `meta/rnd_recording.json`: `--data` recorded with `--cameras corner2,topview` is evaluated with them.

Data: `lerobot-rnd-record --task reach-v3 --episodes 10 --root data/mw_reach-v3_10 --repo-id local/mw_reach-v3_10
--seed 0` (recorded by this script when missing).
"""

import argparse
import json
import os
import re
import shlex
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from benchmarks.harness.reports import median_update_s_from_log, wilson_interval  # noqa: E402
from lerobot_rnd.precision import cpu_bf16_is_fast  # noqa: E402
from lerobot_rnd.sim.record import recorded_env_args, recorded_setting  # noqa: E402

OUT_JSON = REPO / "benchmarks" / "results" / "ablation_cpu.json"
WORK = REPO / "outputs" / "ablation"
DATA = REPO / "data" / "mw_reach-v3_10"

# name -> (training overrides, checkpoint of (None: its own training), sampler overrides)
ROWS = {
    "default": ([], None, []),  # x0 point update, embeddings std 1, history RGB untouched (research code)
    "ddim_points": ([], "default", ["--policy.point_update=ddim"]),  # the paper's equation on points
    "history_overlay": (["--policy.history_rgb_overlay=true"], None, []),
    "conv_patch": (["--policy.patch_embed=conv"], None, []),  # strided-conv RGB patch embedding
    "conv_ddim_points": ([], "conv_patch", ["--policy.point_update=ddim"]),
    # the paper's 16-px patches (a 8x8 grid at 128 px, against 4x4): 8 gripper patches cover what 4 of 32 px did
    "patch16": (["--policy.patch_size=16", "--policy.gripper_patches=8"], None, []),
    # today's config defaults trained again (the rows above ran under earlier defaults), and the same checkpoint
    # re-planning every 4 steps instead of executing the whole 8-step chunk open loop (more closed-loop looks)
    "current_defaults": ([], None, []),
    "replan_every_4": ([], "current_defaults", ["--policy.n_action_steps=4"]),
    "inference_steps_8": ([], "current_defaults", ["--policy.num_inference_steps=8"]),  # twice the denoising steps
    "width_384": (["--policy.dim_model=384"], None, []),  # capacity in the transformer
    # no point maps in (RGB only, renders still drawn on the future frames): is the rendered gripper's explicit 3-D
    # position a shortcut that lets the network recall demos by where the gripper is instead of reading the goal?
    "no_point_maps": (["--policy.use_point_map_input=false"], None, []),
    # one observation instead of two: with a history frame, behaviour cloning can learn to continue the past
    # motion instead of reading the goal (the "copycat" problem, Wen et al. 2020); ACT sees one observation
    "obs_steps_1": (["--policy.n_obs_steps=1"], None, []),
    # dropout in the transformer (ACT trains with 0.1): R&D-AI fits its demos but carries them over to new goals
    # less than ACT does
    "dropout_0.1": (["--policy.dropout=0.1"], None, []),
}
# Rows of switches since retired from the config (EMA, shift augmentation, camera dropout, the ResNet-18 and 3x3
# conv encoders, the first-step training fraction, the embedding init, the "interpolate" point update, the
# "clean"/"refine" denoising steps) stay in the archived JSON (benchmarks/results/INDEX.md); the code that ran
# them is git tag ablation-switches-2026-12.


def sh(argv: list[str], log: Path) -> None:
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log, "w") as f:
        r = subprocess.run(argv, stdout=f, stderr=subprocess.STDOUT, cwd=REPO)
    if r.returncode != 0:
        raise RuntimeError(f"{argv[0]} failed (rc {r.returncode}), see {log}")


def final_loss(log: Path) -> float | None:
    m = re.findall(r"loss:([0-9.]+)", log.read_text(errors="replace")) if log.exists() else []
    return float(m[-1]) if m else None


def check_reused_checkpoint(ckpt: Path, train_args: list[str], steps: int, data: Path) -> None:
    """Refuse a --checkpoint whose training differs from the row's (switches, steps, demos)."""
    cfg_path = ckpt / "train_config.json"
    if not cfg_path.exists():
        raise SystemExit(f"--checkpoint {ckpt}: no train_config.json (give a pretrained_model folder)")
    cfg = json.loads(cfg_path.read_text())
    problems = []
    if cfg.get("steps") != steps:
        problems.append(f"trained for {cfg.get('steps')} steps, not --steps {steps}")
    if Path(cfg["dataset"]["root"]).resolve() != data:
        problems.append(f"trained on {cfg['dataset']['root']}, not --data {data}")
    for arg in train_args:
        key, _, val = arg.removeprefix("--policy.").partition("=")
        have = cfg["policy"].get(key)
        if str(have).lower() != val.lower():
            problems.append(f"policy.{key} is {have}, the row wants {val}")
    if problems:
        raise SystemExit(f"--checkpoint {ckpt} does not match its row: " + "; ".join(problems))


# The training switches a row's checkpoint was trained with, read back from its train_config.json: the config's
# defaults change between rows' runs (patch_embed became "conv"), so a row's overrides alone don't say what ran.
RECORDED_SWITCHES = ("patch_size", "gripper_patches", "patch_embed", "history_rgb_overlay", "dropout", "point_update",
                     "dim_model", "n_obs_steps", "use_point_map_input")  # fmt: skip


def trained_switches(ckpt: Path) -> dict:
    """{switch: value} of RECORDED_SWITCHES from a pretrained_model folder's train_config.json ({} if missing)."""
    cfg_path = ckpt / "train_config.json"
    if not cfg_path.exists():
        return {}
    policy = json.loads(cfg_path.read_text()).get("policy", {})
    return {k: policy[k] for k in RECORDED_SWITCHES if k in policy}


def reused_train_command(ckpt: Path) -> list[str] | None:
    """The lerobot-train command of a run_benchmark.py checkpoint (<run>/train/checkpoints/N/pretrained_model)."""
    run_json = ckpt.parents[3] / "run.json"
    if not run_json.exists():
        return None
    return json.loads(run_json.read_text()).get("commands", {}).get("train")


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
    p.add_argument("--checkpoint", action="append", default=[], metavar="ROW=DIR",
                   help="evaluate this existing pretrained_model folder for ROW instead of training it (e.g. the "
                        "benchmark's run of the same config and demos); refused if its training differs")  # fmt: skip
    a = p.parse_args(argv)
    reuse = {}
    for spec in a.checkpoint:
        row, sep, path = spec.partition("=")
        if not sep or row not in ROWS or ROWS[row][1] is not None:
            p.error(f"--checkpoint {spec!r}: expected ROW=DIR with ROW one of the training rows "
                    f"{[r for r, v in ROWS.items() if v[1] is None]}")  # fmt: skip
        reuse[row] = Path(path).resolve()
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
    cameras = list(recorded_setting(rec_settings, "cameras"))
    n_demos = json.loads((data / "meta" / "info.json").read_text())["total_episodes"]
    extra_steps = recorded_setting(rec_settings, "extra_steps")
    for row in res["rows"]:
        row.setdefault("demos_expert_reach_target", expert)
        row.setdefault("demos_cameras", cameras)
        row.setdefault("demos", n_demos)
        row.setdefault("demos_extra_steps", extra_steps)
    done = {r["name"] for r in res["rows"]}
    res["description"] = (
        f"`python benchmarks/run_ablation.py{'' if out_json == OUT_JSON else ' --out ' + a.out} ...` (each row's "
        f"`ablation_command` has the whole call; R&D-AI CPU tier, {n_demos} demos of reach-v3 recorded with seed "
        f"{recorded_setting(rec_settings, 'seed')}, "
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
        reused = reuse.get(ckpt_of or name)
        if reused is not None:
            check_reused_checkpoint(reused, ROWS[ckpt_of or name][0], a.steps, data)
            ckpt = reused
        train_cmd = [str(bindir / "lerobot-train"), "--config_path=policies_config/metaworld/rnd_ai_cpu.json",
                     f"--dataset.root={data}", f"--dataset.repo_id={repo_id}", f"--steps={a.steps}",
                     "--save_freq=500", "--log_freq=50", f"--output_dir={run / 'train'}", *ROWS[ckpt_of or name][0]]  # fmt: skip
        t0 = time.time()
        if reused is not None:  # trained elsewhere: take the command from its harness run.json if there is one
            train_cmd = reused_train_command(reused)
        elif not ckpt.exists():
            print(f"[{name}] training {run.name} ...", flush=True)
            sh(train_cmd, run / "train.log")
        eval_dir = work / name / f"val_{a.val_seed}"
        eval_cmd = [str(bindir / "lerobot-eval"), f"--policy.path={ckpt}", "--env.type=rnd_mw", "--env.task=reach-v3",
                    f"--eval.n_episodes={a.episodes}", "--eval.batch_size=10", "--policy.device=cpu",
                    f"--seed={a.val_seed}", f"--output_dir={eval_dir}", *recorded_env_args(rec_settings), *sampler_args]  # fmt: skip
        if not (eval_dir / "eval_info.json").exists():
            print(f"[{name}] evaluating ...", flush=True)
            sh(eval_cmd, work / name / "eval.log")
        info = json.loads((eval_dir / "eval_info.json").read_text())
        succ = [bool(s) for s in info["per_task"][0]["metrics"]["successes"]]
        lo, hi = wilson_interval(sum(succ), len(succ))
        train_log = reused.parents[3] / "train.log" if reused else run / "train.log"
        res["rows"].append({
            "name": name, "train": " ".join(train_args) or "(config defaults)",
            "sampler": " ".join(sampler_args) or "(config defaults)", "steps": a.steps,
            "final_loss": final_loss(train_log),
            "update_s_median_logged": median_update_s_from_log(train_log.read_text(errors="replace"))
            if train_log.exists() else None,
            "checkpoint": str(ckpt.relative_to(REPO)) if ckpt.is_relative_to(REPO) else str(ckpt), "successes": sum(succ), "episodes": len(succ),
            "success_rate": sum(succ) / len(succ), "ci95": [lo, hi], "val_seeds": [a.val_seed, a.val_seed + len(succ) - 1],
            "per_episode_success": succ,
            "max_rewards": [round(float(x), 6) for x in info["per_task"][0]["metrics"].get("max_rewards") or []],
            "commands": {"train": train_cmd, "eval": eval_cmd},
            "trained_switches": trained_switches(ckpt), "bf16_autocast_on_this_cpu": cpu_bf16_is_fast(),
            "demos_expert_reach_target": expert, "demos_cameras": cameras, "demos": n_demos,
            "demos_extra_steps": extra_steps,
            "ablation_command": shlex.join(["python", "benchmarks/run_ablation.py", *(sys.argv[1:] if argv is None else argv)]),
            "seconds": round(time.time() - t0, 1),
        })  # fmt: skip
        out_json.write_text(json.dumps(res, indent=1))
        print(f"[{name}] {sum(succ)}/{len(succ)}; wrote {out_json}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
