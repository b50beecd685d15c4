#!/usr/bin/env python3
"""`scaledp demo` on a host that stalls: the whole process stopped (SIGSTOP) for STALL_MS every
PERIOD_MS while it records, as a busy laptop or a loaded CI runner stops it now and then.

    python3 scripts/stall-demo.py [--bin target/release/scaledp] [--stall-ms 60] [--runs 3]

Prints one line per run (the demo's exit code and its `converted` / `rejected` lines) and the
tally. Reproduces the converter's rule on joint holes: with 60-80 ms stalls every 0.5 s, the
1 kHz arm stream has 60-80 ms holes, sound at the 10 Hz ticks; 120 ms stalls give holes wider
than a tick, and the episodes are rejected, naming the streams. Linux/macOS only (signals).
"""

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

def small_rig(root: str, out: str) -> str:
    """The shipped Franka rig with 64x48 cameras, as the test suite's `small_franka`."""
    lines = []
    with open(os.path.join(root, "rigs", "franka_2zed.toml")) as f:
        for line in f:
            if line.startswith("width = "):
                line = "width = 64\n"
            elif line.startswith("height = "):
                line = "height = 48\n"
            lines.append(line)
    path = os.path.join(out, "rig.toml")
    with open(path, "w") as f:
        f.writelines(lines)
    return path


def run_once(binary: str, rig: str, work: str, stall_s: float, period_s: float) -> tuple[int, str]:
    out = os.path.join(work, "demo")
    shutil.rmtree(out, ignore_errors=True)
    log = os.path.join(work, "log.txt")
    with open(log, "w") as f:
        p = subprocess.Popen(
            [binary, "demo", "--episodes", "2", "--duration", "3", "--batch-size", "8",
             "--rig", rig, "--out", out],
            stdin=subprocess.DEVNULL, stdout=f, stderr=subprocess.STDOUT)
        time.sleep(1.0)  # the rig starting up
        for _ in range(14):  # ~8 s: both episodes
            if p.poll() is not None:
                break
            os.kill(p.pid, signal.SIGSTOP)
            time.sleep(stall_s)
            os.kill(p.pid, signal.SIGCONT)
            time.sleep(period_s)
        try:
            rc = p.wait(timeout=300)
        except subprocess.TimeoutExpired:
            p.kill()
            rc = -1
    with open(log) as f:
        lines = [l.strip() for l in f if "converted" in l or "rejected:" in l]
    return rc, " | ".join(dict.fromkeys(lines))


def main() -> int:
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", default=os.path.join(root, "target", "release", "scaledp"))
    ap.add_argument("--stall-ms", type=float, default=60.0)
    ap.add_argument("--period-ms", type=float, default=500.0, help="time between stalls")
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    if not os.path.isfile(args.bin):
        print(f"error: {args.bin}: no such binary (cargo build --release -p scaledp)", file=sys.stderr)
        return 2
    ok = 0
    with tempfile.TemporaryDirectory() as work:
        rig = small_rig(root, work)
        for i in range(args.runs):
            rc, lines = run_once(args.bin, rig, work, args.stall_ms / 1e3, args.period_ms / 1e3)
            ok += rc == 0
            print(f"run {i + 1}: {args.stall_ms:.0f} ms stalls every {args.period_ms:.0f} ms: exit {rc}: {lines}")
    print(f"{ok} of {args.runs} demos succeeded")
    return 0


if __name__ == "__main__":
    sys.exit(main())
