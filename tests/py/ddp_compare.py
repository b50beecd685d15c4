"""Compares two runs of python -m scaledp_data.train (e.g. 1 process and 2 gloo ranks with the
same global batch): throughput, the loader's wait per step and rank, and the weight difference
after the last common checkpoint.

    python ddp_compare.py RUN_A RUN_B

Prints one JSON line per run (samples/s over the steps after the first, mean data wait per step
and rank) and the largest |difference| of the raw weights, AdamW moments and EMA weights.
"""

import json
import os
import sys

from safetensors.torch import load_file


def summary(run):
    """Throughput and loader waits of a run's metrics.jsonl (the first step, which allocates,
    left out)."""
    recs = [json.loads(line)["record"] for line in open(os.path.join(run, "metrics.jsonl"))]
    recs = [r for r in recs if "lr" in r][1:]
    busy = sum(r["step_s"] for r in recs)
    ranks = recs[0].get("ranks", 1)
    waits = [r.get("data_wait_s_per_rank", [r["data_wait_s"]]) for r in recs]
    per_rank = [sum(w[i] for w in waits) / len(waits) for i in range(ranks)]
    return {"run": run, "ranks": ranks, "steps_timed": len(recs),
            "samples_per_s": sum(r["samples"] for r in recs) / busy,
            "step_s": busy / len(recs), "data_wait_s_per_step_per_rank": per_rank,
            "data_wait_share": sum(per_rank) / len(per_rank) / (busy / len(recs))}


def last_checkpoint(run):
    """The run's latest checkpoint directory."""
    root = os.path.join(run, "checkpoints")
    return os.path.join(root, sorted(d for d in os.listdir(root) if d.startswith("step_"))[-1])


def main():
    """Prints the comparison."""
    a, b = sys.argv[1], sys.argv[2]
    ca, cb = last_checkpoint(a), last_checkpoint(b)
    diffs = {}
    for f in ("train_state.safetensors", "model.safetensors"):
        ta, tb = load_file(os.path.join(ca, f)), load_file(os.path.join(cb, f))
        diffs[f] = max(float((ta[k] - tb[k]).abs().max()) for k in ta)
    print(json.dumps(summary(a)))
    print(json.dumps(summary(b)))
    print(json.dumps({"checkpoints": [ca, cb], "max_abs_diff": diffs}))


if __name__ == "__main__":
    main()
