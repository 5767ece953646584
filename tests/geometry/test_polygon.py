"""Even-odd point-in-region tests of parameter-plane loops (`rgm.geometry.polygon.inside_polygons`),
against an independent oracle: the winding number from the angles the loops' edges subtend at each point
(odd: inside an outer loop and outside its holes), for random star-shaped loops with holes, points kept
clear of the edges, and the (edge, point) pairs handled in chunks of every size."""
import numpy as np
from hypothesis import given, settings, strategies as st

import rgm.geometry.polygon as polygon
from rgm.geometry.polygon import inside_polygons


def star(rng, k, centre, radius, clockwise=False):
    ang = np.sort(rng.uniform(0, 2 * np.pi, k))
    loop = centre + np.column_stack([np.cos(ang), np.sin(ang)]) * radius * rng.uniform(0.5, 1.0, (k, 1))
    return loop[::-1] if clockwise else loop


def winding(points, loops):
    total = np.zeros(len(points))
    for loop in loops:
        a = loop[None, :, :] - points[:, None, :]
        b = np.roll(loop, -1, axis=0)[None, :, :] - points[:, None, :]
        total += np.arctan2(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0], (a * b).sum(axis=-1)).sum(axis=1)
    return np.rint(total / (2 * np.pi)).astype(int)


def clearance(points, loops):
    d = np.full(len(points), np.inf)
    for loop in loops:
        a, b = loop, np.roll(loop, -1, axis=0)
        ab = b - a
        t = np.clip(((points[:, None] - a) * ab).sum(-1) / (ab * ab).sum(-1), 0, 1)
        d = np.minimum(d, np.linalg.norm(points[:, None] - (a + t[..., None] * ab), axis=-1).min(axis=1))
    return d


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 5000))
def test_even_odd_matches_the_winding_number(seed, chunk):
    rng = np.random.default_rng(seed)
    loops = [star(rng, int(rng.integers(3, 200)), np.zeros(2), 1.0)]
    for _ in range(int(rng.integers(0, 3))):   # holes, clockwise, well inside
        loops.append(star(rng, int(rng.integers(3, 30)), rng.uniform(-0.1, 0.1, 2), 0.15, clockwise=True))
    points = rng.uniform(-1.1, 1.1, (int(rng.integers(0, 2000)), 2))
    if rng.random() < 0.3:   # rows of points at the loops' vertex heights: ties in y
        points[: len(points) // 2, 1] = rng.choice(np.vstack(loops)[:, 1], len(points) // 2)
    points = points[clearance(points, loops) > 1e-9]
    saved = polygon._CHUNK
    polygon._CHUNK = chunk
    try:
        got = inside_polygons(points, loops)
    finally:
        polygon._CHUNK = saved
    assert np.array_equal(got, winding(points, loops) % 2 == 1)


def test_empty_inputs():
    assert inside_polygons(np.zeros((0, 2)), [np.eye(3)[:, :2]]).shape == (0,)
    assert not inside_polygons(np.zeros((3, 2)), []).any()


def test_many_points_against_a_long_loop():
    """100,000 points against a 3,000-vertex loop sampling a seven-lobed curve (within 1e-3 of it): each
    point clear of the curve is inside exactly when it is inside the curve."""
    n = 100_000
    ang = np.linspace(0, 2 * np.pi, 3000, endpoint=False)
    loop = np.column_stack([np.cos(ang), np.sin(ang)]) * (1 + 0.2 * np.sin(7 * ang))[:, None]
    points = np.random.default_rng(0).uniform(-1.3, 1.3, (n, 2))
    got = inside_polygons(points, [loop])
    r, t = np.hypot(points[:, 0], points[:, 1]), np.arctan2(points[:, 1], points[:, 0])
    clear = np.abs(r - (1 + 0.2 * np.sin(7 * t))) > 1e-3     # the polygon is within 1e-3 of the curve
    assert np.array_equal(got[clear], (r < 1 + 0.2 * np.sin(7 * t))[clear])
