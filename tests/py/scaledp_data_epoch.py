"""The Python route for `scaledp bench load`: one shuffled epoch of `scaledp_data.Loader` (the
Rust loader through its Python module) with the benchmark's options, each batch dropped before
the next as a training loop does (so its image buffer returns to the loader's pool).

Usage: scaledp_data_epoch.py DATASET [--batch-size B] [--threads T]
Prints one JSON line: {"samples": N, "images": N, "seconds": S, "open_seconds": S}.
"""
import argparse
import json
import time


def main():
    p = argparse.ArgumentParser()
    p.add_argument("dataset")
    p.add_argument("--batch-size", type=int, default=64)
    p.add_argument("--threads", type=int, default=0)
    a = p.parse_args()

    import scaledp_data

    t0 = time.perf_counter()
    loader = scaledp_data.Loader(a.dataset, obs_horizon=2, action_chunk=16,
                                 batch_size=a.batch_size, threads=a.threads, seed=0)
    open_s = time.perf_counter() - t0
    samples = images = 0
    t1 = time.perf_counter()
    for batch in loader:
        imgs = batch["observation.images"]
        if imgs.dtype.name != "uint8" or imgs.ndim != 6:
            raise SystemExit(f"images {imgs.dtype} {imgs.shape}")
        samples += imgs.shape[0]
        images += imgs.shape[0] * imgs.shape[1] * imgs.shape[2]
    seconds = time.perf_counter() - t1
    print(json.dumps({"samples": samples, "images": images, "seconds": seconds,
                      "open_seconds": open_s}))


if __name__ == "__main__":
    main()
