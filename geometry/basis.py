"""B-spline basis functions and their derivatives for many parameters at once.

Everything here works on a whole parameter array `u (m,)` at a time: the Cox–de Boor triangle of
Piegl & Tiller (*The NURBS Book*, 2nd ed.) is computed over arrays, so the Python loops run over the
degree (a handful of iterations), never over the points.

- `find_spans`         A2.1, vectorised with `np.searchsorted`.
- `basis_functions`    A2.2, the p+1 non-zero basis values per parameter, shape (m, p+1).
- `basis_derivatives`  A2.3, those values and their derivatives up to `order`, shape (order+1, m, p+1).
- `basis_functions_t`, `basis_derivatives_t`  the same in point-last layout, (p+1, m) and
                       (order+1, p+1, m): contiguous rows over the points, which is what the
                       vectorised evaluators contract with (the two above are transposed views).
- `basis_matrix`       the full (m, n) collocation matrix as `scipy.sparse.csr_matrix`, the building
                       block of least-squares fitting (row i holds N_j(u_i), and its derivatives on request).

A knot vector `knots (n+p+1,)` of degree `p` defines `n` basis functions on the domain
`[knots[p], knots[n]]`; spans are indices `k` with `knots[k] <= u < knots[k+1]` and
`p <= k <= n-1`, so the non-zero functions at `u` are `N_{k-p} .. N_k`.
"""
from __future__ import annotations

import numpy as np

from rgm.errors import GeometryError

__all__ = ["find_spans", "basis_functions", "basis_functions_t", "basis_derivatives", "basis_derivatives_t",
           "basis_matrix", "domain_of"]


def domain_of(knots: np.ndarray, degree: int) -> tuple[float, float]:
    """The parameter domain `(knots[p], knots[n])` of a knot vector with n = len(knots) - p - 1."""
    n = len(knots) - degree - 1
    return float(knots[degree]), float(knots[n])


def find_spans(knots: np.ndarray, degree: int, u: np.ndarray) -> np.ndarray:
    """Knot span index of every parameter (Piegl & Tiller A2.1, vectorised).

    knots : (n+p+1,) non-decreasing;  u : (m,) parameters, clamped into the domain first.
    Returns int (m,) spans `k` with `knots[k] <= u < knots[k+1]`; at the right end of the domain the
    last non-empty span is used so that `u = knots[n]` evaluates the closing end of the curve.
    Repeated knots are handled by taking the non-empty span to the right (`side="right"`).
    """
    n = len(knots) - degree - 1
    first = np.searchsorted(knots, knots[degree], side="right") - 1
    last = np.searchsorted(knots, knots[n], side="left") - 1
    spans = np.searchsorted(knots, u, side="right") - 1
    return np.clip(spans, first, last)


def basis_functions(knots: np.ndarray, degree: int, u: np.ndarray,
                    spans: np.ndarray | None = None) -> np.ndarray:
    """The p+1 non-vanishing basis functions N_{k-p..k}(u) at each parameter (A2.2, vectorised).

    Returns (m, p+1) float64: column r is N_{span-p+r}(u). Rows sum to one (partition of unity).
    This is the transpose (a view) of `basis_functions_t`, which evaluators use directly.
    """
    return basis_functions_t(knots, degree, u, spans).T


def basis_functions_t(knots: np.ndarray, degree: int, u: np.ndarray,
                      spans: np.ndarray | None = None) -> np.ndarray:
    """`basis_functions` in the transposed layout (p+1, m): row r is N_{span-p+r}(u) for all u.

    Piegl & Tiller A2.2 run over whole arrays: each step of the triangle is a handful of in-place
    operations on contiguous (m,) rows, and the 2p knots around every span are gathered once as
    a (2p, m) table, so the cost is ~5 p(p+1)/2 array passes and no per-point Python work.
    The denominators are never zero: spans are non-empty, so knots[k+r+1] - knots[k+1-j+r] > 0.
    """
    p = degree
    u = np.asarray(u, dtype=float)
    if spans is None:
        spans = find_spans(knots, degree, u)
    m = u.shape[0]
    values = np.empty((p + 1, m))
    values[0] = 1.0
    # K[r] = knots[span + 1 - p + r], r = 0..2p-1; left_j = u - K[p-j], right_j = K[p-1+j] - u.
    window = np.asarray(knots, dtype=float).take(spans[None, :] + np.arange(1 - p, p + 1)[:, None])
    left = u - window[p - 1::-1]          # left[j-1]  = u - knots[span + 1 - j]
    right = window[p:] - u                # right[j-1] = knots[span + j] - u
    temp, saved = np.empty(m), np.empty(m)
    for j in range(1, p + 1):
        for r in range(j):
            np.add(right[r], left[j - r - 1], out=temp)
            np.divide(values[r], temp, out=temp)
            np.multiply(right[r], temp, out=values[r])
            if r:
                values[r] += saved
            np.multiply(left[j - r - 1], temp, out=saved)
        values[j] = saved
    return values


def basis_derivatives(knots: np.ndarray, degree: int, u: np.ndarray, order: int,
                      spans: np.ndarray | None = None) -> np.ndarray:
    """Non-vanishing basis functions and their derivatives up to `order` (A2.3, vectorised).

    Returns (order+1, m, p+1): `[k, i, r]` is d^k/du^k N_{span_i - p + r}(u_i). Derivatives of
    order above the degree are zero. A transposed view of `basis_derivatives_t`.
    """
    return basis_derivatives_t(knots, degree, u, order, spans).transpose(0, 2, 1)


def basis_derivatives_t(knots: np.ndarray, degree: int, u: np.ndarray, order: int,
                        spans: np.ndarray | None = None) -> np.ndarray:
    """`basis_derivatives` in the layout (order+1, p+1, m): `[k, r]` is d^k/du^k N_{span-p+r}(u).

    Piegl & Tiller A2.3 over whole arrays (the loops run over degree and order only).
    """
    p = degree
    u = np.asarray(u, dtype=float)
    if spans is None:
        spans = find_spans(knots, degree, u)
    m = u.shape[0]
    ders = np.zeros((order + 1, p + 1, m))
    # ndu: upper triangle holds basis functions of rising degree, lower triangle the knot differences.
    ndu = np.empty((p + 1, p + 1, m))
    ndu[0, 0] = 1.0
    left = np.empty((p + 1, m))
    right = np.empty((p + 1, m))
    for j in range(1, p + 1):
        left[j] = u - knots[spans + 1 - j]
        right[j] = knots[spans + j] - u
        saved = np.zeros(m)
        for r in range(j):
            ndu[j, r] = right[r + 1] + left[j - r]
            temp = ndu[r, j - 1] / ndu[j, r]
            ndu[r, j] = saved + right[r + 1] * temp
            saved = left[j - r] * temp
        ndu[j, j] = saved
    ders[0] = ndu[:, p]
    top = min(order, p)
    a = np.zeros((2, p + 1, m))
    for r in range(p + 1):
        s1, s2 = 0, 1
        a[0, 0] = 1.0
        for k in range(1, top + 1):
            d = np.zeros(m)
            rk, pk = r - k, p - k
            if r >= k:
                a[s2, 0] = a[s1, 0] / ndu[pk + 1, rk]
                d = a[s2, 0] * ndu[rk, pk]
            j1 = 1 if rk >= -1 else -rk
            j2 = k - 1 if r - 1 <= pk else p - r
            for j in range(j1, j2 + 1):
                a[s2, j] = (a[s1, j] - a[s1, j - 1]) / ndu[pk + 1, rk + j]
                d = d + a[s2, j] * ndu[rk + j, pk]
            if r <= pk:
                a[s2, k] = -a[s1, k - 1] / ndu[pk + 1, r]
                d = d + a[s2, k] * ndu[r, pk]
            ders[k, r] = d
            s1, s2 = s2, s1
    factor = float(p)
    for k in range(1, top + 1):
        ders[k] *= factor
        factor *= p - k
    return ders


def basis_matrix(knots, degree: int, u, order: int = 0):
    """Sparse collocation matrix of the B-spline basis (or of its `order`-th derivative).

    knots : (n+p+1,);  u : (m,) parameters in the domain.
    Returns `scipy.sparse.csr_matrix` of shape (m, n) with at most p+1 non-zeros per row:
    entry (i, j) = d^order/du^order N_j(u_i). `A @ ctrl` evaluates a polynomial B-spline whose
    control points are `ctrl (n, d)`; least-squares fitting solves `A x ≈ data`.
    """
    from scipy.sparse import csr_matrix

    knots = np.asarray(knots, dtype=float)
    u = np.atleast_1d(np.asarray(u, dtype=float))
    n = len(knots) - degree - 1
    if n < degree + 1:
        raise GeometryError(f"knot vector of length {len(knots)} is too short for degree {degree}")
    spans = find_spans(knots, degree, u)
    values = basis_derivatives(knots, degree, u, order, spans)[order] if order else \
        basis_functions(knots, degree, u, spans)
    m = u.shape[0]
    columns = (spans - degree)[:, None] + np.arange(degree + 1)[None, :]
    indptr = np.arange(0, m * (degree + 1) + 1, degree + 1)
    return csr_matrix((values.ravel(), columns.ravel(), indptr), shape=(m, n))
