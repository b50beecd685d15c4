#!/usr/bin/env bash
# Stops the ALOHA study (scripts/aloha-study.sh) so that it loses no training: the queue first,
# so that it starts nothing else, then the running `experiment compare` with SIGINT, on which
# its trainer writes a checkpoint at the step it is on and exits without scoring. Restarting
# the queue resumes from that checkpoint. Without this, a session that ends kills the run and
# loses up to `--checkpoint-every` steps (500, about 16 min on the 2-core machine).
#
#   bash scripts/pause-study.sh     # then, later: nohup bash scripts/aloha-study.sh BIN >> … &
set -uo pipefail
cd "$(dirname "$0")/.."
log=runs/logs/study.log
mkdir -p runs/logs

queue=$(pgrep -f "bash scripts/aloha-study.sh" || true)
compare=$(pgrep -f "runs/bin/[^ ]* experiment compare" || true)
if [ -z "$queue$compare" ]; then
  echo "no study is running"
  exit 0
fi
[ -n "$queue" ] && kill $queue
if [ -n "$compare" ]; then
  kill -CONT $compare 2>/dev/null || true   # a paused run must run to see the signal
  kill -INT $compare
  # One training step (about 2 s here) and the checkpoint's write; bounded.
  for _ in $(seq 1 120); do
    kill -0 $compare 2>/dev/null || break
    sleep 1
  done
  if kill -0 $compare 2>/dev/null; then
    echo "experiment compare ($compare) still runs after 120 s: left as it is" >&2
    exit 1
  fi
fi
msg="=== $(date -u +%FT%TZ) paused by scripts/pause-study.sh (queue ${queue:-none}, compare ${compare:-none})"
echo "$msg" | tee -a "$log"
