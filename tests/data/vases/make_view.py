"""Regenerate `birdbath_view.ply` in this folder from /work/shared/data/vases/birdBath_decimated.ply.

An orthographic range view of the bird bath's mesh (a photogrammetric, fused surface, open at the
bottom), seen from the side and 20 degrees from below: the outer wall with the holes the photogrammetry
left in it (through them the ray meets the inside of the basin, far behind), and the two birds branching
up from the rim. Each pixel of a 4 mm lattice takes the nearest triangle its ray hits (an exact z-buffer
of the triangles), then Gaussian noise of 0.1 mm along the ray and 1 % outliers moved along it by
5-30 mm, from a fixed seed. Written in the Cyberware ASCII PLY layout (vertex + range_grid), units as
the mesh (mm).
"""
from pathlib import Path

import numpy as np

from rgm.fitters.io import read_scan

SRC = Path("/work/shared/data/vases/birdBath_decimated.ply")
PITCH, NOISE, OUTLIERS, SEED = 4.0, 0.1, 0.01, 0
VIEW = np.array([0.0, np.cos(np.radians(20)), np.sin(np.radians(20))])   # the rays' direction


def zbuffer(vertices, faces, pitch):
    """(rows, cols) height z of the highest triangle over each pixel centre (x, y) (the sensor looks down
    -z from above), NaN where no triangle lies; and the pixel lattice's x, y origins."""
    tri = vertices[faces]                                             # (m, 3, 3)
    x0, y0 = vertices[:, 0].min(), vertices[:, 1].min()
    lo = np.ceil((tri[..., :2].min(axis=1) - [x0, y0]) / pitch - 0.5).astype(int)
    hi = np.floor((tri[..., :2].max(axis=1) - [x0, y0]) / pitch - 0.5).astype(int)
    span = np.maximum(hi - lo + 1, 0)
    count = span[:, 0] * span[:, 1]
    t = np.repeat(np.arange(len(tri)), count)                          # candidate (triangle, pixel) pairs
    k = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    i = lo[t, 0] + k // np.maximum(span[t, 1], 1)
    j = lo[t, 1] + k % np.maximum(span[t, 1], 1)
    p = np.c_[x0 + (i + 0.5) * pitch, y0 + (j + 0.5) * pitch]
    a, b, c = tri[t, 0], tri[t, 1], tri[t, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        w1 = ((p[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (p[:, 1] - a[:, 1])) / det
        w2 = ((b[:, 0] - a[:, 0]) * (p[:, 1] - a[:, 1]) - (p[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
    hit = (det != 0) & (w1 >= 0) & (w2 >= 0) & (w1 + w2 <= 1)
    z = (a[:, 2] + w1 * (b[:, 2] - a[:, 2]) + w2 * (c[:, 2] - a[:, 2]))[hit]
    i, j = i[hit], j[hit]
    shape = (i.max() + 1, j.max() + 1)
    depth = np.full(shape, -np.inf)
    np.maximum.at(depth, (i, j), z)
    depth[~np.isfinite(depth)] = np.nan
    return depth, x0, y0


def main():
    mesh = read_scan(SRC)
    e1 = np.cross(VIEW, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    turn = np.array([e1, np.cross(-VIEW, e1), -VIEW])    # rows: the view frame, z towards the sensor
    v = mesh.points @ turn.T
    depth, x0, y0 = zbuffer(v, mesh.faces, PITCH)
    rng = np.random.default_rng(SEED)
    ii, jj = np.nonzero(np.isfinite(depth))
    z = depth[ii, jj] + rng.normal(0, NOISE, len(ii))
    bad = rng.random(len(z)) < OUTLIERS
    z[bad] += rng.choice([-1, 1], bad.sum()) * rng.uniform(5, 30, bad.sum())
    pts = np.c_[x0 + (ii + 0.5) * PITCH, y0 + (jj + 0.5) * PITCH, z] @ turn     # back to the mesh's frame
    grid = np.full(depth.shape, -1)
    grid[ii, jj] = np.arange(len(ii))
    rows, cols = grid.shape
    out = ["ply", "format ascii 1.0", f"obj_info num_cols {cols}", f"obj_info num_rows {rows}",
           f"comment side view of birdBath_decimated.ply from 20 deg below: {PITCH:g} mm pixels, "
           f"{NOISE:g} mm noise, {OUTLIERS:.0%} outliers (make_view.py)",
           f"element vertex {len(pts)}", "property float x", "property float y", "property float z",
           f"element range_grid {rows * cols}", "property list uchar int vertex_indices", "end_header"]
    out += [f"{x:.2f} {y:.2f} {z:.2f}" for x, y, z in pts]
    out += ["0" if k < 0 else f"1 {k}" for k in grid.ravel()]
    (Path(__file__).parent / "birdbath_view.ply").write_text("\n".join(out) + "\n")


if __name__ == "__main__":
    main()
