"""Turns image features of a LeRobot v3.0 dataset into video features the way LeRobot 0.4.4
writes them, for the loader's tests: each episode encoded on its own with PyAV as
`lerobot.datasets.video_utils.encode_video_frames` does (libsvtav1, yuv420p, g=2, crf=30,
preset 12), then episodes concatenated into `videos/{key}/chunk-000/file-NNN.mp4` by stream
copy through ffmpeg's concat demuxer (as `concatenate_video_files` does); H.264 (libx264) and
HEVC (libx265) files are encoded as one stream per file (their B-frames do not survive the
concat demuxer), with `--gop` frames per group of pictures; `videos/{key}/{chunk_index,file_index,from_timestamp,
to_timestamp}` written to meta/episodes, the image column dropped from the data files and
info.json's feature turned into a `video` one.

It also writes what LeRobot's pyav backend would return: every frame of every file decoded by
PyAV and converted with `frame.to_rgb().to_ndarray()` (torchvision's VideoReader does exactly
that), as REFERENCE/<file path with / as _>.rgb (frames x H x W x 3 bytes) and a JSON index
of their presentation times.

Usage: make_video_dataset.py DATASET REFERENCE --keys k1,k2 [--codec av1|h264|hevc]
                             [--episodes-per-file N] [--gop 2] [--no-reference]
The dataset's own meta/episodes files get the video columns (a minimal file is written when it
has none); `scaledp bench load` uses the same script for its video dataset.
Prints JSON {"files": {rel: {"times": [...], "width": W, "height": H, "rgb": path}}}.
"""
import argparse
import hashlib
import io
import shutil
import json
from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from PIL import Image

ENCODERS = {
    # codec: (ffmpeg encoder, options, info.json codec name)
    "av1": ("libsvtav1", {"g": "2", "crf": "30", "preset": "12"}, "av1"),
    "h264": ("libx264", {"g": "2", "crf": "23"}, "h264"),
    "hevc": ("libx265", {"g": "2", "crf": "28", "x265-params": "log-level=error"}, "hevc"),
}


def encode(frames, path, codec, fps, gop):
    name, options, _ = ENCODERS[codec]
    options = dict(options, g=str(gop))
    h, w = frames[0].shape[:2]
    with av.open(str(path), "w") as out:
        stream = out.add_stream(name, fps, options=options)
        stream.pix_fmt = "yuv420p"
        stream.width, stream.height = w, h
        for rgb in frames:
            frame = av.VideoFrame.from_image(Image.fromarray(rgb))
            for packet in stream.encode(frame):
                out.mux(packet)
        for packet in stream.encode():
            out.mux(packet)


def concatenate(parts, path):
    listing = path.with_suffix(".ffconcat")
    listing.write_text("ffconcat version 1.0\n" + "".join(f"file '{p.resolve()}'\n" for p in parts))
    src = av.open(str(listing), mode="r", format="concat", options={"safe": "0"})
    dst = av.open(str(path), mode="w", options={"movflags": "faststart"})
    ins = src.streams.video[0]
    outs = dst.add_stream_from_template(template=ins, opaque=True)
    outs.time_base = ins.time_base
    for packet in src.demux(ins):
        if packet.dts is None:
            continue
        packet.stream = outs
        dst.mux(packet)
    src.close()
    dst.close()
    listing.unlink()


def reference(path):
    """Every frame as LeRobot's pyav backend sees it: (times, frames)."""
    times, frames = [], []
    with av.open(str(path)) as c:
        for frame in c.decode(video=0):
            times.append(float(frame.pts * frame.time_base))
            frames.append(frame.to_rgb().to_ndarray())
    return times, np.stack(frames)


def decode_all(encoded):
    return [np.asarray(Image.open(io.BytesIO(b)).convert("RGB")) for b in encoded]


def episode_frames(data_files, key):
    """(episode_index, [encoded images]) of `key`, episode after episode, one data file in memory at a time."""
    for f in data_files:
        t = pq.read_table(f, columns=["episode_index", key])
        eps = t.column("episode_index").to_pylist()
        imgs = t.column(key).combine_chunks().field("bytes")
        start = 0
        while start < len(eps):
            end = start
            while end < len(eps) and eps[end] == eps[start]:
                end += 1
            yield eps[start], [imgs[i].as_py() for i in range(start, end)]
            start = end


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dataset")
    ap.add_argument("reference", help="where decoded references go (and temporary parts)")
    ap.add_argument("--keys", required=True)
    ap.add_argument("--codec", default="av1", choices=sorted(ENCODERS))
    ap.add_argument("--episodes-per-file", type=int, default=1000)
    ap.add_argument("--gop", type=int, default=2)
    ap.add_argument("--no-reference", action="store_true", help="skip decoding the files back")
    a = ap.parse_args()
    root, ref_dir = Path(a.dataset), Path(a.reference)
    ref_dir.mkdir(parents=True, exist_ok=True)
    info = json.loads((root / "meta/info.json").read_text())
    fps = info["fps"]
    keys = [k if k.startswith("observation.images.") else f"observation.images.{k}" for k in a.keys.split(",")]
    data_files = sorted((root / "data").glob("*/*.parquet"))
    video_cols = {}
    out_files = {}
    tmp = ref_dir / "parts"
    tmp.mkdir(exist_ok=True)
    for key in keys:
        cols = {c: {} for c in ("chunk_index", "file_index", "from_timestamp", "to_timestamp")}
        shape, group, file_index = None, [], 0

        def close_file():
            nonlocal group, file_index
            parts = [p for p, _ in group]
            rel = f"videos/{key}/chunk-000/file-{file_index:03d}.mp4"
            (root / rel).parent.mkdir(parents=True, exist_ok=True)
            if a.codec == "av1":
                concatenate(parts, root / rel)
                for p in parts:
                    p.unlink()
            else:
                # x264/x265 B-frames do not survive the concat demuxer: one stream per file.
                encode([f for _, frames in group for f in frames], root / rel, a.codec, fps, a.gop)
            if not a.no_reference:
                times, frames = reference(root / rel)
                rgb = ref_dir / (rel.replace("/", "_") + ".rgb")
                rgb.write_bytes(frames.tobytes())
                out_files[rel] = {"times": times, "height": int(frames.shape[1]),
                                  "width": int(frames.shape[2]), "rgb": str(rgb)}
            group, file_index = [], file_index + 1

        t = Fraction(0)
        # Episodes with the same images (a dataset merged with itself) are encoded once.
        encoded_parts = {}
        for e, encoded in episode_frames(data_files, key):
            digest = hashlib.sha256(b"".join(encoded)).hexdigest()
            if shape is None:
                shape = decode_all(encoded[:1])[0].shape
            if a.codec == "av1":
                part = tmp / f"{e}.mp4"
                if digest in encoded_parts:
                    shutil.copyfile(encoded_parts[digest], part)
                else:
                    encode(decode_all(encoded), part, a.codec, fps, a.gop)
                    kept = tmp / f"cache-{digest}.mp4"
                    shutil.copyfile(part, kept)
                    encoded_parts[digest] = kept
                group.append((part, None))
            else:
                group.append((None, decode_all(encoded)))
            frames = encoded
            duration = Fraction(len(frames), 1) / Fraction(fps)
            cols["chunk_index"][e] = 0
            cols["file_index"][e] = file_index
            cols["from_timestamp"][e] = float(t)
            cols["to_timestamp"][e] = float(t + duration)
            t += duration
            if len(group) == a.episodes_per_file:
                close_file()
                t = Fraction(0)
        if group:
            close_file()
        for kept in encoded_parts.values():
            kept.unlink()
        video_cols[key] = cols
        info["features"][key] = {
            "dtype": "video",
            "shape": list(shape),
            "names": ["height", "width", "channels"],
            "info": {
                "video.height": shape[0],
                "video.width": shape[1],
                "video.codec": ENCODERS[a.codec][2],
                "video.pix_fmt": "yuv420p",
                "video.is_depth_map": False,
                "video.fps": fps,
                "video.channels": 3,
                "has_audio": False,
            },
        }
    tmp.rmdir()
    for f in data_files:
        t = pq.read_table(f)
        pq.write_table(t.drop_columns([k for k in keys if k in t.column_names]), f)
    # meta/episodes: the video columns added to what is there (LeRobot's or our converter's
    # files), or a minimal file for a fixture that has none.
    ep_files = sorted((root / "meta/episodes").glob("*/*.parquet"))
    if not ep_files:
        t = pq.read_table(data_files[0], columns=["episode_index"]) if len(data_files) == 1 else \
            pa.concat_tables([pq.read_table(f, columns=["episode_index"]) for f in data_files])
        eps = t.column("episode_index").to_pylist()
        episodes = sorted(set(eps))
        lengths = [eps.count(e) for e in episodes]
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).tolist()
        table = pa.table({
            "episode_index": episodes,
            "length": lengths,
            "tasks": [["test"] for _ in episodes],
            "data/chunk_index": [0] * len(episodes),
            "data/file_index": [0] * len(episodes),
            "dataset_from_index": starts,
            "dataset_to_index": [s + n for s, n in zip(starts, lengths)],
        })
        ep_files = [root / "meta/episodes/chunk-000/file-000.parquet"]
        ep_files[0].parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(table, ep_files[0])
    for f in ep_files:
        table = pq.read_table(f)
        eps = table.column("episode_index").to_pylist()
        for key, cols in video_cols.items():
            for c, values in cols.items():
                name = f"videos/{key}/{c}"
                if name in table.column_names:
                    table = table.drop_columns([name])
                table = table.append_column(name, pa.array([values[e] for e in eps]))
        pq.write_table(table, f)
    info["video_path"] = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    (root / "meta/info.json").write_text(json.dumps(info, indent=4))
    print(json.dumps({"files": out_files}))


if __name__ == "__main__":
    main()
