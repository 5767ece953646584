"""112/114 parametric splines become exact B-splines: evaluation agrees with the power-basis
polynomials of the file (the oracle) on every segment / patch."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from rgm.backends.iges_legacy import spline_curve, spline_surface


def _breaks(rng, k):
    return np.concatenate([[rng.uniform(-2, 2)], rng.uniform(0.2, 2.0, k)]).cumsum()


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5))
def test_spline_curve_matches_its_polynomials(seed, n):
    rng = np.random.default_rng(seed)
    t = _breaks(rng, n)
    coef = rng.normal(size=(n, 3, 4))
    for i in range(n - 1):  # make the pieces meet (C0), as a file's spline does
        s = t[i + 1] - t[i]
        coef[i + 1, :, 0] = coef[i] @ s ** np.arange(4)
    curve = spline_curve(t, coef, 3)
    for i in range(n):
        u = np.linspace(t[i], t[i + 1], 7)
        s = u - t[i]
        expect = np.einsum("ck,mk->mc", coef[i], s[:, None] ** np.arange(4))
        assert np.allclose(curve.evaluate(u), expect, rtol=0, atol=1e-9)


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 3), st.integers(1, 3))
def test_spline_surface_matches_its_patch_polynomials(seed, m, n):
    rng = np.random.default_rng(seed)
    tu, tv = _breaks(rng, m), _breaks(rng, n)
    # one global bicubic polynomial restricted to each patch, so the patches join exactly
    g = rng.normal(size=(3, 4, 4))

    def poly(u, v):
        return np.einsum("cpq,mp,mq->mc", g, u[:, None] ** np.arange(4), v[:, None] ** np.arange(4))

    patches = np.zeros((m, n, 3, 16))
    from math import comb

    for i in range(m):
        for j in range(n):  # re-expand the polynomial about (tu[i], tv[j])
            a = np.zeros((3, 4, 4))
            for p in range(4):
                for q in range(4):
                    for pp in range(p, 4):
                        for qq in range(q, 4):
                            a[:, p, q] += g[:, pp, qq] * comb(pp, p) * comb(qq, q) * tu[i] ** (pp - p) * tv[j] ** (qq - q)
            patches[i, j] = a.transpose(0, 2, 1).reshape(3, 16)  # index p + 4 q
    s = spline_surface(tu, tv, patches)
    u = rng.uniform(tu[0], tu[-1], 50)
    v = rng.uniform(tv[0], tv[-1], 50)
    assert np.allclose(s.evaluate(u, v), poly(u, v), rtol=1e-9, atol=1e-7)
