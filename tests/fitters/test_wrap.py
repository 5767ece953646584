"""A full wrap as one closed surface cut into two faces (`rgm.fitters.wrap`): the closure is exact (C1
across u = 0 / 1), a face is the closed surface itself (knot insertion), and the two faces' seams are the
same curve on both, so their G0 gap is round-off. Synthetic wraps with fixed seeds."""
import numpy as np
from hypothesis import given, settings, strategies as st

from rgm.fitters.freeform import CurveFit
from rgm.fitters.freeform_surface import fit_surface
from rgm.fitters.trimloops import check_loops
from rgm.fitters.wrap import arc, fit_wrap
from rgm.geometry import NurbsSurface
from rgm.geometry.inversion import closest_point_surface


def lobed_tube(seed: int, n: int = 5000, noise: float = 0.05):
    """n points (mm) on a tube of radius 20 + 2 cos(3 t) mm, 40 mm long, Gaussian noise; with their angle
    over 2 pi (u) and height share (v) as parameters."""
    rng = np.random.default_rng(seed)
    t, z = rng.uniform(0, 2 * np.pi, n), rng.uniform(0, 40, n)
    r = 20 + 2 * np.cos(3 * t + seed)
    p = np.c_[r * np.cos(t), r * np.sin(t), z] + rng.normal(0, noise, (n, 3))
    return p, t / (2 * np.pi), z / 40


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 1000))
def test_a_closed_net_is_c1_across_its_seam_and_an_arc_is_the_same_surface(seed):
    p, u, v = lobed_tube(seed, 3000)
    fit = fit_surface(p, 0.3, params=(u, 0.1 + 0.8 * v), statistic="p95", closed_u=True)
    s = fit.nurbs()
    t = np.linspace(0, 1, 9)
    d0, d1 = s.derivatives(np.zeros(9), t), s.derivatives(np.ones(9), t)
    assert np.array_equal(d0[0, 0], d1[0, 0])                       # P_0 = P_{n-1}: the same points
    assert np.allclose(d0[1, 0], d1[1, 0], rtol=1e-9, atol=1e-9)    # and the same tangent across the seam
    rng = np.random.default_rng(seed)
    a = rng.uniform(0, 1)
    b = a + rng.uniform(0.05, 0.95)                                 # past 1: the arc wraps through u = 0
    ku, ctrl = arc(fit.knots_u, fit.ctrl, 3, a, b)
    piece = NurbsSurface(3, 3, ku, fit.knots_v, ctrl, None)
    x, y = rng.uniform(0, 1, 200), rng.uniform(0, 1, 200)
    assert np.allclose(piece.evaluate(x, y), s.evaluate(np.mod(a + x * (b - a), 1.0), y), atol=1e-9)


def _seam_lines(shape, band):
    return [q for q in shape.outer if isinstance(q, CurveFit) and q.degree == 1 and len(q.ctrl) == 2
            and np.isin(q.ctrl[:, 0], band).all()]


def test_the_two_faces_of_a_wrap_meet_along_the_same_curve_and_meet_the_tolerance():
    p, u, v = lobed_tube(3)
    faces = fit_wrap(p, u, v, 0.2, statistic="p95", reach=5 * 0.9)
    assert len(faces) == 2
    assert sorted(np.r_[faces[0][0], faces[1][0]].tolist()) == list(range(len(p)))   # each point in one face
    surfaces = [shape.nurbs() for _, shape, _, _ in faces]
    for k, (own, shape, _, params) in enumerate(faces):
        assert shape.fit.stats.holds and shape.fit.stats.p95 <= 0.2
        assert check_loops(shape.loops.outer, shape.loops.holes) == []
        band = shape.loops.band
        lines = _seam_lines(shape, band)
        # both seams are straight loop pieces on the iso-lines, running (nearly) the data's whole height
        assert {float(q.ctrl[0, 0]) for q in lines} == set(band)
        for end in band:
            height = sum(abs(q.ctrl[1, 1] - q.ctrl[0, 1]) for q in lines if q.ctrl[0, 0] == end)
            assert height >= 0.9 * np.ptp(params[1])
        # the seams lie on the other face's surface: G0 to round-off
        t = np.linspace(0, 1, 40)[:, None]
        xyz = np.vstack([surfaces[k].evaluate(*(q.ctrl[0] + t * (q.ctrl[1] - q.ctrl[0])).T) for q in lines])
        assert np.max(closest_point_surface(surfaces[1 - k], xyz)[3]) < 1e-9
        # the face is the tube, not only near its points: its data's own distances
        assert np.percentile(shape.distance(p[own]), 95) <= 0.2
