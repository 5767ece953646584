"""Tessellation of model surfaces, trimmed faces and shells to a certified chordal deviation.

`tessellate(obj, tol, angle_tol)` returns (vertices (n, 3), triangles (m, 3)) such that every triangle
lies within `tol` (model units) of its exact surface, checked by *measurement*: every triangle is
sampled on a 6-step barycentric lattice (15 points on its edges, 10 inside) and each sample's distance
to the surface is bounded from above, first by the surface point at the sample's interpolated (u, v),
then, where that bound fails, by Gauss-Newton closest points. With `angle_tol` (radians) the triangle's
normal must also be within `angle_tol` of the surface normals at its corners.

Pipeline:
1. Faces (`rgm.backends.mesh_faces`): each surface/face becomes a parameter-space patch with its
   boundary loops as pieces.
2. Edges (`rgm.backends.mesh_edges`): pieces whose 3-D images coincide are grouped and sampled once,
   so faces sharing an edge share its vertices and closed solids come out watertight.
3. Each face is meshed in a scaled (u, v) plane where the initial grid's cells (spacing from measured
   sagittas per knot span) are unit squares: the grid points clear of the boundary plus the boundary
   samples are triangulated by a constrained Delaunay triangulation (`rgm.backends.mesh_cdt`), so the
   trimming loops are edges and no triangle lies outside them. Refinement is greedy: every failing
   triangle gets a point where its measured deviation is largest (or the midpoint of its longest edge
   when only the normal fails); a failure on a boundary edge splits that edge for every face sharing it.
   A planar face is triangulated in its plane from its boundary samples alone (`rgm.backends.mesh_planar`).
   The faces are refined in lock-step (`run_together`): each pass, the samples every face measures are
   evaluated and projected together (`rgm.backends.mesh_surface.PatchStack`), as are the faces'
   boundaries and trimming-curve projections, so a part's per-face costs are paid once per pass.
4. Per-face orientation is made consistent across shared edges; closed components face outwards.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rgm.errors import BackendError
from rgm.geometry.polygon import inside_polygons

from .mesh_cdt import Incremental, OnSegment, constrained_delaunay
from .mesh_edges import CERTIFY, Edges, segment_distance, uv_of
from .mesh_surface import evaluate_together, project_together
from .mesh_faces import collect_faces
from .mesh_planar import plane_frame, simple_loops


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
#: the samples on the edges, and for each its step (1..5, in sixths) from the edge's first corner k
#: (edge k runs from corner k to corner k + 1, whose weight that is)
_ON_EDGE = np.flatnonzero(_EDGE_OF_SAMPLE >= 0)
_STEP = np.rint(6 * _BARY[_ON_EDGE, (_EDGE_OF_SAMPLE[_ON_EDGE] + 1) % 3]).astype(int)
#: the centroid, measured first with the edge midpoints (a failing triangle fails there mostly), and
#: the other samples inside
_CENTROID = int(np.flatnonzero(np.isclose(_BARY, 1 / 3).all(axis=1))[0])
_INNER = np.flatnonzero((_EDGE_OF_SAMPLE < 0) & (np.arange(len(_BARY)) != _CENTROID))
_EDGES = np.array([(0, 1), (1, 2), (2, 0)])
#: initial grid points nearer than this to the boundary (in grid cells) are left out: no slivers
CLEARANCE = 0.3
#: boundary segments longer than this (in grid cells) are split before meshing
LONGEST_SEGMENT = 2.0
MAX_PASSES = 80
MAX_POINTS = 4_000_000


@dataclass
class Mesh:
    """Result of `tessellate_faces`: vertices (n, 3), triangles (m, 3) and the faces they came from."""

    vertices: np.ndarray
    triangles: np.ndarray
    faces: list


# --- faces: grid, triangulation, measured refinement ----------------------------------------------

def _grids(patches, tol) -> list:
    """Initial grid lines [(gu, gv)] per patch: every knot span cut into max(1, ceil(8 sqrt(d / tol)))
    equal steps, d the largest sagitta measured over 8 probe steps of the span along several iso-lines;
    all the patches' probes evaluated together (`evaluate_together`)."""
    plans, uvs = [], []
    for patch in patches:
        (u0, u1), (v0, v1) = patch.domain
        bu = np.unique(np.concatenate([[u0, u1], patch.breaks_u]))
        bv = np.unique(np.concatenate([[v0, v1], patch.breaks_v]))
        for breaks, lo, hi, other, first in ((bu, v0, v1, bv, True), (bv, u0, u1, bu, False)):
            probes = np.unique(np.concatenate([np.linspace(lo, hi, 9), other, 0.5 * (other[:-1] + other[1:])]))
            t = breaks[:-1, None] + np.diff(breaks)[:, None] * np.linspace(0, 1, 17)[None, :]   # (spans, 17)
            tt, pp = np.meshgrid(t.ravel(), probes, indexing="ij")
            uvs.append(np.column_stack([tt.ravel(), pp.ravel()] if first else [pp.ravel(), tt.ravel()]))
            plans.append((breaks, len(probes)))
    lines = []
    for (breaks, m), pts in zip(plans, evaluate_together([p for p in patches for _ in (0, 1)], uvs)):
        pts = pts.reshape(len(breaks) - 1, 17, m, 3)
        ends, mids = pts[:, 0::2], pts[:, 1::2]
        d = segment_distance(mids, ends[:, :-1], ends[:, 1:]).max(axis=(1, 2))
        n = np.maximum(1, np.ceil(8 * np.sqrt(d / (CERTIFY * tol)))).astype(int)
        lines.append(np.unique(np.concatenate([[breaks[0]]] + [np.linspace(a, b, k + 1)[1:]
                                                               for a, b, k in zip(breaks[:-1], breaks[1:], n)])))
    return list(zip(lines[0::2], lines[1::2]))


def _degenerate_s(piece, grid):
    """Samples of a degenerate (pole) piece: the grid lines it crosses, so pole fans follow the grid."""
    a, b = piece.uv(np.array([0.0, 1.0]))
    k = int(np.argmax(np.abs(b - a)))
    if abs(b[1 - k] - a[1 - k]) > 1e-12 * (1 + abs(b[k] - a[k])) or b[k] == a[k]:
        return np.array([0.0, 1.0])
    s = (grid[k] - a[k]) / (b[k] - a[k])
    return np.unique(np.concatenate([[0.0, 1.0], s[(s > 0) & (s < 1)]]))


class _FaceMesher:
    """Mesh one face given the current edge sampling. `passes` refines until every triangle is certified
    (driven by `run_together` with the other faces); boundary splits it needs are made on the shared
    edges (so neighbours may have to run again)."""

    def __init__(self, face, edges, piece_ids, tol, angle_tol):
        self.face, self.edges, self.piece_ids = face, edges, piece_ids
        self.tol, self.angle_tol = tol, angle_tol
        self.requests = set()
        self.last = Incremental()
        self.frame = plane_frame(face.patch, tol)
        self.interior = np.zeros((0, 2))
        # a curved face's grid is set by `tessellate_faces` (`_grids`, for all faces at once); on a planar
        # one the grid only sets where the poles' samples fall
        if self.frame is not None:
            face.grid = (np.unique(np.concatenate([face.patch.domain[0], face.patch.breaks_u])),
                         np.unique(np.concatenate([face.patch.domain[1], face.patch.breaks_v])))

    def start(self, found=None):
        """Take up the boundary (`_boundary`, with `found` as `boundaries` gives it); on a face meshed in
        (u, v), the initial grid points clear of the boundary and split requests for the boundary
        segments longer than LONGEST_SEGMENT grid cells."""
        self._boundary(found)
        if self.frame is not None:
            return
        gu, gv = self.face.grid
        uu, vv = np.meshgrid(gu[1:-1], gv[1:-1], indexing="ij")
        self.interior = self._clear_of_boundary(np.column_stack([uu.ravel(), vv.ravel()]))
        p = self.scaled(self.b_uv)
        long = np.linalg.norm(p[self.segments[:, 1]] - p[self.segments[:, 0]], axis=1) > LONGEST_SEGMENT
        self.requests |= self._refs(np.flatnonzero(long))

    def samples(self):
        """The face's boundary samples on the current edge sampling: (pieces, parameters, vertex ids, edge
        groups, rep indices, loops), the parameters each piece's, the rest per sample."""
        face, edges = self.face, self.edges
        params, ids, groups, reps, loops = [], [], [], [], []
        n0 = 0
        for loop, pids in zip(face.loops, self.piece_ids):
            n = 0
            for piece, j in zip(loop, pids):
                s, vid, g, idx = edges.samples(j, _degenerate_s(piece, face.grid) if edges.degenerate[j] else None)
                params.append(s[:-1])
                ids.append(vid[:-1])
                groups.append(np.full(len(s) - 1, g))
                reps.append(np.minimum(idx[:-1], idx[1:]))
                n += len(s) - 1
            loops.append(n0 + np.arange(n))
            n0 += n
        return [p for loop in face.loops for p in loop], params, ids, groups, reps, loops

    def _boundary(self, found=None):
        """Boundary samples (uv, vertex ids), loops and segments from the current edge sampling; `found`:
        (`samples`, their uv), as `boundaries` finds them for many faces at once."""
        (_, _, ids, groups, reps, loops), uvs = found or boundaries([self])[0]
        self.loops = loops
        self.segments = np.concatenate([np.column_stack([lp, np.roll(lp, -1)]) for lp in loops]).astype(np.int64)
        self.b_uv = np.concatenate(uvs)
        self.b_ids = np.concatenate(ids)
        self.seg_group = np.concatenate(groups)                # per segment: its edge group (-1: a pole)
        self.seg_rep = np.concatenate(reps)                    # and the index of its rep segment
        self.versions = self.edges.version.copy()
        self.certified = np.zeros(0, np.int64)                 # keys of triangles measured within tol
        self.last.reset()                                     # the boundary points changed

    def _refs(self, segments) -> set:
        """Split requests {(group, rep index)} for boundary segments (indices; poles left out)."""
        g, k = self.seg_group[segments], self.seg_rep[segments]
        return set(zip(g[g >= 0].tolist(), k[g >= 0].tolist()))

    def refresh(self, found=None):
        """Take up the current edge sampling (after this face or a neighbour split a shared edge);
        `found` as for `_boundary`."""
        self._boundary(found)
        if len(self.interior):
            p = self.scaled(self.b_uv)
            self.interior = self.interior[inside_polygons(self.scaled(self.interior), [p[lp] for lp in self.loops])]

    def scaled(self, uv):
        """Grid-index coordinates: the initial grid's cells become unit squares, so Delaunay works in a
        metric adapted to the resolution each direction needs (anisotropic cells stay well shaped)."""
        gu, gv = self.face.grid
        return np.column_stack([np.interp(uv[:, 0], gu, np.arange(len(gu))),
                                np.interp(uv[:, 1], gv, np.arange(len(gv)))])

    def _clear_of_boundary(self, cand):
        """Candidates inside the loops and at least CLEARANCE grid cells from the boundary polyline."""
        from scipy.spatial import cKDTree

        if len(cand) == 0:
            return cand
        p, q = self.scaled(self.b_uv), self.scaled(cand)
        a, b = p[self.segments[:, 0]], p[self.segments[:, 1]]
        k = np.maximum(1, np.ceil(np.linalg.norm(b - a, axis=1) / (0.5 * CLEARANCE))).astype(int)
        t = np.concatenate([np.arange(m) / m for m in k])
        dense = np.repeat(a, k, axis=0) + t[:, None] * np.repeat(b - a, k, axis=0)
        far = cKDTree(dense).query(q, distance_upper_bound=CLEARANCE)[0] > CLEARANCE
        keep = far & inside_polygons(q, [p[lp] for lp in self.loops])
        return cand[keep]

    def _flat(self) -> bool:
        """Triangulate a planar face in its plane from its boundary samples alone (`mesh_planar`); False
        when its loops make no valid polygon there (the face is then meshed in (u, v) as any other)."""
        o, e1, e2 = self.frame
        xyz = self.edges.coords()[self.b_ids]
        loops = [lp[k] for lp in self.loops for k in simple_loops(self.b_ids[lp])]
        if not loops:
            return False
        used = np.concatenate(loops)
        local = np.full(len(xyz), -1)
        local[used] = np.arange(len(used))
        segments = np.concatenate([np.column_stack([local[lp], np.roll(local[lp], -1)]) for lp in loops])
        try:
            tri = constrained_delaunay((xyz[used] - o) @ np.column_stack([e1, e2]), segments,
                                       [local[lp] for lp in loops])
        except BackendError:
            return False
        self.tri_local, self.xyz, self.uv = used[tri], xyz, self.b_uv
        return True

    def passes(self):
        """The refinement as a generator: it yields each measurement it needs, (points (k, 3), parameter
        guesses (k, 2)), and is sent the upper bounds of their distances to the surface (`deviations`),
        so that `run_together` measures many faces in one call per pass."""
        from scipy.spatial import cKDTree

        if self.frame is not None:
            if self._flat():
                return
            self.frame = None
            self.face.grid = _grids([self.face.patch], self.tol)[0]
            self.start()
        patch, nb = self.face.patch, None
        for _ in range(MAX_PASSES):
            if self.requests:   # split the boundary segments that failed and take up the new sampling
                self.edges.split(self.requests)
                self.requests = set()
                self.refresh()
                continue
            nb = len(self.b_uv)
            uv = np.concatenate([self.b_uv, self.interior])
            p = self.scaled(uv)
            try:
                tri = constrained_delaunay(p, self.segments, self.loops, n_fixed=nb, state=self.last)
            except OnSegment as exc:   # free points on a boundary segment: leave them out
                self.interior = np.delete(self.interior, exc.ids - nb, axis=0)
                self.certified = np.zeros(0, np.int64)
                self.last.reset()
                continue
            xyz = np.concatenate([self.edges.coords()[self.b_ids],
                                  patch.evaluate(self.interior[:, 0], self.interior[:, 1])])
            gid = np.concatenate([self.b_ids, -1 - np.arange(len(self.interior))])[tri]
            live = (gid[:, 0] != gid[:, 1]) & (gid[:, 1] != gid[:, 2]) & (gid[:, 0] != gid[:, 2])
            tri = tri[live]
            key = np.sort(tri, axis=1)
            key = (key[:, 0] << 42) + (key[:, 1] << 21) + key[:, 2]
            todo = ~np.isin(key, self.certified)
            fail = np.zeros(len(tri), bool)
            worst = np.zeros(len(tri), int)
            fail[todo], worst[todo] = yield from self._measure(tri[todo], xyz, uv)
            self.certified = np.union1d(self.certified, key[todo & ~fail])
            if not fail.any():
                self.tri_local, self.xyz, self.uv = tri, xyz, uv
                return
            new = self._proposals(tri[fail], worst[fail], uv, xyz)
            if len(new):
                _, first = np.unique(np.round(self.scaled(new), 10), axis=0, return_index=True)
                new = new[np.sort(first)]
                new = new[cKDTree(p).query(self.scaled(new))[0] > 1e-9]
            if len(new) == 0 and not self.requests:
                raise BackendError("a face could not be refined to the tolerance: its surface may be singular "
                                   "(zero derivatives) inside the face")
            if len(self.interior) + len(new) > MAX_POINTS:
                raise BackendError(f"a face needs more than {MAX_POINTS} points at tol {self.tol:g}: choose a "
                                   f"coarser tolerance")
            self.interior = np.concatenate([self.interior, new])
        raise BackendError(f"a face did not reach the tolerance after {MAX_PASSES} refinement passes")

    def _proposals(self, tf, wf, uv, xyz):
        """Points (k, 2) to insert for failing triangles tf (f, 3) with worst samples wf (f,) (a sample
        index, or -1 - corner pair for a normal failure: split that edge); failures on a boundary edge
        become split requests instead."""
        normal = wf < 0
        edge = np.where(normal, -1 - wf, _EDGE_OF_SAMPLE[np.maximum(wf, 0)])
        ends = _EDGES[np.maximum(edge, 0)]
        rows = np.arange(len(tf))
        a, b = tf[rows, ends[:, 0]], tf[rows, ends[:, 1]]
        n = len(uv)
        seg = np.minimum(self.segments[:, 0], self.segments[:, 1]) * n + np.maximum(self.segments[:, 0],
                                                                                    self.segments[:, 1])
        order = np.argsort(seg)
        ekey = np.minimum(a, b) * n + np.maximum(a, b)
        pos = np.minimum(np.searchsorted(seg[order], ekey), len(seg) - 1)
        on_boundary = (edge >= 0) & (seg[order][pos] == ekey)
        self.requests |= self._refs(order[pos[on_boundary]])
        at = np.einsum("tk,tkd->td", _BARY[np.maximum(wf, 0)], uv[tf])
        at[normal] = 0.5 * (uv[a[normal]] + uv[b[normal]])
        return at[~on_boundary]

    def _measure(self, tri, xyz, uv):
        """(failing (t,), worst (t,)) of triangles tri (t, 3) (local ids into xyz (n, 3) and uv (n, 2)):
        worst is the lattice sample of largest deviation, or -1 - k when only the normal fails and edge k
        (the longest) should be split. The edge midpoints and centroid are measured first; only the
        triangles they pass are measured on the whole lattice. A lattice sample on an edge is a sample
        of that edge, so it is measured once for the two triangles sharing the edge (an edge sample is
        the same point and guess from either side)."""
        limit = CERTIFY * self.tol
        n = len(xyz)
        a, b = tri, tri[:, [1, 2, 0]]                                  # edge k runs from corner k to k + 1
        keys, eid = np.unique((np.minimum(a, b) * n + np.maximum(a, b)).ravel(), return_inverse=True)
        eid = eid.reshape(-1, 3)
        lo, hi = keys // n, keys % n
        k = _EDGE_OF_SAMPLE[_ON_EDGE]
        slot = eid[:, k] * 5 + np.where(a[:, k] < b[:, k], _STEP - 1, 5 - _STEP)   # (t, 15) into (e, 5)

        def along(edges, steps):   # points and guesses at steps / 6 from lo to hi, (len(edges) * len(steps), .)
            w = np.asarray(steps, float)[None, :, None] / 6
            x = (1 - w) * xyz[lo[edges], None] + w * xyz[hi[edges], None]
            g = (1 - w) * uv[lo[edges], None] + w * uv[hi[edges], None]
            return x.reshape(-1, 3), g.reshape(-1, 2)

        def inside(rows, samples):   # points and guesses at barycentric samples, (len(rows) * len(samples), .)
            x = np.einsum("sk,tkd->tsd", samples, xyz[tri[rows]]).reshape(-1, 3)
            g = np.einsum("sk,tkd->tsd", samples, uv[tri[rows]]).reshape(-1, 2)
            return x, g

        def deviation(*parts):   # one measurement of all the parts' points (with other faces'), split back
            d = yield np.concatenate([x for x, _ in parts]), np.concatenate([g for _, g in parts])
            return np.split(d, np.cumsum([len(x) for x, _ in parts[:-1]]))

        on_edge = np.zeros((len(keys), 5))
        dist = np.zeros((len(tri), len(_BARY)))
        on_edge[:, 2], dist[:, _CENTROID] = yield from deviation(along(np.arange(len(keys)), [3]),
                                                                 inside(np.arange(len(tri)), _BARY[[_CENTROID]]))
        dist[:, _ON_EDGE] = on_edge.ravel()[slot]
        full = np.flatnonzero((dist <= limit).all(axis=1))             # only the coarse samples are set
        if len(full):
            edges = np.unique(eid[full])
            rest, inner = yield from deviation(along(edges, [1, 2, 4, 5]), inside(full, _BARY[_INNER]))
            on_edge[edges[:, None], [0, 1, 3, 4]] = rest.reshape(-1, 4)
            dist[full[:, None], _ON_EDGE] = on_edge.ravel()[slot[full]]
            dist[full[:, None], _INNER] = inner.reshape(len(full), -1)
        fail, worst = (dist > limit).any(axis=1), np.argmax(dist, axis=1)
        if self.angle_tol:
            v, uvt = xyz[tri], uv[tri]
            nrm = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
            nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
            ns = self.face.patch.normal(uvt[..., 0].ravel(), uvt[..., 1].ravel()).reshape(-1, 3, 3)
            valid = np.linalg.norm(ns, axis=2) > 0
            cos = np.einsum("td,tkd->tk", nrm, ns)
            bent = (valid & (cos < np.cos(self.angle_tol))).any(axis=1) & ~fail
            longest = np.argmax(np.linalg.norm(v[:, [1, 2, 0]] - v, axis=2), axis=1)
            worst[bent] = -1 - longest[bent]
            fail |= bent
        return fail, worst


# --- assembly, orientation, public API ------------------------------------------------------------

def _model_size(faces) -> float:
    pts = np.concatenate([_patch_probe(f.patch) for f in faces])
    return float(np.linalg.norm(pts.max(0) - pts.min(0))) or 1.0


def _patch_probe(patch):
    uu, vv = np.meshgrid(np.linspace(*patch.domain[0], 9), np.linspace(*patch.domain[1], 9), indexing="ij")
    return patch.evaluate(uu.ravel(), vv.ravel())


def _uses_changed(mesher, edges) -> bool:
    """True when an edge group on this face's boundary was split after the face was meshed."""
    groups = set(mesher.seg_group[mesher.seg_group >= 0].tolist())
    return any(mesher.versions[g] != edges.version[g] for g in groups)


def deviations(requests) -> list:
    """Upper bounds [(k_i,)] of the distances of points x_i (k_i, 3) to the surfaces of their faces, for
    requests [(mesher, x_i, guesses (k_i, 2))]: the surface point at the guess, then Gauss-Newton closest
    points (one step, then two more) where that bound exceeds CERTIFY * the mesher's tol; every face's
    points evaluated and projected together (`evaluate_together`, `project_together`)."""
    patches = [m.face.patch for m, _, _ in requests]
    xs, guesses = [x for _, x, _ in requests], [g.copy() for _, _, g in requests]
    dist = [np.linalg.norm(x - p, axis=1) for x, p in zip(xs, evaluate_together(patches, guesses))]
    for iterations in (1, 2):
        rows = [np.flatnonzero(d > CERTIFY * m.tol) for d, (m, _, _) in zip(dist, requests)]
        live = [i for i, r in enumerate(rows) if len(r)]
        if not live:
            break
        found = project_together([patches[i] for i in live], [xs[i][rows[i]] for i in live],
                                 [guesses[i][rows[i]] for i in live], iterations)
        for i, (uv, d) in zip(live, found):
            guesses[i][rows[i]] = uv
            dist[i][rows[i]] = np.minimum(dist[i][rows[i]], d)
    return dist


def run_together(meshers):
    """Run every mesher's refinement (`_FaceMesher.passes`) in lock-step: each round, the measurements
    all the unfinished faces ask for are made in one `deviations` call."""
    waiting = {}
    for m in meshers:
        gen = m.passes()
        try:
            waiting[m] = (gen, next(gen))
        except StopIteration:
            pass
    while waiting:
        asked = list(waiting.items())
        answers = deviations([(m, x, g) for m, (_, (x, g)) in asked])
        for (m, (gen, _)), d in zip(asked, answers):
            try:
                waiting[m] = (gen, gen.send(d))
            except StopIteration:
                del waiting[m]


def boundaries(meshers) -> list:
    """[(samples, uv)] of every mesher's boundary on the current edge sampling (`_FaceMesher.samples`),
    their (u, v) found by one `uv_of` for all faces' pieces (projections stacked across faces)."""
    sampled = [m.samples() for m in meshers]
    uvs = uv_of([p for s in sampled for p in s[0]], [t for s in sampled for t in s[1]])
    cut = np.cumsum([len(s[0]) for s in sampled])
    return [(s, uvs[a:b]) for s, a, b in zip(sampled, np.r_[0, cut[:-1]], cut)]


def tessellate_faces(faces, tol: float, angle_tol: float | None = None, eps: float | None = None) -> Mesh:
    """Mesh face records (see `collect_faces`) to chordal deviation `tol` and normal deviation `angle_tol`."""
    if not tol > 0:
        raise BackendError(f"the mesh tolerance must be positive, got {tol}")
    if not faces:
        raise BackendError("nothing to tessellate: the model exports no surfaces or faces")
    size = _model_size(faces)
    eps = max(1e-9 * size, 1e-3 * tol) if eps is None else eps
    edges = Edges(faces, tol, eps)
    ids, k = [], 0
    for f in faces:
        ids.append([list(range(k + sum(len(l) for l in f.loops[:i]), k + sum(len(l) for l in f.loops[:i + 1])))
                    for i in range(len(f.loops))])
        k += sum(len(l) for l in f.loops)
    meshers = [_FaceMesher(f, edges, pid, tol, angle_tol) for f, pid in zip(faces, ids)]
    curved = [m for m in meshers if m.frame is None]
    for m, grid in zip(curved, _grids([m.face.patch for m in curved], tol)):
        m.face.grid = grid
    for m, found in zip(meshers, boundaries(meshers)):
        m.start(found)
    run_together(meshers)
    for _ in range(16):   # a face that split a shared edge changed its neighbours' boundaries: redo those
        stale = [m for m in meshers if _uses_changed(m, edges)]
        if not stale:
            break
        for m, found in zip(stale, boundaries(stale)):
            m.refresh(found)
        run_together(stale)
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
    """Per-face flips making shared edges run opposite ways (a walk over the faces' adjacency, which
    also labels its connected components), then closed components face outwards."""
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
    _, one = np.unique(np.minimum(fa, fb) * nfaces + np.maximum(fa, fb), return_index=True)   # per face pair
    fa, fb, same = fa[one], fb[one], same[one]
    flip = np.zeros(nfaces, bool)
    comp = -np.ones(nfaces, int)
    adj = {}
    for a, b, s in zip(fa.tolist(), fb.tolist(), same.tolist()):
        adj.setdefault(a, {})[b] = s
        adj.setdefault(b, {})[a] = s
    for start in range(nfaces):
        if comp[start] >= 0:
            continue
        comp[start] = start
        stack = [start]
        while stack:
            a = stack.pop()
            for b, s in adj.get(a, {}).items():
                if comp[b] < 0:
                    comp[b] = start
                    flip[b] = flip[a] ^ s
                    stack.append(b)
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


def face_samples(objs, samples: int = 60, curve_tol=None):
    """(points (k, 3) on the exact faces, model size): up to `samples` mesh vertices per face, from a
    coarse tessellation (tol = size / 200); used to verify exported files against rgm's evaluation.
    Lazy intersections in trims are approximated at `curve_tol` (model units, or a function of the
    model size giving them; default: the model tolerance): a verifier that holds a file to finer than
    the model tolerance passes its own fraction, so that the vertices on an intersection edge are as
    accurate as the file's exact edge is held to be."""
    faces = collect_faces(objs, tol=None)
    size = _model_size(faces)
    if curve_tol is not None:
        faces = collect_faces(objs, tol=curve_tol(size) if callable(curve_tol) else curve_tol)
    mesh = tessellate_faces(faces, size / 200)
    pts = []
    for f in faces:
        ids = np.unique(f.tri)
        pick = ids[np.linspace(0, len(ids) - 1, min(samples, len(ids))).astype(int)]
        pts.append(mesh.vertices[pick])
    return np.concatenate(pts), size


def open_edges(triangles) -> int:
    """Edges of a triangle mesh not used by exactly two triangles (0: watertight)."""
    e = np.sort(triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, count = np.unique(e, axis=0, return_counts=True)
    return int((count != 2).sum())


def write_mesh(model, path, *, fmt: str, tol: float | None = None, angle_tol: float | None = None, report=None,
               **ignored):
    """Tessellate `model` and write it through trimesh as binary STL, OBJ, PLY or GLB, atomically.
    `tol` (model units) defaults to the model's `tolerance`. `report` (a callable taking one line of
    text), when given, gets the mesh's size, its certified tolerances and whether it is watertight."""
    from rgm.atomic import write_atomic

    fmt = fmt.lower()
    if fmt not in ("stl", "obj", "ply", "glb"):
        raise BackendError(f"unknown mesh format {fmt!r}; choose stl, obj, ply or glb")
    tol = model.tolerance if tol is None else tol
    vertices, triangles = tessellate(model, tol, angle_tol)
    import trimesh

    data = trimesh.Trimesh(vertices, triangles, process=False).export(file_type=fmt)
    out = write_atomic(path, data)
    if report is not None:
        bad = open_edges(triangles)
        angle = f", normals within {np.degrees(angle_tol):g} deg" if angle_tol else ""
        report(f"{len(triangles)} triangles, {len(vertices)} vertices, chordal deviation <= {tol:g} {model.units} "
               f"(measured on every triangle){angle}; "
               + ("watertight" if bad == 0 else f"{bad} open or non-manifold edges (open surfaces have a border)"))
    return out
