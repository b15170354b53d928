#!/usr/bin/env bash
# GPU-scale benchmark (R&D-AI/A/I vs ACT vs Diffusion Policy), one slice of at most ~9 minutes per call,
# for a GPU machine with no network that runs at most 10 minutes per command. Run the SAME command again
# and again until it exits 0:
#
#   bash benchmarks/gpu_scale.sh            # exit 3: more work remains -> run it again
#                                           # exit 0: complete; exit 1: a run failed (see results.md)
#
# Each call: records the demos that are still missing (never interrupted half-way: a recording starts only
# if it fits), trains with `lerobot-train` until 20 s before the budget ends (stopping right after a
# checkpoint when the next one would not fit), resumes the next call from checkpoints/last with
# `lerobot-train --config_path=<run>/train/checkpoints/last/pretrained_model/train_config.json --resume=true`,
# evaluates in chunks of 10 episodes (`lerobot-eval --seed=1000+10k`), skips everything already done, and
# rewrites benchmarks/results/$NAME/{results.json,results.md,success_vs_demos.png} with what is finished.
#
# State lives in outputs/benchmark/$NAME (checkpoints, logs) and outputs/benchmark/data (datasets): the
# machine must keep the repository folder between calls (a fresh, bare machine starts the benchmark over).
# Disk: ~1.3 GB per paper-size R&D run while training (model + AdamW state), ~0.43 GB once evaluated.
#
# Size (unmeasured estimate, from /work/shared/gpu/README.md's 99 ms per paper-size ViT forward+backward at
# batch 32 in bf16; fp32 plus rendering and PNG decoding is slower): 25k steps x batch 32 takes hours per
# R&D run, so the default 2 tasks x 2 demo counts x 5 methods is tens of GPU-hours, i.e. hundreds of calls.
# For a first pass use e.g. STEPS=5000 TASKS=reach-v3.
#
# Knobs (environment): NAME TASKS DEMOS METHODS SEEDS STEPS BATCH EVAL_EPISODES PROTOCOL MAX_MINUTES PYTHON;
# any further arguments go to run_benchmark.py (e.g. --train-arg all:--policy.use_amp=true).
set -uo pipefail
START=$(date +%s)
cd "$(dirname "$0")/.."

NAME="${NAME:-gpu}"
TASKS="${TASKS:-reach-v3,push-v3}"
DEMOS="${DEMOS:-10,20}"
METHODS="${METHODS:-rnd_ai,rnd_a,rnd_i,act,diffusion}"
SEEDS="${SEEDS:-0}"
STEPS="${STEPS:-25000}"
BATCH="${BATCH:-32}"
EVAL_EPISODES="${EVAL_EPISODES:-50}"
PROTOCOL="${PROTOCOL:-random}"
MAX_MINUTES="${MAX_MINUTES:-9}"  # for the whole call, set-up included

export MUJOCO_GL="${MUJOCO_GL:-egl}" HF_HUB_OFFLINE=1 WANDB_MODE=disabled PYTHONUNBUFFERED=1

# Python: the project's venv if there is one, else the machine's python3. On the offline GPU machine of
# this workplace, lerobot 0.4.4 and its extra packages travel as wheels in .whl/ with setup_site.sh
# (see /work/shared/gpu/README.md; add metaworld==3.0.0, imageio, scipy, trimesh, pytorch_kinematics and
# matplotlib wheels for the simulator and the reports); the project itself is used from PYTHONPATH, and
# run_benchmark.py then launches lerobot-train / lerobot-eval through wrappers that import the plugin.
PYTHON="${PYTHON:-}"
if [ -z "$PYTHON" ]; then
  if [ -x .venv/bin/python ]; then PYTHON=.venv/bin/python; else PYTHON=python3; fi
fi
if ! "$PYTHON" -c "import lerobot" 2>/dev/null; then
  if [ -f .whl/setup_site.sh ]; then
    # shellcheck disable=SC1091
    source .whl/setup_site.sh || exit 1
  else
    echo "lerobot is not importable with $PYTHON and there is no .whl/setup_site.sh" >&2
    exit 1
  fi
fi
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"
"$PYTHON" -c "import torch; assert torch.cuda.is_available(), 'no CUDA device'" || exit 1

LEFT=$(awk -v m="$MAX_MINUTES" -v s="$START" -v n="$(date +%s)" 'BEGIN { printf "%.2f", m - (n - s) / 60 }')
"$PYTHON" benchmarks/run_benchmark.py --scale gpu --protocol "$PROTOCOL" \
  --tasks "$TASKS" --demos "$DEMOS" --methods "$METHODS" --seed "$SEEDS" \
  --steps "$STEPS" --batch-size "$BATCH" --eval-episodes "$EVAL_EPISODES" \
  --out "benchmarks/results/$NAME" --work-dir "outputs/benchmark/$NAME" --data-dir outputs/benchmark/data \
  --resume --max-minutes "$LEFT" "$@"
rc=$?

# Where the machine hands back only a folder $OUT (as this workplace's device tool does), copy the reports.
if [ -n "${OUT:-}" ] && [ -d "${OUT:-}" ]; then
  cp "benchmarks/results/$NAME"/results.json "benchmarks/results/$NAME"/results.md "$OUT"/ 2>/dev/null
  cp "benchmarks/results/$NAME"/*.png "$OUT"/ 2>/dev/null
fi
case $rc in
  0) echo "benchmark complete: benchmarks/results/$NAME/results.md" ;;
  3) echo "more work remains: run 'bash benchmarks/gpu_scale.sh' again" ;;
  *) echo "benchmark finished with failures (exit $rc): see benchmarks/results/$NAME/results.md" ;;
esac
exit $rc
