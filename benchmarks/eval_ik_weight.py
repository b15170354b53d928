#!/usr/bin/env python
"""Success of one joint-space R&D checkpoint per IK orientation weight, on validation seeds.

R&D's gripper poses reach a joint-space robot (the SO-101) through inverse kinematics; its
``ik_orientation_weight`` (``lerobot_rnd.action_adapters.JointPositionAdapter``) is used only at inference, so one
trained checkpoint can be evaluated with several. For every weight this copies the checkpoint's
``pretrained_model`` with that weight in its action adapter (config.json's ``action_adapter``), runs ``lerobot-eval`` in chunks of
``--chunk`` episodes from ``--seed`` (validation seeds: below the benchmark's test seeds, 1000 and up; the choice
is made here, never on test seeds), and writes successes with Wilson intervals. Finished chunks are kept: rerun
the same command to resume.

    python benchmarks/eval_ik_weight.py --checkpoint <run>/train/checkpoints/last/pretrained_model \\
        --env-type rnd_so101 --task pick-cube --weights 1,0.1 --episodes 30 --seed 100 \\
        --work-dir outputs/ik_weight/pick-cube --out benchmarks/results/so101_ik_weight/pick-cube.json
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

_REPO = Path(__file__).resolve().parents[1]
if str(_REPO) not in sys.path:
    sys.path.insert(0, str(_REPO))

from benchmarks.harness.files import _rel, write_result_json
from benchmarks.harness.processes import run_logged, tool_argv
from benchmarks.harness.reports import wilson_interval

TEST_SEEDS_FROM = 1000


def with_weight(checkpoint: Path, weight: float, dest: Path) -> Path:
    """A copy of ``checkpoint`` (a pretrained_model folder) whose action adapter has ``ik_orientation_weight``."""
    cfg = json.loads((checkpoint / "config.json").read_text())
    adapter = cfg.get("action_adapter") or {}  # RnDConfig.action_adapter: {"type": ..., **kwargs}
    if adapter.get("type") != "joint_positions":
        raise SystemExit(f"{checkpoint}: its action adapter is {adapter.get('type')!r}; the IK weight "
                         "applies to joint_positions (a joint-space robot such as the SO-101)")  # fmt: skip
    if dest.exists():
        shutil.rmtree(dest)
    shutil.copytree(checkpoint, dest)
    adapter["ik_orientation_weight"] = weight
    (dest / "config.json").write_text(json.dumps(cfg, indent=4))
    return dest


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--checkpoint", required=True, help="a pretrained_model folder of an rnd policy")
    p.add_argument("--env-type", default="rnd_so101")
    p.add_argument("--task", required=True)
    p.add_argument("--weights", default="1,0.1")
    p.add_argument("--episodes", type=int, default=30)
    p.add_argument("--chunk", type=int, default=10, help="episodes per lerobot-eval call (and its batch size)")
    p.add_argument("--seed", type=int, default=100, help="first validation seed (episode i: seed + i)")
    p.add_argument("--episode-length", type=int, default=150)
    p.add_argument("--device", default="cpu")
    p.add_argument("--work-dir", required=True)
    p.add_argument("--out", required=True, help="JSON file to write")
    a = p.parse_args(argv)
    if a.seed + a.episodes > TEST_SEEDS_FROM:
        p.error(f"seeds {a.seed}..{a.seed + a.episodes - 1} reach the test seeds ({TEST_SEEDS_FROM} and up): "
                "choose the weight on validation seeds")  # fmt: skip
    checkpoint = Path(a.checkpoint).resolve()
    if not (checkpoint / "config.json").exists():
        p.error(f"--checkpoint {checkpoint} has no config.json (give the pretrained_model folder)")
    work = Path(a.work_dir).resolve()
    rows = []
    for w in [float(x) for x in a.weights.split(",") if x]:
        wdir = work / f"weight_{w:g}"
        marker = wdir / "pretrained_model" / "config.json"
        if not marker.exists():
            with_weight(checkpoint, w, wdir / "pretrained_model")
        successes: list[bool] = []
        for start in range(0, a.episodes, a.chunk):
            k = min(a.chunk, a.episodes - start)
            edir = wdir / "eval" / f"ep{start:04d}-{start + k - 1:04d}"
            info_path = edir / "eval_info.json"
            if not info_path.exists():
                if edir.exists():
                    shutil.rmtree(edir)
                argv_eval = tool_argv("lerobot-eval", "auto") + [
                    f"--policy.path={wdir / 'pretrained_model'}", f"--policy.device={a.device}",
                    f"--env.type={a.env_type}", f"--env.task={a.task}", f"--env.episode_length={a.episode_length}",
                    f"--eval.n_episodes={k}", f"--eval.batch_size={k}", f"--seed={a.seed + start}",
                    f"--output_dir={edir}",
                ]  # fmt: skip
                r = run_logged(argv_eval, wdir / "eval.log")
                if r.rc != 0 or not info_path.exists():
                    raise SystemExit(f"lerobot-eval failed (rc {r.rc}); log {wdir / 'eval.log'}:\n{r.tail}")
            info = json.loads(info_path.read_text())
            successes += [bool(x) for x in info["per_task"][0]["metrics"]["successes"][:k]]
        n, s = len(successes), sum(successes)
        lo, hi = wilson_interval(s, n)
        rows.append({"ik_orientation_weight": w, "successes": s, "episodes": n, "wilson95": [lo, hi],
                     "per_episode": successes})  # fmt: skip
        print(f"ik_orientation_weight {w:g}: {s}/{n} ({lo:.0%}-{hi:.0%})", flush=True)
    out = {"benchmark": "ik_weight", "checkpoint": _rel(checkpoint), "env_type": a.env_type, "task": a.task,
           "seeds": [a.seed, a.seed + a.episodes - 1], "episode_length": a.episode_length,
           "results": rows}  # fmt: skip
    write_result_json(a.out, out, argv, script="benchmarks/eval_ik_weight.py")
    return 0


if __name__ == "__main__":
    sys.exit(main())
