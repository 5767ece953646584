"""Boundary pieces of faces and the edges they form: grouping of coincident pieces, sampling to a
chordal tolerance, and the vertices every face on an edge shares.

A piece is a face's boundary curve in the face's (u, v), uv(s) for s in [0, 1]. Pieces whose 3-D images
coincide (the shared edge of two faces of a shell, the seam of a closed surface) form one group; the
group is sampled once, on its representative piece, so that every face using the edge gets the same
vertices and closed solids come out watertight. Degenerate pieces (poles) are one vertex.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rgm.errors import BackendError

from .mesh_surface import Patch, evaluate_together, project_together

#: sampled chords must be within CERTIFY * tol: the margin covers the maximum falling between samples
CERTIFY = 0.98


@dataclass
class Piece:
    """One boundary piece of a face: uv(s) for s in [0, 1] on `patch`, with derivative breaks.
    `domain_side`: a side of the patch's parameter rectangle, sampled in equal steps per knot span as
    the face's initial grid lines are (`rgm.backends.mesh._grid`), so the grid meets it at its samples."""

    patch: Patch
    uv: object
    breaks: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0]))
    domain_side: bool = False

    def xyz(self, s) -> np.ndarray:
        uv = self.uv(np.clip(np.asarray(s, float), 0.0, 1.0))
        return self.patch.evaluate(uv[:, 0], uv[:, 1])

def uv_of(pieces, params) -> list:
    """[uv (k_i, 2)] of pieces[i] at parameters params[i] (k_i,) (clipped into [0, 1]). Pieces that
    follow a 3-D curve's closest points on their patch (`rgm.backends.mesh_faces._Projected`) are
    projected together, one Gauss-Newton run for all of them on each stack of patches
    (`rgm.backends.mesh_surface.project_together`): a part's trimming curves would otherwise cost one run
    per piece and call."""
    from .mesh_faces import ITERATIONS, _Projected

    params = [np.clip(np.asarray(s, float), 0.0, 1.0) for s in params]
    out = [None] * len(pieces)
    projected = []
    for i, p in enumerate(pieces):
        if isinstance(p.uv, _Projected):
            projected.append(i)
        else:
            out[i] = p.uv(params[i])
    starts = [pieces[i].uv.start(params[i]) for i in projected]
    found = project_together([pieces[i].uv.patch for i in projected], [x for x, _ in starts], [g for _, g in starts],
                             ITERATIONS)
    for i, (x, _), (u, d) in zip(projected, starts, found):
        out[i] = pieces[i].uv.finish(params[i], x, u, d)
    return out


def xyz_of(pieces, params) -> list:
    """[xyz (k_i, 3)] of pieces[i] at parameters params[i] (k_i,): the (u, v) of all pieces (`uv_of`),
    evaluated together (`rgm.backends.mesh_surface.evaluate_together`: sub-patches between creases share
    their surface's evaluation, NURBS patches of one kind are stacked) rather than one call per piece,
    which is what small models spend their time on."""
    return evaluate_together([p.patch for p in pieces], uv_of(pieces, params))


def _cut(a, b, k) -> np.ndarray:
    """The inner points of intervals [a, b] (m,) each cut into k (m,) equal parts, concatenated."""
    k = np.asarray(k, int)
    which = np.repeat(np.arange(len(k)), k - 1)
    j = np.arange(len(which)) - np.repeat(np.cumsum(k - 1) - (k - 1), k - 1) + 1
    return ((b - a)[which] / k[which]) * j + a[which]   # as np.linspace computes them


#: an inner break of a piece where its tangent turns by more than this (radians) keeps a sample (a corner)
_CORNER = np.radians(1.0)


def _corners(pts) -> np.ndarray:
    """(spans - 1,) whether the tangent turns at each inner break, from probes pts (spans, k, 3) (one-sided
    second-order differences: on a smooth curve they agree to the square of the probe step)."""
    t_end = 3 * pts[:-1, -1] - 4 * pts[:-1, -2] + pts[:-1, -3]
    t_start = -3 * pts[1:, 0] + 4 * pts[1:, 1] - pts[1:, 2]
    n = np.linalg.norm(t_end, axis=1) * np.linalg.norm(t_start, axis=1)
    return np.einsum("ij,ij->i", t_end, t_start) < np.cos(_CORNER) * n


def _equidistributed(b, w, corner) -> np.ndarray:
    """Inner samples of a piece with breaks b (m + 1,) given w (m, k), the chords each of k equal probe
    steps per span needs (sqrt of its sagitta over the limit: the sagitta scales as the square of the
    step), and the inner breaks that are corners (m - 1,). Between corners (where a sample stays) the
    piece gets ceil(sum w) chords at equal shares of the cumulative need (linear within a probe step):
    shorter where the curve bends more or runs faster in its parameter, and smooth knots are crossed
    rather than rounded up to on each side."""
    k = w.shape[1]
    s = np.append((b[:-1, None] + np.diff(b)[:, None] * (np.arange(k) / k)[None, :]).ravel(), b[-1])
    need = w.ravel()
    at = np.flatnonzero(corner) + 1
    cuts = np.concatenate([[0], at * k, [len(need)]])
    out = [b[at]]
    for lo, hi in zip(cuts[:-1], cuts[1:]):
        run = need[lo:hi]
        total = run.sum()
        n = max(1, int(np.ceil(total - 1e-9)))
        if n > 1:
            run = np.maximum(run, 1e-6 * total)                          # strictly increasing shares
            share = np.concatenate([[0.0], np.cumsum(run)]) / run.sum()
            out.append(np.interp(np.arange(1, n) / n, share, s[lo:hi + 1]))
    return np.concatenate(out)


def _sample_pieces(pieces, tol, sides) -> list:
    """Parameters s (k,) in [0, 1] per piece such that every chord of the piece's 3-D image is within
    `tol` of it (point-to-segment distance at 3 inner points per chord). A piece starts with the chords
    its sagittas over 16 probe steps per span call for, equidistributed between its corners
    (`_equidistributed`), or, where `sides` says it runs along a face's domain side, in equal steps per
    span; a chord still failing by d is cut into ceil(sqrt(d / tol)) equal parts. All pieces are
    sampled together: one `xyz_of` per round."""
    limit = CERTIFY * tol
    fine = np.linspace(0, 1, 33)
    spans = [p.breaks for p in pieces]
    probes = xyz_of(pieces, [(b[:-1, None] + np.diff(b)[:, None] * fine[None, :]).ravel() for b in spans])
    # the sagittas and corners of every piece's spans at once (one call each, not one per piece)
    pts = np.concatenate(probes).reshape(-1, 33, 3)                               # (all spans, 33, 3)
    need = np.sqrt(segment_distance(pts[:, 1::2], pts[:, 0:-1:2], pts[:, 2::2]) / limit)   # (all spans, 16)
    turn = _corners(pts)              # across consecutive spans; those across two pieces are not used
    first = np.cumsum([0] + [len(b) - 1 for b in spans])
    out = []
    for b, lo, hi, side in zip(spans, first[:-1], first[1:], sides):
        w = need[lo:hi]
        if side:   # equal steps per span, sized by its neediest probe step (as the grid lines are)
            inner = np.concatenate([b[1:-1], _cut(b[:-1], b[1:], np.maximum(1, np.ceil(16 * w.max(axis=1))))])
        else:
            inner = _equidistributed(b, w, turn[lo:hi - 1])
        out.append(np.unique(np.concatenate([b[[0, -1]], inner])))
    fr = np.array([0.25, 0.5, 0.75])
    active = list(range(len(pieces)))
    for _ in range(40):
        if not active:
            return out
        at = [np.concatenate([out[i], (out[i][:-1, None] + np.diff(out[i])[:, None] * fr).ravel()]) for i in active]
        still = []
        for i, xyz in zip(active, xyz_of([pieces[i] for i in active], at)):
            s = out[i]
            p, q = xyz[:len(s)], xyz[len(s):].reshape(len(s) - 1, 3, 3)
            dev = segment_distance(q, p[:-1, None], p[1:, None]).max(axis=1)
            bad = dev > limit
            if bad.any():
                k = np.clip(np.ceil(np.sqrt(dev[bad] / limit)), 2, 64).astype(int)
                out[i] = np.unique(np.concatenate([s, _cut(s[:-1][bad], s[1:][bad], k)]))
                still.append(i)
        active = still
    raise BackendError("a boundary curve could not be sampled to the tolerance")


def segment_distance(q, a, b):
    """Distances of points q (..., 3) to segments [a, b] (broadcast)."""
    ab = b - a
    t = np.clip(((q - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-300), 0, 1)
    return np.linalg.norm(q - (a + t[..., None] * ab), axis=-1)


def _parallel(a, b, eps):
    """Whether two pieces' probes (17, 3) at the same parameters coincide within eps as they are (True) or
    with one reversed (False); None when neither: the pieces are parameterised differently (or differ).
    Coincident edges of a shell and the two sides of a seam are usually the same curve, and then a
    member's parameters are its representative's, with no inversion."""
    if np.abs(a - b).max() < eps:
        return True
    if np.abs(a - b[::-1]).max() < eps:
        return False
    return None


def _invert(piece, pts, iterations=8):
    """Parameters s (k,) of the points of piece closest to pts (k, 3): nearest of 513 samples, then up to
    `iterations` Newton steps on (C(s) - X) . C'(s) = 0 with central differences (one batched
    evaluation per step), stopping once no parameter moves by more than 1e-13."""
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
        if np.abs(step).max(initial=0.0) < 1e-13:
            break
    return s, np.linalg.norm(piece.xyz(s) - pts, axis=1)[:k]


class Edges:
    """Groups of coincident pieces, sampled once; global vertices."""

    def __init__(self, faces, tol, eps):
        from scipy.sparse.csgraph import connected_components
        from scipy.sparse import coo_matrix
        from scipy.spatial import cKDTree

        self.tol, self.eps = tol, eps
        self.pieces = [p for f in faces for loop in f.loops for p in loop]
        probe = np.stack(xyz_of(self.pieces, [np.linspace(0, 1, 17)] * len(self.pieces)))   # (pieces, 17, 3)
        ends = probe[:, [0, -1]].reshape(-1, 3)
        pairs = cKDTree(ends).query_pairs(eps, output_type="ndarray")
        n = len(ends)
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n)) if len(pairs) \
            else coo_matrix((n, n))
        _, label = connected_components(graph, directed=False)
        _, corner = np.unique(label, return_inverse=True)
        self.corner = corner.reshape(-1, 2)                          # (pieces, 2) corner ids
        self.vertices = [ends[np.unique(corner, return_index=True)[1]]]
        self.nvert = len(self.vertices[0])
        lengths = np.linalg.norm(np.diff(probe, axis=1), axis=2).sum(axis=1)
        self.degenerate = lengths < eps
        self.group = -np.ones(len(self.pieces), int)
        self.same_dir = np.ones(len(self.pieces), bool)
        reps = []
        ends_of = {}   # pieces by their pair of corners: only those can coincide
        for i in np.flatnonzero(~self.degenerate).tolist():
            ends_of.setdefault(tuple(sorted(self.corner[i].tolist())), []).append(i)
        for i, p in enumerate(self.pieces):
            if self.degenerate[i] or self.group[i] >= 0:
                continue
            self.group[i] = len(reps)
            reps.append(i)
            for j in ends_of[tuple(sorted(self.corner[i].tolist()))]:
                if j <= i or self.group[j] >= 0:
                    continue
                same = _parallel(probe[i], probe[j], eps)   # same parameterisation, either way round
                if same is None:
                    sq, dq = _invert(p, probe[j, 4:13:4])
                    same = sq[2] > sq[0] if dq.max() < eps else None
                if same is not None:
                    self.group[j] = self.group[i]
                    self.same_dir[j] = same
        self.reps = reps
        self.version = np.zeros(len(reps), int)
        sides = np.zeros(len(reps), bool)            # groups with a member along a face's domain side
        member = self.group >= 0
        np.logical_or.at(sides, self.group[member], np.array([p.domain_side for p in self.pieces])[member])
        self.rep_s = _sample_pieces([self.pieces[r] for r in reps], tol, sides)
        self.rep_ids = [None] * len(reps)
        self.member_s = {}
        self._assign_ids()

    def _assign_ids(self):
        """Vertex ids of every group sampled anew, and each member piece's parameters at its
        representative's samples (the same parameters, reversed or not, when they land on the samples;
        else closest points); the new samples of all groups evaluated together."""
        todo = [g for g, ids in enumerate(self.rep_ids) if ids is None or len(ids) != len(self.rep_s[g])]
        inner = xyz_of([self.pieces[self.reps[g]] for g in todo], [self.rep_s[g][1:-1] for g in todo])
        members, guesses, targets = [], [], []
        for g, pts in zip(todo, inner):
            r, s = self.reps[g], self.rep_s[g]
            ids = np.concatenate([[self.corner[r, 0]], self.nvert + np.arange(len(pts)), [self.corner[r, 1]]])
            self.vertices.append(pts)
            self.nvert += len(pts)
            self.rep_ids[g] = ids
            self.member_s[r] = s
            for j in np.flatnonzero(self.group == g):
                if j != r:
                    members.append(j)
                    guesses.append(s if self.same_dir[j] else 1.0 - s)
                    targets.append(np.concatenate([self.vertices[0][ids[:1]], pts, self.vertices[0][ids[-1:]]]))
        for j, sj, pts, xyz in zip(members, guesses, targets, xyz_of([self.pieces[j] for j in members], guesses)):
            if np.abs(xyz - pts).max() >= self.eps:   # not the same parameterisation
                sj, _ = _invert(self.pieces[j], pts)
            sj = sj.copy()
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
        """(s (k,), vertex ids (k,), group, rep indices (k,)) of piece j, in the piece's direction; a
        degenerate piece (a pole) takes the parameters `degenerate_s` (unused, may be None, otherwise)."""
        if self.degenerate[j]:
            s = degenerate_s
            return s, np.full(len(s), self.corner[j, 0]), -1, np.zeros(len(s), int)
        g = self.group[j]
        sj = self.member_s[j]
        idx = np.arange(len(sj))
        if not self.same_dir[j]:
            sj, idx = sj[::-1], idx[::-1]
        return sj, self.rep_ids[g][idx], g, idx
