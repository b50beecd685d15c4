#!/usr/bin/env bash
# 1 process vs N gloo ranks on this machine, the same global batch: samples/s, the loader's wait
# per step and rank, and the weight difference after the run (tests/py/ddp_compare.py).
#
#   bash scripts/bench-ddp.sh DATASET [RANKS] [trainer flags...]
#   bash scripts/bench-ddp.sh datasets/cube 2 --steps 20 --batch-size 16 --image-size 84x84
#
# Uses .venv-bench's torch (scripts/setup-bench-python.sh) and the scaledp_data wheel
# (scripts/build-python.sh), on loopback.
set -euo pipefail
cd "$(dirname "$0")/.."
DATASET=${1:?usage: bench-ddp.sh DATASET [RANKS] [trainer flags...]}
RANKS=${2:-2}
shift $(( $# >= 2 ? 2 : 1 ))
OUT=$(mktemp -d "${TMPDIR:-/tmp}/scaledp-bench-ddp.XXXXXX")
trap 'rm -rf "$OUT"' EXIT
[ -x .venv-bench/bin/python ] || bash scripts/setup-bench-python.sh
WHEEL=$(ls -t target/wheels/scaledp_data-*.whl | head -n 1)
.venv-bench/bin/python -m zipfile -e "$WHEEL" "$OUT/site"
export PYTHONPATH="$OUT/site" GLOO_SOCKET_IFNAME=lo
FLAGS=(--val-every 0 --checkpoint-every 0 --device cpu "$@")
echo "1 process:"
.venv-bench/bin/python -m scaledp_data.train "$DATASET" --out "$OUT/one" "${FLAGS[@]}"
echo "$RANKS gloo ranks:"
PORT=$(.venv-bench/bin/python -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
.venv-bench/bin/python -m torch.distributed.run --nnodes 1 --nproc-per-node "$RANKS" \
  --master-addr 127.0.0.1 --master-port "$PORT" \
  -m scaledp_data.train "$DATASET" --out "$OUT/many" "${FLAGS[@]}"
.venv-bench/bin/python tests/py/ddp_compare.py "$OUT/one" "$OUT/many"
