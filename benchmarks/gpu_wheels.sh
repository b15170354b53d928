#!/usr/bin/env bash
# Download, on a machine with package-registry access, the wheels that lerobot 0.4.4 needs on the GPU machine
# (Python 3.12, its own torch), into the git-ignored .whl/ that device_check.sh installs from there.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 -m pip download --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
  --platform manylinux_2_28_x86_64 --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
  -d .whl -r benchmarks/gpu_wheels_cp312.txt
