"""Regenerate the small bunny copies in this folder from /work/shared/data/stanford-bunny/.

Each view keeps every 4th row and column of its Cyberware range grid and is written in the original
ASCII PLY layout (vertex + range_grid element), so the tests exercise the real reader on real data.
"""
from pathlib import Path

from rgm.fitters.io import read_conf

SRC = Path("/work/shared/data/stanford-bunny/bun.conf")
VIEWS = ("bun000.ply", "bun045.ply", "bun090.ply")
STEP = 4


def main():
    here = Path(__file__).parent
    conf_lines = [ln for ln in SRC.read_text().splitlines() if any(v in ln for v in VIEWS)]
    (here / "bun.conf").write_text("\n".join(conf_lines) + "\n")
    for scan in read_conf(SRC):
        name = Path(scan.source).name
        if name not in VIEWS:
            continue
        small = scan.decimate(STEP)
        rows, cols = small.grid.shape
        out = ["ply", "format ascii 1.0", "obj_info is_cyberware_data 1",
               f"obj_info num_cols {cols}", f"obj_info num_rows {rows}",
               f"comment every {STEP}th row and column of {name}",
               f"element vertex {small.n}", "property float x", "property float y", "property float z",
               f"element range_grid {rows * cols}", "property list uchar int vertex_indices", "end_header"]
        out += [f"{x:.6g} {y:.6g} {z:.6g}" for x, y, z in small.points]
        out += ["0" if i < 0 else f"1 {i}" for i in small.grid.ravel()]
        (here / name).write_text("\n".join(out) + "\n")


if __name__ == "__main__":
    main()
