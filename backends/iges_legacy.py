"""Legacy IGES spline entities as exact B-splines: 112 parametric spline curve, 114 parametric
spline surface (piecewise cubic polynomials in the power basis, IGES 5.3 §4.9 and §4.11).

Each cubic piece a0 + a1 s + a2 s^2 + a3 s^3 on s in [0, h] is converted to its Bezier control
points b_i = sum_k C(i, k) / C(3, k) h^k a_k (the power-to-Bernstein change of basis), and the
pieces are joined into a clamped cubic B-spline with triple knots at the breakpoints (so the result
is exactly the file's curve or surface, C0 at the breaks whatever continuity the file claims).
"""
from __future__ import annotations

from math import comb

import numpy as np

from rgm.geometry import NurbsCurve, NurbsSurface

__all__ = ["spline_curve", "spline_surface", "BASIS"]

#: power (on [0, 1]) -> Bernstein coefficients of a cubic: b = BASIS @ a
BASIS = np.array([[comb(i, k) / comb(3, k) if k <= i else 0.0 for k in range(4)] for i in range(4)])


def _knots(breaks: np.ndarray) -> np.ndarray:
    return np.concatenate([[breaks[0]] * 4, np.repeat(breaks[1:-1], 3), [breaks[-1]] * 4])


def spline_curve(breaks: np.ndarray, coefficients: np.ndarray, dim: int) -> NurbsCurve:
    """112 → NurbsCurve. breaks (n+1,); coefficients (n, 3, 4): per segment AX..DX, AY..DY, AZ..DZ
    in powers of s = t - T(i); `dim` 2 or 3 of the result."""
    h = np.diff(breaks)                                                  # (n,)
    scaled = coefficients * h[:, None, None] ** np.arange(4)             # a_k h^k
    bez = np.einsum("ik,nck->nic", BASIS, scaled)                        # (n, 4, 3) Bezier points
    ctrl = np.concatenate([bez[:1, 0], bez[:, 1:].reshape(-1, 3)])
    return NurbsCurve(3, _knots(breaks), ctrl[:, :dim], None)


def spline_surface(tu: np.ndarray, tv: np.ndarray, patches: np.ndarray) -> NurbsSurface:
    """114 → NurbsSurface. tu (m+1,), tv (n+1,); patches (m, n, 3, 16): per patch and coordinate the
    16 coefficients A, B, ..., S of sum a[p + 4 q] s^p t^q (s = u - TU(i), t = v - TV(j))."""
    m, n = len(tu) - 1, len(tv) - 1
    a = patches.reshape(m, n, 3, 4, 4).transpose(0, 1, 2, 4, 3)          # [..., p (s power), q (t power)]
    hu, hv = np.diff(tu), np.diff(tv)
    a = a * (hu[:, None, None, None, None] ** np.arange(4)[:, None]) * (hv[None, :, None, None, None] ** np.arange(4))
    bez = np.einsum("ip,mncpq,jq->mnijc", BASIS, a, BASIS)               # (m, n, 4, 4, 3)
    net = np.empty((3 * m + 1, 3 * n + 1, 3))
    for i in range(m):
        for j in range(n):
            net[3 * i:3 * i + 4, 3 * j:3 * j + 4] = bez[i, j]
    return NurbsSurface(3, 3, _knots(tu), _knots(tv), net, None)
