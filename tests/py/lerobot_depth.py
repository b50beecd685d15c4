"""LeRobot 0.4.4 itself on a dataset with depth features, intrinsics and episode metadata
(needs the LeRobot venv, scripts/setup-bench-python.sh).

  lerobot_depth.py DATASET OUT.bin
      Opens DATASET with LeRobotDataset (no video), reads every frame's depth features as
      LeRobot returns them (tensors), and writes them to OUT.bin as float32 (index order, depth
      keys sorted, each H x W); prints {"keys": [...], "dtypes": {...}, "shapes": {...},
      "frames": N, "episode_index": [...], "frame_index": [...], "camera_keys": [...],
      "intrinsics": {camera: K}, "episodes": {column: [per episode]}} (K from the dataset's
      meta.info, as LeRobot loaded it; the episodes' `tasks` and `scaledp/*` columns as
      LeRobot's meta.episodes holds them).
"""
import json
import sys
from pathlib import Path

import numpy as np


def main(root, out):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset("scaledp/depth", root=root)
    keys = sorted(k for k in ds.meta.features if k.startswith("observation.depth."))
    frames, eps, fis, dtypes, shapes = [], [], [], {}, {}
    for i in range(len(ds)):
        item = ds[i]
        eps.append(int(item["episode_index"]))
        fis.append(int(item["frame_index"]))
        for k in keys:
            t = item[k]
            dtypes[k] = str(t.dtype)
            shapes[k] = list(t.shape)
            frames.append(t.to(dtype=__import__("torch").float32).numpy())
    Path(out).write_bytes(np.stack(frames).astype(np.float32).tobytes())
    cams = ds.meta.info.get("scaledp", {}).get("cameras", {})
    episodes = ds.meta.episodes
    meta = {k: list(episodes[k]) for k in episodes.column_names
            if k == "tasks" or k.startswith("scaledp/")}
    print(json.dumps({
        "keys": keys, "dtypes": dtypes, "shapes": shapes, "frames": len(ds),
        "episode_index": eps, "frame_index": fis, "camera_keys": list(ds.meta.camera_keys),
        "intrinsics": {c: v["intrinsics"]["k"] for c, v in cams.items() if "intrinsics" in v},
        "episodes": meta,
    }))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
