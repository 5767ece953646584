"""Random NURBS curves and surfaces for the geometry property tests (hypothesis draws the seed
and the structure; numpy fills in the numbers)."""
from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from rgm.geometry import NurbsCurve, NurbsSurface


def random_knots(rng, degree: int, n: int) -> np.ndarray:
    """Clamped knot vector on [0, 1] with random interior knots, some repeated up to p times."""
    count = n - degree - 1
    inner = list(np.round(rng.uniform(0.02, 0.98, count), 6))
    for i in range(count):
        if rng.random() < 0.25 and i > 0:
            # repeat an earlier knot, keeping multiplicity <= degree
            value = inner[i - 1]
            if inner.count(value) < degree:
                inner[i] = value
    return np.r_[np.zeros(degree + 1), np.sort(inner), np.ones(degree + 1)]


@st.composite
def curves(draw, dim: int = 3, max_degree: int = 4):
    degree = draw(st.integers(1, max_degree))
    n = draw(st.integers(degree + 1, degree + 6))
    rational = draw(st.booleans())
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    weights = rng.uniform(0.3, 3.0, n) if rational else None
    return NurbsCurve(degree, random_knots(rng, degree, n), rng.uniform(-1, 1, (n, dim)), weights)


@st.composite
def surfaces(draw, max_degree: int = 3):
    pu, pv = draw(st.integers(1, max_degree)), draw(st.integers(1, max_degree))
    nu, nv = draw(st.integers(pu + 1, pu + 4)), draw(st.integers(pv + 1, pv + 4))
    rational = draw(st.booleans())
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    weights = rng.uniform(0.3, 3.0, (nu, nv)) if rational else None
    return NurbsSurface(pu, pv, random_knots(rng, pu, nu), random_knots(rng, pv, nv),
                        rng.uniform(-1, 1, (nu, nv, 3)), weights)


def size(obj) -> float:
    """Diagonal of the control box: the length scale of the 1e-12 x size tolerances."""
    box = obj.bbox()
    return float(np.linalg.norm(box[1] - box[0])) or 1.0
