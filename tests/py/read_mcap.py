"""Reads an MCAP recording with two independent ROS 2 readers and prints what they saw as JSON.

1. `mcap` + `mcap_ros2` (Foxglove's Python reader and CDR decoder)
2. `rosbags.highlevel.AnyReader` (which rejects non-ros2 profiles and files without end magic)

Output: {"header": {...}, "channels": [...], "metadata": {...},
         "mcap_ros2": [msg...], "rosbags": [msg...]} where each msg is
{"topic", "log_time", "publish_time", "stamp_ns", "sha256" (of the raw CDR payload), plus
"encoding"/"width"/"height"/"step" for images or "name"/"position" for joint states}.
"""
import hashlib
import json
import sys
from pathlib import Path

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore


def fields(msg):
    d = {"stamp_ns": msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec}
    if hasattr(msg, "encoding"):
        d.update(encoding=msg.encoding, width=int(msg.width), height=int(msg.height), step=int(msg.step),
                 data_len=len(msg.data))
    if hasattr(msg, "position"):
        d.update(name=list(msg.name), position=[float(x) for x in msg.position])
    return d


def main(path):
    out = {"mcap_ros2": [], "rosbags": []}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        out["header"] = {"profile": header.profile, "library": header.library}
        summary = reader.get_summary()
        out["channels"] = [
            {"topic": c.topic, "message_encoding": c.message_encoding, "metadata": dict(c.metadata),
             "schema_name": summary.schemas[c.schema_id].name,
             "schema_encoding": summary.schemas[c.schema_id].encoding,
             "schema_data": summary.schemas[c.schema_id].data.decode()}
            for c in summary.channels.values()
        ]
        out["metadata"] = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            d = {"topic": channel.topic, "log_time": message.log_time, "publish_time": message.publish_time,
                 "sha256": hashlib.sha256(message.data).hexdigest()}
            d.update(fields(decoded))
            out["mcap_ros2"].append(d)
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with AnyReader([Path(path)], default_typestore=ts) as r:
        for conn, t, raw in r.messages():
            d = {"topic": conn.topic, "log_time": t, "sha256": hashlib.sha256(bytes(raw)).hexdigest()}
            d.update(fields(r.deserialize(raw, conn.msgtype)))
            out["rosbags"].append(d)
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv[1])
