"""Scan readers and writers: range images keep their pixel grid, clouds stay clouds.

Formats
-------
- PLY, ascii and binary (own parser, numpy only). Two kinds of range image are recognised:
  the Stanford/Cyberware `range_grid` element (``obj_info num_cols/num_rows``; each cell is an empty
  list or one vertex index, row-major) and the PCL organised cloud (``obj_info num_cols/num_rows`` and
  exactly rows*cols vertices, NaN = no sample).  A `face` element is kept as triangles.
- XYZ / PTS / TXT / CSV text: one point per line, the first three columns are x y z (a PTS point-count
  line is skipped).
- OBJ, STL, OFF, GLB: through trimesh, imported lazily (only these formats load it); vertices at the
  same position (STL repeats every face's corners) become one point.
- Range grids: ``.npy`` (depth (rows, cols) or xyz (rows, cols, 3)), ``.npz`` (arrays ``depth`` or ``xyz``
  and optional ``mask``) and ``.grid`` text (one image row per line, ``nan`` = invalid pixel).  A depth
  image lives on a square pixel lattice of pitch `pitch`: point (col*pitch, row*pitch, depth), seen by an
  orthographic sensor looking along -z.
- Stanford ``.conf`` multi-view sets: ``bmesh FILE tx ty tz qi qj qk qr``.  A scan point p goes to the
  common frame as p_world = R(q)^T p + t with q = (qi, qj, qk, qr) = (x, y, z, w)
  (convention checked on the bunny, see /work/shared/data/README.md).

Every reader returns a `Scan` whose points are finite; bad input raises `ScanError` naming the file.
"""
from __future__ import annotations

import dataclasses
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rgm.errors import RgmError

__all__ = [
    "Scan", "ScanError", "read_scan", "read_ply", "read_conf", "read_views", "scan_from_depth",
    "write_ply", "write_conf", "pose_from_conf", "conf_from_pose", "quat_to_matrix", "matrix_to_quat",
]


class ScanError(RgmError):
    """A scan file that cannot be used: unreadable, empty, non-finite, degenerate or inconsistent."""


@dataclass(frozen=True, eq=False)
class Scan:
    """One view of a part, in its own (sensor) frame.

    points : (n, 3) float64, finite, in the file's units.
    grid : (rows, cols) int64 or None. Range images only: grid[r, c] is the index of the pixel's point in
        `points`, -1 where the pixel is invalid (no return, dropped outlier).
    normals : (n, 3) float64 unit vectors or None.
    faces : (m, 3) int64 triangles of a mesh input, or None.
    origin : (3,) sensor position (perspective sensors) or None.
    view_dir : (3,) unit viewing direction of an orthographic sensor (points are seen from
        -view_dir), or None.
    pose : (4, 4) rigid transform from this scan's frame to the common frame.
    source : the file it came from (for messages and reports).
    """

    points: np.ndarray
    grid: np.ndarray | None = None
    normals: np.ndarray | None = None
    faces: np.ndarray | None = None
    origin: np.ndarray | None = None
    view_dir: np.ndarray | None = None
    pose: np.ndarray = field(default_factory=lambda: np.eye(4))
    source: str = "<memory>"

    @property
    def n(self) -> int:
        return len(self.points)

    @property
    def mask(self) -> np.ndarray | None:
        """(rows, cols) bool, True where a range-image pixel holds a valid point."""
        return None if self.grid is None else self.grid >= 0

    def world_points(self) -> np.ndarray:
        """(n, 3) points mapped into the common frame by `pose`."""
        return self.points @ self.pose[:3, :3].T + self.pose[:3, 3]

    def world_normals(self) -> np.ndarray | None:
        return None if self.normals is None else self.normals @ self.pose[:3, :3].T

    def sensor_directions(self) -> np.ndarray | None:
        """(n, 3) unit vectors from each point towards the sensor, or None if the sensor is unknown."""
        if self.origin is not None:
            d = np.asarray(self.origin, float) - self.points
            return d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
        if self.view_dir is not None:
            v = -np.asarray(self.view_dir, float)
            return np.broadcast_to(v / np.linalg.norm(v), self.points.shape)
        return None

    def replace(self, **changes) -> "Scan":
        return dataclasses.replace(self, **changes)

    def select(self, keep: np.ndarray) -> "Scan":
        """The scan restricted to points where `keep` ((n,) bool) is True; grid pixels of dropped
        points become invalid and faces using them are removed."""
        keep = np.asarray(keep, bool)
        new_index = np.full(self.n + 1, -1, np.int64)  # slot n maps grid's -1 to -1
        new_index[:-1][keep] = np.arange(int(keep.sum()))
        grid = None if self.grid is None else new_index[self.grid]
        faces = None
        if self.faces is not None:
            f = new_index[self.faces]
            faces = f[(f >= 0).all(axis=1)]
        normals = None if self.normals is None else self.normals[keep]
        return self.replace(points=self.points[keep], grid=grid, normals=normals, faces=faces)

    def decimate(self, step: int) -> "Scan":
        """A range image keeping every `step`-th row and column (grid kept), or every `step`-th point of
        a cloud. Used to make small test copies of real scans."""
        if self.grid is None:
            keep = np.zeros(self.n, bool)
            keep[::step] = True
            return self.select(keep)
        sub = self.grid[::step, ::step]
        keep = np.zeros(self.n, bool)
        keep[sub[sub >= 0]] = True
        new = self.select(keep)
        remap = np.full(self.n + 1, -1, np.int64)
        remap[:-1][keep] = np.arange(new.n)
        return new.replace(grid=remap[sub])


# --------------------------------------------------------------------------------------------- poses
def quat_to_matrix(q) -> np.ndarray:
    """(3, 3) rotation matrix of the quaternion q = (x, y, z, w) (normalised first)."""
    x, y, z, w = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def matrix_to_quat(r) -> np.ndarray:
    """Unit quaternion (x, y, z, w), w >= 0, of a (3, 3) rotation matrix (Shepperd's method)."""
    r = np.asarray(r, float)
    tr = np.trace(r)
    cand = np.array([tr, r[0, 0], r[1, 1], r[2, 2]])
    k = int(np.argmax(cand))
    if k == 0:
        s = 2 * np.sqrt(1 + tr)
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, s / 4]
    elif k == 1:
        s = 2 * np.sqrt(1 + r[0, 0] - r[1, 1] - r[2, 2])
        q = [s / 4, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] - r[1, 2]) / s]
    elif k == 2:
        s = 2 * np.sqrt(1 + r[1, 1] - r[0, 0] - r[2, 2])
        q = [(r[0, 1] + r[1, 0]) / s, s / 4, (r[1, 2] + r[2, 1]) / s, (r[0, 2] - r[2, 0]) / s]
    else:
        s = 2 * np.sqrt(1 + r[2, 2] - r[0, 0] - r[1, 1])
        q = [(r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, s / 4, (r[1, 0] - r[0, 1]) / s]
    q = np.array(q)
    return q if q[3] >= 0 else -q


def pose_from_conf(t, q) -> np.ndarray:
    """(4, 4) scan-to-common-frame pose of a Stanford .conf entry: p_world = R(q)^T p + t."""
    pose = np.eye(4)
    pose[:3, :3] = quat_to_matrix(q).T
    pose[:3, 3] = t
    return pose


def conf_from_pose(pose) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of `pose_from_conf`: (t (3,), q (4,) as x, y, z, w)."""
    pose = np.asarray(pose, float)
    return pose[:3, 3].copy(), matrix_to_quat(pose[:3, :3].T)


# ------------------------------------------------------------------------------------------ checks
def _finish(scan: Scan) -> Scan:
    """Validate a freshly read scan: non-empty, finite, not all equal, grid consistent."""
    p = scan.points
    name = scan.source
    if p.ndim != 2 or p.shape[1] != 3:
        raise ScanError(f"{name}: expected (n, 3) points, got shape {p.shape}")
    if len(p) == 0:
        raise ScanError(f"{name}: the scan is empty (no valid points)")
    bad = ~np.isfinite(p).all(axis=1)
    if bad.any():
        raise ScanError(f"{name}: {int(bad.sum())} point(s) have NaN or infinite coordinates "
                        f"(first at index {int(np.argmax(bad))})")
    if len(p) > 1 and float(np.ptp(p, axis=0).max()) == 0.0:
        raise ScanError(f"{name}: all {len(p)} points are equal to {p[0].tolist()}")
    if scan.grid is not None:
        g = scan.grid
        if g.ndim != 2 or g.min() < -1 or g.max() >= len(p):
            raise ScanError(f"{name}: range grid does not index the {len(p)} points")
    if scan.faces is not None and len(scan.faces) and (scan.faces.min() < 0 or scan.faces.max() >= len(p)):
        raise ScanError(f"{name}: a face refers to a vertex that does not exist")
    return scan


# --------------------------------------------------------------------------------------------- PLY
_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


def _ply_header(fh, name):
    """Parse a PLY header: (format, elements [(name, count, [(prop, dtype, count_dtype|None)])], info)."""
    if fh.readline().strip() != b"ply":
        raise ScanError(f"{name}: not a PLY file (first line is not `ply`)")
    fmt, elements, info = None, [], {}
    while True:
        raw = fh.readline()
        if not raw:
            raise ScanError(f"{name}: PLY header has no `end_header`")
        words = raw.decode("latin-1").split()
        if not words or words[0] == "comment":
            continue
        try:
            if words[0] == "format":
                fmt = words[1]
            elif words[0] == "obj_info":
                if len(words) >= 3:
                    info[words[1]] = words[2]
            elif words[0] == "element":
                elements.append((words[1], int(words[2]), []))
            elif words[0] == "property":
                if words[1] == "list":
                    elements[-1][2].append((words[4], _PLY_TYPES[words[3]], _PLY_TYPES[words[2]]))
                else:
                    elements[-1][2].append((words[2], _PLY_TYPES[words[1]], None))
            elif words[0] == "end_header":
                break
        except (IndexError, KeyError, ValueError):
            raise ScanError(f"{name}: unreadable PLY header line `{raw.decode('latin-1').strip()}`") from None
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise ScanError(f"{name}: unknown PLY format `{fmt}`")
    return fmt, elements, info


def _ragged_ascii(rows: list[str], el_name, name):
    """Rows `k v1 .. vk` of an ascii list property -> (counts (n,), values (sum k,)), vectorised."""
    text = "\n".join(rows)
    b = np.frombuffer(text.encode("latin-1"), np.uint8)
    space = (b == 32) | (b == 9) | (b == 10) | (b == 13)
    start = ~space & np.r_[True, space[:-1]]                     # first byte of every token
    line = np.cumsum(b == 10)
    per_line = np.bincount(line[start], minlength=len(rows))
    try:
        flat = np.array(text.split(), dtype=np.int64)
    except ValueError:
        raise ScanError(f"{name}: element `{el_name}` has non-integer list entries") from None
    starts = np.r_[0, np.cumsum(per_line)[:-1]]
    counts = flat[np.minimum(starts, len(flat) - 1)] if len(flat) else np.zeros(len(rows), np.int64)
    if len(per_line) != len(rows) or not np.array_equal(per_line, counts + 1):
        raise ScanError(f"{name}: element `{el_name}`: a list's length does not match its count")
    keep = np.ones(len(flat), bool)
    keep[starts] = False
    return counts, flat[keep]


def _ply_ascii(body: bytes, elements, name):
    lines = body.decode("latin-1").splitlines()
    pos, out = 0, {}
    for el_name, count, props in elements:
        chunk = lines[pos:pos + count]
        if len(chunk) < count:
            raise ScanError(f"{name}: file ends inside element `{el_name}` ({len(chunk)} of {count} rows)")
        pos += count
        if all(p[2] is None for p in props):
            try:
                arr = np.array(" ".join(chunk).split(), dtype=float).reshape(count, len(props))
            except ValueError:
                raise ScanError(f"{name}: element `{el_name}` rows do not have {len(props)} numbers") from None
            out[el_name] = {p[0]: arr[:, i] for i, p in enumerate(props)}
        elif len(props) == 1:
            out[el_name] = {props[0][0]: _ragged_ascii(chunk, el_name, name)}
        else:
            raise ScanError(f"{name}: element `{el_name}` mixes list and scalar properties (unsupported)")
    return out


def _ply_binary(body: bytes, elements, endian, name):
    pos, out = 0, {}
    for el_name, count, props in elements:
        if all(p[2] is None for p in props):
            dt = np.dtype([(p[0], endian + p[1]) for p in props])
            if pos + dt.itemsize * count > len(body):
                raise ScanError(f"{name}: file ends inside element `{el_name}`")
            arr = np.frombuffer(body, dt, count, pos)
            pos += dt.itemsize * count
            out[el_name] = {p[0]: arr[p[0]].astype(float) for p in props}
            continue
        if len(props) != 1:
            raise ScanError(f"{name}: element `{el_name}` mixes list and scalar properties (unsupported)")
        prop, item_t, count_t = props[0]
        ct, it = np.dtype(endian + count_t), np.dtype(endian + item_t)
        first = int(np.frombuffer(body, ct, 1, pos)[0]) if count else 0
        dt = np.dtype([("n", ct), ("v", it, (first,))])
        fixed = np.frombuffer(body, dt, count, pos) if pos + dt.itemsize * count <= len(body) else None
        if fixed is not None and (fixed["n"] == first).all():  # all lists the same length (triangles)
            out[el_name] = {prop: (np.full(count, first, np.int64), fixed["v"].astype(np.int64).ravel())}
            pos += dt.itemsize * count
            continue
        counts, values, pos = _ragged_binary(body, pos, count, ct, it, el_name, name)
        out[el_name] = {prop: (counts, values)}
    return out


def _ragged_binary(body: bytes, pos: int, count: int, ct: np.dtype, it: np.dtype, el_name, name):
    """`count` binary lists `k v1 .. vk` (count type ct, item type it) from body[pos:], vectorised:
    every byte offset gets the offset of the record that would follow a record starting there, and
    pointer doubling (Wyllie 1979) walks the chain from pos in log2(count) passes.
    Returns (counts (count,), values (sum k,) int64, the offset after the last list)."""
    buf = np.frombuffer(body, np.uint8, offset=pos)
    cs, size = ct.itemsize, it.itemsize
    L = len(buf)
    if count == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), pos
    if L < cs:
        raise ScanError(f"{name}: file ends inside element `{el_name}`")
    k_at = np.lib.stride_tricks.sliding_window_view(buf, cs).copy().view(ct)[:, 0].astype(np.int64)
    jump = np.full(L + 1, L, np.int64)                          # offset L: past the end (absorbing)
    jump[:len(k_at)] = np.minimum(np.arange(len(k_at)) + cs + size * np.maximum(k_at, 0), L)
    starts, m = np.zeros(1, np.int64), 1
    while m < count:                                            # starts of records 0 .. 2m-1
        starts = np.concatenate([starts, jump[starts]])
        jump, m = jump[jump], 2 * m
    starts = starts[:count]
    if starts[-1] > L - cs or (k_at[starts] < 0).any():
        raise ScanError(f"{name}: file ends inside element `{el_name}`")
    counts = k_at[starts]
    end = int(starts[-1] + cs + size * counts[-1])
    if end > L:
        raise ScanError(f"{name}: file ends inside element `{el_name}`")
    first = np.repeat(starts + cs, counts)
    offsets = first + size * (np.arange(len(first)) - np.repeat(np.cumsum(counts) - counts, counts))
    values = buf[offsets[:, None] + np.arange(size)].copy().view(it)[:, 0].astype(np.int64)
    return counts, values, pos + end


def read_ply(path) -> Scan:
    """Read a PLY file (ascii or binary) into a `Scan`; range grids become `Scan.grid`."""
    path = Path(path)
    name = str(path)
    try:
        with open(path, "rb") as fh:
            fmt, elements, info = _ply_header(fh, name)
            body = fh.read()
    except OSError as exc:
        raise ScanError(f"{name}: cannot read ({exc.strerror})") from None
    if fmt == "ascii":
        data = _ply_ascii(body, elements, name)
    else:
        data = _ply_binary(body, elements, "<" if fmt == "binary_little_endian" else ">", name)
    vert = data.get("vertex")
    if vert is None or not {"x", "y", "z"} <= set(vert):
        raise ScanError(f"{name}: PLY has no vertex element with x, y, z")
    points = np.column_stack([vert["x"], vert["y"], vert["z"]]).astype(np.float64)
    normals = None
    if {"nx", "ny", "nz"} <= set(vert):
        normals = np.column_stack([vert["nx"], vert["ny"], vert["nz"]]).astype(np.float64)
    faces = None
    face = data.get("face")
    if face:
        counts, values = next(iter(face.values()))
        first = np.r_[0, np.cumsum(counts)[:-1]]
        tri = first[counts == 3]
        faces = values[tri[:, None] + np.arange(3)].reshape(-1, 3)  # polygons other than triangles: skipped
    grid = None
    rows, cols = int(info.get("num_rows", 0)), int(info.get("num_cols", 0))
    view_dir = origin = None
    if "range_grid" in data:
        counts, values = next(iter(data["range_grid"].values()))
        if len(counts) != rows * cols:
            raise ScanError(f"{name}: grid size mismatch: range_grid has {len(counts)} cells, "
                            f"num_rows x num_cols = {rows} x {cols}")
        first = np.r_[0, np.cumsum(counts)[:-1]]
        flat = np.where(counts > 0, values[np.minimum(first, max(len(values) - 1, 0))] if len(values) else -1, -1)
        grid = flat.reshape(rows, cols).astype(np.int64)
        view_dir = np.array([0.0, 0.0, -1.0])  # Cyberware: scanner on +z (checked on the bunny)
    elif rows and cols:
        if rows * cols != len(points):
            raise ScanError(f"{name}: grid size mismatch: {len(points)} vertices, "
                            f"num_rows x num_cols = {rows} x {cols}")
        valid = np.isfinite(points).all(axis=1)
        grid = np.where(valid, np.cumsum(valid) - 1, -1).reshape(rows, cols)
        points = points[valid]
        normals = None if normals is None else normals[valid]
        origin = np.zeros(3)  # organised (stereo/ToF) clouds are in the camera frame
    return _finish(Scan(points, grid=grid, normals=normals, faces=faces, origin=origin,
                        view_dir=view_dir, source=name))


# ----------------------------------------------------------------------------------- other formats
def _read_text_points(path: Path) -> Scan:
    name = str(path)
    try:
        text = path.read_text(encoding="latin-1")
    except OSError as exc:
        raise ScanError(f"{name}: cannot read ({exc.strerror})") from None
    lines = [ln for ln in re.split(r"[\r\n]+", text) if ln.strip() and not ln.lstrip().startswith("#")]
    if lines and len(lines[0].replace(",", " ").split()) == 1:  # PTS: point-count line
        lines = lines[1:]
    if not lines:
        raise ScanError(f"{name}: the scan is empty (no points)")
    rows = [ln.replace(",", " ").split() for ln in lines]
    widths = {len(r) for r in rows}
    if min(widths) < 3:
        raise ScanError(f"{name}: a line has fewer than 3 coordinates")
    try:
        points = np.array([r[:3] for r in rows], dtype=float)
    except ValueError:
        raise ScanError(f"{name}: non-numeric coordinates") from None
    return _finish(Scan(points, source=name))


def _read_mesh(path: Path) -> Scan:
    import trimesh  # heavy: only for mesh formats

    name = str(path)
    try:
        mesh = trimesh.load(str(path), force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for bad files
        raise ScanError(f"{name}: cannot read mesh ({exc})") from None
    vertices, faces = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    if not len(vertices):
        return _finish(Scan(vertices.reshape(0, 3), source=name))
    # STL stores every face's corners (and OBJ seams repeat them): one point per position, faces remapped,
    # in the order of first appearance
    _, first, inverse = np.unique(vertices, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return _finish(Scan(vertices[first[order]], faces=rank[inverse.ravel()][faces], source=name))


def scan_from_depth(depth, mask=None, pitch: float = 1.0, source: str = "<memory>") -> Scan:
    """A range image from a depth array.

    depth : (rows, cols) heights z (NaN/inf = invalid) on a lattice of `pitch` (x = col*pitch,
        y = row*pitch), or (rows, cols, 3) xyz per pixel. The sensor looks along -z.
    mask : (rows, cols) bool, True = valid pixel, or None.
    """
    depth = np.asarray(depth, float)
    if depth.ndim == 2:
        rows, cols = depth.shape
        r, c = np.mgrid[0:rows, 0:cols]
        xyz = np.stack([c * pitch, r * pitch, depth], axis=-1).astype(float)
    elif depth.ndim == 3 and depth.shape[2] == 3:
        rows, cols = depth.shape[:2]
        xyz = depth
    else:
        raise ScanError(f"{source}: a range grid must be (rows, cols) or (rows, cols, 3), got {depth.shape}")
    valid = np.isfinite(xyz).all(axis=-1)
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape != (rows, cols):
            raise ScanError(f"{source}: grid size mismatch: mask {mask.shape} vs image {(rows, cols)}")
        valid &= mask.astype(bool)
    grid = np.where(valid, np.cumsum(valid.ravel()).reshape(rows, cols) - 1, -1)
    return _finish(Scan(xyz[valid].reshape(-1, 3), grid=grid, view_dir=np.array([0.0, 0.0, -1.0]),
                        source=source))


def _read_grid_file(path: Path, mask, pitch) -> Scan:
    name = str(path)
    try:
        if path.suffix.lower() == ".npy":
            depth = np.load(path, allow_pickle=False)
        elif path.suffix.lower() == ".npz":
            with np.load(path, allow_pickle=False) as z:
                key = "depth" if "depth" in z else "xyz" if "xyz" in z else None
                if key is None:
                    raise ScanError(f"{name}: .npz needs an array `depth` or `xyz`")
                depth = z[key]
                if mask is None and "mask" in z:
                    mask = z["mask"]
        else:
            rows = [ln.split() for ln in path.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
            if len({len(r) for r in rows}) > 1:
                raise ScanError(f"{name}: grid size mismatch: rows of different lengths")
            depth = np.array(rows, dtype=float)
    except (OSError, ValueError) as exc:
        raise ScanError(f"{name}: cannot read range grid ({exc})") from None
    if isinstance(mask, (str, os.PathLike)):
        try:
            mask = np.load(mask, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise ScanError(f"{mask}: cannot read mask ({exc})") from None
    return scan_from_depth(depth, mask=mask, pitch=pitch, source=name)


_MESH_SUFFIXES = {".obj", ".stl", ".off", ".glb", ".gltf"}
_TEXT_SUFFIXES = {".xyz", ".pts", ".txt", ".csv", ".asc"}
_GRID_SUFFIXES = {".npy", ".npz", ".grid"}


def read_scan(path, *, mask=None, pitch: float = 1.0) -> Scan:
    """Read any supported scan file (see the module docstring) into a validated `Scan`.

    `mask` (array or .npy path) and `pitch` apply to range-grid files only.
    """
    path = Path(path)
    if not path.exists():
        raise ScanError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix == ".ply":
        return read_ply(path)
    if suffix in _TEXT_SUFFIXES:
        return _read_text_points(path)
    if suffix in _GRID_SUFFIXES:
        return _read_grid_file(path, mask, pitch)
    if suffix in _MESH_SUFFIXES:
        return _read_mesh(path)
    raise ScanError(f"{path}: unknown scan format `{suffix}` (ply, xyz, pts, txt, csv, obj, stl, off, npy, npz, grid)")


def read_conf(path) -> list[Scan]:
    """Read a Stanford .conf multi-view set: every `bmesh`/`mesh` view with its pose."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise ScanError(f"{path}: cannot read ({exc.strerror})") from None
    scans = []
    for lineno, line in enumerate(lines, 1):
        words = line.split()
        if not words or words[0] not in ("bmesh", "mesh"):
            continue
        try:
            t, q = np.array(words[2:5], float), np.array(words[5:9], float)
            if len(q) != 4 or not np.isfinite(q).all() or np.linalg.norm(q) == 0:
                raise ValueError
        except ValueError:
            raise ScanError(f"{path}:{lineno}: expected `bmesh FILE tx ty tz qi qj qk qr`") from None
        scan = read_scan(path.parent / words[1])
        scans.append(scan.replace(pose=pose_from_conf(t, q)))
    if not scans:
        raise ScanError(f"{path}: no `bmesh` lines")
    return scans


def read_views(paths, poses=None) -> list[Scan]:
    """Views for registration: a list of scan files, or a single .conf. With `poses` (a .conf path) each
    view whose file name appears there gets that pose as its initial pose; others keep identity."""
    paths = [Path(p) for p in paths]
    if len(paths) == 1 and paths[0].suffix.lower() == ".conf":
        return read_conf(paths[0])
    scans = [read_scan(p) for p in paths]
    if poses is None:
        return scans
    by_name = {Path(s.source).name: s.pose for s in read_conf_poses(poses)}
    return [s.replace(pose=by_name.get(Path(s.source).name, np.eye(4))) for s in scans]


def read_conf_poses(path) -> list[Scan]:
    """The poses of a .conf without reading its scans: Scans with one dummy point, pose and source."""
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise ScanError(f"{path}: cannot read ({exc.strerror})") from None
    out = []
    for line in lines:
        w = line.split()
        if len(w) >= 9 and w[0] in ("bmesh", "mesh"):
            try:
                pose = pose_from_conf(np.array(w[2:5], float), np.array(w[5:9], float))
            except ValueError:
                raise ScanError(f"{path}: bad pose line `{line.strip()}`") from None
            out.append(Scan(np.zeros((1, 3)), pose=pose, source=str(path.parent / w[1])))
    return out


# ----------------------------------------------------------------------------------------- writers
def write_ply(path, points, faces=None, normals=None, *, overwrite: bool = True) -> Path:
    """Write points (n, 3), optional triangles (m, 3) and normals (n, 3) as binary little-endian PLY,
    atomically."""
    from rgm.atomic import write_atomic

    points = np.asarray(points, float)
    props = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    if normals is not None:
        props += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")]
    vert = np.empty(len(points), np.dtype(props))
    vert["x"], vert["y"], vert["z"] = points.T
    if normals is not None:
        vert["nx"], vert["ny"], vert["nz"] = np.asarray(normals, float).T
    header = ["ply", "format binary_little_endian 1.0", "comment written by rgm",
              f"element vertex {len(points)}"] + [f"property float {p}" for p, _ in props]
    body = [vert.tobytes()]
    if faces is not None:
        faces = np.asarray(faces, np.int64)
        header += [f"element face {len(faces)}", "property list uchar int vertex_indices"]
        rec = np.empty(len(faces), np.dtype([("n", "u1"), ("v", "<i4", (3,))]))
        rec["n"], rec["v"] = 3, faces
        body.append(rec.tobytes())
    header.append("end_header\n")
    return write_atomic(path, "\n".join(header).encode() + b"".join(body), overwrite=overwrite)


def write_conf(path, scans, poses) -> Path:
    """Write a Stanford .conf: one `bmesh FILE tx ty tz qi qj qk qr` line per (scan, pose (4, 4))."""
    from rgm.atomic import write_atomic

    lines = []
    for scan, pose in zip(scans, poses):
        t, q = conf_from_pose(pose)
        lines.append("bmesh " + Path(scan.source).name + " " + " ".join(f"{v:.9g}" for v in (*t, *q)))
    return write_atomic(path, "\n".join(lines) + "\n")
