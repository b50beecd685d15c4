"""Writes ROS bag fixtures of a Franka rig with the Python `rosbags` package (the reference peer).

    make_bags.py OUTDIR [--seconds S] [--seed N]

Writes into OUTDIR (which must exist or is created; the files in it must not exist yet):

* `franka_ros1_none.bag`, `franka_ros1_bz2.bag`, `franka_ros1_lz4.bag`: ROS 1 bags (format 2.0),
  chunks uncompressed / bz2 / lz4 (lz4 frame format, as `rosbags` writes them);
* `franka_rosbag2_mcap/`, `franka_rosbag2_sqlite3/`: rosbag2 directories (version 9) with mcap
  and sqlite3 storage, CDR messages;
* `expected.json`: per file the topics with their ROS 2 type and message count, and per topic the
  first message (by log time): its header stamp (ns), log time (ns) and, for joint topics, its
  joint names and positions; for cameras its size, encoding, step and the byte sum of its pixels.

Topics (the real names of the rig): two ZED cameras (`sensor_msgs/Image`, bgra8 64x48, 30 Hz),
the arm's `sensor_msgs/JointState` (fr3_joint1..7, 1000 Hz, smooth sinusoids) and the gripper's
(fr3_finger_joint1/2, each half the opening width, 50 Hz). Header stamps are capture times on the
nominal grid with +-0.5 ms seeded jitter; log time = stamp + latency (cameras 30 +- 5 ms, joints
0.5 ms). Deterministic for a given seed.
"""

import argparse
import json
import math
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

T0_NS = 1_700_000_000 * 1_000_000_000 + 250_000_000
CAMERAS = {
    "/zed_front/zed_node/rgb/color/rect/image": "zed_front_left_camera_optical_frame",
    "/zed_wrist/zed_node/rgb/color/rect/image": "zed_wrist_left_camera_optical_frame",
}
ARM = "/franka/joint_states"
GRIPPER = "/franka_gripper/joint_states"
WIDTH, HEIGHT = 64, 48
ARM_JOINTS = [f"fr3_joint{i}" for i in range(1, 8)]
FINGERS = ["fr3_finger_joint1", "fr3_finger_joint2"]
Q_HOME = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]
IMAGE = "sensor_msgs/msg/Image"
JOINTS = "sensor_msgs/msg/JointState"


def grid(rng, hz, seconds):
    """Capture stamps (ns): the nominal grid plus uniform jitter in (-0.5 ms, 0.5 ms)."""
    n = int(round(seconds * hz))
    k = np.arange(n, dtype=np.int64)
    nominal = T0_NS + (k * 1_000_000_000) // hz
    return nominal + rng.integers(-499_999, 500_000, size=n, dtype=np.int64)


def make_samples(seconds, seed):
    """All messages as (log_ns, topic, type, fields) with fields independent of the ROS version."""
    rng = np.random.default_rng(seed)
    out = []
    for topic, frame in CAMERAS.items():
        stamps = grid(rng, 30, seconds)
        latency = rng.integers(25_000_000, 35_000_001, size=len(stamps), dtype=np.int64)
        base = rng.integers(0, 256, size=(HEIGHT, WIDTH, 4), dtype=np.uint8)
        for i, (stamp, lat) in enumerate(zip(stamps, latency)):
            pixels = (base + np.uint8(i % 256)).reshape(-1)
            out.append((int(stamp + lat), topic, IMAGE, {"stamp": int(stamp), "frame": frame, "data": pixels}))
    amp = rng.uniform(0.1, 0.4, size=7)
    freq = rng.uniform(0.1, 0.5, size=7)
    phase = rng.uniform(0.0, 2 * math.pi, size=7)
    for stamp in grid(rng, 1000, seconds):
        t = (int(stamp) - T0_NS) * 1e-9
        pos = [Q_HOME[j] + amp[j] * math.sin(2 * math.pi * freq[j] * t + phase[j]) for j in range(7)]
        vel = [amp[j] * 2 * math.pi * freq[j] * math.cos(2 * math.pi * freq[j] * t + phase[j]) for j in range(7)]
        fields = {"stamp": int(stamp), "frame": "", "name": ARM_JOINTS, "position": pos, "velocity": vel,
                  "effort": [0.0] * 7}
        out.append((int(stamp) + 500_000, ARM, JOINTS, fields))
    for stamp in grid(rng, 50, seconds):
        t = (int(stamp) - T0_NS) * 1e-9
        width = 0.04 + 0.035 * math.sin(2 * math.pi * 0.3 * t)
        fields = {"stamp": int(stamp), "frame": "", "name": FINGERS, "position": [width / 2, width / 2],
                  "velocity": [0.0, 0.0], "effort": [0.0, 0.0]}
        out.append((int(stamp) + 500_000, GRIPPER, JOINTS, fields))
    out.sort(key=lambda m: (m[0], m[1]))
    return out


def build(ts, ros1, msgtype, f):
    """A `rosbags` message object of typestore `ts` (ROS 1 headers carry a seq)."""
    time = ts.types["builtin_interfaces/msg/Time"](sec=f["stamp"] // 1_000_000_000, nanosec=f["stamp"] % 1_000_000_000)
    hargs = {"seq": 0} if ros1 else {}
    header = ts.types["std_msgs/msg/Header"](stamp=time, frame_id=f["frame"], **hargs)
    if msgtype == IMAGE:
        return ts.types[IMAGE](header=header, height=HEIGHT, width=WIDTH, encoding="bgra8", is_bigendian=0,
                               step=WIDTH * 4, data=f["data"])
    return ts.types[JOINTS](header=header, name=list(f["name"]), position=np.array(f["position"]),
                            velocity=np.array(f["velocity"]), effort=np.array(f["effort"]))


def write_ros1(path, ts, samples, compression):
    writer = Writer1(path)
    if compression is not None:
        writer.set_compression(compression)
    with writer:
        conns = {}
        for seq_log, topic, msgtype, f in samples:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[topic], seq_log, f["ros1"])


def write_ros2(path, ts, samples, plugin):
    with Writer2(path, version=9, storage_plugin=plugin) as writer:
        conns = {}
        for log, topic, msgtype, f in samples:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[topic], log, f["cdr"])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir", type=Path)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--seed", type=int, default=7)
    args = ap.parse_args()
    args.outdir.mkdir(parents=True, exist_ok=True)

    ts1 = get_typestore(Stores.ROS1_NOETIC)
    ts2 = get_typestore(Stores.ROS2_HUMBLE)
    samples = make_samples(args.seconds, args.seed)
    seq = {}
    for _, topic, msgtype, f in samples:
        msg1 = build(ts1, True, msgtype, f)
        msg1.header.seq = seq.get(topic, 0)
        seq[topic] = msg1.header.seq + 1
        f["ros1"] = bytes(ts1.serialize_ros1(msg1, msgtype))
        f["cdr"] = bytes(ts2.serialize_cdr(build(ts2, False, msgtype, f), msgtype))

    files = {
        "franka_ros1_none.bag": ("ros1", lambda p: write_ros1(p, ts1, samples, None)),
        "franka_ros1_bz2.bag": ("ros1", lambda p: write_ros1(p, ts1, samples, Writer1.CompressionFormat.BZ2)),
        "franka_ros1_lz4.bag": ("ros1", lambda p: write_ros1(p, ts1, samples, Writer1.CompressionFormat.LZ4)),
        "franka_rosbag2_mcap": ("rosbag2", lambda p: write_ros2(p, ts2, samples, StoragePlugin.MCAP)),
        "franka_rosbag2_sqlite3": ("rosbag2", lambda p: write_ros2(p, ts2, samples, StoragePlugin.SQLITE3)),
    }
    counts, types, first = {}, {}, {}
    for log, topic, msgtype, f in samples:
        counts[topic] = counts.get(topic, 0) + 1
        types[topic] = msgtype
        if topic in first:
            continue
        entry = {"stamp_ns": f["stamp"], "log_time_ns": log, "frame_id": f["frame"]}
        if msgtype == JOINTS:
            entry.update(name=list(f["name"]), position=list(f["position"]))
        else:
            entry.update(height=HEIGHT, width=WIDTH, encoding="bgra8", step=WIDTH * 4,
                         data_len=len(f["data"]), data_sum=int(f["data"].astype(np.uint64).sum()))
        first[topic] = entry
    expected = {"seconds": args.seconds, "seed": args.seed, "files": {}, "first": first}
    for name, (fmt, write) in files.items():
        write(args.outdir / name)
        topics = {t: {"type": types[t], "count": counts[t]} for t in sorted(counts)}
        expected["files"][name] = {"format": fmt, "topics": topics}
    (args.outdir / "expected.json").write_text(json.dumps(expected, indent=1))


if __name__ == "__main__":
    main()
