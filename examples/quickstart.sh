#!/usr/bin/env bash
# Quickstart on a CPU, in minutes: record scripted MetaWorld demonstrations, train a small R&D-AI,
# evaluate it with lerobot-eval (success rate + videos). Everything lands in outputs/quickstart/.
# Override the sizes with environment variables, e.g. STEPS=2000 EPISODES=20 bash examples/quickstart.sh
set -euo pipefail
export MUJOCO_GL="${MUJOCO_GL:-egl}" HF_HUB_OFFLINE=1
TASK="${TASK:-reach-v3}"
EPISODES="${EPISODES:-10}"
STEPS="${STEPS:-600}"
EVAL_EPISODES="${EVAL_EPISODES:-5}"
OUT="${OUT:-outputs/quickstart}"
DATA="$OUT/data/mw_${TASK}_${EPISODES}"

if [ ! -d "$DATA" ]; then
  lerobot-rnd-record --task "$TASK" --episodes "$EPISODES" --root "$DATA" --repo-id "local/mw_${TASK}_${EPISODES}" --seed 0
fi

rm -rf "$OUT/train"
lerobot-train --config_path=policies_config/metaworld/rnd_ai_cpu.json \
  --dataset.repo_id="local/mw_${TASK}_${EPISODES}" --dataset.root="$DATA" --env.task="$TASK" \
  --steps="$STEPS" --save_freq="$STEPS" --log_freq=50 --num_workers=2 --output_dir="$OUT/train"

lerobot-eval --policy.path="$OUT/train/checkpoints/last/pretrained_model" \
  --env.type=rnd_mw --env.task="$TASK" --eval.n_episodes="$EVAL_EPISODES" --eval.batch_size=1 \
  --policy.device=cpu --seed=1000 --output_dir="$OUT/eval"

echo "Results: $OUT/eval/eval_info.json; videos: $OUT/eval/videos/"
