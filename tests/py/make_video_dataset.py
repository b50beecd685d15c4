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
                             [--episodes-per-file N] [--gop 2]
Prints JSON {"files": {rel: {"times": [...], "width": W, "height": H, "rgb": path}}}.
"""
import argparse
import io
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


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dataset")
    ap.add_argument("reference")
    ap.add_argument("--keys", required=True)
    ap.add_argument("--codec", default="av1", choices=sorted(ENCODERS))
    ap.add_argument("--episodes-per-file", type=int, default=1000)
    ap.add_argument("--gop", type=int, default=2)
    a = ap.parse_args()
    root, ref_dir = Path(a.dataset), Path(a.reference)
    ref_dir.mkdir(parents=True, exist_ok=True)
    info = json.loads((root / "meta/info.json").read_text())
    fps = info["fps"]
    keys = [k if k.startswith("observation.images.") else f"observation.images.{k}" for k in a.keys.split(",")]
    data_files = sorted((root / "data").glob("*/*.parquet"))
    tables = [pq.read_table(f) for f in data_files]
    rows = pa.concat_tables(tables).to_pydict()
    episodes = sorted(set(rows["episode_index"]))
    meta = {
        "episode_index": episodes,
        "length": [rows["episode_index"].count(e) for e in episodes],
        "tasks": [["test"] for _ in episodes],
        "data/chunk_index": [0 for _ in episodes],
        "data/file_index": [0 for _ in episodes],
    }
    start = 0
    meta["dataset_from_index"], meta["dataset_to_index"] = [], []
    for n in meta["length"]:
        meta["dataset_from_index"].append(start)
        meta["dataset_to_index"].append(start + n)
        start += n
    out_files = {}
    tmp = ref_dir / "parts"
    tmp.mkdir(exist_ok=True)
    for key in keys:
        cols = {c: [] for c in ("chunk_index", "file_index", "from_timestamp", "to_timestamp")}
        shape = None
        groups = [episodes[i:i + a.episodes_per_file] for i in range(0, len(episodes), a.episodes_per_file)]
        for file_index, group in enumerate(groups):
            parts, t, stream = [], Fraction(0), []
            for e in group:
                frames = [
                    np.asarray(Image.open(io.BytesIO(img["bytes"])).convert("RGB"))
                    for img, ep in zip(rows[key], rows["episode_index"])
                    if ep == e
                ]
                shape = frames[0].shape
                if a.codec == "av1":
                    part = tmp / f"{key}-{e}.mp4"
                    encode(frames, part, a.codec, fps, a.gop)
                    parts.append(part)
                else:
                    stream += frames
                duration = Fraction(len(frames), 1) / Fraction(fps)
                cols["chunk_index"].append(0)
                cols["file_index"].append(file_index)
                cols["from_timestamp"].append(float(t))
                cols["to_timestamp"].append(float(t + duration))
                t += duration
            rel = f"videos/{key}/chunk-000/file-{file_index:03d}.mp4"
            (root / rel).parent.mkdir(parents=True, exist_ok=True)
            if parts:
                concatenate(parts, root / rel)
            else:
                # x264/x265 B-frames do not survive the concat demuxer: one stream per file.
                encode(stream, root / rel, a.codec, fps, a.gop)
            for p in parts:
                p.unlink()
            times, frames = reference(root / rel)
            rgb = ref_dir / (rel.replace("/", "_") + ".rgb")
            rgb.write_bytes(frames.tobytes())
            out_files[rel] = {"times": times, "height": int(frames.shape[1]), "width": int(frames.shape[2]), "rgb": str(rgb)}
        for c, v in cols.items():
            meta[f"videos/{key}/{c}"] = v
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
    for f, t in zip(data_files, tables):
        pq.write_table(t.drop_columns([k for k in keys if k in t.column_names]), f)
    (root / "meta/episodes/chunk-000").mkdir(parents=True, exist_ok=True)
    pq.write_table(pa.table(meta), root / "meta/episodes/chunk-000/file-000.parquet")
    info["video_path"] = "videos/{video_key}/chunk-{chunk_index:03d}/file-{file_index:03d}.mp4"
    (root / "meta/info.json").write_text(json.dumps(info, indent=4))
    print(json.dumps({"files": out_files}))


if __name__ == "__main__":
    main()
