"""NURBS curves: immutable, evaluated over whole parameter arrays.

A curve of degree p has a knot vector `knots (n+p+1,)`, Euclidean control points `ctrl (n, d)`
(d = 2 for parameter-space curves, 3 for model-space curves) and optional weights `(n,)`; weights
None means a polynomial B-spline. Internally the homogeneous control points `(w*P, w)` of shape
(n, d+1) are kept, because evaluation, derivatives and all knot operations are linear in them.
"""
from __future__ import annotations

from math import comb

import numpy as np

from rgm.errors import GeometryError

from . import _validate as V
from .basis import basis_derivatives, basis_functions, find_spans

__all__ = ["NurbsCurve", "rational_derivatives"]


def rational_derivatives(hders: np.ndarray) -> np.ndarray:
    """Euclidean derivatives from homogeneous ones by the quotient rule (Piegl & Tiller A4.2).

    hders : (order+1, m, d+1) derivatives of (w*C, w). Returns (order+1, m, d).
    """
    a, w = hders[..., :-1], hders[..., -1:]
    out = np.empty_like(a)
    for k in range(hders.shape[0]):
        v = a[k].copy()
        for i in range(1, k + 1):
            v -= comb(k, i) * w[i] * out[k - i]
        out[k] = v / w[0]
    return out


class NurbsCurve:
    """A (rational) B-spline curve; see the module docstring for the data layout.

    Raises GeometryError when the knot vector, control points or weights are inconsistent.
    """

    __slots__ = ("degree", "knots", "ctrl", "weights", "_pw")

    def __init__(self, degree, knots, ctrl, weights=None):
        degree = V.check_degree(degree)
        ctrl = V.check_points(ctrl, "(n, 2) or (n, 3)", (2, 3), 2)
        knots = V.check_knots(knots, degree, ctrl.shape[0])
        weights = V.check_weights(weights, ctrl.shape[:1])
        w = np.ones(ctrl.shape[0]) if weights is None else weights
        pw = V.frozen(np.hstack([ctrl * w[:, None], w[:, None]]))
        for name, value in zip(self.__slots__, (degree, knots, ctrl, weights, pw)):
            object.__setattr__(self, name, value)

    def __setattr__(self, name, value):
        raise AttributeError("NurbsCurve is immutable; operations return new curves")

    def __reduce__(self):
        """Pickled by its defining data, rebuilt (and checked) by the constructor: copies to worker
        processes and saved results stay immutable."""
        return type(self), (self.degree, self.knots, self.ctrl, self.weights)

    @classmethod
    def from_homogeneous(cls, degree: int, knots, pw, rational: bool = True) -> "NurbsCurve":
        """Build from homogeneous control points `pw (n, d+1)` = (w*P, w)."""
        pw = np.asarray(pw, dtype=float)
        w = pw[:, -1]
        if np.any(w <= 0):
            raise GeometryError("homogeneous control points need positive weights")
        return cls(degree, knots, pw[:, :-1] / w[:, None], w if rational else None)

    # -- properties --------------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of control points."""
        return self.ctrl.shape[0]

    @property
    def dim(self) -> int:
        """Dimension d of the control points (2 or 3)."""
        return self.ctrl.shape[1]

    @property
    def domain(self) -> tuple[float, float]:
        """Parameter domain (knots[p], knots[n])."""
        return float(self.knots[self.degree]), float(self.knots[self.n])

    @property
    def is_rational(self) -> bool:
        return self.weights is not None

    @property
    def homogeneous(self) -> np.ndarray:
        """Read-only homogeneous control points (n, d+1) = (w*P, w)."""
        return self._pw

    @property
    def start(self) -> np.ndarray:
        return self.evaluate([self.domain[0]])[0]

    @property
    def end(self) -> np.ndarray:
        return self.evaluate([self.domain[1]])[0]

    def __repr__(self) -> str:
        kind = "rational" if self.is_rational else "polynomial"
        return (f"NurbsCurve(degree={self.degree}, n={self.n}, dim={self.dim}, {kind}, "
                f"domain=({self.domain[0]:g}, {self.domain[1]:g}))")

    # -- evaluation --------------------------------------------------------------------------
    def _gather(self, spans: np.ndarray) -> np.ndarray:
        """Homogeneous control points of each span: (m, p+1, d+1)."""
        idx = spans[:, None] - self.degree + np.arange(self.degree + 1)[None, :]
        return self._pw[idx]

    def evaluate(self, u) -> np.ndarray:
        """Points C(u) for parameters u (m,) in the domain; returns (m, d)."""
        u = V.check_params(u, self.domain)
        spans = find_spans(self.knots, self.degree, u)
        basis = basis_functions(self.knots, self.degree, u, spans)
        h = np.einsum("mk,mkd->md", basis, self._gather(spans))
        return h[:, :-1] / h[:, -1:]

    def derivatives(self, u, order: int = 1) -> np.ndarray:
        """C and its derivatives d^k C/du^k, k = 0..order, at u (m,); returns (order+1, m, d).

        Homogeneous derivatives from A2.3 basis derivatives, then the rational quotient rule (A4.2).
        """
        order = V.check_degree(order, "derivative order") if order else 0
        u = V.check_params(u, self.domain)
        spans = find_spans(self.knots, self.degree, u)
        ders = basis_derivatives(self.knots, self.degree, u, order, spans)
        hders = np.einsum("kmr,mrd->kmd", ders, self._gather(spans))
        return rational_derivatives(hders)

    def tangent(self, u) -> np.ndarray:
        """Unit tangent vectors (m, d); zero where the derivative vanishes."""
        d1 = self.derivatives(u, 1)[1]
        length = np.linalg.norm(d1, axis=1, keepdims=True)
        return np.divide(d1, length, out=np.zeros_like(d1), where=length > 0)

    def curvature(self, u) -> np.ndarray:
        """Curvature |C' x C''| / |C'|^3 at u (m,), in 1/length."""
        _, d1, d2 = self.derivatives(u, 2)
        if self.dim == 2:
            cross = np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
        else:
            cross = np.linalg.norm(np.cross(d1, d2), axis=1)
        speed = np.linalg.norm(d1, axis=1)
        return np.divide(cross, speed ** 3, out=np.zeros_like(cross), where=speed > 0)

    def sample(self, count: int) -> tuple[np.ndarray, np.ndarray]:
        """`count` parameters evenly spread over the domain and their points: (u (count,), pts (count, d))."""
        u = np.linspace(*self.domain, count)
        return u, self.evaluate(u)

    def bbox(self) -> np.ndarray:
        """Axis-aligned box [min, max] of shape (2, d) containing the curve.

        The control polygon's box: it encloses the curve by the convex-hull property (weights > 0).
        """
        return np.stack([self.ctrl.min(axis=0), self.ctrl.max(axis=0)])

    def length(self, samples_per_span: int = 16) -> float:
        """Arc length by Gauss–Legendre quadrature on every knot span (model units)."""
        breaks = np.unique(self.knots[self.degree:self.n + 1])
        x, wq = np.polynomial.legendre.leggauss(samples_per_span)
        a, b = breaks[:-1, None], breaks[1:, None]
        u = (0.5 * (b - a) * x[None, :] + 0.5 * (a + b)).ravel()
        speed = np.linalg.norm(self.derivatives(u, 1)[1], axis=1).reshape(a.shape[0], -1)
        return float(np.sum(0.5 * (b - a) * speed * wq[None, :]))

    # -- shape-preserving operations (rgm.geometry.knots) ---------------------------------------
    def _with(self, degree, knots, pw) -> "NurbsCurve":
        return NurbsCurve.from_homogeneous(degree, knots, pw, self.is_rational)

    def insert_knot(self, u: float, times: int = 1) -> "NurbsCurve":
        """Insert knot u `times` times (Piegl & Tiller A5.1 via A5.4); the shape is unchanged."""
        from .knots import refine_knots
        times = V.check_degree(times, "times")
        return self._with(self.degree, *refine_knots(self.knots, self.degree, self._pw,
                                                     np.full(times, float(u))))

    def refine(self, new_knots) -> "NurbsCurve":
        """Insert all of `new_knots` at once (knot refinement, A5.4)."""
        from .knots import refine_knots
        return self._with(self.degree, *refine_knots(self.knots, self.degree, self._pw, new_knots))

    def split(self, u: float) -> tuple["NurbsCurve", "NurbsCurve"]:
        """Two curves meeting at C(u), covering [u0, u] and [u, u1] with the same parameterisation."""
        from .knots import split_knots
        (ka, pa), (kb, pb) = split_knots(self.knots, self.degree, self._pw, float(u))
        return self._with(self.degree, ka, pa), self._with(self.degree, kb, pb)

    def elevate(self, times: int = 1) -> "NurbsCurve":
        """Raise the degree by `times`; the shape is unchanged (see knots.elevate_degree)."""
        from .knots import elevate_degree
        times = V.check_degree(times, "times")
        return self._with(self.degree + times, *elevate_degree(self.knots, self.degree, self._pw, times))

    def reverse(self) -> "NurbsCurve":
        """The same curve traversed the other way, on the same domain: C'(u) = C(u0 + u1 - u)."""
        lo, hi = self.domain
        return self._with(self.degree, lo + hi - self.knots[::-1], self._pw[::-1])

    def reparameterize(self, u0: float, u1: float) -> "NurbsCurve":
        """The same curve on domain [u0, u1] by an affine change of the knots."""
        from .knots import rescale_knots
        return self._with(self.degree, rescale_knots(self.knots, self.degree, u0, u1), self._pw)

    def transform(self, matrix) -> "NurbsCurve":
        """Apply a homogeneous transform ((d+1) x (d+1), e.g. 4x4 for 3-D) to the curve.

        The homogeneous control points are mapped, which is exact for affine and projective maps.
        """
        matrix = V.check_matrix(matrix, self.dim)
        with np.errstate(over="ignore", invalid="ignore"):
            pw = self._pw @ matrix.T
        if not np.isfinite(pw).all():
            raise GeometryError("the transform takes the control points beyond the floating-point range")
        rational = self.is_rational or not np.allclose(matrix[-1, :-1], 0.0) or matrix[-1, -1] != 1.0
        if np.any(pw[:, -1] <= 0):
            raise GeometryError("projective transform sends a control point to a non-positive weight")
        return NurbsCurve.from_homogeneous(self.degree, self.knots, pw, rational)

    def closest_point(self, points):
        """Closest points on the curve: (u (k,), pts (k, d), dist (k,)) for query points (k, d)."""
        from .inversion import closest_point_curve
        return closest_point_curve(self, points)
