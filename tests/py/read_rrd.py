"""Reads an .rrd file with the rerun-sdk Python package and prints what it holds as JSON.

    read_rrd.py FILE.rrd

Output: {"recordings": [{"application_id", "recording_id", "name", "entities": {path: {
"static": {component: value}, "rows": [{timeline: int, component: value, ...}]}}}]}.
Timelines are integers (timestamps and durations in ns, sequences as is). Scalars are lists of
floats, text is a string, images are {"sha256", "bytes"} of their buffer or blob (plus
"format" for raw images: [width, height, color model]), line strips are lists of point counts,
translations are [x, y, z]. Rows are in no particular order.
"""

import hashlib
import json
import sys

import pyarrow as pa
from rerun.experimental import RrdReader


def value(component, v):
    if v is None:
        return None
    if component.endswith(":buffer") or component.endswith(":blob"):
        data = bytes(v[0]) if isinstance(v, list) and v and isinstance(v[0], (bytes, list)) else v
        if isinstance(data, list):
            data = bytes(data)
        return {"sha256": hashlib.sha256(data).hexdigest(), "bytes": len(data)}
    if component == "Image:format":
        f = v[0]
        return [f.get("width"), f.get("height"), f.get("color_model")]
    if component.endswith(":strips"):
        return [len(s) for s in v]
    if isinstance(v, list) and len(v) == 1 and not component.endswith(":scalars"):
        return v[0]
    return v


def plain(column):
    t = column.type
    if pa.types.is_timestamp(t) or pa.types.is_duration(t):
        return column.cast(pa.int64()).to_pylist()
    return column.to_pylist()


def main(path):
    reader = RrdReader(path)
    out = []
    for store in reader.recordings():
        entities = {}
        name = None
        for chunk in reader.stream(store=store):
            batch = chunk.to_record_batch()
            entity = chunk.entity_path
            timelines = set(chunk.timeline_names)
            cols = {n: plain(batch.column(n)) for n in batch.schema.names if n != "rerun.controls.RowId"}
            if entity == "/__properties":
                for n, vals in cols.items():
                    if n.endswith(":name") and vals and vals[0]:
                        name = vals[0][0] if isinstance(vals[0], list) else vals[0]
                continue
            e = entities.setdefault(entity, {"static": {}, "rows": []})
            for i in range(batch.num_rows):
                row = {}
                for n, vals in cols.items():
                    v = vals[i]
                    if n in timelines:
                        row[n] = v
                    elif v is not None:
                        row[n] = value(n, v)
                if chunk.is_static:
                    e["static"].update({k: v for k, v in row.items() if k not in timelines})
                else:
                    e["rows"].append(row)
        out.append(
            {
                "application_id": store.application_id,
                "recording_id": store.recording_id,
                "name": name,
                "entities": entities,
            }
        )
    json.dump({"recordings": out}, sys.stdout)


if __name__ == "__main__":
    main(sys.argv[1])
