"""Writes the hostile-input corpus of `scaledp convert`: good inputs of every kind, the same
recording broken in every way a disk, a network or a driver breaks files, and well-formed files
whose content cannot make an episode. Written with the public `rosbags` and `mcap` writers, then
by byte surgery on the good files.

    make_corpus.py OUTDIR [--seconds S] [--seed N]

Writes every case into OUTDIR (created; it must not hold the cases yet) and prints JSON:

    {"good": [NAME, ...], "bad": {NAME: REASON, ...}}

NAME is a file or rosbag2 directory in OUTDIR; REASON a part of the one line `scaledp convert`
must print for that input (its cause, in words a user can act on). The good inputs are one
recording written in every format (and one whose stamps wobble): they detect to the same rig, so
converted without `--rig` they make one dataset. Cases named `a_*` sort before every good input:
an input that the converter wrongly took would define the dataset's layout and reject the good
ones.

The recording: a Franka rig as make_bags.py writes it (two ZED cameras, bgra8 32x24 at 30 Hz;
the arm's JointState fr3_joint1..7 at 250 Hz; the gripper's at 50 Hz), S seconds, header stamps
on the nominal grid with seeded jitter, log time = stamp + latency. Deterministic for a seed.
"""

import argparse
import json
import math
import random
import shutil
import sqlite3
import struct
import zlib
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_typestore

T0_NS = 1_700_000_000 * 1_000_000_000 + 250_000_000
FRONT = "/zed_front/zed_node/rgb/color/rect/image"
WRIST = "/zed_wrist/zed_node/rgb/color/rect/image"
ARM = "/franka/joint_states"
GRIPPER = "/franka_gripper/joint_states"
W, H = 32, 24
ARM_JOINTS = [f"fr3_joint{i}" for i in range(1, 8)]
FINGERS = ["fr3_finger_joint1", "fr3_finger_joint2"]
Q_HOME = [0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785]
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED = "sensor_msgs/msg/CompressedImage"
JOINTS = "sensor_msgs/msg/JointState"
MCAP_MAGIC = b"\x89MCAP0\r\n"
TS1 = get_typestore(Stores.ROS1_NOETIC)
TS2 = get_typestore(Stores.ROS2_HUMBLE)


# ---------------------------------------------------------------------------------------------
# The recording: messages as dicts, independent of the serialization.


def grid(rng, hz, seconds):
    n = int(round(seconds * hz))
    k = np.arange(n, dtype=np.int64)
    return T0_NS + (k * 1_000_000_000) // hz + rng.integers(-300_000, 300_000, size=n, dtype=np.int64)


def recording(seconds, seed):
    """[{log, topic, type, stamp, ...fields}] sorted by log time."""
    rng = np.random.default_rng(seed)
    out = []
    for topic in (FRONT, WRIST):
        base = rng.integers(0, 256, size=(H, W, 4), dtype=np.uint8)
        for i, stamp in enumerate(grid(rng, 30, seconds)):
            out.append({"log": int(stamp) + 30_000_000, "topic": topic, "type": IMAGE, "stamp": int(stamp),
                        "height": H, "width": W, "encoding": "bgra8", "step": W * 4,
                        "data": (base + np.uint8(i % 256)).reshape(-1)})
    amp, freq = rng.uniform(0.1, 0.3, size=7), rng.uniform(0.1, 0.4, size=7)
    for stamp in grid(rng, 250, seconds):
        t = (int(stamp) - T0_NS) * 1e-9
        pos = [Q_HOME[j] + amp[j] * math.sin(2 * math.pi * freq[j] * t) for j in range(7)]
        out.append({"log": int(stamp) + 500_000, "topic": ARM, "type": JOINTS, "stamp": int(stamp),
                    "name": list(ARM_JOINTS), "position": pos})
    for stamp in grid(rng, 50, seconds):
        t = (int(stamp) - T0_NS) * 1e-9
        width = 0.04 + 0.03 * math.sin(2 * math.pi * 0.3 * t)
        out.append({"log": int(stamp) + 500_000, "topic": GRIPPER, "type": JOINTS, "stamp": int(stamp),
                    "name": list(FINGERS), "position": [width / 2, width / 2]})
    out.sort(key=lambda m: (m["log"], m["topic"]))
    return out


def copy(msgs):
    return [dict(m) for m in msgs]


def of(msgs, topic):
    return [m for m in msgs if m["topic"] == topic]


def serialize(m, ros1):
    ts = TS1 if ros1 else TS2
    stamp = m["stamp"] % (1 << 63)
    time = ts.types["builtin_interfaces/msg/Time"](sec=(stamp // 1_000_000_000) % (1 << 31),
                                                   nanosec=stamp % 1_000_000_000)
    header = ts.types["std_msgs/msg/Header"](stamp=time, frame_id="", **({"seq": 0} if ros1 else {}))
    if m["type"] == IMAGE:
        msg = ts.types[IMAGE](header=header, height=m["height"], width=m["width"], encoding=m["encoding"],
                              is_bigendian=0, step=m["step"], data=np.asarray(m["data"], dtype=np.uint8))
    elif m["type"] == COMPRESSED:
        msg = ts.types[COMPRESSED](header=header, format=m["format"], data=np.frombuffer(m["data"], dtype=np.uint8))
    else:
        n = len(m["position"])
        msg = ts.types[JOINTS](header=header, name=m["name"], position=np.array(m["position"], dtype=np.float64),
                               velocity=np.zeros(n), effort=np.zeros(n))
    data = bytes(TS1.serialize_ros1(msg, m["type"]) if ros1 else TS2.serialize_cdr(msg, m["type"]))
    if "truncate" in m:
        data = data[: m["truncate"]]
    return data


# ---------------------------------------------------------------------------------------------
# Writers.


def write_mcap(path, msgs, profile="ros2", compression=CompressionType.LZ4, encoding=None):
    """A ros2 MCAP with the public `mcap` writer: 16 KiB chunks, CRCs, summary."""
    with open(path, "wb") as f:
        w = McapWriter(f, chunk_size=16 << 10, compression=compression)
        w.start(profile=profile, library="make_corpus.py")
        schemas, channels = {}, {}
        for m in msgs:
            if m["topic"] in channels:
                continue
            if m["type"] not in schemas:
                text = TS2.generate_msgdef(m["type"], ros_version=2)[0]
                schemas[m["type"]] = w.register_schema(name=m["type"], encoding="ros2msg", data=text.encode())
            enc = (encoding or {}).get(m["topic"], "cdr")
            channels[m["topic"]] = w.register_channel(topic=m["topic"], message_encoding=enc,
                                                      schema_id=schemas[m["type"]])
        seq = {}
        for m in msgs:
            seq[m["topic"]] = seq.get(m["topic"], 0) + 1
            w.add_message(channel_id=channels[m["topic"]], log_time=m["log"], publish_time=m["log"],
                          data=serialize(m, False), sequence=seq[m["topic"]])
        w.finish()


def write_ros1(path, msgs, compression=None):
    writer = Writer1(path)
    writer.chunk_threshold = 32 << 10
    if compression is not None:
        writer.set_compression(compression)
    with writer:
        conns = {}
        for m in msgs:
            if m["topic"] not in conns:
                conns[m["topic"]] = writer.add_connection(m["topic"], m["type"], typestore=TS1)
            writer.write(conns[m["topic"]], m["log"], serialize(m, True))


def write_rosbag2(path, msgs, plugin):
    with Writer2(path, version=9, storage_plugin=plugin) as writer:
        conns = {}
        for m in msgs:
            if m["topic"] not in conns:
                conns[m["topic"]] = writer.add_connection(m["topic"], m["type"], typestore=TS2)
            writer.write(conns[m["topic"]], m["log"], serialize(m, False))


# ---------------------------------------------------------------------------------------------
# Byte surgery.


def mcap_records(data):
    """(offset, opcode, body offset, body length) of each top-level record after the magic."""
    out, at = [], 8
    while at + 9 <= len(data):
        op = data[at]
        (n,) = struct.unpack_from("<Q", data, at + 1)
        out.append((at, op, at + 9, n))
        if op == 0x02 or at + 9 + n > len(data):  # footer, or a record past the end
            break
        at += 9 + n
    return out


def first_chunk(data):
    """(record offset, body offset) of the first chunk record (opcode 0x06)."""
    for at, op, body, _ in mcap_records(data):
        if op == 0x06:
            return at, body
    raise ValueError("no chunk")


def flip_bits(data, lo, hi, n, rng):
    b = bytearray(data)
    for _ in range(n):
        i = rng.randrange(lo, hi)
        b[i] ^= 1 << rng.randrange(8)
    return bytes(b)


def ros1_records(data):
    """(offset, header fields, data offset, data length) of each record after the magic line."""
    out, at = [], 13
    while at + 4 <= len(data):
        (hl,) = struct.unpack_from("<I", data, at)
        header = data[at + 4: at + 4 + hl]
        fields, p = {}, 0
        while p + 4 <= len(header):
            (fl,) = struct.unpack_from("<I", header, p)
            k, _, v = header[p + 4: p + 4 + fl].partition(b"=")
            fields[k.decode()] = (at + 4 + p + 4 + len(k) + 1, v)
            p += 4 + fl
        (dl,) = struct.unpack_from("<I", data, at + 4 + hl)
        out.append((at, fields, at + 8 + hl, dl))
        at += 8 + hl + dl
    return out


def ros1_first_chunk_data(data):
    for _, fields, d, n in ros1_records(data):
        if fields.get("op", (0, b""))[1] == b"\x05":
            return d, n
    raise ValueError("no chunk")


# ---------------------------------------------------------------------------------------------
# Cases.


def png_bomb(width, height):
    """A PNG whose header claims `width` x `height` RGB, with a few bytes of pixel data."""
    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b"")


def content_cases(good):
    """Well-formed MCAP files whose content is wrong: (name, messages, reason)."""
    cases = []

    def case(name, reason, edit):
        msgs = copy(good)
        msgs = edit(msgs) or msgs
        cases.append((name, msgs, reason))

    def nan(msgs):
        of(msgs, ARM)[100]["position"] = [*Q_HOME[:3], float("nan"), *Q_HOME[4:]]
    case("c_nan_joint.mcap", "joint 'fr3_joint4' on /franka/joint_states is NaN", nan)

    def missing(msgs):
        for m in of(msgs, ARM)[50:]:
            m["name"], m["position"] = m["name"][:6], m["position"][:6]
    case("c_missing_joint.mcap", "joint 'fr3_joint7' is missing from /franka/joint_states", missing)

    def fewer(msgs):
        m = of(msgs, ARM)[60]
        m["position"] = m["position"][:5]
    case("c_fewer_positions.mcap", "7 names but 5 positions", fewer)

    def short(msgs):
        for m in of(msgs, FRONT)[10:]:
            m["data"] = m["data"][: W * 4 * (H - 1)]
    case("c_short_image.mcap", f"{W * 4 * (H - 1)} data bytes, but {H} rows of step {W * 4} need {W * 4 * H}", short)

    def absurd(msgs):
        for m in of(msgs, FRONT):
            m["width"] = m["height"] = m["step"] = 0xFFFF_FFFF
    case("c_absurd_dimensions.mcap", "4294967295×4294967295", absurd)

    def zero(msgs):
        for m in of(msgs, WRIST):
            m["width"] = 0
    case("c_zero_width.mcap", "empty image 0×24", zero)

    def encoding(msgs):
        for m in of(msgs, FRONT):
            m["encoding"], m["step"] = "16UC1", W * 2
    case("c_unsupported_encoding.mcap", "a 16UC1 depth image where colour frames are expected", encoding)

    def bomb(msgs):
        data = png_bomb(60_000, 60_000)
        for m in of(msgs, WRIST):
            m.update(type=COMPRESSED, format="png", data=data)
    case("c_png_bomb.mcap", "60000×60000", bomb)

    def garbage_jpeg(msgs):
        for m in of(msgs, WRIST):
            m.update(type=COMPRESSED, format="jpeg", data=b"\xff\xd8\xff\xe0 not a jpeg at all")
    case("c_garbage_jpeg.mcap", "jpeg image", garbage_jpeg)

    case("a_cameras_no_arm.mcap", "no arm", lambda msgs: [m for m in msgs if m["type"] != JOINTS])
    case("a_arm_no_cameras.mcap", "no camera", lambda msgs: [m for m in msgs if m["type"] == JOINTS])

    def reset(msgs):
        for m in of(msgs, FRONT)[30:]:
            m["stamp"] -= 1000 * 1_000_000_000
    case("c_clock_reset.mcap", "time runs backwards on " + FRONT, reset)

    def apart(msgs):
        for m in msgs:
            if m["type"] == JOINTS:
                m["stamp"] += 60 * 1_000_000_000
                m["log"] += 60 * 1_000_000_000
        msgs.sort(key=lambda m: (m["log"], m["topic"]))
    case("c_never_overlap.mcap", "do not overlap", apart)

    def jump(msgs):
        of(msgs, GRIPPER)[-1]["stamp"] += 1_000_000 * 1_000_000_000  # 11.6 days ahead
    case("c_stamp_jump.mcap", "time jumps forward on " + GRIPPER, jump)

    def truncated_cdr(msgs):
        of(msgs, ARM)[40]["truncate"] = 9
    case("c_truncated_cdr.mcap", "/franka/joint_states message at", truncated_cdr)

    def wrong_type(msgs):
        for m in of(msgs, GRIPPER)[5:]:
            m.update(type=IMAGE, height=1, width=1, encoding="rgb8", step=3, data=np.zeros(3, dtype=np.uint8))
        return msgs
    # The gripper channel keeps its JointState schema (the first message defines it): later
    # payloads are Images and do not decode as JointStates.
    case("c_wrong_payload_type.mcap", "/franka_gripper/joint_states message at", wrong_type)
    return cases


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir", type=Path)
    ap.add_argument("--seconds", type=float, default=2.0)
    ap.add_argument("--seed", type=int, default=5)
    args = ap.parse_args()
    out = args.outdir
    out.mkdir(parents=True, exist_ok=True)
    rng = random.Random(args.seed)
    good_msgs = recording(args.seconds, args.seed)
    good, bad = [], {}

    # Good inputs: one recording in every format.
    write_mcap(out / "good_standalone.mcap", good_msgs)
    write_mcap(out / "good_zstd.mcap", good_msgs, compression=CompressionType.ZSTD)
    write_ros1(out / "good_ros1_none.bag", good_msgs)
    write_ros1(out / "good_ros1_bz2.bag", good_msgs, Writer1.CompressionFormat.BZ2)
    write_ros1(out / "good_ros1_lz4.bag", good_msgs, Writer1.CompressionFormat.LZ4)
    write_rosbag2(out / "good_rosbag2_mcap", good_msgs, StoragePlugin.MCAP)
    write_rosbag2(out / "good_rosbag2_sqlite3", good_msgs, StoragePlugin.SQLITE3)
    good += ["good_standalone.mcap", "good_zstd.mcap", "good_ros1_none.bag", "good_ros1_bz2.bag",
             "good_ros1_lz4.bag", "good_rosbag2_mcap", "good_rosbag2_sqlite3"]
    # Stamps that wobble: a joint stamp now and then a few ms behind its predecessor, one camera
    # frame 40 ms early (behind the frame before it). Reordered, counted, converted.
    wobble = copy(good_msgs)
    for i, m in enumerate(of(wobble, ARM)):
        if i % 50 == 25:
            m["stamp"] -= 6_000_000
    of(wobble, FRONT)[20]["stamp"] -= 40_000_000
    write_mcap(out / "good_wobbling_stamps.mcap", wobble)
    good.append("good_wobbling_stamps.mcap")
    # A rosbag2 directory without its metadata.yaml is no bag, but its storage file is a
    # standalone input of its own (what a copy of only the .db3 gives).
    shutil.copytree(out / "good_rosbag2_sqlite3", out / "good_r2_no_metadata")
    (out / "good_r2_no_metadata" / "metadata.yaml").unlink()
    good.append("good_r2_no_metadata")

    # MCAP byte surgery on the LZ4 file.
    mc = (out / "good_standalone.mcap").read_bytes()
    chunk_at, chunk_body = first_chunk(mc)
    # Chunk body: start u64, end u64, uncompressed size u64, uncompressed crc u32, compression
    # string (u32 length + bytes), records (u64 length + bytes).
    (clen,) = struct.unpack_from("<I", mc, chunk_body + 28)
    data_at = chunk_body + 32 + clen + 8

    def put(name, data, reason):
        (out / name).write_bytes(data)
        bad[name] = reason

    put("m_empty.mcap", b"", "not an MCAP file")
    put("m_magic_only.mcap", MCAP_MAGIC, "truncated or corrupt MCAP")
    put("m_truncated_in_header.mcap", mc[:20], "truncated or corrupt MCAP")
    put("m_truncated_in_chunk.mcap", mc[: data_at + 100], "truncated or corrupt MCAP")
    put("m_truncated_half.mcap", mc[: len(mc) // 2], "truncated or corrupt MCAP")
    put("m_truncated_no_footer.mcap", mc[:-30], "truncated or corrupt MCAP")
    put("m_bit_flips.mcap", flip_bits(mc, data_at, data_at + 2000, 24, rng), "corrupt MCAP chunk")
    zeroed = bytearray(mc)
    zeroed[data_at + 64: data_at + 64 + 4096] = bytes(4096)
    put("m_zeroed_block.mcap", bytes(zeroed), "corrupt MCAP chunk")
    huge = bytearray(mc)
    struct.pack_into("<Q", huge, chunk_at + 1, (1 << 63) - 1)
    put("m_huge_record_length.mcap", bytes(huge), "truncated or corrupt MCAP")
    huge = bytearray(mc)
    struct.pack_into("<Q", huge, chunk_body + 16, 1 << 40)
    put("m_huge_chunk_size.mcap", bytes(huge), "corrupt MCAP chunk")
    crc = bytearray(mc)
    struct.pack_into("<I", crc, chunk_body + 24, struct.unpack_from("<I", mc, chunk_body + 24)[0] ^ 0xDEADBEEF)
    put("m_chunk_crc_mismatch.mcap", bytes(crc), "CRC")
    odd = bytearray(mc)
    odd[chunk_body + 32: chunk_body + 32 + clen] = b"br4"[:clen]
    put("m_unknown_compression.mcap", bytes(odd), "unsupported chunk compression 'br4'")
    write_mcap(out / "m_wrong_profile.mcap", good_msgs, profile="ros1")
    bad["m_wrong_profile.mcap"] = "MCAP profile is 'ros1', expected 'ros2'"
    write_mcap(out / "m_json_encoding.mcap", good_msgs, encoding={FRONT: "json"})
    bad["m_json_encoding.mcap"] = "message encoding 'json', expected 'cdr'"
    put("m_bag_named_mcap.mcap", (out / "good_ros1_none.bag").read_bytes(), "not an MCAP file")

    # ROS 1 byte surgery.
    bag = (out / "good_ros1_none.bag").read_bytes()
    put("r1_truncated.bag", bag[: len(bag) * 6 // 10], "truncated")
    put("r1_truncated_in_magic.bag", bag[:10], "truncated")
    # A compressed chunk's stream broken where its structure is: bz2 checks a CRC per block,
    # but lz4 frames as `rosbags` writes them carry no checksum, so zeros among literal bytes
    # would only change pixels; the frame header is broken instead.
    for kind, at in (("bz2", 1 / 3), ("lz4", 0)):
        b = (out / f"good_ros1_{kind}.bag").read_bytes()
        d, n = ros1_first_chunk_data(b)
        broken = bytearray(b)
        start = d + int(n * at)
        broken[start: start + 64] = bytes(64)
        put(f"r1_bad_{kind}.bag", bytes(broken), f"{kind} chunk")
    unindexed = bytearray(bag)
    pos, _ = ros1_records(bag)[0][1]["index_pos"]
    struct.pack_into("<Q", unindexed, pos, 0)
    put("r1_unindexed.bag", bytes(unindexed), "rosbag reindex")
    put("r1_version_1_2.bag", b"#ROSBAG V1.2\n" + bag[13:], "unsupported bag version '#ROSBAG V1.2'")
    put("r1_mcap_named_bag.bag", mc, "not a ROS 1 bag")

    # rosbag2.
    src = out / "good_rosbag2_sqlite3"
    meta = (src / "metadata.yaml").read_text()
    db3 = next(src.glob("*.db3"))

    def bag2(name, reason, metadata=None, db=None):
        d = out / name
        d.mkdir()
        (d / "metadata.yaml").write_text(meta if metadata is None else metadata)
        if db is not None:
            (d / db3.name).write_bytes(db)
        bad[name] = reason

    bag2("r2_broken_metadata", "metadata.yaml", "rosbag2_bagfile_information: [version: 9\n  {{{",
         db3.read_bytes())
    bag2("r2_not_a_bag_metadata", "metadata.yaml", "hello: world\n", db3.read_bytes())
    bag2("r2_escaping_paths", "outside the bag directory",
         meta.replace(f"- {db3.name}", "- ../good_rosbag2_sqlite3/" + db3.name), db3.read_bytes())
    bag2("r2_listed_file_missing", "metadata.yaml", meta)
    dbb = bytearray(db3.read_bytes())
    dbb[len(dbb) // 3: len(dbb) // 3 + 8192] = bytes(range(256)) * 32
    bag2("r2_corrupt_sqlite", "rosbag2 sqlite3 storage", None, bytes(dbb))
    put("r2_not_sqlite.db3", bytes(rng.randrange(256) for _ in range(4096)), "rosbag2 sqlite3 storage")
    con = sqlite3.connect(out / "r2_no_messages_table.db3")
    con.execute("CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT, type TEXT, serialization_format TEXT)")
    con.commit()
    con.close()
    bad["r2_no_messages_table.db3"] = "no such table: messages"
    shutil.copy(db3, out / "r2_negative_timestamp.db3")
    con = sqlite3.connect(out / "r2_negative_timestamp.db3")
    con.execute("UPDATE messages SET timestamp = -5 WHERE id = 3")
    con.commit()
    con.close()
    bad["r2_negative_timestamp.db3"] = "negative timestamp -5"
    # Found by the fuzzer (converter/src/fuzz.rs): the `mcap` crate's reader allocates what a
    # chunk header claims, and 2^48 bytes aborted the whole conversion.
    d = out / "r2_mcap_huge_chunk"
    shutil.copytree(out / "good_rosbag2_mcap", d)
    storage = next(d.glob("*.mcap"))
    b = bytearray(storage.read_bytes())
    _, body = first_chunk(b)
    struct.pack_into("<Q", b, body + 16, 1 << 48)
    storage.write_bytes(bytes(b))
    bad["r2_mcap_huge_chunk"] = "corrupt MCAP chunk"
    d = out / "r2_compressed_storage"
    d.mkdir()
    (d / "metadata.yaml").write_text(meta.replace("compression_format: ''", "compression_format: zstd")
                                     .replace("compression_mode: ''", "compression_mode: FILE")
                                     .replace(f"- {db3.name}", f"- {db3.name}.zstd"))
    (d / (db3.name + ".zstd")).write_bytes(b"(\xb5/\xfd")
    bad["r2_compressed_storage"] = "compressed rosbag2 storage (compression_format: zstd) is not supported"

    # Well-formed files, bad content.
    for name, msgs, reason in content_cases(good_msgs):
        write_mcap(out / name, msgs)
        bad[name] = reason

    print(json.dumps({"good": sorted(good), "bad": dict(sorted(bad.items()))}))


if __name__ == "__main__":
    main()
