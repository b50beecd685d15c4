"""A strip of one camera's frames from an MCAP episode, as a PNG (how the rollout pictures in
docs/results/ were made from `scaledp eval --recordings DIR` episodes).

    .venv/bin/python scripts/mcap-frames.py EPISODE.mcap OUT.png 2.0,4.0,6.5 [--topic T] [--scale 5]

Times are seconds from the episode's first frame; each picks the nearest frame (raw
`sensor_msgs/Image`, rgb8 or bgr8). Runs in the project's .venv (bash scripts/setup-python.sh).
"""
import argparse

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from PIL import Image

p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
p.add_argument("episode")
p.add_argument("out")
p.add_argument("times", help="comma-separated seconds from the first frame")
p.add_argument("--topic", help="camera topic (default: the first Image topic)")
p.add_argument("--scale", type=int, default=5, help="nearest-neighbour upscaling")
a = p.parse_args()

frames = []
with open(a.episode, "rb") as f:
    for schema, channel, _, msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
        if schema.name != "sensor_msgs/msg/Image" or (a.topic and channel.topic != a.topic):
            continue
        a.topic = channel.topic
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        if msg.encoding not in ("rgb8", "bgr8"):
            raise SystemExit(f"{a.episode}: {channel.topic} is {msg.encoding}, not rgb8/bgr8")
        im = Image.frombytes("RGB", (msg.width, msg.height), bytes(msg.data))
        if msg.encoding == "bgr8":
            im = Image.merge("RGB", im.split()[::-1])
        frames.append((stamp, im))
if not frames:
    raise SystemExit(f"{a.episode}: no sensor_msgs/Image messages")
t0 = frames[0][0]
tiles = [min(frames, key=lambda fr: abs(fr[0] - t0 - float(t)))[1] for t in a.times.split(",")]
w, h = tiles[0].size
strip = Image.new("RGB", (w * len(tiles), h))
for i, im in enumerate(tiles):
    strip.paste(im, (i * w, 0))
strip.resize((strip.width * a.scale, strip.height * a.scale), Image.NEAREST).save(a.out)
print(f"{a.out}: {len(tiles)} frames of {a.topic} ({w}x{h}) from {len(frames)}")
