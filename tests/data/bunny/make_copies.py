"""Regenerate the small bunny copies in this folder from /work/shared/data/stanford-bunny/.

Each view keeps every 4th row and column of its Cyberware range grid and is written in the original
PLY layout (vertex + range_grid element), so the tests exercise the real reader on real data:
bun000, bun045 and bun090 as ASCII like the originals, the other seven as binary little-endian PLY
(half the size, and the binary path of the range_grid reader).  bun.conf keeps the original's lines.
"""
from pathlib import Path

from rgm.fitters.io import read_conf

SRC = Path("/work/shared/data/stanford-bunny/bun.conf")
ASCII = ("bun000.ply", "bun045.ply", "bun090.ply")
STEP = 4


def _header(fmt, name, rows, cols, n):
    return ["ply", f"format {fmt} 1.0", "obj_info is_cyberware_data 1",
            f"obj_info num_cols {cols}", f"obj_info num_rows {rows}",
            f"comment every {STEP}th row and column of {name}",
            f"element vertex {n}", "property float x", "property float y", "property float z",
            f"element range_grid {rows * cols}", "property list uchar int vertex_indices", "end_header"]


def main():
    here = Path(__file__).parent
    conf_lines = [ln for ln in SRC.read_text().splitlines() if ln.startswith("bmesh")]
    (here / "bun.conf").write_text("\n".join(conf_lines) + "\n")
    for scan in read_conf(SRC):
        name = Path(scan.source).name
        small = scan.decimate(STEP)
        rows, cols = small.grid.shape
        if name in ASCII:
            out = _header("ascii", name, rows, cols, small.n)
            out += [f"{x:.6g} {y:.6g} {z:.6g}" for x, y, z in small.points]
            out += ["0" if i < 0 else f"1 {i}" for i in small.grid.ravel()]
            (here / name).write_text("\n".join(out) + "\n")
            continue
        head = ("\n".join(_header("binary_little_endian", name, rows, cols, small.n)) + "\n").encode()
        cells = b"".join(b"\x00" if i < 0 else b"\x01" + int(i).to_bytes(4, "little", signed=True)
                         for i in small.grid.ravel())
        (here / name).write_bytes(head + small.points.astype("<f4").tobytes() + cells)


if __name__ == "__main__":
    main()
