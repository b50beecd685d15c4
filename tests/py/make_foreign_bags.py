"""Writes a rosbag2 of a bimanual UR5 rig whose cameras publish `sensor_msgs/CompressedImage`
(one JPEG, one PNG, as image_transport's `.../compressed` topics carry them), with the Python
`rosbags` package (the reference peer). No rig is stored in it: `scaledp convert` must detect one.

    make_foreign_bags.py OUTDIR [--seconds S] [--seed N]

Writes `OUTDIR/ur_compressed/` (rosbag2 version 9, mcap storage, CDR messages) and prints JSON:
{"cameras": {TOPIC: {"format": F, "green": G, "stamps_ns": [...]}}, "t0_ns": T0}.

Topics: `/left/joint_states`, `/right/joint_states` (left_/right_ prefixed UR joint names,
125 Hz), `/left/gripper/joint_states`, `/right/gripper/joint_states` (Robotiq 2F-85 knuckle,
50 Hz), `/cam_high/color/image_raw/compressed` (JPEG) and `/cam_wrist/color/image_raw/compressed`
(PNG), 64x48 at 30 Hz. Frame k of a camera: its top half eight vertical stripes, stripe i white
when bit i of k is set, else black; its bottom half two flat colours, left (200, G, 40) and right
(40, G, 200), G fixed per camera. A decoded frame tells which frame it is, which camera it came
from, its channel order and orientation. Header stamps are capture times on the
nominal grid with +-0.5 ms seeded jitter; log time = stamp + latency.
"""

import argparse
import io
import json
import math
from pathlib import Path

import numpy as np
from PIL import Image
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer
from rosbags.typesys import Stores, get_typestore

T0_NS = 1_700_000_000 * 1_000_000_000 + 500_000_000
WIDTH, HEIGHT = 64, 48
UR = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]
HOME = [0.0, -1.9, 1.9, -1.57, -1.57, 0.0]
CAMERAS = {
    "/cam_high/color/image_raw/compressed": ("rgb8; jpeg compressed bgr8", 90),
    "/cam_wrist/color/image_raw/compressed": ("png", 160),
}
JOINTS = "sensor_msgs/msg/JointState"
COMPRESSED = "sensor_msgs/msg/CompressedImage"


def grid(rng, hz, seconds):
    n = int(round(seconds * hz))
    k = np.arange(n, dtype=np.int64)
    return T0_NS + (k * 1_000_000_000) // hz + rng.integers(-499_999, 500_000, size=n, dtype=np.int64)


def frame(k, green, fmt):
    px = np.zeros((HEIGHT, WIDTH, 3), dtype=np.uint8)
    stripe = WIDTH // 8
    for i in range(8):
        if k >> i & 1:
            px[: HEIGHT // 2, i * stripe : (i + 1) * stripe] = 255
    px[HEIGHT // 2 :, : WIDTH // 2] = (200, green, 40)
    px[HEIGHT // 2 :, WIDTH // 2 :] = (40, green, 200)
    buf = io.BytesIO()
    if "jpeg" in fmt:
        Image.fromarray(px).save(buf, format="JPEG", quality=95)
    else:
        Image.fromarray(px).save(buf, format="PNG")
    return np.frombuffer(buf.getvalue(), dtype=np.uint8)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir", type=Path)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--seed", type=int, default=11)
    args = ap.parse_args()
    args.outdir.mkdir(parents=True, exist_ok=True)
    ts = get_typestore(Stores.ROS2_HUMBLE)
    rng = np.random.default_rng(args.seed)
    Time, Header = ts.types["builtin_interfaces/msg/Time"], ts.types["std_msgs/msg/Header"]

    def header(stamp):
        return Header(stamp=Time(sec=int(stamp) // 1_000_000_000, nanosec=int(stamp) % 1_000_000_000), frame_id="")

    def joints(stamp, names, pos):
        n = len(names)
        return ts.types[JOINTS](header=header(stamp), name=names, position=np.array(pos, dtype=np.float64),
                                velocity=np.zeros(n), effort=np.zeros(n))

    msgs = []  # (log_ns, topic, type, message)
    expected = {"cameras": {}, "t0_ns": T0_NS}
    for topic, (fmt, green) in CAMERAS.items():
        stamps = grid(rng, 30, args.seconds)
        for k, stamp in enumerate(stamps):
            img = ts.types[COMPRESSED](header=header(stamp), format=fmt, data=frame(k, green, fmt))
            msgs.append((int(stamp) + int(rng.integers(25_000_000, 35_000_000)), topic, COMPRESSED, img))
        expected["cameras"][topic] = {"format": fmt, "green": green, "stamps_ns": [int(s) for s in stamps]}
    for side, phase in (("left", 0.0), ("right", 1.0)):
        names = [f"{side}_{j}" for j in UR]
        for stamp in grid(rng, 125, args.seconds):
            t = (int(stamp) - T0_NS) * 1e-9
            pos = [q + 0.3 * math.sin(2 * math.pi * 0.2 * t + phase + j) for j, q in enumerate(HOME)]
            msgs.append((int(stamp) + 500_000, f"/{side}/joint_states", JOINTS, joints(stamp, names, pos)))
        for stamp in grid(rng, 50, args.seconds):
            t = (int(stamp) - T0_NS) * 1e-9
            knuckle = 0.4 + 0.3 * math.sin(2 * math.pi * 0.3 * t + phase)
            msgs.append((int(stamp) + 500_000, f"/{side}/gripper/joint_states", JOINTS,
                         joints(stamp, [f"{side}_robotiq_85_left_knuckle_joint"], [knuckle])))
    msgs.sort(key=lambda m: (m[0], m[1]))
    with Writer(args.outdir / "ur_compressed", version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {}
        for log, topic, msgtype, msg in msgs:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[topic], log, bytes(ts.serialize_cdr(msg, msgtype)))
    print(json.dumps(expected))


if __name__ == "__main__":
    main()
