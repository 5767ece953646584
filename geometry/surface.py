"""NURBS tensor-product surfaces: immutable, evaluated over whole parameter arrays.

Data layout: control net `ctrl (nu, nv, 3)` indexed [i_u, j_v], weights `(nu, nv)` or None
(polynomial), knot vectors `knots_u (nu+p+1,)`, `knots_v (nv+q+1,)`. The homogeneous net
`(w*P, w)` of shape (nu, nv, 4) is kept for evaluation and knot operations.

Paired evaluation (`evaluate`, `derivatives`) works on blocks of `_CHUNK` parameter pairs, all in
point-last layout so that every numpy pass runs over a contiguous (m,) row:

1. spans by `np.searchsorted` (A2.1) and the (p+1) and (q+1) non-zero basis values (A2.2, or A2.3
   for derivatives) of every point at once, shapes (p+1, m) and (q+1, m);
2. one gather of each point's (p+1) x (q+1) window from the coordinate-major net `(c, nu*nv)`,
   giving (c, p+1, q+1, m) for c = 3 (polynomial) or 4 (homogeneous) coordinates;
3. the tensor-product sum S = sum_i N_i(u) sum_j N_j(v) P_ij (A3.5; A4.3 divides the homogeneous
   sum by w) contracted one direction at a time: v first, (c, p+1, q+1, m) -> (c, p+1, m), then
   u -> (c, m).

A block's window is c (p+1)(q+1) m doubles (3-4 MB for bicubic blocks of 8192, the fastest size
measured on a 1 MB L2 / 32 MB L3 machine), so memory is bounded for any number of points.
Grids use two sparse basis matrices.
"""
from __future__ import annotations

from math import comb

import numpy as np

from rgm.errors import GeometryError

from . import _validate as V
from .basis import basis_derivatives_t, basis_functions_t, basis_matrix, find_spans

__all__ = ["NurbsSurface"]

_CHUNK = 1 << 13     # parameter pairs per block: the gathered windows stay in cache (measured best)


def _rational_surface_derivatives(h: np.ndarray, order: int) -> np.ndarray:
    """Euclidean partials from homogeneous ones (Piegl & Tiller A4.4).

    h : (order+1, order+1, m, 4) homogeneous partials [k, l] = d^{k+l}/du^k dv^l (w*S, w).
    Returns (order+1, order+1, m, 3); entries with k + l > order are left zero.
    """
    a, w = h[..., :3], h[..., 3:]
    out = np.zeros_like(a)
    for k in range(order + 1):
        for l in range(order - k + 1):
            v = a[k, l].copy()
            for j in range(1, l + 1):
                v -= comb(l, j) * w[0, j] * out[k, l - j]
            for i in range(1, k + 1):
                v -= comb(k, i) * w[i, 0] * out[k - i, l]
                v2 = np.zeros_like(v)
                for j in range(1, l + 1):
                    v2 += comb(l, j) * w[i, j] * out[k - i, l - j]
                v -= comb(k, i) * v2
            out[k, l] = v / w[0, 0]
    return out


class NurbsSurface:
    """A (rational) tensor-product B-spline surface; see the module docstring for the layout.

    Raises GeometryError when knots, control net or weights are inconsistent.
    """

    __slots__ = ("degree_u", "degree_v", "knots_u", "knots_v", "ctrl", "weights", "_pw", "_coords")

    def __init__(self, degree_u, degree_v, knots_u, knots_v, ctrl, weights=None):
        degree_u = V.check_degree(degree_u, "degree_u")
        degree_v = V.check_degree(degree_v, "degree_v")
        ctrl = V.check_points(ctrl, "(nu, nv, 3)", (3,), 3)
        nu, nv = ctrl.shape[:2]
        knots_u = V.check_knots(knots_u, degree_u, nu, "knots_u")
        knots_v = V.check_knots(knots_v, degree_v, nv, "knots_v")
        weights = V.check_weights(weights, (nu, nv))
        w = np.ones((nu, nv)) if weights is None else weights
        pw = V.frozen(np.concatenate([ctrl * w[..., None], w[..., None]], axis=2))
        coords = V.frozen(pw.reshape(-1, 4).T)      # (4, nu*nv) coordinate-major, for gathers
        values = (degree_u, degree_v, knots_u, knots_v, ctrl, weights, pw, coords)
        for name, value in zip(self.__slots__, values):
            object.__setattr__(self, name, value)

    def __setattr__(self, name, value):
        raise AttributeError("NurbsSurface is immutable; operations return new surfaces")

    def __reduce__(self):
        """Pickled by its defining data, rebuilt (and checked) by the constructor (see NurbsCurve)."""
        return type(self), (self.degree_u, self.degree_v, self.knots_u, self.knots_v, self.ctrl, self.weights)

    @classmethod
    def from_homogeneous(cls, degree_u, degree_v, knots_u, knots_v, pw, rational=True) -> "NurbsSurface":
        """Build from a homogeneous net `pw (nu, nv, 4)` = (w*P, w)."""
        pw = np.asarray(pw, dtype=float)
        w = pw[..., -1]
        if np.any(w <= 0):
            raise GeometryError("homogeneous control net needs positive weights")
        return cls(degree_u, degree_v, knots_u, knots_v, pw[..., :-1] / w[..., None],
                   w if rational else None)

    # -- properties --------------------------------------------------------------------------
    @property
    def nu(self) -> int:
        return self.ctrl.shape[0]

    @property
    def nv(self) -> int:
        return self.ctrl.shape[1]

    @property
    def dim(self) -> int:
        return 3

    @property
    def is_rational(self) -> bool:
        return self.weights is not None

    @property
    def homogeneous(self) -> np.ndarray:
        """Read-only homogeneous control net (nu, nv, 4)."""
        return self._pw

    @property
    def domain(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """((u0, u1), (v0, v1))."""
        return ((float(self.knots_u[self.degree_u]), float(self.knots_u[self.nu])),
                (float(self.knots_v[self.degree_v]), float(self.knots_v[self.nv])))

    def __repr__(self) -> str:
        kind = "rational" if self.is_rational else "polynomial"
        (u0, u1), (v0, v1) = self.domain
        return (f"NurbsSurface(degree=({self.degree_u}, {self.degree_v}), net={self.nu}x{self.nv}, "
                f"{kind}, domain=(({u0:g}, {u1:g}), ({v0:g}, {v1:g})))")

    # -- evaluation --------------------------------------------------------------------------
    def _params(self, u, v):
        (du, dv) = self.domain
        u = V.check_params(u, du, "u")
        v = V.check_params(v, dv, "v")
        if u.shape != v.shape:
            raise GeometryError(f"u and v must pair up: shapes {u.shape} and {v.shape}")
        return u, v

    def _windows(self, su, sv, ncoord: int) -> np.ndarray:
        """Each pair's control window: (ncoord, p+1, q+1, m), `[c, i, j, k]` = Pw[su_k-p+i, sv_k-q+j, c].

        su, sv : (m,) spans. One `take` from the coordinate-major net with a (p+1)(q+1) x m index.
        """
        p, q = self.degree_u, self.degree_v
        corner = (su - p) * self.nv + (sv - q)
        offsets = (np.arange(p + 1)[:, None] * self.nv + np.arange(q + 1)[None, :]).reshape(-1, 1)
        windows = self._coords[:ncoord].take(corner[None, :] + offsets, axis=1)
        return windows.reshape(ncoord, p + 1, q + 1, su.shape[0])

    def _evaluate_block(self, u, v, ncoord: int) -> np.ndarray:
        """Homogeneous (ncoord = 4) or polynomial (3) coordinates of one block: (ncoord, m).

        u, v : (m,). Spans, basis rows (p+1, m) and (q+1, m), the windows, then A3.5's double sum
        contracted one direction at a time (see the module docstring).
        """
        p, q = self.degree_u, self.degree_v
        su = find_spans(self.knots_u, p, u)
        sv = find_spans(self.knots_v, q, v)
        bu = basis_functions_t(self.knots_u, p, u, su)
        bv = basis_functions_t(self.knots_v, q, v, sv)
        rows = np.einsum("cijm,jm->cim", self._windows(su, sv, ncoord), bv)
        return np.einsum("cim,im->cm", rows, bu)

    def evaluate(self, u, v) -> np.ndarray:
        """Points S(u_i, v_i) for paired parameter arrays u, v (m,); returns (m, 3).

        Blocks of `_CHUNK` pairs (module docstring); rational surfaces divide by w per block.
        """
        u, v = self._params(u, v)
        ncoord = 4 if self.is_rational else 3
        out = np.empty((u.shape[0], 3))
        for s in range(0, u.shape[0], _CHUNK):
            h = self._evaluate_block(u[s:s + _CHUNK], v[s:s + _CHUNK], ncoord)
            out[s:s + _CHUNK] = (h[:3] / h[3] if ncoord == 4 else h).T
        return out

    def evaluate_grid(self, u, v) -> np.ndarray:
        """Points on the tensor grid u (a,) x v (b,); returns (a, b, 3) with [i, j] = S(u_i, v_j).

        Two sparse products: (a, nu) basis matrix times the net, then times the (b, nv) matrix.
        """
        (du, dv) = self.domain
        u = V.check_params(u, du, "u")
        v = V.check_params(v, dv, "v")
        mu = basis_matrix(self.knots_u, self.degree_u, u)
        mv = basis_matrix(self.knots_v, self.degree_v, v)
        rows = mu @ self._pw.reshape(self.nu, -1)                       # (a, nv*4)
        rows = rows.reshape(u.shape[0], self.nv, 4).transpose(1, 0, 2)  # (nv, a, 4)
        h = (mv @ rows.reshape(self.nv, -1)).reshape(v.shape[0], u.shape[0], 4).transpose(1, 0, 2)
        return h[..., :3] / h[..., 3:]

    def derivatives(self, u, v, order: int = 1) -> np.ndarray:
        """Partial derivatives up to total order `order` at paired parameters u, v (m,).

        Returns (order+1, order+1, m, 3): entry [k, l] = d^{k+l} S / du^k dv^l for k + l <= order
        (entries beyond that are zero). [0, 0] is the point itself. Partials of the net by A3.6
        (basis derivatives A2.3, contracted like `evaluate`); for rational surfaces those are the
        homogeneous partials, turned Euclidean by the quotient rule A4.4.
        """
        order = V.check_degree(order, "derivative order") if order else 0
        u, v = self._params(u, v)
        out = np.zeros((order + 1, order + 1, u.shape[0], 3))
        for s in range(0, u.shape[0], _CHUNK):
            block = slice(s, s + _CHUNK)
            out[:, :, block] = self._derivatives_block(u[block], v[block], order)
        return out

    def _derivatives_block(self, u, v, order):
        """Euclidean partials (order+1, order+1, m, 3) of one block u, v (m,): A3.6 on the
        homogeneous net and A4.4 for rational surfaces, A3.6 on the points for polynomial ones."""
        p, q = self.degree_u, self.degree_v
        su = find_spans(self.knots_u, p, u)
        sv = find_spans(self.knots_v, q, v)
        du = basis_derivatives_t(self.knots_u, p, u, order, su)     # (order+1, p+1, m)
        dv = basis_derivatives_t(self.knots_v, q, v, order, sv)     # (order+1, q+1, m)
        ncoord = 4 if self.is_rational else 3
        windows = self._windows(su, sv, ncoord)                     # (ncoord, p+1, q+1, m)
        h = np.zeros((order + 1, order + 1, ncoord, u.shape[0]))
        for l in range(order + 1):
            rows = np.einsum("cijm,jm->cim", windows, dv[l])
            for k in range(order + 1 - l):
                h[k, l] = np.einsum("cim,im->cm", rows, du[k])
        h = h.transpose(0, 1, 3, 2)
        return _rational_surface_derivatives(h, order) if self.is_rational else h

    def normal(self, u, v) -> np.ndarray:
        """Unit normals Su x Sv / |Su x Sv| at paired parameters (m,); (m, 3), zero where degenerate."""
        d = self.derivatives(u, v, 1)
        n = np.cross(d[1, 0], d[0, 1])
        length = np.linalg.norm(n, axis=1, keepdims=True)
        return np.divide(n, length, out=np.zeros_like(n), where=length > 0)

    def curvatures(self, u, v) -> tuple[np.ndarray, np.ndarray]:
        """Principal curvatures (k1 >= k2), each (m,), in 1/length, signed against `normal`.

        From the first (E, F, G) and second (L, M, N) fundamental forms: Gaussian curvature
        K = (LN - M^2)/(EG - F^2), mean H = (EN - 2FM + GL) / (2(EG - F^2)), k = H ± sqrt(H^2 - K).
        """
        d = self.derivatives(u, v, 2)
        su, sv = d[1, 0], d[0, 1]
        n = np.cross(su, sv)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        e, f, g = (np.einsum("md,md->m", a, b) for a, b in ((su, su), (su, sv), (sv, sv)))
        ll, mm, nn = (np.einsum("md,md->m", x, n) for x in (d[2, 0], d[1, 1], d[0, 2]))
        det = e * g - f * f
        gauss = (ll * nn - mm * mm) / det
        mean = (e * nn - 2 * f * mm + g * ll) / (2 * det)
        root = np.sqrt(np.maximum(mean * mean - gauss, 0.0))
        return mean + root, mean - root

    def bbox(self) -> np.ndarray:
        """Axis-aligned box (2, 3) containing the surface: the control net's box (convex hull)."""
        net = self.ctrl.reshape(-1, 3)
        return np.stack([net.min(axis=0), net.max(axis=0)])

    def iso_curve(self, direction: str, t: float):
        """The isoparametric curve at u = t ('u') or v = t ('v') as an exact NurbsCurve."""
        from .curve import NurbsCurve
        direction = _check_direction(direction)
        (du, dv) = self.domain
        if direction == "u":
            t = V.check_params([t], du, "u")
            row = basis_matrix(self.knots_u, self.degree_u, t) @ self._pw.reshape(self.nu, -1)
            return NurbsCurve.from_homogeneous(self.degree_v, self.knots_v, row.reshape(self.nv, 4),
                                               self.is_rational)
        t = V.check_params([t], dv, "v")
        col = basis_matrix(self.knots_v, self.degree_v, t) @ \
            self._pw.transpose(1, 0, 2).reshape(self.nv, -1)
        return NurbsCurve.from_homogeneous(self.degree_u, self.knots_u, col.reshape(self.nu, 4),
                                           self.is_rational)

    # -- shape-preserving operations (rgm.geometry.knots), per direction ------------------------
    def _along(self, direction: str, operation):
        """Apply `operation(knots, degree, pw2d) -> (degree, knots, pw2d)` along one direction."""
        direction = _check_direction(direction)
        pw = self._pw if direction == "u" else self._pw.transpose(1, 0, 2)
        degree = self.degree_u if direction == "u" else self.degree_v
        knots = self.knots_u if direction == "u" else self.knots_v
        other = pw.shape[1]
        new_degree, new_knots, flat = operation(knots, degree, pw.reshape(pw.shape[0], -1))
        net = flat.reshape(flat.shape[0], other, 4)
        if direction == "u":
            return NurbsSurface.from_homogeneous(new_degree, self.degree_v, new_knots, self.knots_v,
                                                 net, self.is_rational)
        return NurbsSurface.from_homogeneous(self.degree_u, new_degree, self.knots_u, new_knots,
                                             net.transpose(1, 0, 2), self.is_rational)

    def insert_knot(self, direction: str, t: float, times: int = 1) -> "NurbsSurface":
        """Insert knot t `times` times in direction 'u' or 'v' (A5.3 via refinement); shape unchanged."""
        times = V.check_degree(times, "times")
        return self.refine(direction, np.full(times, float(t)))

    def refine(self, direction: str, new_knots) -> "NurbsSurface":
        """Knot refinement in one direction (Piegl & Tiller A5.5); the shape is unchanged."""
        from .knots import refine_knots
        return self._along(direction, lambda k, p, pw: (p, *refine_knots(k, p, pw, new_knots)))

    def split(self, direction: str, t: float) -> tuple["NurbsSurface", "NurbsSurface"]:
        """Split at u = t or v = t into two surfaces with the same parameterisation."""
        from .knots import split_knots
        halves = []
        for side in (0, 1):
            halves.append(self._along(direction, lambda k, p, pw: (p, *split_knots(k, p, pw, float(t))[side])))
        return halves[0], halves[1]

    def elevate(self, direction: str, times: int = 1) -> "NurbsSurface":
        """Raise the degree in direction 'u' or 'v' by `times`, all rows at once (see knots.elevate_degree)."""
        from .knots import elevate_degree
        times = V.check_degree(times, "times")
        return self._along(direction, lambda k, p, pw: (p + times, *elevate_degree(k, p, pw, times)))

    def reverse(self, direction: str) -> "NurbsSurface":
        """Reverse the parameter direction 'u' or 'v' (the normal flips); the point set is unchanged."""
        def flip(knots, degree, pw):
            n = pw.shape[0]
            return degree, knots[degree] + knots[n] - knots[::-1], pw[::-1]
        return self._along(direction, flip)

    def reparameterize(self, direction: str, t0: float, t1: float) -> "NurbsSurface":
        """Map direction 'u' or 'v' affinely onto [t0, t1]."""
        from .knots import rescale_knots
        return self._along(direction, lambda k, p, pw: (p, rescale_knots(k, p, t0, t1), pw))

    def swap_uv(self) -> "NurbsSurface":
        """The same surface with u and v exchanged (the normal flips)."""
        return NurbsSurface.from_homogeneous(self.degree_v, self.degree_u, self.knots_v, self.knots_u,
                                             self._pw.transpose(1, 0, 2), self.is_rational)

    def transform(self, matrix) -> "NurbsSurface":
        """Apply a 4x4 homogeneous transform to the control net (exact for affine/projective maps)."""
        matrix = V.check_matrix(matrix, 3)
        with np.errstate(over="ignore", invalid="ignore"):
            pw = self._pw @ matrix.T
        if not np.isfinite(pw).all():
            raise GeometryError("the transform takes the control points beyond the floating-point range")
        rational = self.is_rational or not np.allclose(matrix[3, :3], 0.0) or matrix[3, 3] != 1.0
        if np.any(pw[..., 3] <= 0):
            raise GeometryError("projective transform sends a control point to a non-positive weight")
        return NurbsSurface.from_homogeneous(self.degree_u, self.degree_v, self.knots_u, self.knots_v,
                                             pw, rational)

    def closest_point(self, points):
        """Closest points on the surface: (u (k,), v (k,), pts (k, 3), dist (k,)) for points (k, 3)."""
        from .inversion import closest_point_surface
        return closest_point_surface(self, points)


def _check_direction(direction) -> str:
    if direction not in ("u", "v"):
        raise GeometryError(f"direction must be 'u' or 'v', not {direction!r}")
    return direction
