"""Checks a dataset written by `scaledp convert` against what LeRobot v3.0 reads, using the
dataset LeRobot itself wrote (tests/fixtures/lerobot_v3_example) as the reference.

Usage: check_lerobot.py DATASET EXAMPLE
Prints JSON {"errors": [...], "episodes": N, "frames": N, "tasks": [...], "features": {...}}.
"""
import io
import json
import sys
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

STATS = ["min", "max", "mean", "std", "count", "q01", "q10", "q50", "q90", "q99"]


def main(ds, ex):
    ds, ex = Path(ds), Path(ex)
    errors = []
    info = json.loads((ds / "meta/info.json").read_text())
    ref_info = json.loads((ex / "meta/info.json").read_text())
    for k in ref_info:
        if k not in info:
            errors.append(f"info.json lacks {k}")
    if info.get("codebase_version") != "v3.0":
        errors.append("codebase_version is not v3.0")
    feats = info["features"]
    for name, f in feats.items():
        if set(f) != {"dtype", "shape", "names"}:
            errors.append(f"feature {name} has keys {sorted(f)}")
        # A vector names its elements; a feature of more axes (images, depth) names its axes.
        if len(f["shape"]) > 1:
            if f["names"] is not None and len(f["names"]) != len(f["shape"]):
                errors.append(f"feature {name}: {len(f['names'])} names for shape {f['shape']}")
        elif f["dtype"] in ("float32",) and f["names"] is not None and len(f["names"]) != f["shape"][0]:
            errors.append(f"feature {name}: {len(f['names'])} names for shape {f['shape']}")

    # Data files: every column typed as LeRobot types it.
    ref_data = pq.read_table(ex / "data/chunk-000/file-000.parquet").schema
    ref_image_type = next(f.type for f in ref_data if f.name.startswith("observation.images."))
    files = sorted((ds / "data").glob("*/*.parquet"))
    tables = [pq.read_table(f) for f in files]
    rows = [r for t in tables for r in t.to_pylist()]
    for t, f in zip(tables, files):
        for field in t.schema:
            if field.name.startswith("observation.images."):
                if field.type != ref_image_type:
                    errors.append(f"{f.name}: {field.name} is {field.type}")
            elif field.name in ref_data.names:
                ref = ref_data.field(field.name).type
                if pa.types.is_fixed_size_list(ref):
                    # Same element type; the length is the feature's own (info.json shape).
                    ok = (pa.types.is_fixed_size_list(field.type) and field.type.value_type == ref.value_type
                          and field.type.list_size == feats[field.name]["shape"][0])
                else:
                    ok = ref == field.type
                if not ok:
                    errors.append(f"{f.name}: {field.name} is {field.type}, LeRobot writes {ref}")
        for name, feat in feats.items():
            if name not in t.schema.names:
                errors.append(f"{f.name}: no column {name}")
    rows.sort(key=lambda r: r["index"])
    if [r["index"] for r in rows] != list(range(len(rows))):
        errors.append("global index is not 0..N-1")

    # Episodes metadata.
    ref_eps = pq.read_table(ex / "meta/episodes/chunk-000/file-000.parquet").schema
    eps_t = pq.read_table(ds / "meta/episodes/chunk-000/file-000.parquet")
    for field in ref_eps:
        if "images" in field.name:
            continue
        if field.name not in eps_t.schema.names:
            errors.append(f"episodes parquet lacks {field.name}")
        elif eps_t.schema.field(field.name).type != field.type:
            errors.append(f"episodes {field.name} is {eps_t.schema.field(field.name).type}, LeRobot writes {field.type}")
    for cam in [n for n in feats if n.startswith("observation.images.")]:
        for s in STATS:
            col = f"stats/{cam}/{s}"
            want = "list<element: int64>" if s == "count" else "list<element: list<element: list<element: double>>>"
            if col not in eps_t.schema.names or str(eps_t.schema.field(col).type) != want:
                errors.append(f"episodes {col} missing or not {want}")
    eps = eps_t.to_pylist()
    if info["total_episodes"] != len(eps) or info["total_frames"] != len(rows):
        errors.append(f"info.json says {info['total_episodes']} episodes / {info['total_frames']} frames, found {len(eps)} / {len(rows)}")
    for e in eps:
        mine = [r for r in rows if r["episode_index"] == e["episode_index"]]
        if len(mine) != e["length"] or (mine and (mine[0]["index"], mine[-1]["index"] + 1) != (e["dataset_from_index"], e["dataset_to_index"])):
            errors.append(f"episode {e['episode_index']}: rows do not match length/from/to")
        if [r["frame_index"] for r in mine] != list(range(len(mine))):
            errors.append(f"episode {e['episode_index']}: frame_index is not 0..L-1")
        ts = [r["timestamp"] for r in mine]
        if any(b <= a for a, b in zip(ts, ts[1:])):
            errors.append(f"episode {e['episode_index']}: timestamps not increasing")
        for a, b in zip(mine, mine[1:]):
            if a["action"] != b["observation.state"]:
                errors.append(f"episode {e['episode_index']} frame {a['frame_index']}: action is not the next state")
                break

    # Tasks: a pandas-indexed table, as LeRobot reads it with pd.read_parquet.
    tasks_t = pq.read_table(ds / "meta/tasks.parquet")
    if tasks_t.schema.names != ["task_index", "__index_level_0__"] or b"pandas" not in (tasks_t.schema.metadata or {}):
        errors.append(f"tasks.parquet columns {tasks_t.schema.names}")
    tasks = tasks_t.column("__index_level_0__").to_pylist()

    # Stats: every feature with every statistic.
    stats = json.loads((ds / "meta/stats.json").read_text())
    for name in feats:
        if name not in stats or set(stats[name]) != set(STATS):
            errors.append(f"stats.json: {name} incomplete")
        elif stats[name]["count"] != [len(rows)]:
            errors.append(f"stats.json: {name} count {stats[name]['count']} != {len(rows)}")

    # Images decode to the declared size.
    try:
        from PIL import Image
    except ImportError:
        Image = None
    for cam, f in feats.items():
        if f["dtype"] != "image":
            continue
        for r in rows[:: max(1, len(rows) // 20)]:
            data = r[cam]["bytes"]
            if data[:2] != b"\xff\xd8":
                errors.append(f"{cam}: not JPEG")
                break
            if Image is not None:
                im = Image.open(io.BytesIO(data))
                if [im.size[1], im.size[0], len(im.getbands())] != f["shape"]:
                    errors.append(f"{cam}: image {im.size} {im.mode} vs shape {f['shape']}")
                    break
    print(json.dumps({"errors": errors, "episodes": len(eps), "frames": len(rows), "tasks": tasks,
                      "features": {k: v["names"] for k, v in feats.items()}, "info": info}))


if __name__ == "__main__":
    main(*sys.argv[1:3])
