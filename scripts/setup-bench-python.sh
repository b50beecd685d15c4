#!/usr/bin/env bash
# Creates .venv-bench with LeRobot (pinned) for `scaledp bench load`'s baseline (the
# LeRobotDataset + torch DataLoader route on the same dataset) and for the video conformance
# tests (datasets/tests/lerobot_video.rs: frames of a dataset LeRobot wrote, as LeRobot returns
# them). It pulls torch from PyPI (about 4.6 GB of wheels, CUDA libraries included); a second
# run finds everything installed. `scaledp bench load` and the tests find it at
# .venv-bench/bin/python (or set SCALEDP_BENCH_PYTHON).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
LEROBOT_VERSION=0.4.4
if [ ! -x .venv-bench/bin/python ]; then
  "$PY" -m venv .venv-bench
fi
# Already there: nothing to ask PyPI (pip's no-op resolution of LeRobot's ~120 packages
# still took 2 minutes here).
if .venv-bench/bin/python -c "import importlib.metadata as m, sys; sys.exit(m.version('lerobot') != '${LEROBOT_VERSION}')" 2>/dev/null; then
  echo "bench python ready: lerobot ${LEROBOT_VERSION} (installed)"
  exit 0
fi
.venv-bench/bin/python -m pip install --quiet --disable-pip-version-check --upgrade pip
# --no-cache-dir: a fresh machine would otherwise keep a second copy of those 4.6 GB in pip's
# cache, and CI's disk is shared with a release build of ~90 executables. pip holds every
# downloaded wheel until the install ends: its temporary files go beside the venv, on the disk
# this script reports on, rather than in a /tmp that may be a small tmpfs.
tmp=.venv-bench/pip-tmp
mkdir -p "$tmp"
trap 'rm -rf "$tmp"' EXIT
if ! TMPDIR="$PWD/$tmp" .venv-bench/bin/python -m pip install --no-cache-dir --disable-pip-version-check "lerobot==${LEROBOT_VERSION}"; then
  read -r free mount < <(df -Pk . | awk 'NR == 2 {printf "%.1f %s\n", $4 / 1048576, $6}')
  echo "scripts/setup-bench-python.sh: installing lerobot ${LEROBOT_VERSION} failed with ${free} GB free on ${mount}; it needs about 13 GB there while installing (4.6 GB of wheels, 8.3 GB installed); run it again once there is room (it resumes)" >&2
  exit 1
fi
.venv-bench/bin/python -c "import torch, lerobot; from lerobot.datasets.lerobot_dataset import LeRobotDataset; print('bench python ready: lerobot', lerobot.__version__ if hasattr(lerobot, '__version__') else '${LEROBOT_VERSION}', 'torch', torch.__version__)"
