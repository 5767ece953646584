"""Regenerate `bun000_crop.ply` in this folder from /work/shared/data/stanford-bunny/bun000.ply.

A full-resolution window of the raw range image (rows 30-79, columns 120-179: the top of the bunny's
back with its silhouette, about 0.75 mm pixels), in the original ASCII PLY layout (vertex +
range_grid element), metres; for the free-form fit at the scanner's own resolution.
"""
from pathlib import Path

import numpy as np

from rgm.fitters.io import read_scan

SRC = Path("/work/shared/data/stanford-bunny/bun000.ply")
ROWS, COLS = slice(30, 80), slice(120, 180)


def main():
    scan = read_scan(SRC)
    grid = scan.grid[ROWS, COLS]
    keep = grid[grid >= 0]
    remap = np.full(scan.n + 1, -1, np.int64)
    remap[keep] = np.arange(len(keep))
    grid = remap[grid]
    rows, cols = grid.shape
    out = ["ply", "format ascii 1.0", "obj_info is_cyberware_data 1",
           f"obj_info num_cols {cols}", f"obj_info num_rows {rows}",
           f"comment rows {ROWS.start}-{ROWS.stop - 1}, columns {COLS.start}-{COLS.stop - 1} of bun000.ply",
           f"element vertex {len(keep)}", "property float x", "property float y", "property float z",
           f"element range_grid {rows * cols}", "property list uchar int vertex_indices", "end_header"]
    out += [f"{x:.6g} {y:.6g} {z:.6g}" for x, y, z in scan.points[keep]]
    out += ["0" if i < 0 else f"1 {i}" for i in grid.ravel()]
    (Path(__file__).parent / "bun000_crop.ply").write_text("\n".join(out) + "\n")


if __name__ == "__main__":
    main()
