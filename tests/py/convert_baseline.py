"""The usual single-process Python route from recorder MCAP episodes to LeRobot-style parquet,
as a baseline for `scaledp bench convert`.

usage: convert_baseline.py RECORDINGS_DIR OUT_DIR

Per episode (`*.mcap` in RECORDINGS_DIR, sorted): `rosbags.highlevel.AnyReader` reads it; a
single pass in log order; ticks at 10 Hz run from the latest first header stamp to the earliest
last one; each camera gives its latest frame at or before the tick (a frame is decoded once the
next frame of its camera shows which ticks it covers, so only the chosen frames are decoded and
only JPEGs are kept): bgra8/rgb8 → RGB (numpy), `Image.resize((320, 240), LANCZOS)`, JPEG q90
(Pillow); joint positions are linearly interpolated (numpy). One parquet per episode (pyarrow).
Prints {"frames": N, "seconds": S}.
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
    step = 1e9 / FPS
    with AnyReader([path], default_typestore=typestore) as reader:
        cams = sorted((c for c in reader.connections if c.msgtype == IMAGE), key=lambda c: c.topic)
        joints = sorted((c for c in reader.connections if c.msgtype == JOINTS), key=lambda c: c.topic)
        topics = [c.topic for c in cams + joints]
        first, last = {}, {}
        joint_t = {c.topic: [] for c in joints}
        joint_q = {c.topic: [] for c in joints}
        pending = {c.topic: [] for c in cams}  # frames seen before every stream has started
        prev = {c.topic: None for c in cams}  # (stamp, msg) of the latest frame
        images = {c.topic: {} for c in cams}  # tick -> JPEG
        start = None

        def advance(topic, stamp, msg):
            # Ticks in [previous frame's stamp, this stamp) take the previous frame.
            p = prev[topic]
            if p is not None:
                k0 = max(0, int(np.ceil((p[0] - start) / step - 1e-9)))
                k1 = int(np.ceil((stamp - start) / step - 1e-9))
                if k1 > k0:
                    data = jpeg(to_rgb(p[1]))
                    for k in range(k0, k1):
                        images[topic][k] = data
            prev[topic] = (stamp, msg)

        # One pass in log order: joint positions kept, camera frames encoded as soon as the next
        # frame of that camera shows which ticks they cover.
        for conn, _, raw in reader.messages(connections=cams + joints):
            msg = reader.deserialize(raw, conn.msgtype)
            t = stamp_ns(msg)
            first.setdefault(conn.topic, t)
            last[conn.topic] = t
            if conn.msgtype == JOINTS:
                joint_t[conn.topic].append(t)
                joint_q[conn.topic].append(msg.position)
            elif start is None:
                pending[conn.topic].append((t, msg))
            else:
                advance(conn.topic, t, msg)
            if start is None and len(first) == len(topics):
                start = max(first.values())
                for topic, frames in pending.items():
                    for t, m in frames:
                        advance(topic, t, m)
                pending = {}
        end = min(last[t] for t in topics)
        n = int((end - start) // step) + 1
        for topic, p in prev.items():  # the last frame covers the remaining ticks
            k0 = max(0, int(np.ceil((p[0] - start) / step - 1e-9)))
            if k0 < n:
                data = jpeg(to_rgb(p[1]))
                for k in range(k0, n):
                    images[topic][k] = data
        images = {topic: [per_tick[k] for k in range(n)] for topic, per_tick in images.items()}
    ticks = start + np.round(np.arange(n) * step).astype(np.int64)
    jt = {k: np.array(v, dtype=np.int64) for k, v in joint_t.items()}
    jq = {k: np.array(v, dtype=np.float64) for k, v in joint_q.items()}
    state = np.concatenate(
        [np.stack([np.interp(ticks, jt[k], jq[k][:, j]) for j in range(jq[k].shape[1])], axis=1)
         for k in jt], axis=1).astype(np.float32)
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
