"""Mean colours of a grid of cells of every frame of every camera of a LeRobot dataset written by
`scaledp convert`, decoded with Pillow.

    frame_colours.py DATASET COLS ROWS

Prints JSON {"observation.images.NAME": [[[r, g, b] per cell, row by row, left to right], ...]}
with frames in global index order (one entry per dataset frame). Each cell's mean leaves out a
border of an eighth of the cell on every side, where resampling blends neighbouring cells.
"""
import io
import json
import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
from PIL import Image


def cells(px, cols, rows):
    h, w = px.shape[0] // rows, px.shape[1] // cols
    my, mx = max(1, h // 8), max(1, w // 8)
    out = []
    for r in range(rows):
        for c in range(cols):
            cell = px[r * h + my : (r + 1) * h - my, c * w + mx : (c + 1) * w - mx]
            out.append([round(float(v), 2) for v in cell.reshape(-1, 3).mean(axis=0)])
    return out


def main(ds, cols, rows):
    ds = Path(ds)
    info = json.loads((ds / "meta/info.json").read_text())
    cams = [n for n, f in info["features"].items() if f["dtype"] == "image"]
    records = []
    for f in sorted((ds / "data").glob("*/*.parquet")):
        records.extend(pq.read_table(f, columns=cams + ["index"]).to_pylist())
    records.sort(key=lambda r: r["index"])
    out = {}
    for cam in cams:
        out[cam] = [
            cells(np.asarray(Image.open(io.BytesIO(r[cam]["bytes"])).convert("RGB"), dtype=np.float64), cols, rows)
            for r in records
        ]
    print(json.dumps(out))


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]))
