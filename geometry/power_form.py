"""Per-span power form of B-spline and NURBS curves and surfaces: a fast evaluator for many parameters.

On each non-empty knot span (span pair) the basis functions are polynomials; their coefficients, combined
with the control points (homogeneous, for rational forms), give per-span polynomial coefficients, so a
point and its first derivatives are a span lookup and a Horner evaluation: no basis recursion per call.
The polynomials are Taylor expansions about the span midpoints (`_span_matrices`), so points and
first derivatives agree with `rgm.geometry`'s evaluators to round-off on spans of any length (tested in
tests/backends/test_mesh_tessellate.py). Parameters are clipped into the domain, not validated: this is
for internal hot paths (the mesher's refinement), not for user input. Degrees above _POWER_MAX_DEGREE
are left to the exact evaluators.
"""
from __future__ import annotations

from bisect import bisect_right
from functools import lru_cache

import numpy as np

from rgm.geometry.basis import basis_derivatives_t

__all__ = ["power_form", "SurfaceStack", "key"]

#: highest degree converted to the per-span power form (the Taylor form is as accurate as the exact
#: evaluators up to it, tested); higher degrees use the exact evaluators
_POWER_MAX_DEGREE = 8
#: parameter pairs per block of the power-form evaluator (the gathered coefficients stay in cache)
_POWER_CHUNK = 4096


def _span_matrices(knots, degree):
    """(breaks (s+1,), M (s, p+1, p+1), spans (s,) knot indices): on non-empty span k the basis functions
    N_{span-p+r} are sum_a M[k, r, a] x^a with x = (t - c) / h in [-1/2, 1/2], c and h the span's
    midpoint and length.

    M is the Taylor expansion about the midpoint, M[k, r, a] = h^a / a! N_r^(a)(c), from the basis
    derivatives (A2.3): every coefficient carries rounding relative to its own size (about h^a times an
    a-th derivative), so d/dt = (1/h) d/dx is as accurate as A2.3's on a span of any length. Coefficients
    interpolated from values at nodes of the span (a Vandermonde solve) carry rounding of the size of the
    values in every coefficient, which the 1/h amplifies: Su off by 2e-9 (exact 41) on a degree-5 span
    5e-4 long (seed 124 of the power-form test in tests/backends/test_mesh_tessellate.py). The midpoint
    keeps |x|^a <= 2^-a: expanded about the span's start (x in [0, 1]) the coefficients are larger, and
    the long spans of that surface lost 7e-12 in Su and 6e-13 in the points (6e-14 and 5e-15 here)."""
    knots = np.asarray(knots, float)
    return _span_matrices_of(knots.tobytes(), degree)


@lru_cache(maxsize=256)
def _span_matrices_of(key: bytes, p: int):
    """`_span_matrices` of the knot vector whose float64 bytes are `key`: kept, since a part's trimming
    curves share a few knot vectors (lines, arcs) and each is put in power form (read-only results)."""
    knots = np.frombuffer(key, float)
    lo, hi = knots[p], knots[len(knots) - p - 1]
    breaks = np.unique(knots[(knots >= lo) & (knots <= hi)])
    spans = np.searchsorted(knots, breaks[:-1], side="right") - 1
    ders = basis_derivatives_t(knots, p, _midpoints(breaks), p, spans)      # (a, r, s)
    a = np.arange(p + 1)
    scale = np.diff(breaks)[None, :] ** a[:, None] / np.cumprod(np.maximum(a, 1))[:, None]   # h^a / a!
    return breaks, (ders * scale[:, None, :]).transpose(2, 1, 0), spans


def _midpoints(breaks):
    """The midpoints (s,) of the spans between breaks (s+1,): the expansion points of the power form."""
    return 0.5 * (breaks[:-1] + breaks[1:])


class _Spans:
    """The breaks of one parameter direction, set up once for `locate`: the inner breaks (a searchsorted
    over them gives the span with no clipping of the result), the span midpoints and the reciprocal span
    lengths."""

    def __init__(self, breaks):
        self.lo, self.hi = float(breaks[0]), float(breaks[-1])
        self.inner = np.ascontiguousarray(breaks[1:-1])
        self.mid = _midpoints(breaks)
        self.inv = 1.0 / np.diff(breaks)
        self.lists = (self.inner.tolist(), self.mid.tolist(), self.inv.tolist())

    def locate_one(self, t: float):
        """`locate` of one parameter, in Python floats (the same operations, so the same values)."""
        inner, mid, inv = self.lists
        t = min(max(t, self.lo), self.hi)
        k = bisect_right(inner, t)
        return k, (t - mid[k]) * inv[k], inv[k]

    def locate(self, t):
        """(span (m,), local x (m,) in [-1/2, 1/2], 1 / span length (m,)) of parameters t (m,) clipped into
        [breaks[0], breaks[-1]] (np.minimum/np.maximum: np.clip's dispatch costs more on small arrays)."""
        t = np.minimum(np.maximum(t, self.lo), self.hi)
        k = np.searchsorted(self.inner, t, side="right")
        inv = self.inv[k]
        return k, (t - self.mid[k]) * inv, inv


def _horner(c, x, n):
    """sum_a c[a] x^a (a = 0..n) for coefficients c (n+1, ..., m) and x (m,); in place on one copy
    (no temporary per step)."""
    out = c[n].copy()
    for a in range(n - 1, -1, -1):
        out *= x
        out += c[a]
    return out


def _horner_d(c, x, n):
    """d/dx of `_horner(c, x, n)`: sum_a a c[a] x^(a-1)."""
    if n == 0:
        return np.zeros_like(c[0])
    out = c[n] * float(n)
    for a in range(n - 1, 0, -1):
        out *= x
        out += c[a] * float(a)
    return out


class _CurvePower:
    """A NurbsCurve in per-span power form over its homogeneous coordinates."""

    def __init__(self, curve):
        self.p = curve.degree
        breaks, m, spans = _span_matrices(curve.knots, curve.degree)
        self.spans = _Spans(breaks)
        win = curve.homogeneous[spans[:, None] - self.p + np.arange(self.p + 1)[None, :]]   # (s, r, c)
        self.nc = win.shape[-1]
        coef = np.einsum("sra,src->sac", m, win).reshape(len(spans), -1)
        self.flat_t = np.ascontiguousarray(coef.T)                           # (a, c) x span
        self.rational = curve.is_rational

    def d(self, t, order):
        """Points (m, d) and, for order 1, first derivatives (m, d). The coefficients are gathered
        point-last (a, c, m), as for surfaces."""
        k, x, inv = self.spans.locate(np.asarray(t, float))
        c = self.flat_t.take(k, axis=1).reshape(self.p + 1, self.nc, len(k))
        h = _horner(c, x, self.p)                                            # (c, m)
        pt = h[:-1] / h[-1] if self.rational else h[:-1]
        if not order:
            return pt.T, None
        hd = _horner_d(c, x, self.p)
        hd *= inv
        if self.rational:
            return pt.T, ((hd[:-1] - hd[-1] * pt) / h[-1]).T
        return pt.T, hd[:-1].T


class _SurfacePower:
    """A NurbsSurface in per-span-pair power form over its homogeneous coordinates."""

    def __init__(self, surface):
        p, q = self.p, self.q = surface.degree_u, surface.degree_v
        bu, mu, su = _span_matrices(surface.knots_u, p)
        bv, mv, sv = _span_matrices(surface.knots_v, q)
        self.spans_u, self.spans_v = _Spans(bu), _Spans(bv)
        pw = surface.homogeneous                                             # (nu, nv, 4)
        iu = su[:, None] - p + np.arange(p + 1)[None, :]
        iv = sv[:, None] - q + np.arange(q + 1)[None, :]
        win = pw[iu[:, None, :, None], iv[None, :, None, :]]                 # (su, sv, r, s, 4)
        coef = np.einsum("ira,jsb,ijrsc->ijabc", mu, mv, win)               # (su, sv, a, b, 4)
        self.rational = surface.is_rational
        if not self.rational:
            coef = coef[..., :3]
        self.nsv = len(sv)
        self.nc = coef.shape[-1]
        self.flat_t = np.ascontiguousarray(coef.reshape(len(su) * len(sv), -1).T)   # (a, b, c) x span pair

    def d(self, u, v, order):
        """Points (m, 3) and, for order 1, the partials Su, Sv (m, 3) (blocks of _POWER_CHUNK)."""
        return _in_blocks(self._block, (np.asarray(u, float), np.asarray(v, float)), order)

    def _block(self, u, v, order):
        """`d` on one block."""
        ku, xu, iu = self.spans_u.locate(u)
        kv, xv, iv = self.spans_v.locate(v)
        return _pairs(self, ku * self.nsv + kv, xu, iu, xv, iv, order)

    def d1_one(self, u: float, v: float):
        """`d(u, v, 1)` of one parameter pair: ((1, 3), (1, 3), (1, 3)), the same values. Marching an
        intersection asks for one point at a time, where numpy's per-call cost is most of `d`'s: this
        runs the same Horner steps in Python floats, in the same order (so the same roundings)."""
        p, q, nc = self.p, self.q, self.nc
        ku, xu, iu = self.spans_u.locate_one(u)
        kv, xv, iv = self.spans_v.locate_one(v)
        c = self.flat_t[:, ku * self.nsv + kv].tolist()          # (a, b, c) flattened
        m = (q + 1) * nc                                          # stride of one power of x_u in c
        row, row_d = [], []                                       # in u, per (b, c): value, d/dx_u
        for j in range(m):
            out = c[p * m + j]
            for a in range(p - 1, -1, -1):
                out = out * xu + c[a * m + j]
            row.append(out)
            if p == 0:
                row_d.append(0.0)
                continue
            out = c[p * m + j] * float(p)
            for a in range(p - 1, 0, -1):
                out = out * xu + c[a * m + j] * float(a)
            row_d.append(out)
        h, hu, hv = [], [], []
        for k in range(nc):                                        # in v, per coordinate
            out, out_u = row[q * nc + k], row_d[q * nc + k]
            for b in range(q - 1, -1, -1):
                out = out * xv + row[b * nc + k]
                out_u = out_u * xv + row_d[b * nc + k]
            h.append(out)
            hu.append(out_u * iu)
            if q == 0:
                hv.append(0.0 * iv)
                continue
            out = row[q * nc + k] * float(q)
            for b in range(q - 1, 0, -1):
                out = out * xv + row[b * nc + k] * float(b)
            hv.append(out * iv)
        if self.rational:
            w = h[3]
            pt = [h[0] / w, h[1] / w, h[2] / w]
            su = [(hu[i] - hu[3] * pt[i]) / w for i in range(3)]
            sv = [(hv[i] - hv[3] * pt[i]) / w for i in range(3)]
            return np.array([pt]), np.array([su]), np.array([sv])
        return np.array([h]), np.array([hu]), np.array([hv])


def _in_blocks(block, args, order):
    """block(*args, order) over blocks of _POWER_CHUNK parameters (the gathered coefficients stay in
    cache), the three results concatenated."""
    if len(args[0]) <= _POWER_CHUNK:
        return block(*args, order)
    parts = [block(*(a[s:s + _POWER_CHUNK] for a in args), order) for s in range(0, len(args[0]), _POWER_CHUNK)]
    return tuple(None if parts[0][i] is None else np.concatenate([b[i] for b in parts]) for i in range(3))


def _pairs(form, cols, xu, iu, xv, iv, order):
    """Points (m, 3) and, for order 1, Su, Sv of a surface power form (`_SurfacePower`, `SurfaceStack`)
    at span pairs `cols` (m,) (columns of its flat_t), local x and reciprocal span lengths per direction.
    The coefficients are gathered point-last, (a, b, c, m): every Horner step is then one pass over
    contiguous rows of m values (point-first, a step loops over short rows of (b, c) per point, about
    twice the time from a few hundred points on)."""
    p, q = form.p, form.q
    c = form.flat_t.take(cols, axis=1).reshape(p + 1, q + 1, form.nc, len(cols))
    row = _horner(c, xu, p)                                      # in u: (b, c, m)
    h = _horner(row, xv, q)                                      # (c, m)
    pt = h[:3] / h[3] if form.rational else h
    if not order:
        return pt.T, None, None
    hu = _horner(_horner_d(c, xu, p), xv, q)
    hv = _horner_d(row, xv, q)
    hu *= iu
    hv *= iv
    if form.rational:
        w = h[3]
        return pt.T, ((hu[:3] - hu[3] * pt) / w).T, ((hv[:3] - hv[3] * pt) / w).T
    return pt.T, hu.T, hv.T


class _StackedSpans:
    """The `_Spans` of several surfaces in one direction, located together: parameter t of surface w is
    keyed w + (t - lo_w) / (hi_w - lo_w) (times 1 - 1e-9, below the next surface's keys), and one
    searchsorted over all surfaces' keyed inner breaks, less the count of the surfaces before w, gives
    the span within w. Keys are computed alike for breaks and parameters, so a parameter on a break
    lands on the span after it, as in `_Spans.locate`; the local x comes from w's own breaks."""

    def __init__(self, spans):
        self.lo = np.array([s.lo for s in spans])
        self.hi = np.array([s.hi for s in spans])
        self.scale = (1 - 1e-9) / (self.hi - self.lo)
        counts = np.array([len(s.inner) for s in spans])
        self.before = np.concatenate([[0], np.cumsum(counts)[:-1]])
        self.keys = np.concatenate([w + (s.inner - s.lo) * self.scale[w] for w, s in enumerate(spans)])
        self.first = np.concatenate([[0], np.cumsum(counts + 1)[:-1]])   # each surface's first span
        self.mid = np.concatenate([s.mid for s in spans])
        self.inv = np.concatenate([s.inv for s in spans])

    def locate(self, which, t):
        """(span within its surface (m,), local x (m,), 1 / span length (m,)) of t (m,) on surfaces `which`."""
        lo = self.lo[which]
        t = np.minimum(np.maximum(t, lo), self.hi[which])
        k = np.searchsorted(self.keys, which + (t - lo) * self.scale[which], side="right") - self.before[which]
        g = self.first[which] + k
        inv = self.inv[g]
        return k, (t - self.mid[g]) * inv, inv


class SurfaceStack:
    """Power forms of several surfaces of one kind (degrees, rational or not: `key`) evaluated in one
    call, each point naming its surface: the many small surfaces of a part (a plate's holes) cost one
    span lookup and one Horner pass, not one per surface."""

    def __init__(self, forms):
        first = forms[0]
        if any(key(f) != key(first) for f in forms):
            raise ValueError("a SurfaceStack holds surfaces of one degree pair and kind")
        self.p, self.q, self.nc, self.rational = first.p, first.q, first.nc, first.rational
        self.spans_u = _StackedSpans([f.spans_u for f in forms])
        self.spans_v = _StackedSpans([f.spans_v for f in forms])
        self.nsv = np.array([f.nsv for f in forms])
        self.pair0 = np.concatenate([[0], np.cumsum([f.flat_t.shape[1] for f in forms])[:-1]])
        self.flat_t = np.concatenate([f.flat_t for f in forms], axis=1)

    def d(self, which, u, v, order):
        """Points (m, 3) and, for order 1, Su, Sv (m, 3) of surfaces `which` (m,) at (u, v)."""
        return _in_blocks(self._block, (np.asarray(which, np.intp), np.asarray(u, float), np.asarray(v, float)),
                          order)

    def _block(self, which, u, v, order):
        ku, xu, iu = self.spans_u.locate(which, u)
        kv, xv, iv = self.spans_v.locate(which, v)
        return _pairs(self, self.pair0[which] + ku * self.nsv[which] + kv, xu, iu, xv, iv, order)


def key(form) -> tuple:
    """What surface power forms must share to be stacked (`SurfaceStack`): degrees and kind."""
    return form.p, form.q, form.nc, form.rational


def power_form(obj):
    """The power form of a NurbsSurface or NurbsCurve, or None above _POWER_MAX_DEGREE (use its own
    evaluator then)."""
    surface = hasattr(obj, "degree_u")
    degrees = (obj.degree_u, obj.degree_v) if surface else (obj.degree,)
    if max(degrees) > _POWER_MAX_DEGREE:
        return None
    return _SurfacePower(obj) if surface else _CurvePower(obj)
