"""The fitting pipeline: intake -> filter -> register -> split -> classify -> build -> certify -> emit.

`fit_scans` returns the `.rgm` text and a JSON-ready report with per-stage timings; progress goes to
stderr only when it is a terminal.  Parts classified as cylinder, other_revolution or sphere become
surfaces of revolution with conic profiles; boxes become exact extruded boxes; ellipsoids and free-form
parts are reported and not modelled (free-form NURBS fitting is a separate builder).
"""
from __future__ import annotations

import hashlib
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["FitResult", "fit_scans", "fit_points", "sha256_of"]

REVOLUTION_KINDS = ("cylinder", "other_revolution", "sphere")


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
    from rgm.fitters.primitives import BoxFit
    from rgm.fitters.revolution import sample_revolution

    if isinstance(shape, BoxFit):
        return shape.sample_surface(spacing)
    return sample_revolution(shape.profile, shape.frame, spacing)


def fit_points(points, *, tol: float, statistic: str = "p95", sources=(), options=None, stages=None,
               seed: int = 0, title: str = "part") -> FitResult:
    """Fit already filtered, registered points (n, 3) in mm: split, classify, build, certify, emit."""
    from rgm.fitters.certificate import certify, surface_coverage
    from rgm.fitters.classify import classify, spacing as point_spacing, split_parts
    from rgm.fitters.emit import annotations, emit_part, write_rgm

    stages = stages or _Stages(False)
    points = np.asarray(points, float)
    with stages("split"):
        pitch = point_spacing(points)
        parts = split_parts(points)
    emitted, certificates, notes, report_parts = [], [], [], []
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
            shape = _build(pts, cls, tol, seed)
        if shape is None:
            msg = (f"{name}: classified {cls.category} (confidence {cls.confidence:.2f}); no exact builder for it "
                   f"yet (free-form NURBS surfaces are a separate step), so it is not modelled")
            notes.append(msg)
            entry["modelled"] = False
            report_parts.append(entry)
            continue
        with stages("emit"):
            part = emit_part(shape, name, suffix, snap=tol / 10)
        with stages("certify"):
            dist = part.ideal.distance(pts)
            cov = surface_coverage(_surface_samples(part.ideal, 2 * pitch), pts, 4 * pitch)
            cert = certify(dist, tol, statistic=statistic, coverage=cov)
        part.annotations = annotations(cls, cert, list(sources))
        emitted.append(part)
        certificates.append(cert)
        entry.update(modelled=True, params={n: v for n, v, _ in part.params}, certificate=cert.as_dict())
        report_parts.append(entry)
    with stages("emit"):
        text = write_rgm(emitted, inputs=list(sources), options=options or {"tol": tol, "statistic": statistic},
                         tol=tol, notes=notes, title=title)
    report = {"inputs": [{"path": p, "sha256": h} for p, h in sources], "options": options or {},
              "points": int(len(points)), "spacing": pitch, "parts": report_parts, "notes": notes,
              "timings": stages.times}
    return FitResult(text, report, emitted, certificates)


def fit_scans(paths, *, tol: float, poses=None, statistic: str = "p95", register: bool = False,
              scale: float = 1.0, progress: bool = True, title: str | None = None) -> FitResult:
    """The whole pipeline from scan files.  `scale` converts the scans' units to mm (1000 for metres).
    Views are taken to be in one frame (their poses from `poses` or a .conf) unless `register`, which
    runs `rgm.fitters.register.register_views` (from those poses when given) and leaves out failed views."""
    from rgm.fitters.filters import statistical_outliers
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
        points = np.vstack([s.world_points() for s in scans]) * scale
        points = points[~statistical_outliers(points)]
    if len(points) < 200:
        raise ScanError(f"{len(points)} points left after filtering: too few to fit a part")
    options = {"tol": f"{tol:g}", "statistic": statistic, "scale": f"{scale:g}", "register": register,
               "poses": str(poses) if poses else "none"}
    result = fit_points(points, tol=tol, statistic=statistic, sources=sources, options=options, stages=stages,
                        title=title or "part")
    if registration:
        result.report["registration"] = registration
        dropped = [r["file"] for r in registration if r["status"] not in ("reference", "ok")]
        result.report["notes"] += [f"view {f} failed registration and was left out" for f in dropped]
    return result
