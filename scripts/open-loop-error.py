"""Open-loop action error of `scaledp predict --out` files: the mean absolute difference between
predicted and recorded actions over the steps of each chunk a controller executes, averaged
per file and over files (how docs/experiments.md compares arms on held-out demonstrations).

    python3 scripts/open-loop-error.py pred-*.csv [--steps 16] [--prefix right_]

Padded steps (past the episode's end) are left out; `--prefix` keeps the dimensions whose
name starts with it (grippers are always left out with a prefix, as their units differ).
Standard library only.
"""
import argparse
import csv
import statistics
import sys

p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
p.add_argument("files", nargs="+")
p.add_argument("--steps", type=int, default=16, help="executed steps of each chunk")
p.add_argument("--prefix", help="only dimensions whose name starts with this")
a = p.parse_args()

per_file = []
for path in a.files:
    try:
        with open(path, newline="") as f:
            r = csv.DictReader(f)
            dims = [k[len("predicted_"):] for k in r.fieldnames or [] if k.startswith("predicted_")]
            if a.prefix:
                dims = [d for d in dims if d.startswith(a.prefix) and "gripper" not in d]
            if not dims:
                sys.exit(f"{path}: no predicted_* columns{' matching ' + a.prefix if a.prefix else ''}")
            errs = [
                abs(float(row["predicted_" + d]) - float(row["recorded_" + d]))
                for row in r
                if int(row["step"]) < a.steps and row["padded"] != "1"
                for d in dims
            ]
    except (OSError, KeyError, ValueError) as e:
        sys.exit(f"{path}: not a `scaledp predict --out` file ({e})")
    if not errs:
        sys.exit(f"{path}: no unpadded step below {a.steps}")
    per_file.append(statistics.mean(errs))
    print(f"{path}: {per_file[-1]:.5f}")
print(f"mean over {len(per_file)} files: {statistics.mean(per_file):.5f}")
