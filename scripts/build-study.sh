#!/usr/bin/env bash
# Builds the study's binary (scripts/aloha-study.sh) from a clean commit, on any machine: a
# release build of `scaledp` in a detached worktree of that commit under runs/build/, copied to
# runs/bin/scaledp-<rev>. A machine that lost runs/ rebuilds the same revision this way; the
# binary's SHA-256 then differs from the first build's (each results file records its own).
#
#   bash scripts/build-study.sh 0e049df    # about 23 min on the 2-core machine
set -euo pipefail
cd "$(dirname "$0")/.."
want=${1:?usage: scripts/build-study.sh COMMIT}
full=$(git rev-parse --verify --quiet "$want^{commit}") || { echo "$want: not a commit of this repository" >&2; exit 2; }
short=${full:0:7}
out=runs/bin/scaledp-$short
if [ -x "$out" ]; then
  echo "$out: already built"
  exit 0
fi
tree=runs/build/$short
if [ ! -e "$tree/.git" ]; then
  mkdir -p runs/build
  git worktree add --detach "$tree" "$full"
fi
(cd "$tree" && cargo build --release --locked --bin scaledp)
# The binary names its commit (experiment/src/provenance.rs): clean, or it writes no result.
if ! grep -qa "$full" "$tree/target/release/scaledp" || grep -qa "$full-dirty" "$tree/target/release/scaledp"; then
  echo "$tree/target/release/scaledp does not name $full clean: not a study binary" >&2
  exit 1
fi
mkdir -p runs/bin
cp "$tree/target/release/scaledp" "$out.partial"
mv "$out.partial" "$out"
echo "$out: built from $full, sha256 $(sha256sum "$out" | cut -d' ' -f1)"
