#!/usr/bin/env bash
# Lands what the study (scripts/aloha-study.sh) has written under docs/results/: rebuilds every
# benchmark's table, plot and the README's results summary from the files, copies the training
# machine's pause log beside them (docs/experiments.md cites it), and runs the results test,
# which fails on a file that misses a field of the schema or a table that differs from the
# files. It commits nothing: read the new rows, write the reading in docs/experiments.md, then
# commit the files and tables together.
#
#   bash scripts/land-study.sh runs/bin/scaledp-<rev>    # a clean build with `experiment report`
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${1:?usage: scripts/land-study.sh PATH-TO-SCALEDP-BINARY}
[ -x "$bin" ] || { echo "$bin: not an executable" >&2; exit 2; }

for dir in docs/results/*/; do
  name=$(basename "$dir")
  ls "$dir"/*--*.json >/dev/null 2>&1 || continue # a benchmark holds <task>--<arm>.json; historical/ and logs/ do not
  echo "== experiment report --name $name"
  "$bin" experiment report --name "$name" --readme README.md
done
# The machine's log goes on from the committed one; a new machine starts its log from that copy
# (`cp docs/results/logs/pauses.log runs/logs/`), or this copy would drop the earlier entries.
committed=docs/results/logs/pauses.log
if [ -f runs/logs/pauses.log ]; then
  if [ -f "$committed" ] && ! head -c "$(stat -c %s "$committed")" runs/logs/pauses.log | cmp -s - "$committed"; then
    echo "runs/logs/pauses.log does not go on from $committed (a new machine?): start it from the committed copy" >&2
    exit 1
  fi
  mkdir -p docs/results/logs
  cp runs/logs/pauses.log "$committed"
fi
# The workspace's lint wrapper, as scripts/test.sh builds: the same build units, so no rebuild
# of the dependencies.
export RUSTC_WORKSPACE_WRAPPER="$(rustup which clippy-driver)"
export CLIPPY_ARGS="-D__CLIPPY_HACKERY__warnings__CLIPPY_HACKERY__"
echo "== the results test"
cargo test --release --workspace --locked --test results
git status --short docs README.md
