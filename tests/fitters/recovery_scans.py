"""Test helpers for model recovery: exact ray-cast range views of revolved polyline profiles (the paper's
pin), superellipsoid clouds, YCB mesh views.  Everything from fixed seeds."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from rgm.fitters.superellipsoid import Superellipsoid

YCB = Path("/work/shared/data/ycb")
PIN_RADIUS, PIN_LENGTH = 27.15, 129.88


def pin_profile(radius=PIN_RADIUS, length=PIN_LENGTH, chamfer=0.0):
    """(k, 2) (r, z) polyline of a pin along its axis, from the axis at z = 0 to the axis at z = length."""
    if chamfer:
        return np.array([[0, 0], [radius - chamfer, 0], [radius, chamfer], [radius, length - chamfer],
                         [radius - chamfer, length], [0, length]], float)
    return np.array([[0, 0], [radius, 0], [radius, length], [0, length]], float)


def turned_profile(radius=PIN_RADIUS, length=PIN_LENGTH, *, fillet=0.0, bump=None, arc_step=np.radians(3.0),
                   bump_step=0.5):
    """(k, 2) (r, z) polyline, axis to axis, of a pin with quarter-circle fillets of radius `fillet` (mm) at
    both end edges and, with bump = (z0, z1, height), a smooth bulge of the mantle between z0 and z1:
    r = radius + 16 height u^2 (1 - u)^2, u = (z - z0) / (z1 - z0) (a quartic: not a conic, tangent to
    the mantle at both ends).  Curves are sampled as chords (`arc_step` radians on the fillets,
    `bump_step` mm along z on the bulge): their sagitta (fillet (1 - cos(arc_step / 2)): 1.4e-3 mm on a 4 mm
    fillet by default; 32 height bump_step^2 / (8 (z1 - z0)^2) on the bulge: 2.4e-3 mm for 6 mm over 50 mm)
    is the truth's own error."""
    pts = [[0.0, 0.0]]
    if fillet:
        a = np.linspace(-np.pi / 2, 0.0, max(2, int(np.ceil(np.pi / 2 / arc_step)) + 1))
        pts += list(np.column_stack([radius - fillet + fillet * np.cos(a), fillet + fillet * np.sin(a)]))
    else:
        pts.append([radius, 0.0])
    if bump is not None:
        z0, z1, height = bump
        u = np.linspace(0.0, 1.0, max(3, int(np.ceil((z1 - z0) / bump_step)) + 1))
        pts += list(np.column_stack([radius + 16 * height * u ** 2 * (1 - u) ** 2, z0 + u * (z1 - z0)]))
    if fillet:
        a = np.linspace(0.0, np.pi / 2, max(2, int(np.ceil(np.pi / 2 / arc_step)) + 1))
        pts += list(np.column_stack([radius - fillet + fillet * np.cos(a), length - fillet + fillet * np.sin(a)]))
    else:
        pts.append([radius, length])
    pts.append([0.0, length])
    return np.array(pts, float)


def revolved_cloud(profile, n, rng, *, noise=0.0):
    """n points (n, 3) area-uniform on the surface made by revolving the (r, z) polyline `profile` about
    the z axis, their exact unit normals (n, 3) (of the polyline's chords), and Gaussian noise `noise`
    (mm) along the normal."""
    seg = np.diff(profile, axis=0)
    length = np.linalg.norm(seg, axis=1)
    area = length * (profile[:-1, 0] + profile[1:, 0])
    k = rng.choice(len(seg), n, p=area / area.sum())
    t = rng.random(n)
    r0, r1 = profile[k, 0], profile[k + 1, 0]
    t = np.where(np.abs(r1 - r0) > 1e-12, (np.sqrt(r0 ** 2 + t * (r1 ** 2 - r0 ** 2)) - r0) / np.where(
        np.abs(r1 - r0) > 1e-12, r1 - r0, 1.0), t)                     # uniform in area, not in length
    rz = profile[k] + t[:, None] * seg[k]
    nr, nz = seg[k, 1] / length[k], -seg[k, 0] / length[k]              # outward for a profile run upwards
    phi = rng.uniform(0, 2 * np.pi, n)
    normals = np.column_stack([nr * np.cos(phi), nr * np.sin(phi), nz])
    points = np.column_stack([rz[:, 0] * np.cos(phi), rz[:, 0] * np.sin(phi), rz[:, 1]])
    return points + rng.normal(0, noise, (n, 1)) * normals, normals


def raycast_revolved(profile, origins, dirs):
    """First hits (m,) t (inf = miss) of rays o + t d (m, 3) with the surface made by revolving the (r, z)
    polyline `profile` about the y axis (z of the profile = world y)."""
    o = origins[:, [0, 2, 1]] * [1, 1, 1]
    d = dirs[:, [0, 2, 1]]
    # in (x, w, y) with axis coordinate y: |x|^2 + |w|^2 = r^2
    best = np.full(len(o), np.inf)
    for (r0, z0), (r1, z1) in zip(profile[:-1], profile[1:]):
        if abs(z1 - z0) < 1e-12:  # disc at z0
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (z0 - o[:, 2]) / d[:, 2]
            hit = o + t[:, None] * d
            r = np.hypot(hit[:, 0], hit[:, 1])
            ok = (t > 0) & (r >= min(r0, r1) - 1e-12) & (r <= max(r0, r1))
            best = np.where(ok & (t < best), t, best)
            continue
        beta = (r1 - r0) / (z1 - z0)
        alpha = r0 - beta * z0                       # r = alpha + beta z
        a = d[:, 0] ** 2 + d[:, 1] ** 2 - beta ** 2 * d[:, 2] ** 2
        b = 2 * (o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1] - beta * d[:, 2] * (alpha + beta * o[:, 2]))
        c = o[:, 0] ** 2 + o[:, 1] ** 2 - (alpha + beta * o[:, 2]) ** 2
        disc = b * b - 4 * a * c
        sq = np.sqrt(np.maximum(disc, 0))
        for sign in (-1, 1):
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (-b + sign * sq) / (2 * a)
            z = o[:, 2] + t * d[:, 2]
            ok = (disc >= 0) & (t > 0) & (z >= min(z0, z1)) & (z <= max(z0, z1)) & (alpha + beta * z >= 0)
            best = np.where(ok & (t < best), t, best)
    return best


def _view_rays(direction, centre, size, pitch):
    d = np.asarray(direction, float)
    d /= np.linalg.norm(d)
    e = np.eye(3)[np.argmin(np.abs(d))]
    u = np.cross(d, e)
    u /= np.linalg.norm(u)
    v = np.cross(d, u)
    s = np.arange(-size, size, pitch)
    gu, gv = np.meshgrid(s, s)
    origins = centre - 3 * size * d + gu.reshape(-1, 1) * u + gv.reshape(-1, 1) * v
    return origins, np.broadcast_to(d, origins.shape).copy()


def scan_views(hit_fn, directions, centre, size, *, pitch, noise, outliers, seed, pose=np.eye(4)):
    """Views (list of (k, 3) world points) of a surface given by hit_fn(origins, dirs) -> t, each with
    Gaussian noise `noise` along the ray and a fraction `outliers` of points moved along the ray by
    2-20 % of `size`; finally mapped by `pose` (4, 4)."""
    rng = np.random.default_rng(seed)
    views = []
    for direction in directions:
        o, d = _view_rays(direction, centre, size, pitch)
        t = hit_fn(o, d)
        ok = np.isfinite(t)
        o, d, t = o[ok], d[ok], t[ok] + rng.normal(0, noise, ok.sum())
        bad = rng.random(len(t)) < outliers
        t[bad] += rng.choice([-1, 1], bad.sum()) * rng.uniform(0.02, 0.2, bad.sum()) * size
        p = o + t[:, None] * d
        views.append(p @ pose[:3, :3].T + pose[:3, 3])
    return views


def pin_views(*, chamfer=0.0, noise=0.03, outliers=0.05, seed=0, pose=np.eye(4), pitch=0.75, profile=None):
    """Several range views of the paper's pin (axis along y; or of another revolved `profile`), three
    around the axis, two oblique views that see the end caps and two that look into grooves."""
    prof = pin_profile(chamfer=chamfer) if profile is None else profile
    dirs = [(1, 0.35, 0), (-0.5, -0.35, 0.87), (-0.5, 0.3, -0.87), (0.3, 1.2, 0.2), (-0.2, -1.2, -0.3)]
    if profile is not None:
        dirs += [(1, -0.5, 0.2), (-1, 0.5, -0.3)]
    return scan_views(lambda o, d: raycast_revolved(prof, o, d), dirs, np.array([0, PIN_LENGTH / 2, 0]),
                      PIN_LENGTH / 2 + 10, pitch=pitch, noise=noise, outliers=outliers, seed=seed, pose=pose)


def one_line(text: str) -> str:
    """The `.rgm` text with the formatter's breaks inside brackets undone (one argument per line, trailing
    commas), so that a call can be looked for as a substring whatever its length."""
    text = re.sub(r",\s*\n\s*([)\]])", r"\1", text)
    text = re.sub(r"([(\[])\s*\n\s*", r"\1", text)
    return re.sub(r",\s*\n\s*", ", ", text)


def assert_rgm_clean(text, filename="part.rgm", *, path=None):
    """The `.rgm` text formats and `rgmc check` reports no diagnostic at all (0 errors, 0 warnings); with
    `path` (the file `rgmc fit` wrote, holding `text`) the file is also in canonical form
    (`rgmc fmt --check` passes)."""
    from rgm.cli import main
    from rgm.commands.check import check_source
    from rgm.commands.fmt import canonical

    assert canonical(text, filename)[0] is not None, f"{filename} does not format"
    diagnostics = check_source(text, filename, None)
    assert diagnostics == [], [d.message for d in diagnostics]
    if path is not None:
        assert main(["fmt", "--check", str(path)]) == 0, f"{path} is not in canonical form"


def random_rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def superellipsoid_cloud(se: Superellipsoid, n, *, noise=0.01, outliers=0.05, rng):
    """n points on `se` (directions uniform on the sphere, pushed radially to the surface), Gaussian noise
    of `noise` x the mean semi-axis, and a fraction `outliers` replaced by uniform points in the box 20 %
    larger than the cloud.  Returns (points, outlier mask)."""
    pts = se.surface_points(rng.normal(size=(n, 3)))
    pts += rng.normal(size=pts.shape) * noise * se.size.mean()
    bad = rng.random(n) < outliers
    lo, hi = pts.min(0), pts.max(0)
    pts[bad] = rng.uniform(lo - 0.2 * (hi - lo), hi + 0.2 * (hi - lo), (bad.sum(), 3))
    return pts, bad


def mesh_views(path, directions, *, pitch, noise, outliers, seed, units=1000.0):
    """Orthographic range views (list of (k, 3), mm) of a mesh file (metres -> mm by `units`): a z-buffer
    of a dense surface sample (about 10 samples a pixel), one point per pixel of side `pitch`, the nearest
    to the sensor; Gaussian noise `noise` along the view direction and a fraction `outliers` moved along
    it by 2-20 % of the part size."""
    import trimesh

    mesh = trimesh.load(path, force="mesh", process=False)
    mesh.apply_scale(units)
    rng = np.random.default_rng(seed)
    dense = trimesh.sample.sample_surface(mesh, int(10 * mesh.area / pitch ** 2), seed=seed)[0]
    size = float(np.linalg.norm(mesh.extents)) / 2
    views = []
    for direction in directions:
        d = np.asarray(direction, float) / np.linalg.norm(direction)
        u = np.cross(d, np.eye(3)[np.argmin(np.abs(d))])
        u /= np.linalg.norm(u)
        v = np.cross(d, u)
        ij = np.floor(np.column_stack([dense @ u, dense @ v]) / pitch).astype(np.int64)
        depth = dense @ d
        key = (ij[:, 0] - ij[:, 0].min()) * (np.ptp(ij[:, 1]) + 1) + (ij[:, 1] - ij[:, 1].min())
        order = np.lexsort((depth, key))
        first = order[np.r_[True, np.diff(key[order]) != 0]]
        p = dense[first] + rng.normal(0, noise, (len(first), 1)) * d
        bad = rng.random(len(p)) < outliers
        p[bad] += (rng.choice([-1, 1], bad.sum()) * rng.uniform(0.02, 0.2, bad.sum()) * size)[:, None] * d
        views.append(p)
    return views, mesh


def _uniform_directions(rng, n):
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def sample_primitive(kind, rng, n=3000, *, noise=0.01, outliers=0.05):
    """n points on a random `kind` ("box", "cylinder", "sphere", "ellipsoid", "free_form") of random size
    (10-100 mm) and pose: area-uniform on the surface, Gaussian noise of `noise` x the mean size, a
    fraction `outliers` uniform in the box 20 % larger than the cloud.  Returns points (n, 3)."""
    if kind == "box":
        half = rng.uniform(10, 100, 3)
        areas = np.array([half[1] * half[2], half[0] * half[2], half[0] * half[1]])
        axis = rng.choice(3, n, p=areas / areas.sum())
        p = rng.uniform(-1, 1, (n, 3)) * half
        p[np.arange(n), axis] = rng.choice([-1, 1], n) * half[axis]
        size = half.mean()
    elif kind == "cylinder":
        r, h = rng.uniform(10, 60), rng.uniform(20, 100)
        cap = rng.random(n) < r / (r + 2 * h)
        phi = rng.uniform(0, 2 * np.pi, n)
        rad = np.where(cap, r * np.sqrt(rng.random(n)), r)
        z = np.where(cap, rng.choice([-1, 1], n) * h, rng.uniform(-h, h, n))
        p = np.column_stack([rad * np.cos(phi), rad * np.sin(phi), z])
        size = (2 * r + h) / 3
    elif kind in ("sphere", "ellipsoid"):
        axes = np.full(3, rng.uniform(10, 100)) if kind == "sphere" else np.sort(rng.uniform(10, 100, 3)) * [1, 1.3, 1.8]
        p = _uniform_directions(rng, n) * axes
        size = axes.mean()
    elif kind == "free_form":
        d = _uniform_directions(rng, n)
        k = rng.normal(size=(4, 3))
        amp = rng.uniform(0.1, 0.3)
        bumps = sum(amp * np.sin(3 * d @ kk + rng.uniform(0, 6)) for kk in k)
        base = rng.uniform(20, 80)
        p = d * base * (1 + bumps)[:, None]
        size = base
    else:
        raise ValueError(kind)
    p = p + rng.normal(0, noise * size, p.shape)
    bad = rng.random(n) < outliers
    lo, hi = p.min(0), p.max(0)
    p[bad] = rng.uniform(lo - 0.2 * (hi - lo), hi + 0.2 * (hi - lo), (bad.sum(), 3))
    return p @ random_rotation(rng).T + rng.uniform(-300, 300, 3)
