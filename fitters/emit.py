"""Writing the recovered parts as formatted, type-correct `.rgm` text.

Each part is built in its own part-aligned frame from named dimensions (`param radius := 27.1500mm;`),
so a designer changes one number, and placed by one rotation (axis and angle) and one translation, each
left out when it is the identity; `snapped_placement` makes an axis or offset that the data cannot tell
from a world axis or from 0 exactly that (the pipeline re-measures the certificate and keeps it only if
it still holds).
The exported binding carries `@source` (scans and their sha256), `@classified` (category, confidence,
runner-up and the superellipsoid's numbers) and `@fit` (the certificate) annotations.

Emission also returns the *idealised* shape, rebuilt from the printed (rounded) numbers, so that the
certificate is measured on exactly the model the file describes.

Revolutions (the paper's pin, Figure 7): profile in the part's x-y plane (x = radius, y = along the axis
from 0 to `length`), revolved about the y axis.  Named dimensions: `radius` (the longest axis-parallel
line), `length` (the profile's extent along the axis), `chamfer` (45-degree lines joining the radius
to an end face, when all agree within their measured uncertainty; `chamfer1`, ... when not), `fillet`
(quarter-circle arcs tangent to an axis-parallel and a radial face; `fillet1`, ... when they differ)
and, per rectangular groove k, `groovek_at`, `groovek_width` and `groovek_depth`; other coordinates are
written as numbers.  A coordinate takes the nearest named expression within the snap distance.  Arcs are `arc(start, through, end)`;
free-form stretches are `bspline(degree: 3, knots: knots([...]), points: [...])` pieces of the `profile`,
their end control points the chain's vertices.
Boxes: a rectangle `base` in the part's x-y plane extruded along z by `height`, with trimmed planes as
bottom and top, as one `shell`; named dimensions `width` (x), `depth` (y), `height` (z).
"""
from __future__ import annotations

import os
import time
from dataclasses import dataclass, field, replace

import numpy as np

from rgm.fitters.primitives import BoxFit
from rgm.fitters.profile2d import Profile, Segment
from rgm.fitters.revolution import RevolutionFit, axis_frame

__all__ = ["EmittedPart", "emit_part", "snapped_placement", "write_rgm", "format_length"]

_DEC = 4  # decimals of lengths (model units): 0.1 micrometre in mm


def format_length(x: float) -> str:
    return f"{round(float(x), _DEC) + 0.0:.{_DEC}f}"


def _num(x: float) -> str:
    s = f"{round(float(x), _DEC) + 0.0:.{_DEC}f}".rstrip("0").rstrip(".")
    return s if s not in ("-0", "") else "0"


@dataclass
class EmittedPart:
    """name: the exported binding; params: (name, value, comment) triples; bindings: text lines
    defining the part's body (`body` name given); ideal: the shape rebuilt from the printed numbers."""

    name: str
    params: list
    bindings: list
    body: str
    ideal: object
    annotations: list = field(default_factory=list)


class _Dims:
    """Coordinates as expressions of named parameters where they match one exactly (after rounding)."""

    def __init__(self, snap: float):
        self.named: list[tuple[str, float]] = []
        self.snap = max(float(snap), 0.6 * 10 ** -_DEC)

    def add(self, name, value):
        value = round(float(value), _DEC)
        self.named.append((name, value))
        return value

    def expr(self, x: float, candidates) -> tuple[str, float]:
        """The candidate (text, value) nearest to x if within snap (the first of equally near ones), else
        x written as a number."""
        x = round(float(x), _DEC)
        best = min(candidates, key=lambda c: abs(x - c[1]), default=None)
        if best is not None and abs(x - best[1]) <= self.snap:
            return best
        return _num(x), x


def _revolution_dims(profile: Profile, suffix: str, snap: float, sigma: float):
    segs, verts = profile.segments, profile.vertices
    dims = _Dims(snap)
    vertical = [s for s in segs if s.kind == "line" and abs(s.p1[0] - s.p0[0]) < 1e-9]
    if len(segs) == 1 and segs[0].kind == "arc" and abs(segs[0].center[0]) <= dims.snap:
        # a sphere: one arc about a centre on the axis, from pole to pole
        radius = dims.add("radius" + suffix, segs[0].radius)
        return dims, [(f"radius{suffix}", radius)], [("0", 0.0), (f"radius{suffix}", radius),
                                                      (f"2 * radius{suffix}", round(2 * radius, _DEC))]
    if not vertical:
        return dims, [], []
    main = max(vertical, key=lambda s: abs(s.p1[1] - s.p0[1]))
    radius = dims.add("radius" + suffix, main.p0[0])
    length = dims.add("length" + suffix, np.ptp(verts[:, 1]))
    chamfers = []   # (size, standard uncertainty) in mm
    for k, s in enumerate(segs):
        dr, dz = abs(s.p1[0] - s.p0[0]), abs(s.p1[1] - s.p0[1])
        touches = any(np.allclose(p, q) for p in (s.p0, s.p1) for q in (main.p0, main.p1))
        if s.kind == "line" and touches and dr > 0 and abs(dr - dz) < 0.02 * max(dr, dz):
            chamfers.append(((dr + dz) / 2, _chamfer_sigma(segs, k, sigma)))
    r_cands, z_cands = [(f"radius{suffix}", radius)], [("0", 0.0), (f"length{suffix}", length)]
    for k, (before, bottom, after) in enumerate(_grooves(segs, radius, dims.snap), 1):
        g = f"groove{k}{suffix}"
        at = dims.add(f"{g}_at", min(bottom.p0[1], bottom.p1[1]))
        width = dims.add(f"{g}_width", abs(bottom.p1[1] - bottom.p0[1]))
        depth = dims.add(f"{g}_depth", radius - bottom.p0[0])
        r_cands.append((f"radius{suffix} - {g}_depth", round(radius - depth, _DEC)))
        z_cands += [(f"{g}_at", at), (f"{g}_at + {g}_width", round(at + width, _DEC))]
    for name, value in _chamfer_params(chamfers, suffix):
        c = dims.add(name, value)
        r_cands.append((f"radius{suffix} - {name}", round(radius - c, _DEC)))
        z_cands += [(name, c), (f"length{suffix} - {name}", round(length - c, _DEC))]
    _fillet_dims(segs, dims, suffix, r_cands, z_cands)
    return dims, r_cands, z_cands


def _chamfer_sigma(segs, k, sigma):
    """Standard uncertainty (mm) of the size of the chamfer segs[k] between its two neighbours, from the
    profile's noise sigma (mm) and the points each line was fitted to: the size is the radius minus the
    chamfer line's offset along the axis, where the end face meets it, so its variance is the sum of the
    three lines' offset variances, sigma^2 / n each and twice that for the 45 deg line (an offset along
    its normal moves its legs by sqrt 2 times as much)."""
    nbs = [segs[j].support for j in (k - 1, k + 1) if 0 <= j < len(segs)]
    return float(sigma * np.sqrt(2.0 / max(segs[k].support, 1) + sum(1.0 / max(n, 1) for n in nbs)))


def _chamfer_params(chamfers, suffix):
    """[(name, size)] of the chamfers [(size, uncertainty)] (mm) in profile order: one `chamfer` (the
    inverse-variance weighted mean) when every two agree within three standard uncertainties of their
    difference (or the printed resolution), else `chamfer1`, `chamfer2`, ..."""
    if not chamfers:
        return []
    size, sd = np.array(chamfers, float).T
    sd = np.where(np.isfinite(sd) & (sd > 0), sd, 0.0)
    limit = np.maximum(3.0 * np.hypot(sd[:, None], sd[None, :]), 10.0 ** -_DEC)
    if np.all(np.abs(size[:, None] - size[None, :]) <= limit):
        w = 1.0 / np.maximum(sd, 10.0 ** -_DEC) ** 2
        return [(f"chamfer{suffix}", float(np.sum(w * size) / np.sum(w)))]
    return [(f"chamfer{k}{suffix}", float(c)) for k, c in enumerate(size, 1)]


_K45 = 1 - np.sqrt(0.5)  # a quarter circle's midpoint sits this fraction of its radius in from the corner


def _fillet_dims(segs, dims, suffix, r_cands, z_cands):
    """Named fillets: quarter-circle arcs whose ends meet an axis-parallel and a radial face (the tangent
    directions at the ends are the axis directions) at a corner whose coordinates are already named
    (`radius`, `0`, `length`, ...).  One `fillet` when all radii agree within snap, else `fillet1`, ...;
    the arcs' ends and midpoints become expressions of it (`radius - fillet`, `0.29289322 * fillet`)."""
    found = []
    for s in segs:
        if s.kind != "arc":
            continue
        legs = np.abs(np.array([s.p0 - s.center, s.p1 - s.center]))
        axial = np.all(np.sort(legs, axis=1)[:, 0] <= dims.snap)           # each end straight off the centre
        quarter = np.all(np.abs(legs.max(axis=1) - s.radius) <= dims.snap) and np.argmax(legs[0]) != np.argmax(legs[1])
        if not (axial and quarter):
            continue
        corner = s.center + np.sign(s.through - s.center) * s.radius
        rx, zx = (next((t for t, v in cands if abs(v - x) <= dims.snap), None)
                  for x, cands in ((corner[0], r_cands), (corner[1], z_cands)))
        if rx is not None and zx is not None:
            found.append((s, corner, rx, zx))
    if not found:
        return
    one = np.ptp([s.radius for s, *_ in found]) <= dims.snap
    if one:
        dims.add("fillet" + suffix, np.mean([s.radius for s, *_ in found]))
    for k, (s, corner, rx, zx) in enumerate(found, 1):
        name = f"fillet{suffix}" if one else f"fillet{k}{suffix}"
        f = dict(dims.named)[name] if one else dims.add(name, s.radius)
        sr, sz = np.sign(s.center - corner)
        for frac, text in ((1.0, name), (_K45, f"{_K45:.8f} * {name}")):
            for corner_x, expr, sign, cands in ((corner[0], rx, sr, r_cands), (corner[1], zx, sz, z_cands)):
                value = round(round(float(corner_x), _DEC) + sign * frac * f, _DEC)
                op = "+" if sign > 0 else "-"
                cands.insert(0, (text if expr == "0" and sign > 0 else f"{expr} {op} {text}", value))



def _grooves(segs, radius, snap):
    """(wall, bottom, wall) triples of rectangular grooves: an axis-parallel line below `radius`
    between two lines across the axis that both reach `radius`."""
    def across(s):
        return s.kind == "line" and abs(s.p1[1] - s.p0[1]) < 1e-9

    out = []
    for a, b, c in zip(segs, segs[1:], segs[2:]):
        if (b.kind == "line" and abs(b.p1[0] - b.p0[0]) < 1e-9 and b.p0[0] < radius - snap
                and across(a) and across(c) and abs(max(a.p0[0], a.p1[0]) - radius) <= snap
                and abs(max(c.p0[0], c.p1[0]) - radius) <= snap):
            out.append((a, b, c))
    return out


def _revolution_part(fit: RevolutionFit, name: str, suffix: str, snap: float) -> EmittedPart:
    dims, r_c, z_c = _revolution_dims(fit.profile, suffix, snap, fit.sigma)

    def point(p):
        (rx, rv), (zx, zv) = dims.expr(p[0], r_c), dims.expr(p[1], z_c)
        return f"pt({rx}, {zx}, 0)", np.array([rv, zv])

    pieces, ideal, exprs = [], [], []
    verts = fit.profile.vertices
    vtext = [point(v) for v in verts]
    for k, seg in enumerate(fit.profile.segments):
        (t0, v0), (t1, v1) = vtext[k], vtext[k + 1]
        if seg.kind == "line":
            pieces.append(f"line({t0}, {t1})")
            ideal.append(Segment(v0, v1))
        elif seg.kind == "arc":
            tm, vm = point(seg.through)
            pieces.append(f"arc({t0}, {tm}, {t1})")
            ideal.append(_arc_segment(v0, vm, v1))
        else:  # a B-spline stretch: its end points are the chain's vertices
            inner = [point(c) for c in seg.ctrl[1:-1]]
            knots = [_knot(u) for u in seg.knots]
            pieces.append(f"bspline(degree: {len(seg.knots) - len(seg.ctrl) - 1}, knots: knots([{', '.join(knots)}]), "
                          f"points: [{', '.join([t0] + [t for t, _ in inner] + [t1])}])")
            ideal.append(Segment(v0, v1, ctrl=np.array([v0] + [v for _, v in inner] + [v1]),
                                 knots=np.array([float(u) for u in knots])))
        exprs.append(t0)
    exprs.append(vtext[-1][0])
    if all(s.kind == "line" for s in fit.profile.segments):
        profile_text = "polyline([" + ", ".join(exprs) + "])"
    else:
        profile_text = "profile(" + ", ".join(pieces) + ")"
    body = f"body{suffix}"
    bindings = [f"axis{suffix} := line(pt(0, 0, 0), pt(0, 1, 0));",
                f"profile{suffix} := {profile_text};",
                f"{body} := revolve(profile{suffix}, axis{suffix}, from: 0deg, to: 360deg);"]
    params = [(n, v, "") for n, v in dims.named]
    frame, placed = _placement(fit.frame, body)
    return EmittedPart(name, params, bindings + [f"{name} := {placed};"], body,
                       RevolutionFit(frame, Profile(tuple(ideal)), fit.sigma, fit.axis_sigma))


def _knot(u: float) -> str:
    """A knot value in [0, 1] as written (10 decimals at most; knot insertion gives dyadic fractions)."""
    return f"{round(float(u), 10) + 0.0:.10f}".rstrip("0").rstrip(".") or "0"


def _arc_segment(p0, through, p1):
    a, b, c = p0, through, p1
    d = 2 * (a[0] * (b[1] - c[1]) + b[0] * (c[1] - a[1]) + c[0] * (a[1] - b[1]))
    sa, sb, sc = a @ a, b @ b, c @ c
    centre = np.array([sa * (b[1] - c[1]) + sb * (c[1] - a[1]) + sc * (a[1] - b[1]),
                       sa * (c[0] - b[0]) + sb * (a[0] - c[0]) + sc * (b[0] - a[0])]) / d
    return Segment(p0, p1, centre, float(np.linalg.norm(a - centre)), through)


def _box_part(fit: BoxFit, name: str, suffix: str) -> EmittedPart:
    w, d, h = (round(float(x), _DEC) for x in fit.dimensions)
    W, D, H = (f"{n}{suffix}" for n in ("width", "depth", "height"))
    corners = [(-1, -1), (1, -1), (1, 1), (-1, 1), (-1, -1)]
    base = ", ".join(f"pt({'-' if sx < 0 else ''}{W} / 2, {'-' if sy < 0 else ''}{D} / 2, -{H} / 2)"
                     for sx, sy in corners)
    body = f"body{suffix}"
    bindings = [f"base{suffix} := polyline([{base}]);",
                f"sides{suffix} := extrude(base{suffix}, vec(0, 0, {H}));",
                f"bottom{suffix} := trim(plane(pt(0, 0, -{H} / 2), vec(0, 0, -1)), outer: loop(base{suffix}));",
                f"top{suffix} := translate(bottom{suffix}, vec(0, 0, {H}));",
                f"{body} := shell([bottom{suffix}, sides{suffix}, top{suffix}]);"]
    frame, placed = _placement(fit.frame, body)
    params = [(W, w, "along the part's x axis"), (D, d, "y"), (H, h, "z")]
    return EmittedPart(name, params, bindings + [f"{name} := {placed};"], body,
                       BoxFit(frame, np.array([w, d, h]) / 2, fit.unseen))


def snapped_placement(shape, resolution: float):
    """The shape (RevolutionFit or BoxFit) with its placement snapped where the data cannot tell the
    difference, and what was snapped ({} when nothing was): a revolution's axis within three standard
    uncertainties (`axis_sigma`, radians) of a world axis becomes that axis, turned about the middle of
    the part (its ends move by half its length times the angle); then each component of the placement's
    translation within `resolution` (mm; the pipeline uses tol / 10, the resolution of its dimensions)
    of 0 becomes 0.  Snapping is a hypothesis: the caller re-measures the certificate on the result and
    keeps it only if the certificate still holds."""
    frame = np.array(shape.frame, float)
    info = {}
    if isinstance(shape, RevolutionFit) and np.isfinite(shape.axis_sigma):
        d = frame[:3, 1]
        k = int(np.argmax(np.abs(d)))
        angle = float(np.arccos(min(1.0, abs(d[k]))))
        if 0.0 < angle <= 3.0 * shape.axis_sigma:
            target = np.sign(d[k]) * np.eye(3)[k]
            middle = frame[:3, 3] + 0.5 * shape.length * d
            frame = axis_frame(middle - 0.5 * shape.length * target, target)
            info["axis"] = {"measured": d.tolist(), "to": ("-" if d[k] < 0 else "") + "xyz"[k],
                            "angle_deg": float(np.degrees(angle)),
                            "limit_deg": float(np.degrees(3.0 * shape.axis_sigma))}
    t = frame[:3, 3]
    small = (np.abs(t) <= resolution) & (t != 0.0)
    if small.any():
        info["offset"] = {"xyz"[i]: float(t[i]) for i in np.flatnonzero(small)}
        info["resolution"] = float(resolution)
        frame[:3, 3] = np.where(small, 0.0, t)
    return (replace(shape, frame=frame) if info else shape), info


def _placement(frame, body):
    """The expression placing `body` by `frame` (4, 4), and the frame rebuilt from the printed numbers."""
    from scipy.spatial.transform import Rotation

    rotvec = Rotation.from_matrix(frame[:3, :3]).as_rotvec()
    angle = float(np.linalg.norm(rotvec))
    expr = body
    ideal = np.eye(4)
    if np.degrees(angle) > 1e-7:
        axis = np.round(rotvec / angle, 8)
        deg = round(float(np.degrees(angle)), 7)
        expr = f"rotate({expr}, axis: vec({', '.join(_vnum(a) for a in axis)}), angle: {deg:.7f}deg)"
        ideal[:3, :3] = Rotation.from_rotvec(axis / np.linalg.norm(axis) * np.radians(deg)).as_matrix()
    t = np.round(frame[:3, 3], _DEC)
    if np.any(t != 0):
        expr = f"translate({expr}, vec({', '.join(_num(x) for x in t)}))"
        ideal[:3, 3] = t
    return ideal, expr


def _vnum(x):
    return f"{x + 0.0:.8f}".rstrip("0").rstrip(".") or "0"


def emit_part(shape, name: str, suffix: str = "", *, snap: float = 0.0) -> EmittedPart:
    """The `.rgm` bindings of a fitted shape (RevolutionFit or BoxFit).  Profile coordinates within
    `snap` (model units; the pipeline uses tol / 10) of a named dimension's expression are written as that
    expression (a chamfer's two legs, say, become one `chamfer`); the certificate measures the result."""
    if isinstance(shape, RevolutionFit):
        return _revolution_part(shape, name, suffix, snap)
    if isinstance(shape, BoxFit):
        return _box_part(shape, name, suffix)
    raise TypeError(f"no emitter for {type(shape).__name__}")


def annotations(classification, certificate, sources, stopped: str = "", g0: float | None = None) -> list[str]:
    """@source, @classified and @fit lines for an exported binding; when the fit's refinement `stopped`
    short of the tolerance, a comment saying why comes first (the @fit annotation has no field for it).
    `g0`: the largest gap (mm) at the face's seams with its neighbours, as `rgm.fitters.seam_check`
    measures the written faces (None: no seam measured)."""
    out = [f"# refinement stopped: {stopped}"] if stopped else []
    if sources:
        names = ", ".join(f'"{s}"' for s, _ in sources)
        hashes = ", ".join(f'"{h}"' for _, h in sources)
        out.append(f"@source(scans: [{names}], sha256: [{hashes}])")
    if classification is not None:
        se = classification.superellipsoid
        out.append(f'@classified(as: "{classification.category}", confidence: {classification.confidence:.3f}, '
                   f'runner_up: "{classification.runner_up}", eps1: {se.eps[0]:.3f}, eps2: {se.eps[1]:.3f}, '
                   f"a1: {se.size[0]:.3f}, a2: {se.size[1]:.3f}, a3: {se.size[2]:.3f}, quality: {se.quality:.5f})")
    if certificate is not None:
        c = certificate
        out.append(f"@fit(points: {c.points}, max: {c.max:.4f}mm, rms: {c.rms:.4f}mm, p95: {c.p95:.4f}mm, "
                   f'tol: {c.tol:g}mm, coverage: {min(max(c.coverage, 0.0), 1.0):.3f}, statistic: "{c.statistic}"'
                   + ("" if g0 is None else f", g0: {g0:.4f}mm") + ")")
    return out


def provenance_date() -> str:
    """UTC date of the run, or of SOURCE_DATE_EPOCH when set (reproducible builds)."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    stamp = int(epoch) if epoch and epoch.isdigit() else int(time.time())
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(stamp))


def write_rgm(parts: list[EmittedPart], *, inputs, options: dict, tol: float, notes=(), title="part") -> str:
    """The whole file: provenance header, units and tolerance, params, bindings, exports."""
    from rgm import __version__

    lines = [f"# {title}.rgm: written by rgmc fit {__version__} from {len(inputs)} scan(s)",
             f"# date: {provenance_date()}",
             "# options: " + " ".join(f"{k}={v}" for k, v in options.items())]
    lines += [f"# input: {path}  sha256 {digest}" for path, digest in inputs]
    lines += [f"# note: {n}" for n in notes]
    lines += ["", "units mm;", f"tolerance {tol:g};", ""]
    for part in parts:
        for pname, value, comment in part.params:
            lines.append(f"param {pname} := {format_length(value)}mm;" + (f"  # {comment}" if comment else ""))
    for part in parts:
        lines.append("")
        lines += part.bindings[:-1]
        lines += part.annotations
        lines.append(part.bindings[-1])
    if parts:
        lines += ["", "export " + ", ".join(p.name for p in parts) + ";"]
    return "\n".join(lines) + "\n"
