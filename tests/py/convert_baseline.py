"""The usual single-process Python route from recorder MCAP episodes to LeRobot-style parquet,
as a baseline for `scaledp bench convert`.

usage: convert_baseline.py RECORDINGS_DIR OUT_DIR

Per episode (`*.mcap` in RECORDINGS_DIR, sorted): `rosbags.highlevel.AnyReader` reads it; a
first pass collects header stamps of every stream and all joint positions; ticks at 10 Hz run
from the latest first stamp to the earliest last stamp; each camera gives its latest frame at or
before the tick, joint positions are linearly interpolated (numpy). A second pass decodes only
the chosen frames: bgra8/rgb8 → RGB (numpy), `Image.resize((320, 240), LANCZOS)`, JPEG q90
(Pillow). One parquet per episode (pyarrow). Prints {"frames": N, "seconds": S}.
"""
import io
import json
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from PIL import Image
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

FPS = 10.0
SIZE = (320, 240)
QUALITY = 90
IMAGE = "sensor_msgs/msg/Image"
JOINTS = "sensor_msgs/msg/JointState"


def stamp_ns(msg):
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def to_rgb(msg):
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    rows = np.asarray(msg.data, dtype=np.uint8).reshape(h, step)
    if msg.encoding in ("bgra8", "bgr8"):
        c = 4 if msg.encoding == "bgra8" else 3
        return np.ascontiguousarray(rows[:, : w * c].reshape(h, w, c)[:, :, 2::-1])
    if msg.encoding in ("rgba8", "rgb8"):
        c = 4 if msg.encoding == "rgba8" else 3
        return np.ascontiguousarray(rows[:, : w * c].reshape(h, w, c)[:, :, :3])
    raise ValueError(f"unsupported encoding {msg.encoding}")


def jpeg(rgb):
    img = Image.fromarray(rgb, "RGB").resize(SIZE, Image.LANCZOS)
    buf = io.BytesIO()
    img.save(buf, format="JPEG", quality=QUALITY)
    return buf.getvalue()


def convert(path, out_dir, episode_index, index0, typestore):
    with AnyReader([path], default_typestore=typestore) as reader:
        cams = sorted((c for c in reader.connections if c.msgtype == IMAGE), key=lambda c: c.topic)
        joints = sorted((c for c in reader.connections if c.msgtype == JOINTS), key=lambda c: c.topic)
        cam_stamps = {c.topic: [] for c in cams}
        joint_t = {c.topic: [] for c in joints}
        joint_q = {c.topic: [] for c in joints}
        # Pass 1: stamps and joint positions.
        for conn, _, raw in reader.messages(connections=cams + joints):
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.msgtype == IMAGE:
                cam_stamps[conn.topic].append(stamp_ns(msg))
            else:
                joint_t[conn.topic].append(stamp_ns(msg))
                joint_q[conn.topic].append(msg.position)
        cam_t = {k: np.sort(np.array(v, dtype=np.int64)) for k, v in cam_stamps.items()}
        jt = {k: np.array(v, dtype=np.int64) for k, v in joint_t.items()}
        jq = {k: np.array(v, dtype=np.float64) for k, v in joint_q.items()}
        firsts = [v[0] for v in cam_t.values()] + [v[0] for v in jt.values()]
        lasts = [v[-1] for v in cam_t.values()] + [v[-1] for v in jt.values()]
        start, end = max(firsts), min(lasts)
        n = int((end - start) // (1e9 / FPS)) + 1
        ticks = start + np.round(np.arange(n) * (1e9 / FPS)).astype(np.int64)
        # Latest frame at or before each tick; joints interpolated per column.
        chosen = {k: np.searchsorted(v, ticks, side="right") - 1 for k, v in cam_t.items()}
        state = np.concatenate(
            [np.stack([np.interp(ticks, jt[k], jq[k][:, j]) for j in range(jq[k].shape[1])], axis=1)
             for k in jt], axis=1).astype(np.float32)
        wanted = {}  # (topic, stamp) -> ticks using that frame
        for k, idx in chosen.items():
            for tick, i in enumerate(idx):
                wanted.setdefault((k, int(cam_t[k][max(i, 0)])), []).append(tick)
        images = {c.topic: [None] * n for c in cams}
        # Pass 2: decode, resize and encode only the chosen frames.
        for conn, _, raw in reader.messages(connections=cams):
            msg = reader.deserialize(raw, conn.msgtype)
            ticks_for = wanted.get((conn.topic, stamp_ns(msg)))
            if ticks_for:
                data = jpeg(to_rgb(msg))
                for tick in ticks_for:
                    images[conn.topic][tick] = data
    ts = (ticks - ticks[0]) / 1e9
    cols = {
        "state": pa.FixedSizeListArray.from_arrays(pa.array(state.ravel(), pa.float32()), state.shape[1]),
        "timestamp": pa.array(ts.astype(np.float32)),
        "frame_index": pa.array(np.arange(n, dtype=np.int64)),
        "episode_index": pa.array(np.full(n, episode_index, dtype=np.int64)),
        "index": pa.array(np.arange(index0, index0 + n, dtype=np.int64)),
    }
    image_type = pa.struct([("bytes", pa.binary()), ("path", pa.string())])
    for topic, frames in images.items():
        name = "observation.images." + topic.strip("/").split("/")[0]
        cols[name] = pa.array([{"bytes": b, "path": None} for b in frames], type=image_type)
    pq.write_table(pa.table(cols), out_dir / f"episode_{episode_index:06d}.parquet")
    return n


def main(recordings, out):
    t0 = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    frames = 0
    for i, path in enumerate(sorted(recordings.glob("*.mcap"))):
        frames += convert(path, out, i, frames, typestore)
    print(json.dumps({"frames": frames, "seconds": time.perf_counter() - t0}))


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(Path(sys.argv[1]), Path(sys.argv[2]))
