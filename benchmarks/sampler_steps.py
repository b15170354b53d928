#!/usr/bin/env python
"""The same trained R&D checkpoints sampled with different numbers of denoising steps, episode for episode.

Two ways to name what to evaluate:

* ``--run-json`` a finished run of ``run_benchmark.py`` (its JSON under ``benchmarks/results/<bench>/runs/``):
  its own ``lerobot-eval`` commands are replayed chunk by chunk (same checkpoint, same seeds, same env flags),
  each with ``--policy.num_inference_steps=N`` added and its own output folder. The run's committed successes
  are copied beside the new ones, so a rerun at the default step count checks that the numbers reproduce.
* ``--checkpoint TASK=DIR`` with ``--seed`` and ``--episodes``: one ``lerobot-eval`` call per step count, its env
  built with the cameras of the demos the checkpoint was trained on (from its ``train_config.json``).

    # test seeds of the CPU benchmark's R&D-AI runs, 4 steps (the default) against 1
    python benchmarks/sampler_steps.py --inference-steps 4,1 --out benchmarks/results/one_step_sampling_test.json \
        --run-json benchmarks/results/cpu_3000_drawer/runs/rnd_ai__drawer-close-v3__n10__seed0.json
    # validation seeds of a checkpoint
    python benchmarks/sampler_steps.py --inference-steps 4,1 --seed 100 --episodes 20 \
        --checkpoint drawer-close-v3=outputs/.../pretrained_model --out benchmarks/results/one_step_sampling_val.json

Finished (checkpoint, step count) entries of ``--out`` are skipped, so an interrupted call resumes; the JSON is
written after each one. The table printed at the end gives successes and the evaluation time ratio against the
first step count given, measured in the same call.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shlex
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from benchmarks.harness.reports import wilson_interval  # noqa: E402
from lerobot_rnd.sim.record import training_env_args  # noqa: E402

WORK = REPO / "outputs" / "sampler_steps"
TEST_SEEDS_FROM = 1000  # the benchmark's evaluation seeds; validation seeds stay below


def with_inference_steps(eval_argv: list[str], steps: int, output_dir: Path, lerobot_eval: str) -> list[str]:
    """``eval_argv`` (a lerobot-eval command) run by ``lerobot_eval`` with ``--output_dir=output_dir`` and
    ``--policy.num_inference_steps=steps``; any earlier value of either flag is dropped."""
    keep = [a for a in eval_argv[1:] if not a.startswith(("--output_dir=", "--policy.num_inference_steps="))]
    return [lerobot_eval, *keep, f"--output_dir={output_dir}", f"--policy.num_inference_steps={steps}"]


def flag(argv: list[str], name: str) -> str | None:
    """Value of ``--name=value`` in ``argv`` (the last one wins, as with draccus), else None."""
    vals = [a.split("=", 1)[1] for a in argv if a.startswith(f"--{name}=")]
    return vals[-1] if vals else None


def checkpoint_env_args(checkpoint: Path) -> list[str]:
    """The ``--env.*`` flags of the demos ``checkpoint`` (a pretrained_model folder) was trained on."""
    cfg = checkpoint / "train_config.json"
    if not cfg.exists():
        return []
    try:
        return training_env_args(json.loads(cfg.read_text()))
    except FileNotFoundError as e:
        raise SystemExit(f"--checkpoint {checkpoint}: {e}") from None


def checkpoint_name(task: str, path: str) -> str:
    """A stable name for a --checkpoint entry: the task and a short digest of the folder's resolved path."""
    return f"{task}__{hashlib.sha1(str(Path(path).resolve()).encode()).hexdigest()[:8]}"


def targets_from_args(a: argparse.Namespace) -> list[dict]:
    """One dict per checkpoint: name, task, eval commands (one per chunk) and the committed successes if any."""
    out = []
    for spec in a.run_json:
        run = json.loads(Path(spec).read_text())
        if run.get("status") != "done":
            raise SystemExit(f"--run-json {spec}: status is {run.get('status')!r}, not 'done'; finish the run first")
        chunks = sorted(run["eval_chunks"].items(), key=lambda kv: int(kv[0].split(":")[0]))
        committed = [bool(s) for _, c in chunks for s in c["successes"]]
        out.append({"name": Path(spec).stem, "task": run["task"], "method": run["method"], "source": spec,
                    "commands": run["commands"]["eval"], "committed_successes": committed,
                    "checkpoint": run["checkpoint"]})  # fmt: skip
    for spec in a.checkpoint:
        task, sep, path = spec.partition("=")
        if not sep or not task or not Path(path).is_dir():
            raise SystemExit(f"--checkpoint {spec!r}: expected TASK=DIR with DIR a pretrained_model folder")
        cmd = ["lerobot-eval", f"--policy.path={path}", "--policy.device=cpu", "--env.type=rnd_mw",
               f"--env.task={task}", "--env.episode_length=300", f"--eval.n_episodes={a.episodes}",
               f"--eval.batch_size={min(10, a.episodes)}", f"--seed={a.seed}",
               *checkpoint_env_args(Path(path))]  # fmt: skip
        out.append({"name": checkpoint_name(task, path), "task": task, "method": "rnd", "source": path,
                    "commands": [cmd], "committed_successes": None, "checkpoint": path})  # fmt: skip
    return out


def evaluate(target: dict, steps: int, work: Path, lerobot_eval: str) -> dict:
    succ, rewards, eval_s, cmds = [], [], 0.0, []
    for i, cmd in enumerate(target["commands"]):
        out_dir = work / target["name"] / f"steps_{steps}" / f"chunk{i}"
        argv = with_inference_steps(cmd, steps, out_dir, lerobot_eval)
        cmds.append(shlex.join(argv))
        if not (out_dir / "eval_info.json").exists():
            log = out_dir.parent / f"chunk{i}.log"
            log.parent.mkdir(parents=True, exist_ok=True)
            t0 = time.time()
            with open(log, "w") as f:
                rc = subprocess.run(argv, stdout=f, stderr=subprocess.STDOUT, cwd=REPO).returncode
            if rc != 0:
                raise RuntimeError(f"lerobot-eval failed (rc {rc}); see {log}")
            (out_dir / "wall_s.txt").write_text(f"{time.time() - t0:.1f}\n")
        info = json.loads((out_dir / "eval_info.json").read_text())
        m = info["per_task"][0]["metrics"]
        succ += [bool(s) for s in m["successes"]]
        rewards += [round(float(x), 6) for x in m.get("max_rewards") or []]
        eval_s += float(info["overall"].get("eval_s") or float((out_dir / "wall_s.txt").read_text()))
    seeds = [int(flag(c, "seed")) for c in target["commands"]]
    lo, hi = wilson_interval(sum(succ), len(succ))
    return {"name": target["name"], "task": target["task"], "method": target["method"], "source": target["source"],
            "checkpoint": target["checkpoint"], "num_inference_steps": steps, "successes": sum(succ),
            "episodes": len(succ), "success_rate": sum(succ) / len(succ), "ci95": [lo, hi],
            "first_seed": min(seeds), "test_seeds": min(seeds) >= TEST_SEEDS_FROM, "per_episode_success": succ,
            "max_rewards": rewards, "eval_s": round(eval_s, 1), "commands": cmds,
            "committed_successes": target["committed_successes"]}  # fmt: skip


def table(entries: list[dict], step_order: list[int]) -> str:
    """Markdown table: one line per (checkpoint, steps), eval time as a ratio to the first step count."""
    lines = ["| checkpoint | task | steps | successes | 95% CI | eval s | x time of first | same episodes as first |",
             "| --- | --- | ---: | ---: | --- | ---: | ---: | ---: |"]  # fmt: skip
    by = {(e["name"], e["num_inference_steps"]): e for e in entries}
    for name in dict.fromkeys(e["name"] for e in entries):
        ref = by.get((name, step_order[0]))
        for s in step_order:
            e = by.get((name, s))
            if e is None:
                continue
            ratio = f"{e['eval_s'] / ref['eval_s']:.2f}" if ref else ""
            same = (f"{sum(a == b for a, b in zip(e['per_episode_success'], ref['per_episode_success']))}"
                    f"/{e['episodes']}") if ref else ""  # fmt: skip
            lines.append(f"| {name} | {e['task']} | {s} | {e['successes']}/{e['episodes']} | "
                         f"{e['ci95'][0]:.0%}-{e['ci95'][1]:.0%} | {e['eval_s']:.0f} | {ratio} | {same} |")  # fmt: skip
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--run-json", action="append", default=[], help="a finished run_benchmark.py run JSON")
    p.add_argument("--checkpoint", action="append", default=[], metavar="TASK=DIR")
    p.add_argument("--seed", type=int, default=100, help="first seed for --checkpoint (validation: below 1000)")
    p.add_argument("--episodes", type=int, default=20, help="episodes for --checkpoint")
    p.add_argument("--inference-steps", default="4,1", help="comma-separated; the first is the time reference")
    p.add_argument("--out", required=True, help="results JSON (resumed when it exists)")
    p.add_argument("--lerobot-eval", default=str(Path(sys.executable).parent / "lerobot-eval"),
                   help="the lerobot-eval executable (default: the one beside this Python)")
    p.add_argument("--work-dir", help="lerobot-eval output folders (default outputs/sampler_steps/<out's stem>)")
    a = p.parse_args(argv)
    try:
        step_order = [int(s) for s in a.inference_steps.split(",")]
    except ValueError:
        p.error(f"--inference-steps {a.inference_steps!r}: expected comma-separated integers such as 4,1")
    if not step_order or min(step_order) < 1:
        p.error("--inference-steps: every step count must be >= 1")
    if not a.run_json and not a.checkpoint:
        p.error("name at least one --run-json or --checkpoint")
    targets = targets_from_args(a)
    out = Path(a.out)
    res = json.loads(out.read_text()) if out.exists() else {"entries": []}
    res["command"] = shlex.join(["python", "benchmarks/sampler_steps.py", *(sys.argv[1:] if argv is None else argv)])
    res["what"] = ("R&D checkpoints sampled with different numbers of denoising steps (lerobot-eval "
                   "--policy.num_inference_steps), the same seeds for every step count; eval_s is lerobot-eval's own "
                   "evaluation time summed over chunks")  # fmt: skip
    done = {(e["name"], e["num_inference_steps"]) for e in res["entries"]}
    lerobot_eval = a.lerobot_eval
    work = Path(a.work_dir) if a.work_dir else WORK / out.stem
    for t in targets:
        for s in step_order:
            if (t["name"], s) in done:
                continue
            print(f"[{t['name']}] {s} denoising step(s) ...", flush=True)
            e = evaluate(t, s, work, lerobot_eval)
            res["entries"].append(e)
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(json.dumps(res, indent=1))
            print(f"[{t['name']}] {s} step(s): {e['successes']}/{e['episodes']} in {e['eval_s']:.0f} s", flush=True)
    print(table(res["entries"], step_order))
    return 0


if __name__ == "__main__":
    sys.exit(main())
