#!/usr/bin/env bash
# Creates .venv-bench with LeRobot (pinned) for `scaledp bench load`'s baseline (the
# LeRobotDataset + torch DataLoader route on the same dataset) and for the video conformance
# tests (datasets/tests/lerobot_video.rs: frames of a dataset LeRobot wrote, as LeRobot returns
# them). It pulls torch from PyPI (about 4.6 GB of wheels, 7.6 GB installed, CUDA libraries
# included: PyPI has no CPU-only torch for Linux); a second run finds everything installed.
# `scaledp bench load` and the tests find it at .venv-bench/bin/python (or set
# SCALEDP_BENCH_PYTHON).
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
free_gb() { df -Pk . | awk 'NR == 2 {printf "%.1f\n", $4 / 1048576}'; }
fail() {
  echo "scripts/setup-bench-python.sh: $1 with $(free_gb) GB free on $(df -Pk . | awk 'NR == 2 {print $6}'); installing LeRobot ${LEROBOT_VERSION} needs about 9.5 GB there (7.6 GB installed, one wheel of up to 0.9 GB at a time); run it again once there is room (it resumes)" >&2
  exit 1
}
# Say so now rather than after gigabytes of downloads. What is installed already counts.
have=$(du -sk .venv-bench | awk '{printf "%.1f\n", $1 / 1048576}')
if awk -v f="$(free_gb)" -v h="$have" 'BEGIN {exit !(f + h < 9.5)}'; then
  fail "not enough disk to start"
fi
pip() {
  # --no-cache-dir: pip's cache would keep a second copy of the wheels, on a disk shared with
  # a release build of ~90 executables. Its temporary files go beside the venv, on the disk
  # this script checks, rather than in a /tmp that may be a small tmpfs.
  TMPDIR="$PWD/$tmp" .venv-bench/bin/python -m pip --disable-pip-version-check "$@"
}
tmp=.venv-bench/pip-tmp
mkdir -p "$tmp"
trap 'rm -rf "$tmp"' EXIT
pip install --quiet --upgrade pip
# One pip install holds every wheel it downloaded until it ends: 4.6 GB on top of what it
# unpacks (CI failed here with 4.3 GB free after the wheels were gone). So pip resolves the
# whole set once (metadata only) and that plan is installed without resolving again: the
# heavy wheels (torch and the CUDA libraries) one per call, then the rest in one call. The
# peak is what is installed plus one wheel. The plan leaves out triton (641 MB),
# torch.compile's GPU code generator: nothing here compiles a model or has a GPU (the tests
# and `bench load` run torch eager on the CPU), and `import torch` does not need it.
pip install --quiet --no-cache-dir --dry-run --ignore-installed --report "$tmp/plan.json" "lerobot==${LEROBOT_VERSION}" ||
  fail "resolving lerobot ${LEROBOT_VERSION} failed"
.venv-bench/bin/python - "$tmp" <<'PY'
import json, re, sys
tmp = sys.argv[1]
plan = json.load(open(f"{tmp}/plan.json"))
with open(f"{tmp}/heavy.txt", "w") as heavy, open(f"{tmp}/rest.txt", "w") as rest:
    for item in plan["install"]:
        name, version = item["metadata"]["name"], item["metadata"]["version"]
        if name.lower() == "triton":
            continue
        heavy_one = re.match(r"(torch|nvidia-|cuda-bindings)", name.lower())
        print(f"{name}=={version}", file=heavy if heavy_one else rest)
PY
mapfile -t heavy < "$tmp/heavy.txt"
i=0
for req in "${heavy[@]}"; do
  i=$((i + 1))
  echo "setup-bench-python.sh: [$i/${#heavy[@]}] $req ($(free_gb) GB free)"
  # --no-compile: Python compiles what the tests import when they import it (LeRobot's
  # dataset and torch's core), not all of torch's 276 MB of bytecode up front.
  pip install --quiet --no-cache-dir --no-compile --no-deps "$req" || fail "installing $req failed"
done
echo "setup-bench-python.sh: lerobot ${LEROBOT_VERSION} and the rest ($(free_gb) GB free)"
pip install --quiet --no-cache-dir --no-deps -r "$tmp/rest.txt" || fail "installing lerobot ${LEROBOT_VERSION} failed"
.venv-bench/bin/python -c "import torch, lerobot; from lerobot.datasets.lerobot_dataset import LeRobotDataset; print('bench python ready: lerobot', lerobot.__version__ if hasattr(lerobot, '__version__') else '${LEROBOT_VERSION}', 'torch', torch.__version__)"
