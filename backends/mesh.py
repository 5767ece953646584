"""Tessellation of model surfaces, trimmed faces and shells to a certified chordal deviation.

`tessellate(obj, tol, angle_tol)` returns (vertices (n, 3), triangles (m, 3)) such that every triangle
lies within `tol` (model units) of its exact surface, checked by *measurement*: at 7 barycentric
samples of every triangle (edge midpoints, centroid, three inner points) the sample's closest point on
the surface is found (Gauss-Newton from the interpolated (u, v)) and the triangle is split until all
distances are <= tol and, with `angle_tol` (radians), the triangle normal is within `angle_tol` of the
surface normals at its corners.

Pipeline:
1. Faces: each surface/face becomes a parameter-space patch (`rgm.backends.mesh_surface`) with its
   boundary loops as pieces uv(s), s in [0, 1]: the domain rectangle of an untrimmed surface, the
   trimming curves of a trimmed face (2-D curves as given, 3-D curves by projection, lazy intersections
   approximated at a tenth of the mesh tolerance).
2. Edges: pieces whose 3-D images coincide (shared edges of a shell, the seam of a closed surface) are
   grouped; each group is sampled once (adaptive chord subdivision to `tol`) and its vertices are used by
   every face, so closed solids come out watertight. Degenerate pieces (poles) are one vertex.
3. Faces are meshed in a scaled (u, v) plane: an initial tensor grid whose spacing comes from measured
   sagittas per knot span, Delaunay triangulation (scipy), triangles outside the trimming loops removed
   (even-odd test), boundary segments kept as edges by removing interior points inside their diametral
   circles (Gabriel condition) and, where still missing, splitting the shared edge (Ruppert-style),
   then measured refinement as above.
4. Per-face orientation is made consistent across shared edges; closed components face outwards.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rgm.errors import BackendError

from .mesh_surface import Patch, surface_patch

def _lattice(steps: int):
    """Barycentric lattice points (k, 3) of a triangle with `steps` per edge, corners left out, and the
    edge each lies on (0: corners 0-1, 1: 1-2, 2: 2-0; -1 inside)."""
    i, j = np.meshgrid(np.arange(steps + 1), np.arange(steps + 1), indexing="ij")
    keep = (i + j <= steps)
    b = np.column_stack([steps - i[keep] - j[keep], i[keep], j[keep]]) / steps
    b = b[(b == 1.0).sum(axis=1) == 0]
    edge = np.select([b[:, 2] == 0, b[:, 0] == 0, b[:, 1] == 0], [0, 1, 2], -1)
    return b, edge


#: samples per triangle: the 6-step barycentric lattice without the corners (15 on the edges, 10 inside)
_BARY, _EDGE_OF_SAMPLE = _lattice(6)
#: the samples must be within CERTIFY * tol: the margin covers the maximum falling between samples
CERTIFY = 0.98
_EDGES = ((0, 1), (1, 2), (2, 0))


@dataclass
class Piece:
    """One boundary piece of a face: uv(s) for s in [0, 1] on `patch`, with derivative breaks."""

    patch: Patch
    uv: object
    breaks: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0]))

    def xyz(self, s) -> np.ndarray:
        uv = self.uv(np.clip(np.asarray(s, float), 0.0, 1.0))
        return self.patch.evaluate(uv[:, 0], uv[:, 1])


@dataclass
class Face:
    patch: Patch
    loops: list            # list[list[Piece]]
    trimmed: bool
    samples: list = field(default_factory=list)   # per loop: list of (uv (k, 2), ids (k,), group, rep idx)
    tri: np.ndarray | None = None                  # (t, 3) global vertex ids
    tri_uv: np.ndarray | None = None               # (t, 3, 2) parameters of the triangle corners


@dataclass
class Mesh:
    """Result of `tessellate_faces`: vertices (n, 3), triangles (m, 3) and the faces they came from."""

    vertices: np.ndarray
    triangles: np.ndarray
    faces: list


# --- faces and their boundary pieces -------------------------------------------------------------

def _curve_piece(patch, nurbs, a=None, b=None):
    """Piece following a 2-D NurbsCurve from parameter a to b (default: its whole domain)."""
    t0, t1 = nurbs.domain
    a = t0 if a is None else a
    b = t1 if b is None else b
    knots = np.unique(nurbs.knots)
    inner = (knots - a) / (b - a)
    breaks = np.unique(np.concatenate([[0.0, 1.0], inner[(inner > 0) & (inner < 1)]]))
    return Piece(patch, lambda s: nurbs.evaluate(np.clip(a + s * (b - a), t0, t1)), breaks)


def _line_piece(patch, p, q):
    p, q = np.asarray(p, float), np.asarray(q, float)
    return Piece(patch, lambda s: p + np.asarray(s)[:, None] * (q - p))


def _intersection_pieces(patch, inter, surface, prev_end, next_start, tol):
    """The part of a lazy intersection's uv branch running from `prev_end` to `next_start` (uv, or None
    when the loop is this one closed branch)."""
    branches = inter.uv_curves(surface, tol)
    if prev_end is None:
        closed = [c for c in branches if np.linalg.norm(c.evaluate(np.array(c.domain))[0]
                                                        - c.evaluate(np.array(c.domain))[1]) < 1e-6]
        if len(closed) != 1:
            raise BackendError(f"the intersection gives {len(closed)} closed branches; a loop needs exactly one")
        return _curve_piece(patch, closed[0])
    best = None
    for c in branches:
        t = np.linspace(*c.domain, 513)
        pts = c.evaluate(t)
        ia = int(np.argmin(np.linalg.norm(pts - prev_end, axis=1)))
        ib = int(np.argmin(np.linalg.norm(pts - next_start, axis=1)))
        err = np.linalg.norm(pts[ia] - prev_end) + np.linalg.norm(pts[ib] - next_start)
        if best is None or err < best[0]:
            best = (err, c, t[ia], t[ib])
    _, c, a, b = best
    return _curve_piece(patch, c, a, b)


def _loop_pieces(loop, surface, patch, tol) -> list:
    """Pieces of a trimming loop in the patch's (u, v)."""
    from rgm.model import IntersectionCurve, Plane

    out = []
    for piece in loop.pieces:
        if isinstance(piece, IntersectionCurve):
            out.append(piece)
        elif piece.dim == 2:
            out.append(_curve_piece(patch, piece.nurbs()))
        else:
            c = piece.nurbs()
            t0, t1 = c.domain
            if isinstance(surface, Plane):
                out.append(Piece(patch, lambda s, c=c: surface.coordinates(c.evaluate(t0 + s * (t1 - t0)))))
            else:
                out.append(Piece(patch, lambda s, c=c: patch.closest(c.evaluate(t0 + s * (t1 - t0)))[0]))
    for k, p in enumerate(out):
        if not isinstance(p, Piece):
            closed = len(out) == 1
            prev_end = None if closed else out[k - 1].uv(np.array([1.0]))[0]
            next_start = None if closed else out[(k + 1) % len(out)].uv(np.array([0.0]))[0]
            out[k] = _intersection_pieces(patch, p, surface, prev_end, next_start, tol)
    return out


def _rectangle(patch) -> list:
    """The four sides of the domain, counter-clockwise in (u, v), with the knots as breaks."""
    (u0, u1), (v0, v1) = patch.domain
    c = [(u0, v0), (u1, v0), (u1, v1), (u0, v1)]
    su = (patch.breaks_u - u0) / (u1 - u0)
    sv = (patch.breaks_v - v0) / (v1 - v0)
    breaks = (su, sv, 1 - su, 1 - sv)
    return [[_with_breaks(_line_piece(patch, c[k], c[(k + 1) % 4]), breaks[k]) for k in range(4)]]


def _with_breaks(piece, s):
    piece.breaks = np.unique(np.concatenate([[0.0, 1.0], np.clip(s, 0, 1)]))
    return piece


def collect_faces(objs, tol) -> list:
    """Face records for model objects (surfaces, trimmed faces, shells); curves are skipped."""
    from rgm.model import Curve, Plane, Shell, Surface, TrimmedFace

    faces = []
    for obj in objs:
        if isinstance(obj, Shell):
            faces += collect_faces(obj.faces, tol)
        elif isinstance(obj, TrimmedFace):
            faces.append(_trimmed_face(obj, tol))
        elif isinstance(obj, Plane):
            raise BackendError(f"`{obj.name or 'plane'}` is an infinite plane; trim it with a loop to mesh it")
        elif isinstance(obj, Surface):
            faces += [Face(p, _rectangle(p), False) for p in surface_patch(obj, trimmed=False).pieces()]
        elif not isinstance(obj, Curve):
            raise BackendError(f"{type(obj).__name__} cannot be tessellated")
    return faces


def _trimmed_face(face, tol):
    from rgm.model import Plane

    surface = face.surface
    if face.outer is None:
        if isinstance(surface, Plane):
            raise BackendError("an infinite plane needs an outer loop to be meshed")
        patch = surface_patch(surface, trimmed=False)
        return Face(patch, _rectangle(patch) + [], True)
    box = None
    if isinstance(surface, Plane):  # the patch box: the loops' plane coordinates
        probe = PlanePatchBox(surface)
        uv = np.concatenate([p.uv(np.linspace(0, 1, 65)) for loop in face.loops()
                             for p in _loop_pieces(loop, surface, probe, tol)])
        lo, hi = uv.min(0), uv.max(0)
        pad = 1e-9 * float(np.max(hi - lo)) + 1e-12
        box = ((lo[0] - pad, hi[0] + pad), (lo[1] - pad, hi[1] + pad))
    patch = surface_patch(surface, trimmed=True, plane_box=box)
    return Face(patch, [_loop_pieces(loop, surface, patch, tol) for loop in face.loops()], True)


class PlanePatchBox(Patch):
    """A stand-in patch for a plane whose box is not yet known (only loop coordinates are asked)."""

    def __init__(self, plane):
        from .mesh_surface import PlanePatch

        self.inner = PlanePatch(plane, ((-np.inf, np.inf), (-np.inf, np.inf)))
        self.domain = self.inner.domain

    def d1(self, u, v):
        return self.inner.d1(u, v)


# --- edges: grouping and sampling ---------------------------------------------------------------

def _sample_piece(piece, tol, s=None):
    """Parameters s (k,) in [0, 1] such that every chord of the piece's 3-D image is within `tol` of it
    (point-to-segment distance at 3 inner points per chord). Each knot span starts with equal steps
    sized from its largest sagitta over 16 probe steps (the sagitta scales as the square of the step);
    a chord still failing by d is cut into ceil(sqrt(d / tol)) equal parts."""
    if s is None:  # per span: equal steps from the largest sagitta over 16 probe steps
        b = piece.breaks
        t = b[:-1, None] + np.diff(b)[:, None] * np.linspace(0, 1, 33)[None, :]
        pts = piece.xyz(t.ravel()).reshape(len(b) - 1, 33, 3)
        d = _segment_distance(pts[:, 1::2], pts[:, 0:-1:2], pts[:, 2::2]).max(axis=1)
        n = np.maximum(1, np.ceil(16 * np.sqrt(d / (CERTIFY * tol)))).astype(int)
        s = np.unique(np.concatenate([np.linspace(a, c, k + 1) for a, c, k in zip(b[:-1], b[1:], n)]))
    for _ in range(40):
        p = piece.xyz(s)
        a, h = s[:-1], np.diff(s)
        fr = np.array([0.25, 0.5, 0.75])
        q = piece.xyz((a[:, None] + h[:, None] * fr).ravel()).reshape(len(a), 3, 3)
        dev = _segment_distance(q, p[:-1, None], p[1:, None]).max(axis=1)
        bad = dev > CERTIFY * tol
        if not bad.any():
            return s
        k = np.clip(np.ceil(np.sqrt(dev[bad] / (CERTIFY * tol))), 2, 64).astype(int)
        new = [a0 + h0 * np.arange(1, ki) / ki for a0, h0, ki in zip(a[bad], h[bad], k)]
        s = np.unique(np.concatenate([s] + new))
    raise BackendError("a boundary curve could not be sampled to the tolerance")


def _segment_distance(q, a, b):
    """Distances of points q (..., 3) to segments [a, b] (broadcast)."""
    ab = b - a
    t = np.clip(((q - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-300), 0, 1)
    return np.linalg.norm(q - (a + t[..., None] * ab), axis=-1)


def _invert(piece, pts, iterations=8):
    """Parameters s (k,) of the points of piece closest to pts (k, 3): nearest of 513 samples, then Newton
    on (C(s) - X) . C'(s) = 0 with central differences (one batched evaluation per step)."""
    grid = np.linspace(0, 1, 513)
    dense = piece.xyz(grid)
    s = grid[np.argmin(((pts[:, None, :] - dense[None]) ** 2).sum(-1), axis=1)]
    h, k = 1e-6, len(pts)
    for _ in range(iterations):
        c, cp, cm = np.split(piece.xyz(np.concatenate([s, s + h, s - h])), 3)
        d, dd = (cp - cm) / (2 * h), (cp - 2 * c + cm) / (h * h)
        r = c - pts
        g = (r * d).sum(1)
        hess = (d * d).sum(1) + (r * dd).sum(1)
        step = np.where(hess > 1e-300, g / np.where(hess > 1e-300, hess, 1.0), 0.0)
        s = np.clip(s - step, 0, 1)
    return s, np.linalg.norm(piece.xyz(s) - pts, axis=1)[:k]


class _Edges:
    """Groups of coincident pieces, sampled once; global vertices."""

    def __init__(self, faces, tol, eps):
        from scipy.sparse.csgraph import connected_components
        from scipy.sparse import coo_matrix
        from scipy.spatial import cKDTree

        self.tol, self.eps = tol, eps
        self.pieces = [p for f in faces for loop in f.loops for p in loop]
        ends = np.concatenate([p.xyz(np.array([0.0, 1.0])) for p in self.pieces])
        pairs = cKDTree(ends).query_pairs(eps, output_type="ndarray")
        n = len(ends)
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n)) if len(pairs) \
            else coo_matrix((n, n))
        _, label = connected_components(graph, directed=False)
        _, corner = np.unique(label, return_inverse=True)
        self.corner = corner.reshape(-1, 2)                          # (pieces, 2) corner ids
        self.vertices = [ends[np.unique(corner, return_index=True)[1]]]
        self.nvert = len(self.vertices[0])
        lengths = np.array([np.linalg.norm(np.diff(p.xyz(np.linspace(0, 1, 17)), axis=0), axis=1).sum()
                            for p in self.pieces])
        self.degenerate = lengths < eps
        self.group = -np.ones(len(self.pieces), int)
        self.same_dir = np.ones(len(self.pieces), bool)
        reps = []
        for i, p in enumerate(self.pieces):
            if self.degenerate[i] or self.group[i] >= 0:
                continue
            self.group[i] = len(reps)
            reps.append(i)
            key = set(self.corner[i])
            mid = None
            for j in range(i + 1, len(self.pieces)):
                if self.group[j] >= 0 or self.degenerate[j] or set(self.corner[j]) != key:
                    continue
                if mid is None:
                    mid = p.xyz(np.array([0.25, 0.5, 0.75]))
                q = self.pieces[j].xyz(np.array([0.25, 0.5, 0.75]))
                sq, dq = _invert(p, q)
                if dq.max() < eps:
                    self.group[j] = self.group[i]
                    self.same_dir[j] = sq[2] > sq[0]
        self.reps = reps
        self.version = np.zeros(len(reps), int)
        self.rep_s = [_sample_piece(self.pieces[r], tol) for r in reps]
        self.rep_ids = [None] * len(reps)
        self.member_s = {}
        self._assign_ids()

    def _assign_ids(self):
        for g, r in enumerate(self.reps):
            if self.rep_ids[g] is not None and len(self.rep_ids[g]) == len(self.rep_s[g]):
                continue
            s = self.rep_s[g]
            inner = self.pieces[r].xyz(s[1:-1])
            ids = np.concatenate([[self.corner[r, 0]], self.nvert + np.arange(len(inner)), [self.corner[r, 1]]])
            self.vertices.append(inner)
            self.nvert += len(inner)
            self.rep_ids[g] = ids
            for j in np.flatnonzero(self.group == g):
                if j == r:
                    self.member_s[j] = s
                    continue
                pts = self.pieces[r].xyz(s)
                sj, _ = _invert(self.pieces[j], pts)
                sj[[0, -1]] = (0.0, 1.0) if self.same_dir[j] else (1.0, 0.0)
                self.member_s[j] = sj

    def split(self, requests) -> None:
        """Insert the midpoint of rep segments {(group, index)}."""
        for g in {g for g, _ in requests}:
            idx = np.array(sorted({k for gg, k in requests if gg == g}))
            s = self.rep_s[g]
            self.rep_s[g] = np.unique(np.concatenate([s, 0.5 * (s[idx] + s[idx + 1])]))
            if len(self.rep_s[g]) > 100_000:
                raise BackendError("a trimming loop keeps needing splits: do the face's loops cross or touch?")
            self.rep_ids[g] = None
            self.version[g] += 1
        self._assign_ids()

    def coords(self) -> np.ndarray:
        return np.concatenate(self.vertices)

    def samples(self, j, degenerate_s):
        """(s (k,), vertex ids (k,), group, rep indices (k,)) of piece j, in the piece's direction."""
        if self.degenerate[j]:
            s = degenerate_s
            return s, np.full(len(s), self.corner[j, 0]), -1, np.zeros(len(s), int)
        g = self.group[j]
        sj = self.member_s[j]
        idx = np.arange(len(sj))
        if not self.same_dir[j]:
            sj, idx = sj[::-1], idx[::-1]
        return sj, self.rep_ids[g][idx], g, idx


# --- faces: grid, triangulation, measured refinement ----------------------------------------------

def _grid(patch, tol):
    """Initial grid lines (gu, gv): every knot span cut into max(1, ceil(8 sqrt(d / tol))) equal steps,
    d the largest sagitta measured over 8 probe steps of the span along several iso-lines."""
    (u0, u1), (v0, v1) = patch.domain

    def along(breaks, lo, hi, other, first):
        probes = np.unique(np.concatenate([np.linspace(lo, hi, 9), other, 0.5 * (other[:-1] + other[1:])]))
        t = breaks[:-1, None] + np.diff(breaks)[:, None] * np.linspace(0, 1, 17)[None, :]   # (spans, 17)
        tt, pp = np.meshgrid(t.ravel(), probes, indexing="ij")
        uv = (tt, pp) if first else (pp, tt)
        pts = patch.evaluate(uv[0].ravel(), uv[1].ravel()).reshape(len(breaks) - 1, 17, len(probes), 3)
        ends, mids = pts[:, 0::2], pts[:, 1::2]
        d = _segment_distance(mids, ends[:, :-1], ends[:, 1:]).max(axis=(1, 2))
        n = np.maximum(1, np.ceil(8 * np.sqrt(d / (CERTIFY * tol)))).astype(int)
        return np.unique(np.concatenate([[breaks[0]]] + [np.linspace(a, b, k + 1)[1:]
                                                         for a, b, k in zip(breaks[:-1], breaks[1:], n)]))

    bu = np.unique(np.concatenate([[u0, u1], patch.breaks_u]))
    bv = np.unique(np.concatenate([[v0, v1], patch.breaks_v]))
    return along(bu, v0, v1, bv, True), along(bv, u0, u1, bu, False)


def _inside(pts, polygons) -> np.ndarray:
    """Even-odd test of points (k, 2) against closed polygons (list of (n, 2)), in chunks."""
    out = np.zeros(len(pts), bool)
    for poly in polygons:
        a, b = poly, np.roll(poly, -1, axis=0)
        step = max(1, 4_000_000 // max(len(poly), 1))
        for s in range(0, len(pts), step):
            x, y = pts[s:s + step, 0:1], pts[s:s + step, 1:2]
            cond = (a[:, 1] > y) != (b[:, 1] > y)
            with np.errstate(divide="ignore", invalid="ignore"):
                xi = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
            out[s:s + step] ^= (np.count_nonzero(cond & (x < xi), axis=1) % 2).astype(bool)
    return out


def _degenerate_s(piece, grid):
    """Samples of a degenerate (pole) piece: the grid lines it crosses, so pole fans follow the grid."""
    a, b = piece.uv(np.array([0.0, 1.0]))
    k = int(np.argmax(np.abs(b - a)))
    if abs(b[1 - k] - a[1 - k]) > 1e-12 * (1 + abs(b[k] - a[k])) or b[k] == a[k]:
        return np.array([0.0, 1.0])
    s = (grid[k] - a[k]) / (b[k] - a[k])
    return np.unique(np.concatenate([[0.0, 1.0], s[(s > 0) & (s < 1)]]))


class _FaceMesher:
    """Mesh one face given the current edge sampling; `run` returns split requests (empty when done)."""

    def __init__(self, face, edges, piece_ids, tol, angle_tol):
        self.face, self.edges, self.piece_ids = face, edges, piece_ids
        self.tol, self.angle_tol = tol, angle_tol
        self._boundary()
        gu, gv = face.grid
        uu, vv = np.meshgrid(gu[1:-1], gv[1:-1], indexing="ij")
        cand = np.column_stack([uu.ravel(), vv.ravel()])
        self.interior = cand[_inside(cand, self.polygons)] if face.trimmed else cand
        self.requests = set()
        self.interior = self._admit(self.interior)

    def _boundary(self):
        """Boundary samples (uv, vertex ids), loop polygons and segments from the current edge sampling."""
        face, edges = self.face, self.edges
        uvs, ids, seg, segments = [], [], [], []
        self.polygons = []
        n0 = 0
        for loop, pids in zip(face.loops, self.piece_ids):
            luv, lid = [], []
            for piece, j in zip(loop, pids):
                s, vid, g, idx = edges.samples(j, _degenerate_s(piece, face.grid))
                luv.append(piece.uv(s)[:-1])
                lid.append(vid[:-1])
                seg += [(g, min(idx[k], idx[k + 1])) for k in range(len(s) - 1)]
            poly = np.concatenate(luv)
            self.polygons.append(poly)
            uvs.append(poly)
            ids += lid
            n = len(poly)
            segments.append(np.column_stack([n0 + np.arange(n), n0 + (np.arange(n) + 1) % n]))
            n0 += n
        self.segments = np.concatenate(segments).astype(np.int64)
        self.b_uv = np.concatenate(uvs)
        self.b_ids = np.concatenate(ids)
        self.seg_ref = seg                                     # per segment: (group, rep index)
        self.versions = edges.version.copy()

    def scaled(self, uv):
        """Grid-index coordinates: the initial grid's cells become unit squares, so Delaunay works in a
        metric adapted to the resolution each direction needs (anisotropic cells stay well shaped)."""
        gu, gv = self.face.grid
        return np.column_stack([np.interp(uv[:, 0], gu, np.arange(len(gu))),
                                np.interp(uv[:, 1], gv, np.arange(len(gv)))])

    def _unscaled(self, p):
        """Inverse of `scaled`: grid-index coordinates back to (u, v)."""
        gu, gv = self.face.grid
        return np.column_stack([np.interp(p[:, 0], np.arange(len(gu)), gu),
                                np.interp(p[:, 1], np.arange(len(gv)), gv)])

    def _admit(self, cand):
        """Drop candidates inside a boundary segment's diametral circle; ask for that segment's split."""
        from scipy.spatial import cKDTree

        if len(cand) == 0:
            return cand
        p = self.scaled(self.b_uv)
        a, b = p[self.segments[:, 0]], p[self.segments[:, 1]]
        mid, rad = 0.5 * (a + b), 0.5 * np.linalg.norm(b - a, axis=1)
        tree = cKDTree(self.scaled(cand))
        hits = tree.query_ball_point(mid, rad * (1 - 1e-9))
        drop = np.zeros(len(cand), bool)
        for k, h in enumerate(hits):
            if h:
                drop[h] = True
                g, idx = self.seg_ref[k]
                if g >= 0 and rad[k] > 0.25:   # segments under half a grid cell are not split again
                    self.requests.add((g, idx))
        return cand[~drop]

    def run(self):
        from scipy.spatial import Delaunay, cKDTree

        patch, tol = self.face.patch, self.tol
        for _ in range(200):
            if self.requests:   # split the encroached/missing boundary segments and rebuild the boundary
                self.edges.split(self.requests)
                self.requests = set()
                self._boundary()
                self.interior = self._admit(self.interior)
                continue
            if not hasattr(self, "certified") or self.certified_for != len(self.b_uv):
                self.certified = np.zeros(0, np.int64)   # keys of triangles already measured within tol
                self.certified_for = len(self.b_uv)
            coords = self.edges.coords()
            seg_keys = np.sort(self.segments, axis=1)
            seg_keys = seg_keys[:, 0] * (1 << 32) + seg_keys[:, 1]
            uv = np.concatenate([self.b_uv, self.interior])
            p = self.scaled(uv)
            # four far ghost corners: no real point lies on the convex hull, where Qhull may drop
            # collinear points; triangles using a ghost are outside the face
            lo, hi = p.min(axis=0), p.max(axis=0)
            pad = 4 * float(np.max(hi - lo))
            ghosts = np.array([[lo[0] - pad, lo[1] - pad], [hi[0] + pad, lo[1] - pad], [hi[0] + pad, hi[1] + pad],
                               [lo[0] - pad, hi[1] + pad]])
            # trimmed faces: joggled input ("QJ"), since Qhull's default "Qt" may triangulate collinear
            # trim samples into flat triangles that hide the boundary segments
            options = "QJ" if self.face.trimmed else None
            tri = Delaunay(np.concatenate([p, ghosts]), qhull_options=options).simplices.astype(np.int64)
            tri = tri[(tri < len(p)).all(axis=1)]
            d1, d2 = p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]]
            area = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
            tri[area < 0] = tri[area < 0][:, [0, 2, 1]]
            tri = tri[_inside(uv[tri].mean(axis=1), self.polygons)]
            e = np.sort(tri[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
            ekeys = e[:, 0] * (1 << 32) + e[:, 1]
            missing = ~np.isin(seg_keys, ekeys)
            if missing.any():
                for k in np.flatnonzero(missing):
                    g, idx = self.seg_ref[k]
                    if g >= 0:
                        self.requests.add((g, idx))
                if self.requests:
                    continue
                raise BackendError("a trimming loop could not be kept in the triangulation")
            xyz = np.concatenate([coords[self.b_ids], patch.evaluate(self.interior[:, 0], self.interior[:, 1])])
            gid = np.concatenate([self.b_ids, -1 - np.arange(len(self.interior))])
            g = gid[tri]
            live = (g[:, 0] != g[:, 1]) & (g[:, 1] != g[:, 2]) & (g[:, 0] != g[:, 2])
            tkey = np.sort(tri, axis=1)
            tkey = (tkey[:, 0] << 42) + (tkey[:, 1] << 21) + tkey[:, 2]
            todo = live & ~np.isin(tkey, self.certified)
            fail, worst = np.zeros(len(tri), bool), np.zeros(len(tri), int)
            fail[todo], worst[todo] = self._measure(xyz[tri[todo]], uv[tri[todo]])
            self.certified = np.union1d(self.certified, tkey[todo & ~fail])
            if not fail.any():
                self.tri_local, self.xyz, self.uv = tri[live], xyz, uv
                return
            tf, wf = tri[fail], worst[fail]
            is_seg = np.isin(ekeys.reshape(-1, 3)[fail], seg_keys)
            edge = _EDGE_OF_SAMPLE[wf]
            on_inner = edge >= 0
            on_inner[on_inner] = ~is_seg[np.flatnonzero(on_inner), edge[on_inner]]
            ends = np.array(_EDGES)[np.maximum(edge, 0)]
            rows = np.arange(len(tf))
            mids = 0.5 * (uv[tf[rows, ends[:, 0]]] + uv[tf[rows, ends[:, 1]]])
            at = np.einsum("tk,tkd->td", _BARY[wf], uv[tf])
            at[edge >= 0] = uv[tf[edge >= 0]].mean(axis=1)      # boundary edge: the centroid instead
            new = np.where(on_inner[:, None], mids, at)
            tree = cKDTree(p)
            dup = np.flatnonzero((tree.query(self.scaled(new))[0] <= 1e-7) & (edge >= 0))
            if len(dup):  # a sliver along a straight boundary: refine the triangle across its long edge
                fail_idx = np.flatnonzero(fail)
                keys3 = ekeys.reshape(-1, 3)
                for r in dup:
                    k = keys3[fail_idx[r], edge[r]]
                    other = np.flatnonzero((keys3 == k).any(axis=1))
                    other = other[other != fail_idx[r]]
                    if len(other):
                        new[r] = uv[tri[other[0]]].mean(axis=0)
                    else:  # nothing across: step off the straight boundary into the face
                        a, b = _EDGES[edge[r]]
                        pa, pb = self.scaled(uv[tf[r, [a, b]]])
                        normal = np.array([pa[1] - pb[1], pb[0] - pa[0]]) * 0.3
                        steps = 0.5 * (pa + pb) + np.stack([normal, -normal])
                        back = self._unscaled(steps)
                        ok = _inside(back, self.polygons)
                        if ok.any():
                            new[r] = back[np.argmax(ok)]
            _, first = np.unique(np.round(self.scaled(new), 9), axis=0, return_index=True)
            new = new[np.sort(first)]
            d, _ = tree.query(self.scaled(new))
            new = self._admit(new[d > 1e-7])
            if len(new) == 0 and not self.requests:
                raise BackendError("a face could not be refined to the tolerance (a sliver along a trimming "
                                   "loop; known limitation of the unconstrained Delaunay step)")
            self.interior = np.concatenate([self.interior, new])
        raise BackendError("a face did not reach the tolerance after 200 refinement passes")

    def _measure(self, v, uvt):
        """(failing (t,), worst sample (t,)) of triangles v (t, 3, 3) with corner parameters uvt (t, 3, 2)."""
        patch = self.face.patch
        x = np.einsum("sk,tkd->tsd", _BARY, v)
        guess = np.einsum("sk,tkd->tsd", _BARY, uvt)
        _, dist = patch.project(x.reshape(-1, 3), guess.reshape(-1, 2), iterations=4)
        dev = dist.reshape(len(v), len(_BARY)) / (CERTIFY * self.tol)
        if self.angle_tol:
            n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
            n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
            ns = patch.normal(uvt[..., 0].ravel(), uvt[..., 1].ravel()).reshape(-1, 3, 3)
            cos = np.einsum("td,tkd->tk", n, ns)
            valid = np.linalg.norm(ns, axis=2) > 0
            ang = np.where(valid, np.arccos(np.clip(cos, -1, 1)), 0.0).max(axis=1) / self.angle_tol
            longest = np.argmax(np.linalg.norm(v[:, [1, 2, 0]] - v, axis=2), axis=1)
            dev[np.arange(len(v)), longest] = np.maximum(dev[np.arange(len(v)), longest], ang)
        return dev.max(axis=1) > 1.0, np.argmax(dev, axis=1)


# --- assembly, orientation, public API ------------------------------------------------------------

def _model_size(faces) -> float:
    pts = np.concatenate([_patch_probe(f.patch) for f in faces])
    return float(np.linalg.norm(pts.max(0) - pts.min(0))) or 1.0


def _patch_probe(patch):
    uu, vv = np.meshgrid(np.linspace(*patch.domain[0], 9), np.linspace(*patch.domain[1], 9), indexing="ij")
    return patch.evaluate(uu.ravel(), vv.ravel())


def _uses_changed(mesher, edges) -> bool:
    """True when an edge group on this face's boundary was split after the face was meshed."""
    groups = {g for g, _ in mesher.seg_ref if g >= 0}
    return any(mesher.versions[g] != edges.version[g] for g in groups)


def tessellate_faces(faces, tol: float, angle_tol: float | None = None, eps: float | None = None) -> Mesh:
    """Mesh face records (see `collect_faces`) to chordal deviation `tol` and normal deviation `angle_tol`."""
    if not tol > 0:
        raise BackendError(f"the mesh tolerance must be positive, got {tol}")
    if not faces:
        raise BackendError("nothing to tessellate: the model exports no surfaces or faces")
    size = _model_size(faces)
    eps = max(1e-9 * size, 1e-3 * tol) if eps is None else eps
    for f in faces:
        f.grid = _grid(f.patch, tol)
    edges = _Edges(faces, tol, eps)
    ids, k = [], 0
    for f in faces:
        ids.append([list(range(k + sum(len(l) for l in f.loops[:i]), k + sum(len(l) for l in f.loops[:i + 1])))
                    for i in range(len(f.loops))])
        k += sum(len(l) for l in f.loops)
    meshers = [_FaceMesher(f, edges, pid, tol, angle_tol) for f, pid in zip(faces, ids)]
    for m in meshers:
        m.run()
    for _ in range(16):   # a face that split a shared edge changed its neighbours' boundaries: redo those
        stale = [m for m in meshers if _uses_changed(m, edges)]
        if not stale:
            break
        for m in stale:
            m._boundary()
            m.interior = m._admit(m.interior)
            m.run()
    else:
        raise BackendError("the shared edges did not settle after 16 rounds of splitting")
    coords = edges.coords()
    verts, tris, owner = [coords], [], []
    n = len(coords)
    for fi, (f, m) in enumerate(zip(faces, meshers)):
        nb = len(m.b_ids)
        gid = np.concatenate([m.b_ids, n + np.arange(len(m.xyz) - nb)])
        verts.append(m.xyz[nb:])
        n += len(m.xyz) - nb
        f.tri, f.tri_uv = gid[m.tri_local], m.uv[m.tri_local]
        tris.append(f.tri)
        owner.append(np.full(len(f.tri), fi))
    vertices, triangles = np.concatenate(verts), np.concatenate(tris)
    flip = _orientation(triangles, np.concatenate(owner), len(faces), vertices)
    for f, fl in zip(faces, flip):
        if fl:
            f.tri, f.tri_uv = f.tri[:, ::-1], f.tri_uv[:, ::-1]
    used = np.unique(triangles)
    remap = np.full(len(vertices), -1)
    remap[used] = np.arange(len(used))
    for f in faces:
        f.tri = remap[f.tri]
    return Mesh(vertices[used], np.concatenate([f.tri for f in faces]), faces)


def _orientation(tri, owner, nfaces, vertices) -> np.ndarray:
    """Per-face flips making shared edges run opposite ways, then closed components face outwards."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    he = tri[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    fo = np.repeat(owner, 3)
    key = np.sort(he, axis=1)
    key = key[:, 0] * len(vertices) + key[:, 1]
    order = np.argsort(key, kind="stable")
    k, he, fo = key[order], he[order], fo[order]
    first = np.flatnonzero(np.diff(k) == 0)
    pair = first[(fo[first] != fo[first + 1])]
    same = he[pair, 0] == he[pair + 1, 0]             # same direction: one face must flip
    fa, fb = fo[pair], fo[pair + 1]
    flip = np.zeros(nfaces, bool)
    seen = np.zeros(nfaces, bool)
    adj = {}
    for a, b, s in zip(fa, fb, same):
        adj.setdefault(a, {})[b] = s
        adj.setdefault(b, {})[a] = s
    for start in range(nfaces):
        if seen[start]:
            continue
        seen[start] = True
        stack = [start]
        while stack:
            a = stack.pop()
            for b, s in adj.get(a, {}).items():
                if not seen[b]:
                    seen[b] = True
                    flip[b] = flip[a] ^ bool(s)
                    stack.append(b)
    graph = coo_matrix((np.ones(len(fa)), (fa, fb)), shape=(nfaces, nfaces))
    _, comp = connected_components(graph, directed=False)
    for c in np.unique(comp):
        members = np.flatnonzero(comp == c)
        t = tri[np.isin(owner, members)]
        t = np.where(np.isin(owner[np.isin(owner, members)], members[flip[members]])[:, None], t[:, ::-1], t)
        e = np.sort(t[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        _, cnt = np.unique(e[:, 0] * len(vertices) + e[:, 1], return_counts=True)
        if np.all(cnt == 2) and signed_volume(vertices, t) < 0:
            flip[members] ^= True
    return flip


def signed_volume(vertices, triangles) -> float:
    """Signed volume enclosed by a closed triangle mesh (divergence theorem); > 0 when facing out."""
    v = vertices[triangles]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def _objects(model_or_obj) -> list:
    from rgm.model import Model

    return model_or_obj.exported() if isinstance(model_or_obj, Model) else [model_or_obj]


def tessellate_mesh(model_or_obj, tol: float, angle_tol: float | None = None) -> Mesh:
    """As `tessellate`, keeping the face records (patches, per-triangle parameters) for measurement."""
    objs = _objects(model_or_obj)
    faces = collect_faces(objs, tol=0.1 * tol)
    return tessellate_faces(faces, tol, angle_tol)


def tessellate(model_or_obj, tol: float, angle_tol: float | None = None):
    """(vertices (n, 3) float64, triangles (m, 3) int64) of a model's exported surfaces/faces/shells or of
    one object, within chordal deviation `tol` (model units) and normal deviation `angle_tol` (radians)."""
    mesh = tessellate_mesh(model_or_obj, tol, angle_tol)
    return mesh.vertices, mesh.triangles


def mesh_deviation(mesh: Mesh, per_edge: int = 8) -> float:
    """Measured max distance from the mesh to its exact surfaces: every triangle sampled on a barycentric
    lattice with `per_edge` steps, each sample's closest point found from scratch (`Patch.closest`)."""
    i, j = np.meshgrid(np.arange(per_edge + 1), np.arange(per_edge + 1), indexing="ij")
    keep = i + j <= per_edge
    a, b = i[keep] / per_edge, j[keep] / per_edge
    bary = np.column_stack([1 - a - b, a, b])
    worst = 0.0
    for f in mesh.faces:
        if f.tri is None or len(f.tri) == 0:
            continue
        x = np.einsum("sk,tkd->tsd", bary, mesh.vertices[f.tri]).reshape(-1, 3)
        _, dist = f.patch.closest(x)
        worst = max(worst, float(dist.max()))
    return worst


def face_samples(objs, samples: int = 60):
    """(points (k, 3) on the exact faces, model size): up to `samples` mesh vertices per face, from a
    coarse tessellation (tol = size / 200); used to verify exported files against rgm's evaluation."""
    faces = collect_faces(objs, tol=None)
    size = _model_size(faces)
    mesh = tessellate_faces(faces, size / 200)
    pts = []
    for f in faces:
        ids = np.unique(f.tri)
        pick = ids[np.linspace(0, len(ids) - 1, min(samples, len(ids))).astype(int)]
        pts.append(mesh.vertices[pick])
    return np.concatenate(pts), size


def write_mesh(model, path, *, fmt: str, tol: float, angle_tol: float | None = None, **ignored):
    """Tessellate `model` and write it through trimesh as binary STL, OBJ, PLY or GLB, atomically."""
    from rgm.atomic import write_atomic

    fmt = fmt.lower()
    if fmt not in ("stl", "obj", "ply", "glb"):
        raise BackendError(f"unknown mesh format {fmt!r}; choose stl, obj, ply or glb")
    vertices, triangles = tessellate(model, tol, angle_tol)
    import trimesh

    data = trimesh.Trimesh(vertices, triangles, process=False).export(file_type=fmt)
    return write_atomic(path, data)
