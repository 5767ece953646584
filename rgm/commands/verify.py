"""`rgmc verify part.rgm VIEW... [--poses FILE] [--scale S]`: re-measure a model against its scans.

The file is compiled (parse, check, evaluate: `rgm.loads`); every binding annotated with `@fit` is
turned into a measurable shape (`rgm.fitters.certificate.shape_from_model`: revolutions, boxes, NURBS
surfaces and trimmed NURBS faces, measured by closest points restricted to the trim), the scans are read
and filtered as `rgmc fit` does, each point is given to the nearest annotated part
(`rgm.fitters.certificate.nearest_part`, as `rgmc fit` certifies), and the certificate is measured again
with the tolerance and statistic written in the annotation.  A certificate that did not
hold when fitted (its recorded figure above its tolerance, as on a bulging carton fitted as a box) must
not get worse: none of its recorded max, rms and p95 may grow by more than 5 % of the tolerance.  The
seams between trimmed faces are measured too, from the file (`rgm.fitters.seam_check`: each face's edges
to its neighbours' faces as written), and held to the same rule against the `g0` the fit recorded.
Exit codes: 0 every certificate and seam holds, 1 one does not (after a hand edit, say) or the input is
bad, 2 usage.
"""
from __future__ import annotations

import os

# the fitters solve many small least-squares problems: BLAS threads only add synchronisation (and are
# pathological on busy machines), so a fresh `rgmc fit`/`verify` process runs BLAS single-threaded
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import sys

#: length units of annotation literals, in mm (rgmc fit writes mm)
_MM = {None: 1.0, "mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4, "um": 1e-3}


def add_arguments(parser) -> None:
    parser.add_argument("model", metavar="part.rgm", help="the .rgm file written by rgmc fit (maybe edited)")
    parser.add_argument("views", nargs="+", metavar="VIEW", help="the scans it was fitted to")
    parser.add_argument("--poses", metavar="FILE.conf", help="poses of the views (Stanford .conf)")
    parser.add_argument("--scale", type=float, default=1.0, help="multiply scan coordinates by this to get mm")


def _fail(message: str) -> int:
    print(f"rgmc verify: error: {message}", file=sys.stderr)
    return 1


def _fit_annotations(program) -> dict:
    """binding name -> {"tol": mm, "statistic": str} from its `@fit` annotation."""
    from rgm.compiler import ast as A

    out = {}
    for stmt in program.statements:
        if not isinstance(stmt, A.Binding):
            continue
        for ann in stmt.annotations:
            if ann.name != "fit":
                continue
            tol, stat = ann.arg("tol"), ann.arg("statistic")
            if not isinstance(tol, A.Number):
                continue
            statistic = stat.value if isinstance(stat, A.String) else "max"
            recorded = {key: ann.arg(key).value * _MM.get(ann.arg(key).unit, 1.0)
                        for key in ("max", "rms", "p95") if isinstance(ann.arg(key), A.Number)}
            g0 = ann.arg("g0")
            out[stmt.name] = {"tol": tol.value * _MM.get(tol.unit, 1.0), "statistic": statistic,
                              "recorded": recorded,
                              "g0": g0.value * _MM.get(g0.unit, 1.0) if isinstance(g0, A.Number) else None}
    return out


def run(args) -> int:
    import rgm
    from rgm.compiler.diagnostics import CompileError, render
    from rgm.compiler.parser import parse
    from rgm.errors import RgmError
    from rgm.fitters.certificate import certify, nearest_part, shape_from_model

    try:
        text = open(args.model, encoding="utf-8").read()
    except (OSError, UnicodeDecodeError) as exc:
        return _fail(f"cannot read {args.model}: {exc}")
    try:
        model = rgm.loads(text, filename=args.model)
    except CompileError as exc:
        for d in exc.diagnostics:
            print(render(d, {args.model: text}), file=sys.stderr)
        return _fail(f"{args.model} does not compile")
    claims = _fit_annotations(parse(text, args.model)[0])
    if not claims:
        return _fail(f"{args.model} has no @fit certificate to verify")
    try:
        shapes = {name: shape_from_model(model.objects[name]) for name in claims if name in model.objects}
        from rgm.fitters.io import read_views
        from rgm.fitters.pipeline import filtered_points

        points = filtered_points(read_views(args.views, args.poses), args.scale)[0]
    except (RgmError, ValueError, OSError, KeyError) as exc:
        return _fail(str(exc))
    names = list(shapes)
    owner, dist = nearest_part([shapes[n] for n in names], points)
    failed = 0
    for k, name in enumerate(names):
        d = dist[owner == k]
        if len(d) == 0:
            print(f"{name}: no scan point lies nearest to it: FAILS", file=sys.stderr)
            failed += 1
            continue
        claim = claims[name]
        cert = certify(d, claim["tol"], statistic=claim["statistic"])
        ok = cert.holds
        note = ""
        rec = claim["recorded"]
        if rec.get(cert.statistic, 0.0) > claim["tol"]:
            # the certificate did not hold when fitted (the file says so): no recorded figure (max, rms,
            # p95) may grow by more than 5 % of the tolerance
            ok = all(getattr(cert, key) <= value + 0.05 * claim["tol"] for key, value in rec.items())
            note = " (did not hold when fitted; recorded " + ", ".join(f"{k} {v:.4f}" for k, v in rec.items()) + " mm)"
        verdict = "FAILS" if not ok else "holds" if cert.holds else "no worse than recorded"
        print(f"{name}: {cert.points} points, max {cert.max:.4f} mm, rms {cert.rms:.4f} mm, p95 {cert.p95:.4f} mm; "
              f"{cert.statistic} {cert.value:.4f} mm {'<=' if cert.holds else '>'} tol {cert.tol:g} mm{note}: "
              f"{verdict}", file=sys.stderr)
        failed += not ok
    failed += _verify_seams(names, shapes, claims, points, owner)
    return 1 if failed else 0


def _verify_seams(names, shapes, claims, points, owner) -> int:
    """Measure the seams between the file's trimmed faces (`rgm.fitters.seam_check`), print them, and
    return how many fail: a seam holds within the smaller of its faces' tolerances, or, where both faces
    record a `g0` (their worst seam gap when fitted), is no worse than the smaller of those plus 5 % of
    the tolerance."""
    from rgm.fitters.freeform_measure import TrimmedNurbs
    from rgm.fitters.seam_check import measure_seams

    faces = {k: shapes[n] for k, n in enumerate(names) if isinstance(shapes[n], TrimmedNurbs)}
    if len(faces) < 2:
        return 0
    seams = measure_seams(faces, points, owner)
    failed = within = 0
    for s in seams:
        a, b = claims[names[s.a]], claims[names[s.b]]
        tol = min(a["tol"], b["tol"])
        recorded = None if a["g0"] is None or b["g0"] is None else min(a["g0"], b["g0"])
        if s.max <= tol:
            verdict, within = "holds", within + 1
        elif recorded is not None and s.max <= recorded + 0.05 * tol:
            verdict = f"no worse than recorded (g0 {recorded:.4f} mm)"
        else:
            verdict, failed = "FAILS", failed + 1
        print(f"seam {names[s.a]} | {names[s.b]}: G0 gap max {s.max:.4f} mm, p95 {s.p95:.4f} mm ({s.samples} edge "
              f"samples, to the nearest other face) {'<=' if s.max <= tol else '>'} tol {tol:g} mm: {verdict}",
              file=sys.stderr)
    print(f"seams: {within} of {len(seams)} within the tolerance", file=sys.stderr)
    return failed
