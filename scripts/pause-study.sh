#!/usr/bin/env bash
# Stops the ALOHA study (scripts/aloha-study.sh) so that it loses no training: the queue first,
# so that it starts nothing else, then its running `experiment compare` with SIGINT. While it
# trains (nearly all of a run's time), its trainer then writes a checkpoint at the step it is on
# and exits without scoring; restarting the queue resumes from that checkpoint. While it
# collects or scores, it does not stop at once: the script waits up to 120 s, then leaves it
# running and says so (an evaluation resumes from its finished episodes' files). Without this,
# a session that ends kills the run and loses up to `--checkpoint-every` steps (500, about
# 16 min on the 2-core machine).
#
#   bash scripts/pause-study.sh     # later: nohup bash scripts/aloha-study.sh BIN >> runs/logs/study.log 2>&1 &
set -uo pipefail
cd "$(dirname "$0")/.."
log=runs/logs/study.log
mkdir -p runs/logs

# The queue as started (`bash scripts/aloha-study.sh BIN`), and the compare it runs: its child.
queue=$(pgrep -f '^bash scripts/aloha-study\.sh ' || true)
compare=""
for q in $queue; do
  compare="$compare $(pgrep -P "$q" -f ' experiment compare ' || true)"
done
compare=$(echo $compare)
if [ -z "$queue" ]; then
  echo "no study queue is running"
  exit 0
fi
kill $queue
for c in $compare; do
  kill -CONT "$c" 2>/dev/null || true # a paused run must run to see the signal
  kill -INT "$c"
done
# A training step (about 2 s here) and the checkpoint's write; bounded.
for _ in $(seq 1 120); do
  alive=""
  for c in $compare; do
    kill -0 "$c" 2>/dev/null && alive="$alive $c"
  done
  [ -z "$alive" ] && break
  sleep 1
done
if [ -n "${alive:-}" ]; then
  echo "experiment compare ($alive ) still runs after 120 s (collecting or scoring?): left as it is" >&2
  echo "=== $(date -u +%FT%TZ) queue stopped by scripts/pause-study.sh; compare$alive still running" >> "$log"
  exit 1
fi
echo "=== $(date -u +%FT%TZ) paused by scripts/pause-study.sh (queue $queue, compare ${compare:-none})" | tee -a "$log"
