"""The LeRobot route for `scaledp bench load`: LeRobotDataset with the same observation window
(To = 2) and action chunk (C = 16) as our loader, iterated by a shuffled torch DataLoader.

Usage: lerobot_baseline.py DATASET [--batches N] [--batch-size B] [--workers W] [--video-backend pyav]
Prints progress on stderr and one JSON line on stdout:
{"lerobot": VERSION, "samples": N, "seconds": S, "init_seconds": S, "warmup_seconds": S, "shapes": {...}}
where seconds covers the N timed batches after one warm-up batch (worker start-up and the
first batch are left out, which favours LeRobot). Needs lerobot (scripts/setup-bench-python.sh);
benchmarks only, never CI.
"""
import argparse
import json
import os
import sys
import time


def main():
    p = argparse.ArgumentParser()
    p.add_argument("dataset")
    p.add_argument("--batches", type=int, default=30)
    p.add_argument("--batch-size", type=int, default=64)
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    p.add_argument("--obs-horizon", type=int, default=2)
    p.add_argument("--action-chunk", type=int, default=16)
    # torchcodec, LeRobot's default, needs FFmpeg libraries installed on the system; PyAV's
    # wheel brings its own.
    p.add_argument("--video-backend", default="pyav")
    a = p.parse_args()

    import torch
    from lerobot.datasets.lerobot_dataset import LeRobotDataset, LeRobotDatasetMetadata

    root = os.path.abspath(a.dataset)
    t0 = time.perf_counter()
    meta = LeRobotDatasetMetadata("scaledp/bench", root=root)
    fps = meta.fps
    cams = list(meta.camera_keys)
    obs = [k / fps for k in range(1 - a.obs_horizon, 1)]
    delta = {cam: obs for cam in cams}
    delta["observation.state"] = obs
    delta["action"] = [k / fps for k in range(a.action_chunk)]
    ds = LeRobotDataset("scaledp/bench", root=root, delta_timestamps=delta, video_backend=a.video_backend)
    init_s = time.perf_counter() - t0
    print(f"LeRobotDataset: {len(ds)} frames, {ds.num_episodes} episodes, cameras {cams}, opened in {init_s:.1f} s",
          file=sys.stderr)

    torch.manual_seed(0)
    loader = torch.utils.data.DataLoader(
        ds, batch_size=a.batch_size, shuffle=True, num_workers=a.workers, drop_last=True,
        persistent_workers=False,
    )
    it = iter(loader)
    t1 = time.perf_counter()
    first = next(it)
    warmup_s = time.perf_counter() - t1
    shapes = {k: list(v.shape) for k, v in first.items() if hasattr(v, "shape")}
    for cam in cams:
        want = [a.batch_size, a.obs_horizon, 3]
        if list(first[cam].shape[:3]) != want:
            raise SystemExit(f"{cam}: batch shape {list(first[cam].shape)}, expected {want} + [H, W]")
    if list(first["action"].shape[:2]) != [a.batch_size, a.action_chunk]:
        raise SystemExit(f"action: batch shape {list(first['action'].shape)}")

    samples = 0
    t2 = time.perf_counter()
    for _ in range(a.batches):
        try:
            batch = next(it)
        except StopIteration:
            break
        samples += batch["action"].shape[0]
    seconds = time.perf_counter() - t2
    from importlib.metadata import version
    print(json.dumps({"lerobot": version("lerobot"), "samples": samples, "seconds": seconds, "init_seconds": init_s,
                      "warmup_seconds": warmup_s, "shapes": shapes}))


if __name__ == "__main__":
    main()
