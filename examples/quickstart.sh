#!/usr/bin/env bash
# Quickstart on a CPU, in minutes: record scripted MetaWorld demonstrations, train the CPU tier of R&D-AI
# (policies_config/metaworld/rnd_ai_cpu.json), evaluate it with lerobot-eval (success rate + videos).
# Everything lands in outputs/quickstart/; the timings and the success rate in outputs/quickstart/summary.json.
# Override the task and sizes with environment variables, e.g. TASK=reach-v3 STEPS=1000 bash examples/quickstart.sh
set -euo pipefail
export MUJOCO_GL="${MUJOCO_GL:-egl}" HF_HUB_OFFLINE=1
TASK="${TASK:-drawer-close-v3}"  # reach-v3 is harder at this scale: see docs/BENCHMARKS.md
EPISODES="${EPISODES:-10}"
STEPS="${STEPS:-500}"
EVAL_EPISODES="${EVAL_EPISODES:-20}"
EVAL_SEED="${EVAL_SEED:-1000}"
OUT="${OUT:-outputs/quickstart}"
DATA="$OUT/data/mw_${TASK}_${EPISODES}"
t0=$(date +%s)

echo "== 1/3 recording $EPISODES scripted demos of $TASK"
if [ ! -d "$DATA" ]; then
  lerobot-rnd-record --task "$TASK" --episodes "$EPISODES" --root "$DATA" --repo-id "local/mw_${TASK}_${EPISODES}" --seed 0
fi
t1=$(date +%s)

echo "== 2/3 training R&D-AI (CPU tier) for $STEPS steps"
rm -rf "$OUT/train"
lerobot-train --config_path=policies_config/metaworld/rnd_ai_cpu.json \
  --dataset.repo_id="local/mw_${TASK}_${EPISODES}" --dataset.root="$DATA" --env.task="$TASK" \
  --steps="$STEPS" --save_freq="$STEPS" --log_freq=50 --output_dir="$OUT/train"
t2=$(date +%s)

echo "== 3/3 evaluating $EVAL_EPISODES episodes (seeds from $EVAL_SEED)"
rm -rf "$OUT/eval"
lerobot-eval --policy.path="$OUT/train/checkpoints/last/pretrained_model" \
  --env.type=rnd_mw --env.task="$TASK" --eval.n_episodes="$EVAL_EPISODES" --eval.batch_size=10 \
  --policy.device=cpu --seed="$EVAL_SEED" --output_dir="$OUT/eval"
t3=$(date +%s)

python - "$OUT" "$t0" "$t1" "$t2" "$t3" "$TASK" "$EPISODES" "$STEPS" <<'PY'
import json, os, platform, subprocess, sys
out, t0, t1, t2, t3, task, episodes, steps = sys.argv[1], *map(int, sys.argv[2:6]), *sys.argv[6:]
info = json.load(open(f"{out}/eval/eval_info.json"))
succ = [bool(s) for s in info["per_task"][0]["metrics"]["successes"]]


def code_commit():
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def cpu_model():
    try:
        with open("/proc/cpuinfo") as f:
            return next(line.split(":", 1)[1].strip() for line in f if line.startswith("model name"))
    except (OSError, StopIteration):
        return platform.processor() or platform.machine()


def bf16_native():
    try:  # whether the CPU tier's autocast_bf16 ran (native bf16) or was skipped (AVX2: float32, slower)
        from lerobot_rnd.precision import cpu_bf16_is_fast
        return cpu_bf16_is_fast()
    except ImportError:
        return None


summary = {
    "command": f"TASK={task} EPISODES={episodes} STEPS={steps} bash examples/quickstart.sh",
    "task": task, "demos": int(episodes), "steps": int(steps), "eval_episodes": len(succ),
    "successes": sum(succ), "success_rate": sum(succ) / len(succ),
    "seconds": {"record": t1 - t0, "train": t2 - t1, "eval": t3 - t2, "total": t3 - t0},
    "machine": {"cpus": os.cpu_count(), "cpu": cpu_model(), "bf16_autocast": bf16_native()},
    "code_commit": code_commit(),
}
json.dump(summary, open(f"{out}/summary.json", "w"), indent=1)
print(f"Success {summary['successes']}/{len(succ)} on {task}; total {summary['seconds']['total']} s "
      f"(record {t1 - t0} s, train {t2 - t1} s, eval {t3 - t2} s). Videos: {out}/eval/videos/")
PY
