#!/usr/bin/env bash
# The ALOHA study of docs/experiments.md ("Why the paper's non-causal ScaleDP fails on ALOHA"),
# in the order it was registered: every run, on the fresh test seeds, with one clean binary.
#
#   bash scripts/aloha-study.sh runs/bin/scaledp-<rev>    # e.g. nohup … > runs/logs/study.log &
#
# The binary must be built from a clean commit (`compare` refuses to write under docs/results/
# otherwise) and is named by that commit, so every result file names the revision that trained
# and scored it. Each step resumes from its checkpoints and skips an arm whose result has landed,
# so the script is restarted as is after an interruption (a session ending, a reboot); a failed
# step is logged and does not stop the ones after it. About 1 h per 2,500-step run and 3 h per
# 7,500-step run on the 2-core machine.
set -uo pipefail
cd "$(dirname "$0")/.."
bin=${1:?usage: scripts/aloha-study.sh PATH-TO-CLEAN-SCALEDP-BINARY}
[ -x "$bin" ] || { echo "$bin: not an executable" >&2; exit 2; }

run() {
  echo "=== $(date -u +%FT%TZ) $bin experiment compare --benchmark aloha $*"
  "$bin" experiment compare --benchmark aloha "$@"
  echo "=== exit $? at $(date -u +%FT%TZ)"
}

# 1. Transfer-cube, the 2,500-step arms, seed 0 then seed 1 (controls once, with `ti` seed 0).
run --tasks transfer-cube --arms ti
for arm in ti-sincos ti-learned-sincos ti-causal; do
  run --tasks transfer-cube --arms "$arm" --no-controls
done
for arm in ti-sincos ti ti-learned-sincos ti-causal; do
  run --tasks transfer-cube --arms "$arm" --train-seed 1 --no-controls
done
# 2. The budget: three times the steps.
for seed in 0 1; do
  for arm in ti-x3 ti-causal-x3; do
    run --tasks transfer-cube --arms "$arm" --train-seed "$seed" --no-controls
  done
done
# 3. The baselines a headline reading needs two seeds of (issue 40, item 4): DP-T and ScaleDP-S
#    on transfer-cube, and the four arms on insertion.
for seed in 0 1; do
  run --tasks transfer-cube --arms dp-t,s --train-seed "$seed" --no-controls
done
run --tasks insertion --arms ti,ti-causal,s,dp-t
run --tasks insertion --arms ti,ti-causal,s,dp-t --train-seed 1 --no-controls
# 4. The winner of step 1 by the registered rule then runs on insertion and on MetaWorld
#    assembly and hand-insert (two seeds each, beside `ti`): added here once the reading names it.
