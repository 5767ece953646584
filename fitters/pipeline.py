"""The fitting pipeline: intake -> filter -> register -> split -> classify -> build -> certify -> emit.

`fit_scans` returns the `.rgm` text and a JSON-ready report with per-stage timings; progress goes to
stderr only when it is a terminal.  Parts classified as cylinder, other_revolution or sphere become
surfaces of revolution with conic profiles; boxes become exact extruded boxes.  Every other part
(free_form, ellipsoid), and a part whose exact shape misses its certificate by more than a tenth of the
part's smallest extent (the shape does not describe the data: a box around one view of a face, say;
a bulging carton stays a box that says its certificate fails), becomes trimmed NURBS patches
(`rgm.fitters.freeform_build`): parameterised by the range grid when the input is one range view, else
by projection onto base surfaces.

Certificates: every filtered point counts for the emitted part nearest to it
(`rgm.fitters.certificate.nearest_part`), exactly as `rgmc verify` re-measures.

Placement: an exact part's axis within its measured uncertainty of a world axis, and offsets within the
dimensions' resolution (tol / 10) of 0, are snapped (`rgm.fitters.emit.snapped_placement`) only if the
certificate re-measured on the snapped model still holds; the report's `placement_snapped` says what was
snapped (or, under `rejected`, what was not and why).  The text is the emitter's; `rgmc fit` writes it
in canonical form once the compiler has checked it (`rgm.commands.fit`).
"""
from __future__ import annotations

import hashlib
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rgm.errors import GeometryError

__all__ = ["FitResult", "fit_scans", "fit_points", "sha256_of"]

REVOLUTION_KINDS = ("cylinder", "other_revolution", "sphere")
#: an exact shape whose certificate fails gives way to free form when its bounded statistic exceeds this
#: fraction of the part's smallest extent
EXACT_SLACK = 0.1
#: range views: pieces of fewer pixels (links cut at depth jumps) are specks, removed by the filter; the
#: free-form builder fits patches down to this size
SPECK_PIXELS = 50


@dataclass
class FitResult:
    text: str
    report: dict
    parts: list       # EmittedPart
    certificates: list


class _Stages:
    def __init__(self, progress: bool):
        self.times: dict[str, float] = {}
        self.progress = progress and sys.stderr.isatty()

    @contextmanager
    def __call__(self, name):
        if self.progress:
            print(f"rgmc fit: {name}...", file=sys.stderr, end="", flush=True)
        t0 = time.perf_counter()
        yield
        dt = time.perf_counter() - t0
        self.times[name] = self.times.get(name, 0.0) + dt
        if self.progress:
            print(f" {dt:.2f} s", file=sys.stderr, flush=True)


def sha256_of(path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _build(points, cls, tol, seed, max_normals=20000):
    """The exact shape for a classified part, or None.  Normals (robust PCA) are estimated on at most
    `max_normals` points: the axis and the box faces need their directions, not every point's."""
    from rgm.fitters.normals import pca_normals
    from rgm.fitters.primitives import fit_box
    from rgm.fitters.revolution import fit_revolution

    if cls.category not in REVOLUTION_KINDS and cls.category != "box":
        return None
    sub = points
    if len(points) > max_normals:
        sub = points[np.random.default_rng(seed).choice(len(points), max_normals, replace=False)]
    normals, _ = pca_normals(sub)
    if cls.category == "box":
        return fit_box(sub, normals, cls.superellipsoid.rotation)
    return fit_revolution(sub, normals, tol=tol, axis_hint=cls.superellipsoid.rotation[:, 2], seed=seed,
                          profile_points=points)


def _surface_samples(shape, spacing):
    from rgm.fitters.revolution import RevolutionFit, sample_revolution

    if isinstance(shape, RevolutionFit):
        return sample_revolution(shape.profile, shape.frame, spacing)
    return shape.sample_surface(spacing)


def _exact(shape, name, suffix, pts, cls, tol, statistic):
    """The emitted exact shape, or None and why when free form must model the part instead; and what of
    its placement was snapped (`_snap`)."""
    from rgm.fitters.certificate import certify
    from rgm.fitters.emit import emit_part

    part = emit_part(shape, name, suffix, snap=tol / 10)
    cert = certify(part.ideal.distance(pts), tol, statistic=statistic)
    if cert.holds:
        part, snapped = _snap(shape, part, name, suffix, pts, tol, statistic)
        return part, "", snapped
    centred = pts - pts.mean(axis=0)
    along = centred @ np.linalg.svd(centred[:: max(1, len(pts) // 20000)], full_matrices=False)[2].T
    extent = float((np.percentile(along, 99, axis=0) - np.percentile(along, 1, axis=0)).min())
    if cert.value <= EXACT_SLACK * extent:
        return part, "", {}
    return None, (f"{name}: classified {cls.category} (confidence {cls.confidence:.2f}), but the {cls.category}'s "
                  f"{statistic} {cert.value:.4f} mm is over {EXACT_SLACK:.0%} of the part's smallest extent "
                  f"({extent:.1f} mm): the shape does not describe the data, so it is modelled as free-form NURBS"), {}


def _snap(shape, part, name, suffix, pts, tol, statistic):
    """The emitted part with its placement snapped (`rgm.fitters.emit.snapped_placement`, offsets at the
    dimensions' resolution tol / 10) if its certificate, re-measured on the snapped model, still holds;
    else the part as fitted.  Returns (part, what was snapped, or why not: a JSON-ready dict)."""
    from rgm.fitters.certificate import certify
    from rgm.fitters.emit import emit_part, snapped_placement

    snapped_shape, snapped = snapped_placement(shape, tol / 10)
    if not snapped:
        return part, {}
    candidate = emit_part(snapped_shape, name, suffix, snap=tol / 10)
    cert = certify(candidate.ideal.distance(pts), tol, statistic=statistic)
    snapped[statistic] = cert.value
    if cert.holds:
        return candidate, snapped
    return part, {"rejected": snapped, "why": f"snapped, the {statistic} would be {cert.value:.4f} mm > tol {tol:g}"}


def _freeform_parts(points, idx, grid, name, suffix, tol, statistic, crease_deg=None):
    """Emitted trimmed-NURBS patches of one part, their report entries and notes (`crease_deg`: the
    splitters' crease angle, None for their defaults)."""
    from rgm.fitters.freeform_build import fit_freeform_part
    from rgm.fitters.freeform_part import emit_freeform_set

    ff = fit_freeform_part(points, idx, tol, statistic=statistic, grid=grid, min_pixels=SPECK_PIXELS,
                           crease_deg=crease_deg)
    single = len(ff.shapes) == 1
    count = range(1, len(ff.shapes) + 1)
    parts = emit_freeform_set(ff.shapes, [name if single else f"{name}_{r}" for r in count],
                              [suffix if single else f"{suffix}_{r}" for r in count], tolerance=tol)
    for part, info in zip(parts, ff.info):
        info["name"] = part.name
    return parts, ff.info, [f"{name}: {n}" for n in ff.notes]


def _beyond_its_points(entry: dict, cert) -> str:
    """Why a free-form patch whose surface met the tolerance on the points it was fitted to has a
    certificate that does not hold: the certificate counts every filtered point nearest to the patch,
    among them points no patch was fitted to (pixels at depth jumps and creases, specks) and points of
    a neighbour nearer to this patch than to their own."""
    r = entry["residual"]
    return (f"met on the {entry['points']} points the surface was fitted to ({r['statistic']} "
            f"{r['value']:.4f} mm), not on all {cert.points} nearest to it: the others lie at depth jumps, "
            f"creases or specks that no patch models, or belong to a neighbour")


def fit_points(points, *, tol: float, statistic: str = "p95", sources=(), options=None, stages=None,
               seed: int = 0, title: str = "part", grid=None, crease_deg: float | None = None) -> FitResult:
    """Fit already filtered, registered points (n, 3) in mm: split, classify, build, certify, emit.
    `grid` (rows, cols) int: when the points are one range view, the index of each pixel's point (-1 where
    it has none); free-form parts are then parameterised by it. `crease_deg`: the normal change (degrees)
    at which free-form data splits into patches (None: 35 for scattered points, 40 for a range view)."""
    from rgm.fitters.certificate import certify, nearest_part, surface_coverage
    from rgm.fitters.classify import classify, spacing as point_spacing, split_parts
    from rgm.fitters.emit import annotations, write_rgm

    stages = stages or _Stages(False)
    points = np.asarray(points, float)
    with stages("split"):
        pitch = point_spacing(points)
        parts = split_parts(points)
    emitted, owners, notes, report_parts = [], [], [], []   # owners: (classification, report entry, stop)
    claimed, free = [], []          # points of exact parts; (classification, entry, idx, name, suffix)
    for k, (idx, se) in enumerate(parts):
        suffix = "" if len(parts) == 1 else f"_{k + 1}"
        name = f"{title}{suffix}"
        pts = points[idx]
        with stages("classify"):
            cls = classify(pts, superellipsoid=se)
        entry = {"name": name, "points": int(len(pts)), "category": cls.category,
                 "confidence": cls.confidence, "runner_up": cls.runner_up, "scores": cls.scores,
                 "superellipsoid": {"size": cls.superellipsoid.size.tolist(), "eps": cls.superellipsoid.eps.tolist(),
                                    "rotation": cls.superellipsoid.rotation.tolist(),
                                    "center": cls.superellipsoid.center.tolist(),
                                    "quality": cls.superellipsoid.quality}}
        with stages("build"):
            try:
                shape, why = _build(pts, cls, tol, seed), ""
            except GeometryError as exc:
                shape, why = None, f"{name}: the {cls.category} builder found no shape ({exc}): modelled as free-form NURBS"
            part, snapped = None, {}
            if shape is not None:
                part, why, snapped = _exact(shape, name, suffix, pts, cls, tol, statistic)
        notes += [why] if why else []
        entry["modelled"] = True
        report_parts.append(entry)
        if part is not None:
            entry.update(model="exact", params={n: v for n, v, _ in part.params}, placement_snapped=snapped)
            emitted.append(part)
            owners.append((cls, entry, ""))
            claimed.append(idx)
        else:
            free.append((cls, entry, idx, name, suffix))
    if grid is not None and free:
        # one range view: its free-form pixels (with any the splitting set aside as specks) are split at
        # their own discontinuities, whatever parts the superellipsoid splitting made of them
        cls, entry, _, _, _ = max(free, key=lambda f: len(f[2]))
        for other in free:
            other[1]["model"] = "free_form"
            other[1]["fitted_with"] = entry["name"]
        pool = np.setdiff1d(np.arange(len(points)), np.concatenate(claimed) if claimed else [])
        tag = "_free" if claimed else ""   # beside exact parts title_1, ...: the free-form patches title_free_1, ...
        free = [(cls, entry, pool, title + tag, tag)]
    for cls, entry, idx, name, suffix in free:
        with stages("free form"):
            patches, infos, ff_notes = _freeform_parts(points, idx, grid, name, suffix, tol, statistic, crease_deg)
        notes += ff_notes
        entry.update(model="free_form", patches=infos)
        emitted += patches
        owners += [(cls, info, info["stopped"]) for info in infos]
    with stages("certify"):
        owner, dist = nearest_part([p.ideal for p in emitted], points)
        certificates, kept = [], {}
        for k, (part, (cls, entry, stopped)) in enumerate(zip(emitted, owners)):
            if not np.any(owner == k):     # wholly behind its neighbours: nothing to certify it with
                notes.append(f"{part.name}: no point lies nearest to it; left out")
                entry["certificate"] = None
                continue
            cov = surface_coverage(_surface_samples(part.ideal, 2 * pitch), points, 4 * pitch)
            cert = certify(dist[owner == k], tol, statistic=statistic, coverage=cov)
            if not cert.holds and not stopped and "residual" in entry:   # a patch whose own fit held
                stopped = entry["stopped"] = _beyond_its_points(entry, cert)
            entry["certificate"] = cert.as_dict()
            certificates.append(cert)
            kept[k] = (cls, cert, stopped)
        seams, g0 = _written_seams(emitted, kept, owner, points, pitch)
        for k, (cls, cert, stopped) in kept.items():
            emitted[k].annotations = annotations(cls, cert, list(sources), stopped, g0.get(k))
        emitted = [emitted[k] for k in kept]
    with stages("emit"):
        text = write_rgm(emitted, inputs=list(sources), options=options or {"tol": tol, "statistic": statistic},
                         tol=tol, notes=notes, title=title)
    report = {"inputs": [{"path": p, "sha256": h} for p, h in sources], "options": options or {},
              "points": int(len(points)), "spacing": pitch, "parts": report_parts, "notes": notes, "seams": seams,
              "timings": stages.times}
    return FitResult(text, report, emitted, certificates)


def _written_seams(emitted, kept, owner, points, pitch) -> tuple[list[dict], dict]:
    """([{"a", "b": part names, "max", "p95": mm, "samples"}], {part index: its largest seam gap}): the
    seams between the trimmed faces kept (`rgm.fitters.seam_check`, on the faces as printed, with the
    points' owners as `rgmc verify` finds them), for the report and the `@fit` annotations' `g0`."""
    from rgm.fitters.freeform_measure import TrimmedNurbs
    from rgm.fitters.seam_check import measure_seams, worst_per_face

    faces = {k: emitted[k].ideal for k in kept if isinstance(emitted[k].ideal, TrimmedNurbs)}
    if len(faces) < 2:
        return [], {}
    seams = measure_seams(faces, points, owner, pitch)
    return ([{"a": emitted[s.a].name, "b": emitted[s.b].name, "max": s.max, "p95": s.p95, "samples": s.samples}
             for s in seams], worst_per_face(seams))


def _view_cells(scans):
    """(rows, cols) index of each pixel's point when the scans are one range view (a range grid, or a
    mesh that triangulates one row by row), -1 where a pixel has none; else None."""
    from rgm.fitters.freeform_part import grid_from_mesh

    if len(scans) != 1:
        return None
    scan = scans[0]
    if scan.grid is not None:
        return scan.grid
    mesh_grid = grid_from_mesh(scan.points, scan.faces)
    return None if mesh_grid is None else np.arange(scan.n).reshape(mesh_grid.shape[:2])


def filtered_points(scans, scale: float = 1.0):
    """The points `rgmc fit` models and `rgmc verify` measures: the views' points in their common frame
    times `scale` (to mm), without statistical outliers and, for one range view, without its specks
    (pieces of fewer than SPECK_PIXELS pixels once links across depth jumps are cut). Returns
    (points (n, 3), grid or None: each pixel's index among them, -1 where none; removed counts)."""
    from rgm.fitters.filters import statistical_outliers
    from rgm.fitters.freeform_part import range_specks

    points = np.vstack([s.world_points() for s in scans]) * scale
    keep = ~statistical_outliers(points)
    removed = {"outliers": int((~keep).sum())}
    cells = _view_cells(scans)
    if cells is None:
        return points[keep], None, removed
    valid = cells >= 0
    valid[valid] = keep[cells[valid]]
    xyz = np.full(cells.shape + (3,), np.nan)
    xyz[valid] = points[cells[valid]]
    speck = range_specks(xyz, valid, min_pixels=SPECK_PIXELS)
    keep[cells[speck]] = False
    removed["specks"] = int(speck.sum())
    new_index = np.full(len(points) + 1, -1)          # slot n maps an empty cell (-1) to -1
    new_index[:-1][keep] = np.arange(int(keep.sum()))
    return points[keep], new_index[cells], removed


def fit_scans(paths, *, tol: float, poses=None, statistic: str = "p95", register: bool = False,
              scale: float = 1.0, progress: bool = True, title: str | None = None,
              crease_deg: float | None = None) -> FitResult:
    """The whole pipeline from scan files.  `scale` converts the scans' units to mm (1000 for metres).
    Views are taken to be in one frame (their poses from `poses` or a .conf) unless `register`, which
    runs `rgm.fitters.register.register_views` (from those poses when given) and leaves out failed views."""
    from rgm.fitters.io import ScanError, read_views

    stages = _Stages(progress)
    with stages("intake"):
        scans = read_views(paths, poses)
        files = [Path(s.source) for s in scans]
        sources = [(str(f), sha256_of(f)) for f in files if f.exists()]
    registration = []
    if register:
        with stages("register"):
            from rgm.fitters.register import register_views

            reports = register_views(scans, use_poses=poses is not None or len(paths) == 1)
            registration = [r.to_json() for r in reports]
            scans = [s.replace(pose=r.transform) for s, r in zip(scans, reports) if r.status in ("reference", "ok")]
    with stages("filter"):
        points, grid, removed = filtered_points(scans, scale)
    if len(points) < 200:
        raise ScanError(f"{len(points)} points left after filtering: too few to fit a part")
    options = {"tol": f"{tol:g}", "statistic": statistic, "scale": f"{scale:g}", "register": register,
               "poses": str(poses) if poses else "none"}
    if crease_deg is not None:
        options["crease_angle"] = f"{crease_deg:g}"
    result = fit_points(points, tol=tol, statistic=statistic, sources=sources, options=options, stages=stages,
                        title=title or "part", grid=grid, crease_deg=crease_deg)
    result.report["filtered_out"] = removed
    if registration:
        result.report["registration"] = registration
        dropped = [r["file"] for r in registration if r["status"] not in ("reference", "ok")]
        result.report["notes"] += [f"view {f} failed registration and was left out" for f in dropped]
    return result
