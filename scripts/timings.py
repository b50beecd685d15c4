#!/usr/bin/env python3
"""The slowest units of a `cargo build --timings` report, and the share of test executables.

Usage: python3 scripts/timings.py target/cargo-timings/cargo-timing.html [N]

Reads the report's UNIT_DATA (each unit: crate, target kind, start and duration in seconds)
and prints the N slowest units (default 15), then the time spent on our crates against the
dependencies, and on integration-test and lib-test executables, so a CI run says where its
release build went.
"""
import json
import re
import sys


def units(path):
    text = open(path, encoding="utf-8").read()
    m = re.search(r"const UNIT_DATA = (\[.*?\n\]);", text, re.S)
    if not m:
        sys.exit(f"{path}: no UNIT_DATA in this timings report")
    return json.loads(m.group(1))


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    path = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 15
    us = units(path)
    wall = max((u["start"] + u["duration"] for u in us), default=0.0)
    print(f"{len(us)} units, {wall:.0f} s wall, {sum(u['duration'] for u in us):.0f} s summed")
    for u in sorted(us, key=lambda u: -u["duration"])[:n]:
        print(f"  {u['duration']:7.1f} s  {u['name']} {u['version']}{u['target']}")
    ours = [u for u in us if u["name"].startswith("scaledp")]
    tests = [u for u in ours if "test" in u["target"]]
    print(f"  our crates: {sum(u['duration'] for u in ours):.0f} s in {len(ours)} units, "
          f"of which test executables {sum(u['duration'] for u in tests):.0f} s in {len(tests)}")


if __name__ == "__main__":
    main()
