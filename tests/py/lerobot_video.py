"""LeRobot itself on video datasets, for the conformance tests (needs the LeRobot venv,
scripts/setup-bench-python.sh).

  lerobot_video.py write OUT [--vcodec libsvtav1|h264]
      Writes a small dataset with LeRobot's own writer (LeRobotDataset.create, add_frame,
      save_episode, finalize: its encode_video_frames, libsvtav1 yuv420p g=2 crf=30 by default)
      — 3 episodes of 64x48 frames from two cameras whose colours code (episode, frame) over
      a noisy texture — and prints {"episodes": [...lengths]}.
  lerobot_video.py read DATASET OUT.bin
      Reads every frame of every video key as LeRobotDataset returns it (video_backend
      "pyav": torchcodec needs FFmpeg libraries on the system), scaled back to uint8, and
      writes them to OUT.bin (index order, keys sorted, each HxWx3); prints {"keys": [...],
      "frames": N, "episode_index": [...], "frame_index": [...], "height": H, "width": W}.
"""
import json
import sys
from pathlib import Path

import numpy as np

W, H = 64, 48
LENGTHS = [7, 3, 9]


def frame(e, f, cam):
    rng = np.random.default_rng(1000 * e + 10 * f + cam)
    img = rng.integers(0, 48, (H, W, 3)).astype(np.int32)
    img[..., 0] += (f % 32) * 6
    img[..., 1] += (e % 32) * 40
    img[..., 2] += 64 + 96 * cam
    return np.clip(img, 0, 255).astype(np.uint8)


def write(out, vcodec):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    features = {
        f"observation.images.{cam}": {
            "dtype": "video",
            "shape": (H, W, 3),
            "names": ["height", "width", "channels"],
        }
        for cam in ("top", "wrist")
    }
    features["observation.state"] = {"dtype": "float32", "shape": (2,), "names": ["a", "b"]}
    features["action"] = {"dtype": "float32", "shape": (2,), "names": ["a", "b"]}
    ds = LeRobotDataset.create("scaledp/video-conformance", fps=10, features=features, root=out,
                               use_videos=True, vcodec=vcodec)
    for e, n in enumerate(LENGTHS):
        for f in range(n):
            ds.add_frame({
                "observation.images.top": frame(e, f, 0),
                "observation.images.wrist": frame(e, f, 1),
                "observation.state": np.array([e, f], np.float32),
                "action": np.array([e, f + 1], np.float32),
                "task": "conformance",
            })
        ds.save_episode()
    ds.finalize()
    print(json.dumps({"episodes": LENGTHS}))


def read(root, out):
    import torch
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset("scaledp/video-conformance", root=root, video_backend="pyav")
    keys = sorted(ds.meta.video_keys)
    frames, eps, fis = [], [], []
    for i in range(len(ds)):
        item = ds[i]
        eps.append(int(item["episode_index"]))
        fis.append(int(item["frame_index"]))
        for k in keys:
            chw = item[k]
            frames.append(torch.round(chw * 255).to(torch.uint8).permute(1, 2, 0).numpy())
    Path(out).write_bytes(np.stack(frames).tobytes())
    print(json.dumps({"keys": keys, "frames": len(ds), "episode_index": eps, "frame_index": fis,
                      "height": H, "width": W}))


if __name__ == "__main__":
    if sys.argv[1] == "write":
        vcodec = sys.argv[4] if len(sys.argv) > 4 and sys.argv[3] == "--vcodec" else "libsvtav1"
        write(sys.argv[2], vcodec)
    else:
        read(sys.argv[2], sys.argv[3])
