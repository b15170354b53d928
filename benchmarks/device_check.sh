#!/usr/bin/env bash
# The prepared GPU check (benchmarks/device_check.py): one command that fits a short device lease.
#
#   bash benchmarks/gpu_wheels.sh                  # HERE, once: download the GPU machine's extra wheels to .whl/
#   bash benchmarks/device_check.sh                # on the GPU machine (carry .whl): ~5-8 minutes, writes
#                                                  # benchmarks/results/device_check_paper_cuda.json
#   bash benchmarks/device_check.sh --smoke        # anywhere, CPU, tiny sizes, < 2 minutes (the test suite runs it)
#
# On a machine without lerobot (the GPU machine: Python 3.12, its own torch) it installs the carried wheels
# from .whl/ into /tmp/site first (benchmarks/gpu_setup_site.sh, from shared/gpu). Nothing is downloaded there.
set -euo pipefail
cd "$(dirname "$0")/.."
PY="${PYTHON:-python3}"
if ! "$PY" -c "import lerobot" 2>/dev/null; then
  if [ ! -d .whl ]; then
    echo "device_check: lerobot is not importable and there is no .whl/ folder: run 'bash benchmarks/gpu_wheels.sh'" \
      "where there is network, then carry .whl/ to this machine" >&2
    exit 2
  fi
  # shellcheck disable=SC1091
  source benchmarks/gpu_setup_site.sh
fi
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"
export HF_HUB_OFFLINE=1
exec timeout "${DEVICE_CHECK_TIMEOUT_S:-540}" "$PY" benchmarks/device_check.py "$@"
