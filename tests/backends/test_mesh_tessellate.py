"""Tessellation to a certified chordal deviation, measured on a dense barycentric lattice of every
triangle against the exact surface: closest points found from scratch (global KD-tree seeds + Newton,
`Patch.closest`, not the mesher's own (u, v)), cross-checked once with rgm.geometry's point inversion."""
import numpy as np
import pytest
from hypothesis import assume, example, given, settings, strategies as st

from rgm.backends.mesh_surface import NurbsPatch
from rgm.backends.mesh import mesh_deviation, signed_volume, tessellate, tessellate_mesh, write_mesh
from rgm.errors import BackendError
from rgm.geometry import NurbsCurve, NurbsSurface
from rgm.model import BSplineCurve, BSplineSurface, Circle, Loop, Model, Polyline, Revolution, Shell, TrimmedFace

LATTICE = 6   # barycentric steps per triangle edge for the deviation measurement (28 samples)


def lattice():
    i, j = np.meshgrid(np.arange(LATTICE + 1), np.arange(LATTICE + 1), indexing="ij")
    keep = i + j <= LATTICE
    a, b = i[keep] / LATTICE, j[keep] / LATTICE
    return np.column_stack([1 - a - b, a, b])


def measured_deviation(vertices, triangles, nurbs, oracle="patch"):
    """Max over dense triangle samples of the distance to the closest point of the exact surface."""
    pts = np.einsum("sk,tkd->tsd", lattice(), vertices[triangles]).reshape(-1, 3)
    if oracle == "geometry":
        return float(nurbs.closest_point(pts)[3].max())
    return float(NurbsPatch(nurbs).closest(pts)[1].max())


def random_surface(seed, n=5, degree=3, size=10.0, bump=2.0):
    rng = np.random.default_rng(seed)
    knots = np.concatenate([np.zeros(degree + 1), np.sort(rng.uniform(0.1, 0.9, n - degree - 1)),
                            np.ones(degree + 1)])
    g = np.linspace(0, size, n)
    ctrl = np.stack(list(np.meshgrid(g, g, indexing="ij")) + [rng.uniform(-bump, bump, (n, n))], axis=-1)
    weights = rng.uniform(0.5, 2.0, (n, n)) if seed % 2 else None
    return NurbsSurface(degree, degree, knots, knots, ctrl, weights)


def edge_counts(triangles, n):
    he = triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    directed = he[:, 0] * n + he[:, 1]
    undirected = np.sort(he, axis=1)
    _, counts = np.unique(undirected[:, 0] * n + undirected[:, 1], return_counts=True)
    return counts, len(np.unique(directed)) == len(directed)


@settings(max_examples=25, deadline=None, database=None)
@given(seed=st.integers(0, 10_000), tol=st.sampled_from([0.3, 0.1, 0.05]))
def test_random_surface_within_tolerance(seed, tol):
    nurbs = random_surface(seed)
    vertices, triangles = tessellate(BSplineSurface(nurbs), tol)
    assert len(triangles) > 0
    assert measured_deviation(vertices, triangles, nurbs) <= tol


@settings(max_examples=25, deadline=None, database=None)
@given(seed=st.integers(0, 10_000), degree=st.integers(1, 8))
@example(seed=124, degree=5)   # a span 5e-4 long: Su was off by 2e-9 when the power form was interpolated
def test_power_form_evaluator_agrees_with_the_geometry_evaluator(seed, degree):
    """The patches evaluate B-splines from per-span power forms: points and first partials agree with
    rgm.geometry's evaluation (rational or not, at span ends and inside, on spans of any length) to
    rounding, up to the highest degree put in power form (8; degree 8 lofts come from OpenCASCADE).
    The bound, 1e-13 of the largest value, is 3x the worst difference over every 7th seed x degrees
    1..8 (3.5e-14 for the partials, at degree 8; 1.8e-14 up to degree 5; points 5e-14, |S| <= 10,
    against 1e-12), the order of rgm.geometry's own error against exact rational arithmetic."""
    from rgm.backends.mesh_surface import RevolutionPatch

    nurbs = random_surface(seed, n=degree + 3, degree=degree)
    patch = NurbsPatch(nurbs)
    assert patch.power is not None
    rng = np.random.default_rng(seed)
    u = np.concatenate([rng.uniform(0, 1, 200), np.unique(nurbs.knots_u)])
    v = np.concatenate([rng.uniform(0, 1, 200), np.unique(nurbs.knots_v)[::-1]])
    d = nurbs.derivatives(u, v, 1)
    for got, want in zip(patch.d1(u, v), (d[0, 0], d[1, 0], d[0, 1])):
        assert np.abs(got - want).max() <= 1e-13 * (1 + np.abs(want).max())
    assert np.abs(patch.evaluate(u, v) - nurbs.evaluate(u, v)).max() <= 1e-13 * 10
    profile = BSplineCurve(NurbsCurve(degree, np.concatenate([np.zeros(degree + 1), [0.3, 0.6], np.ones(degree + 1)]),
                                      rng.uniform(1, 5, (degree + 3, 3)), rng.uniform(0.5, 2, degree + 3)))
    rev = RevolutionPatch(Revolution(profile, [0, 0, 0], [0, 0, 1]))
    c = profile.nurbs().derivatives(v, 1)
    pts, du, dv = rev.d1(np.zeros_like(v), v)
    assert np.abs(pts - c[0]).max() <= 1e-13 * 10 and np.abs(dv - c[1]).max() <= 1e-13 * (1 + np.abs(c[1]).max())


@settings(max_examples=20, deadline=None, database=None)
@given(seed=st.integers(0, 10_000), count=st.integers(1, 6))
def test_stacked_patches_evaluate_and_project_as_each_does_alone(seed, count):
    """Several NURBS patches of one kind evaluated and projected onto together (`PatchStack`: one span
    lookup across their keyed knot vectors, `rgm.geometry.power_form.SurfaceStack`) give what each gives
    alone: points bit for bit, on knots and inside; closest points to round-off (a stack stops its
    Gauss-Newton steps when every patch's have converged, so a patch alone may stop a step earlier), also
    on a patch restricted to a sub-rectangle of its surface (its own clamp box), with points on the
    surface among those off it; unstackable patches (a revolution) are projected alone."""
    from rgm.backends.mesh_surface import RevolutionPatch, evaluate_together, project_together

    rng = np.random.default_rng(seed)
    odd = 2 * rng.integers(0, 2) + 1     # all rational or all polynomial: one kind per stack
    patches = [NurbsPatch(random_surface(odd + 2 * int(rng.integers(0, 5000)), n=int(rng.integers(4, 8))))
               for _ in range(count)]
    patches.append(patches[0].restrict(((0.2, 0.7), (0.1, 0.6))))
    patches.append(RevolutionPatch(Revolution(Polyline([[1, 0, 0], [2, 0, 1], [2, 0, 3]]), [0, 0, 0], [0, 0, 1])))
    uv = []
    for p in patches:
        (u0, u1), (v0, v1) = p.domain
        k = int(rng.integers(1, 40))
        uv.append(np.column_stack([rng.uniform(u0, u1, k), rng.uniform(v0, v1, k)]))
        if isinstance(p, NurbsPatch):
            uv[-1][0] = (p.breaks_u[1], p.breaks_v[-2])        # on knots
    together = evaluate_together(patches, uv)
    for p, a, b in zip(patches, uv, together):
        assert np.array_equal(b, p.whole.evaluate(a[:, 0], a[:, 1]))
    points = [x + rng.normal(0, 0.05, x.shape) * (rng.uniform(size=(len(x), 1)) < 0.7) for x in together]
    guesses = [p.clamp(a + rng.normal(0, 0.02, a.shape)) for p, a in zip(patches, uv)]
    for p, x, g, (got_uv, got_d) in zip(patches, points, guesses, project_together(patches, points, guesses, 4)):
        want_uv, want_d = p.project(x, g, iterations=4)
        assert np.abs(got_uv - want_uv).max() <= 1e-12 and np.abs(got_d - want_d).max() <= 1e-11


def test_deviation_agrees_with_geometry_point_inversion():
    nurbs = random_surface(281)
    vertices, triangles = tessellate(BSplineSurface(nurbs), 0.1)
    ours = measured_deviation(vertices, triangles, nurbs)
    theirs = measured_deviation(vertices, triangles, nurbs, oracle="geometry")
    assert theirs <= 0.1 and abs(ours - theirs) < 1e-6


def star_loop(rng, center, k=9):
    """A random smooth star-shaped closed uv curve around `center`, inside (0.05, 0.95)^2: a clamped cubic
    B-spline on a jittered star polygon (first point repeated), and a dense polygon of it."""
    ang = 2 * np.pi * (np.arange(k) + rng.uniform(-0.3, 0.3, k)) / k
    rad = rng.uniform(0.3, 0.42, k)
    pts = center + np.column_stack([np.cos(ang), np.sin(ang)]) * rad[:, None]
    pts = np.vstack([pts, pts[:1]])
    n = len(pts)
    knots = np.concatenate([np.zeros(4), np.arange(1, n - 3) / (n - 3), np.ones(4)])
    curve = NurbsCurve(3, knots, pts)
    return curve, curve.evaluate(np.linspace(0, 1, 4001))


def inside(pts, poly):
    a, b = poly[:-1], poly[1:]
    x, y = pts[:, 0:1], pts[:, 1:2]
    cond = (a[:, 1] > y) != (b[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = a[:, 0] + (y - a[:, 1]) * (b[:, 0] - a[:, 0]) / (b[:, 1] - a[:, 1])
    return (np.count_nonzero(cond & (x < xi), axis=1) % 2).astype(bool)


def segment_distance(pts, poly):
    """Distance of 2-D points to a closed polyline."""
    a, b = poly[:-1], poly[1:]
    ab = b - a
    t = np.clip(((pts[:, None] - a) * ab).sum(-1) / (ab * ab).sum(-1), 0, 1)
    return np.linalg.norm(pts[:, None] - (a + t[..., None] * ab), axis=-1).min(axis=1)


@settings(max_examples=25, deadline=None, database=None)
@given(seed=st.integers(0, 10_000), tol=st.sampled_from([0.2, 0.1]))
def test_random_trimmed_face_within_tolerance_and_trim(seed, tol):
    rng = np.random.default_rng(seed)
    nurbs = random_surface(seed)
    curve, outer = star_loop(rng, np.array([0.5, 0.5]))
    assume(segment_distance(np.array([[0.5, 0.5]]), outer)[0] > 0.12)   # the hole lies inside the outer loop
    hole = Circle(np.array([0.5, 0.5]), [0, 0, -1], 0.08)
    face = TrimmedFace(BSplineSurface(nurbs), Loop((BSplineCurve(curve),)), (Loop((hole,)),))
    mesh = tessellate_mesh(face, tol)
    v, t = mesh.vertices, mesh.triangles
    assert measured_deviation(v, t, nurbs) <= tol
    # no triangle outside the trim: a triangle point whose (u, v) falls outside the outer loop or inside
    # the hole is within tol (in space) of that trimming curve's image on the surface
    uv = np.concatenate([np.einsum("sk,tkd->tsd", lattice(), f.tri_uv).reshape(-1, 2) for f in mesh.faces])
    ring = 0.5 + 0.08 * np.column_stack([np.cos(np.linspace(0, 2 * np.pi, 2001)), np.sin(np.linspace(0, 2 * np.pi, 2001))])
    for bad, curve in ((~inside(uv, outer), outer), (np.linalg.norm(uv - 0.5, axis=1) < 0.08, ring)):
        if bad.any():
            image = nurbs.evaluate(curve[:, 0], curve[:, 1])
            pts = nurbs.evaluate(uv[bad, 0], uv[bad, 1])
            gap = np.linalg.norm(pts[:, None] - image[None], axis=-1).min(axis=1)
            assert gap.max() <= tol
    # the trimmed region is covered: the area differs from a finer mesh's by at most a boundary strip
    # as wide as the tolerance (chords cut inside curved trimming loops)
    fine_v, fine_t = tessellate(face, tol / 2)
    perimeter = sum(np.linalg.norm(np.diff(nurbs.evaluate(c[:, 0], c[:, 1]), axis=0), axis=1).sum() for c in (outer, ring))
    assert abs(area(v, t) - area(fine_v, fine_t)) <= 2 * tol * perimeter


def test_straight_uv_trim_with_hole():
    """Straight uv trimming lines (collinear samples in (u, v)) around a circular hole."""
    nurbs = random_surface(5)
    outer = Loop((Polyline([[0.1, 0.1], [0.9, 0.1], [0.9, 0.9], [0.1, 0.9], [0.1, 0.1]]),))
    face = TrimmedFace(BSplineSurface(nurbs), outer, (Loop((Circle([0.5, 0.5], [0, 0, -1], 0.2),)),))
    mesh = tessellate_mesh(face, 0.05)
    assert measured_deviation(mesh.vertices, mesh.triangles, nurbs) <= 0.05
    uv = np.concatenate([f.tri_uv.mean(axis=1) for f in mesh.faces])
    assert (uv > 0.1 - 1e-9).all() and (uv < 0.9 + 1e-9).all()


def area(v, t):
    return 0.5 * np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1).sum()


PIN = np.array([[0, 0, 0], [25.95, 0, 0], [27.15, 1.2, 0], [27.15, 128.68, 0], [25.95, 129.88, 0],
                [0, 129.88, 0]])


def pappus(profile):
    """Exact volume and area of a polyline profile (x >= 0, in the xy plane) revolved about the y axis."""
    x0, x1 = profile[:-1, 0], profile[1:, 0]
    dy = np.diff(profile[:, 1])
    ds = np.linalg.norm(np.diff(profile, axis=0), axis=1)
    volume = abs(np.sum(np.pi * dy * (x0 * x0 + x0 * x1 + x1 * x1) / 3))
    return volume, float(np.sum(np.pi * ds * (x0 + x1)))


def pin_model():
    try:
        import rgm

        return rgm.load("examples/pin.rgm")
    except Exception:  # the evaluator is not importable: the same object built directly
        return Model("mm", 0.01, {"pin": Revolution(Polyline(PIN), [0, 0, 0], [0, 1, 0], name="pin")}, ("pin",))


@pytest.mark.parametrize("tol", [0.1, 0.01])
def test_pin_watertight_and_volume(tol):
    model = pin_model()
    vertices, triangles = tessellate(model, tol)
    counts, consistent = edge_counts(triangles, len(vertices))
    assert np.all(counts == 2) and consistent          # closed 2-manifold, consistent orientation
    volume, surface_area = pappus(PIN)
    mesh_volume = signed_volume(vertices, triangles)
    assert mesh_volume > 0                             # facing outwards
    assert abs(mesh_volume - volume) <= tol * surface_area
    # not more triangles than needed: the cylinder needs n segments with r (1 - cos(pi / n)) <= tol
    n_min = int(np.ceil(np.pi / np.arccos(1 - tol / 27.15)))
    assert len(triangles) <= 10 * n_min
    # the end disks are planar: triangulated from their rims alone, no vertex on the axis (a pole fan);
    # their long triangles pass near the axis, where the closest-point oracle must still find the disk
    assert np.hypot(vertices[:, 0], vertices[:, 2]).min() > 25.9
    assert mesh_deviation(tessellate_mesh(model, tol)) <= tol


def test_closest_point_near_a_pole_of_a_revolution():
    """Points on the pin's end disk near the axis, at any angle: the closest point is the point itself
    (the grid's nearest nodes are all the pole, where Gauss-Newton cannot turn; the meridian seed can)."""
    from rgm.backends.mesh_surface import RevolutionPatch

    pin = RevolutionPatch(Revolution(Polyline(PIN), [0, 0, 0], [0, 1, 0]))
    cap = pin.restrict((pin.domain[0], (0.0, 0.2)))
    rng = np.random.default_rng(3)
    r, a = rng.uniform(0, 1.0, 400), rng.uniform(0, 2 * np.pi, 400)
    x = np.column_stack([r * np.cos(a), np.zeros(400), r * np.sin(a)])
    assert cap.closest(x)[1].max() < 1e-9
    assert pin.closest(x)[1].max() < 1e-9


def planar_surface(seed, degree=3, n=6):
    """A NURBS patch lying exactly in a random plane (10 mm square), its (u, v) distorted in the plane
    (a jittered control grid, rational for odd seeds): flat, but not parameterised by plane coordinates."""
    rng = np.random.default_rng(seed)
    knots = np.concatenate([np.zeros(degree + 1), np.sort(rng.uniform(0.1, 0.9, n - degree - 1)),
                            np.ones(degree + 1)])
    g = np.linspace(0, 10.0, n)
    x, y = np.meshgrid(g, g, indexing="ij")
    flat = np.stack([x + rng.uniform(-0.6, 0.6, x.shape), y + rng.uniform(-0.6, 0.6, y.shape)], axis=-1)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    ctrl = flat @ q[:2] + rng.normal(size=3)
    weights = rng.uniform(0.5, 2.0, (n, n)) if seed % 2 else None
    return NurbsSurface(degree, degree, knots, knots, ctrl, weights)


@settings(max_examples=25, deadline=None, database=None)
@given(seed=st.integers(0, 10_000), tol=st.sampled_from([0.1, 0.01]))
def test_planar_trimmed_face_is_its_boundary_polygon(seed, tol):
    """A flat trimmed face (random plane, distorted (u, v), star-shaped outer loop, round hole) is
    triangulated from its boundary samples alone: T = V + 2h - 2 triangles (no interior vertex), within
    tol of the exact surface (measured), facing along Su x Sv, covering the trimmed area."""
    rng = np.random.default_rng(seed)
    nurbs = planar_surface(seed)
    curve, outer = star_loop(rng, np.array([0.5, 0.5]))
    assume(segment_distance(np.array([[0.5, 0.5]]), outer)[0] > 0.12)
    face = TrimmedFace(BSplineSurface(nurbs), Loop((BSplineCurve(curve),)),
                       (Loop((Circle(np.array([0.5, 0.5]), [0, 0, -1], 0.08),)),))
    mesh = tessellate_mesh(face, tol)
    v, t = mesh.vertices, mesh.triangles
    assert len(t) == len(v) + 2 * 1 - 2
    assert measured_deviation(v, t, nurbs) <= tol
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    _, su, sv = NurbsPatch(nurbs).d1(np.array([0.5]), np.array([0.5]))
    assert (n @ np.cross(su, sv)[0] > 0).all()
    fine = tessellate_mesh(face, tol / 10)
    assert len(fine.triangles) == len(fine.vertices)  # still boundary-only: only the chords get closer
    perimeter = sum(np.linalg.norm(np.diff(nurbs.evaluate(c[:, 0], c[:, 1]), axis=0), axis=1).sum()
                    for c in (outer, 0.5 + 0.08 * np.column_stack([np.cos(np.linspace(0, 2 * np.pi, 2001)),
                                                                   np.sin(np.linspace(0, 2 * np.pi, 2001))])))
    assert abs(area(v, t) - area(fine.vertices, fine.triangles)) <= tol * perimeter


def test_holes_of_a_face_without_outer_loop_are_kept():
    """A trimmed face with holes and no outer loop is the whole surface less the holes (its holes were
    dropped before): no triangle inside the hole, and the same area as with the domain as outer loop."""
    nurbs = random_surface(11)
    hole = (Loop((Circle([0.3, 0.5], [0, 0, -1], 0.12),)),)
    mesh = tessellate_mesh(TrimmedFace(BSplineSurface(nurbs), None, hole), 0.05)
    v, t = mesh.vertices, mesh.triangles
    inside = np.linalg.norm(np.concatenate([f.tri_uv.mean(axis=1) for f in mesh.faces]) - [0.3, 0.5], axis=1)
    assert inside.min() >= 0.12 - 0.02
    square = Loop((Polyline([[0, 0], [1, 0], [1, 1], [0, 1], [0, 0]]),))
    v2, t2 = tessellate(TrimmedFace(BSplineSurface(nurbs), square, hole), 0.05)
    ring = nurbs.evaluate(0.3 + 0.12 * np.cos(np.linspace(0, 2 * np.pi, 2001)), 0.5 + 0.12 * np.sin(np.linspace(0, 2 * np.pi, 2001)))
    assert abs(area(v, t) - area(v2, t2)) <= 0.05 * np.linalg.norm(np.diff(ring, axis=0), axis=1).sum()
    # and the hole's own area is what is missing: |Su x Sv| integrated over the disk (midpoint rule, polar)
    r, a = np.meshgrid((np.arange(200) + 0.5) / 200 * 0.12, (np.arange(400) + 0.5) / 400 * 2 * np.pi, indexing="ij")
    _, su, sv = NurbsPatch(nurbs).d1((0.3 + r * np.cos(a)).ravel(), (0.5 + r * np.sin(a)).ravel())
    hole_area = (np.linalg.norm(np.cross(su, sv), axis=1) * r.ravel()).sum() * (0.12 / 200) * (2 * np.pi / 400)
    missing = area(*tessellate(BSplineSurface(nurbs), 0.05)) - area(v, t)   # 1.85 mm^2 of 2.00
    assert abs(missing - hole_area) <= 0.05 * np.linalg.norm(np.diff(ring, axis=0), axis=1).sum()


def test_flat_surface_folded_over_itself_is_meshed_in_uv():
    """A flat patch folding back over itself (x runs 0 -> 10 -> 0 mm along u): its trim circle's image
    crosses itself in the plane, so the plane triangulation is refused and the face is meshed in (u, v)
    (interior points), still within tol and covering the trim (area against a 10x finer mesh)."""
    k = [0, 0, 0, 1, 1, 1]
    x, y = np.meshgrid([0.0, 20.0, 0.0], [0.0, 5.0, 10.0], indexing="ij")
    flat = NurbsSurface(2, 2, k, k, np.stack([x, y, np.zeros_like(x)], axis=-1))
    face = TrimmedFace(BSplineSurface(flat), Loop((Circle([0.5, 0.5], [0, 0, 1], 0.3),)))
    mesh = tessellate_mesh(face, 0.05)
    assert len(mesh.triangles) > len(mesh.vertices) - 2
    assert measured_deviation(mesh.vertices, mesh.triangles, flat) <= 0.05
    fine = tessellate_mesh(face, 0.005)
    ring = flat.evaluate(0.5 + 0.3 * np.cos(np.linspace(0, 2 * np.pi, 2001)), 0.5 + 0.3 * np.sin(np.linspace(0, 2 * np.pi, 2001)))
    perimeter = np.linalg.norm(np.diff(ring, axis=0), axis=1).sum()
    assert abs(area(mesh.vertices, mesh.triangles) - area(fine.vertices, fine.triangles)) <= 0.05 * perimeter


def test_planarity_is_decided_by_the_control_net():
    """Coplanar control points (convex hull) make a face planar; a net 1 % of the tolerance out of its
    plane does not, and neither does a cone (a revolution's profile not perpendicular to its axis)."""
    from rgm.backends.mesh_planar import plane_frame
    from rgm.backends.mesh_surface import RevolutionPatch

    flat = planar_surface(7)
    assert plane_frame(NurbsPatch(flat), 0.1) is not None
    ctrl = flat.ctrl.copy()
    ctrl[2, 3] += 1e-3 * np.cross(ctrl[0, 1] - ctrl[0, 0], ctrl[1, 0] - ctrl[0, 0]) / np.linalg.norm(
        np.cross(ctrl[0, 1] - ctrl[0, 0], ctrl[1, 0] - ctrl[0, 0]))
    assert plane_frame(NurbsPatch(NurbsSurface(3, 3, flat.knots_u, flat.knots_v, ctrl, flat.weights)), 0.1) is None
    pin = RevolutionPatch(Revolution(Polyline(PIN), [0, 0, 0], [0, 1, 0]))
    spans = [pin.restrict((pin.domain[0], (a, b))) for a, b in zip(pin.breaks_v[:-1], pin.breaks_v[1:])]
    assert [plane_frame(p, 0.1) is not None for p in spans] == [True, False, False, False, True]


def test_angle_tolerance_refines_normals():
    nurbs = random_surface(3, bump=3.0)
    v, t = tessellate(BSplineSurface(nurbs), 1.0, angle_tol=np.radians(5))
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    u, w, _, _ = nurbs.closest_point(v[t].reshape(-1, 3))
    ns = nurbs.normal(u, w).reshape(-1, 3, 3)
    angle = np.arccos(np.clip(np.einsum("td,tkd->tk", n, ns), -1, 1))
    assert angle.max() <= np.radians(5) + 1e-9
    assert len(t) > len(tessellate(BSplineSurface(nurbs), 1.0)[1])


def test_shell_of_patches_is_watertight_cube():
    """Six bilinear patches of a unit cube, parameterised in assorted directions: one closed mesh."""
    c = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    k = [0, 0, 1, 1]
    faces = [BSplineSurface(NurbsSurface(1, 1, k, k, np.array([[c[a], c[b]], [c[d], c[e]]])))
             for a, b, e, d in quads]
    v, t = tessellate(Shell(faces), 0.01)
    counts, consistent = edge_counts(t, len(v))
    assert np.all(counts == 2) and consistent
    assert signed_volume(v, t) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("fmt", ["stl", "obj", "ply", "glb"])
def test_write_mesh_formats_read_back(tmp_path, fmt):
    trimesh = pytest.importorskip("trimesh")
    model = pin_model()
    path = write_mesh(model, tmp_path / f"pin.{fmt}", fmt=fmt, tol=0.1)
    loaded = trimesh.load(path, force="mesh")
    v, t = tessellate(model, 0.1)
    assert len(loaded.faces) == len(t)
    assert loaded.is_watertight
    assert loaded.volume == pytest.approx(signed_volume(v, t), rel=1e-5)


def test_write_mesh_reports_size_and_watertightness(tmp_path):
    """The report line (`rgmc compile` prints it) gives the file's triangle count and says watertight only
    for a closed mesh: the pin is, one open patch is not (its border edges are counted, as trimesh does)."""
    trimesh = pytest.importorskip("trimesh")
    lines = []
    path = write_mesh(pin_model(), tmp_path / "pin.stl", fmt="stl", tol=0.1, report=lines.append)
    assert f"{len(trimesh.load(path).faces)} triangles" in lines[0] and lines[0].endswith("watertight")
    patch = Model("mm", 0.01, {"s": BSplineSurface(random_surface(3))}, ("s",))
    path = write_mesh(patch, tmp_path / "s.stl", fmt="stl", tol=0.1, report=lines.append)
    mesh = trimesh.load(path)
    border = int((np.bincount(mesh.edges_unique_inverse) == 1).sum())
    assert not mesh.is_watertight and f"; {border} open or non-manifold edges" in lines[1]


def test_bad_requests_are_clear_errors(tmp_path):
    with pytest.raises(BackendError, match="positive"):
        tessellate(pin_model(), 0.0)
    with pytest.raises(BackendError, match="format"):
        write_mesh(pin_model(), tmp_path / "x.abc", fmt="abc", tol=0.1)
    assert not (tmp_path / "x.abc").exists()


def test_trim_loop_of_3d_curves_across_a_seam():
    """A full cylinder trimmed by 3-D curves as IGES files give it (top circle, the seam line down, bottom
    circle, the seam line up): the seam pieces land on opposite sides of the domain, so the face is the
    whole tube, stitched along its seam, with its exact area up to the chordal bound."""
    from rgm.model import Line

    seam_top, seam_bottom = [5.0, 0.0, 10.0], [5.0, 0.0, -10.0]
    tube = Revolution(Line(seam_bottom, seam_top), [0, 0, 0], [0, 0, 1])
    loop = Loop((Circle([0, 0, 10], [0, 0, -1], 5.0), Line(seam_top, seam_bottom), Circle([0, 0, -10], [0, 0, 1], 5.0),
                 Line(seam_bottom, seam_top)))
    tol = 0.01
    v, t = tessellate(TrimmedFace(tube, loop), tol)
    counts, consistent = edge_counts(t, len(v))
    assert consistent and set(counts) == {1, 2}
    he = np.sort(t[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    keys, n = np.unique(he[:, 0] * len(v) + he[:, 1], return_counts=True)
    rim = np.unique(np.stack([keys[n == 1] // len(v), keys[n == 1] % len(v)]))
    assert np.abs(np.abs(v[rim, 2]) - 10).max() < 1e-9           # open only along the two circles
    assert area(v, t) == pytest.approx(2 * np.pi * 5 * 20, abs=tol * 2 * (2 * np.pi * 5))


def test_angle_tolerance_on_faces_meeting_at_creases():
    """The pin's faces meet at creases (its profile's corners): each face's normals on its own edges are
    its own one-sided ones, so the angle refinement terminates, and every triangle's normal is within
    the angle tolerance of its face's normals at its corners."""
    angle = np.radians(4)
    mesh = tessellate_mesh(pin_model(), 0.1, angle)
    for f in mesh.faces:
        v = mesh.vertices[f.tri]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        ns = f.patch.normal(f.tri_uv[..., 0].ravel(), f.tri_uv[..., 1].ravel()).reshape(-1, 3, 3)
        cos = np.abs(np.einsum("td,tkd->tk", n, ns))     # orientation aside (faces may be flipped outwards)
        assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() <= np.degrees(angle) + 1e-6
    assert len(mesh.triangles) > len(tessellate(pin_model(), 0.1)[1])
