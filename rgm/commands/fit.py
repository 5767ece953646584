"""`rgmc fit VIEW... [--poses FILE.conf] --tol T -o part.rgm [--report fit.json] [--force]`.

Runs the fitting pipeline (`rgm.fitters.pipeline`): intake, outlier filtering, registration (only with
--register; otherwise the views must be in one frame, possibly through --poses), splitting,
superellipsoid classification, the exact builders or the free-form one (trimmed NURBS patches, by the
range grid for a single range view), certificates, and writes the `.rgm` procedure and an optional JSON
report with per-stage timings.  The procedure is written in canonical form (`rgmc fmt`) and only if
`rgmc check` finds no error in that text (a fitter bug is reported, never written; warnings are printed).
Exit codes: 0 written, 1 bad input or nothing could be modelled, 2 usage.
"""
from __future__ import annotations

import os

# the fitters solve many small least-squares problems: BLAS threads only add synchronisation (and are
# pathological on busy machines), so a fresh `rgmc fit`/`verify` process runs BLAS single-threaded
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import json
import sys
from pathlib import Path

from rgm.commands.check import canonical_checked
from rgm.fitters.certificate import STATISTICS


def add_arguments(parser) -> None:
    parser.add_argument("views", nargs="+", metavar="VIEW", help="scan files (ply, xyz, npy, ...) or one .conf")
    parser.add_argument("--poses", metavar="FILE.conf", help="initial/known poses of the views (Stanford .conf)")
    parser.add_argument("--tol", type=float, required=True, help="tolerance in mm that the certificate bounds")
    parser.add_argument("--statistic", choices=STATISTICS, default="p95",
                        help="which deviation statistic --tol bounds (default p95: the max includes noise)")
    parser.add_argument("-o", "--output", required=True, metavar="part.rgm", help="the .rgm file to write")
    parser.add_argument("--report", metavar="fit.json", help="also write a JSON report with stage timings")
    parser.add_argument("--scale", type=float, default=1.0,
                        help="multiply scan coordinates by this to get mm (1000 for scans in metres)")
    parser.add_argument("--register", action="store_true", help="register the views (ICP) before fitting")
    parser.add_argument("--name", default=None, help="binding name of the part (default: the output's stem)")
    parser.add_argument("--crease-angle", type=float, default=None, metavar="DEG",
                        help="normal change (degrees) at which free-form data splits into patches (default 35 for "
                             "merged views, 40 for one range view); lower it where edges are rounded off")
    parser.add_argument("--force", action="store_true", help="overwrite existing output files")


def _fail(message: str) -> int:
    print(f"rgmc fit: error: {message}", file=sys.stderr)
    return 1


def run(args) -> int:
    from rgm.atomic import OutputExists, write_atomic
    from rgm.errors import RgmError

    out = Path(args.output)
    outputs = [out] + ([Path(args.report)] if args.report else [])
    inputs = {Path(v).resolve() for v in args.views} | ({Path(args.poses).resolve()} if args.poses else set())
    if not args.tol > 0:
        return _fail(f"--tol must be a positive length in mm, got {args.tol}")
    if not args.scale > 0:
        return _fail(f"--scale must be positive, got {args.scale}")
    if args.crease_angle is not None and not 0 < args.crease_angle < 90:
        return _fail(f"--crease-angle must lie between 0 and 90 degrees, got {args.crease_angle:g}")
    for path in outputs:
        if path.resolve() in inputs:
            return _fail(f"{path} is an input; refusing to overwrite it")
        if path.exists() and not args.force:
            return _fail(f"{path} exists; pass --force to overwrite it")
    name = args.name or (out.stem if out.stem.isidentifier() else "part")
    try:
        from rgm.fitters.pipeline import fit_scans

        result = fit_scans(args.views, tol=args.tol, poses=args.poses, statistic=args.statistic,
                           register=args.register, scale=args.scale, title=name, crease_deg=args.crease_angle)
    except (RgmError, ValueError, OSError) as exc:
        return _fail(str(exc))
    text, problems, warnings = canonical_checked(result.text, str(out))
    if text is None:
        return _fail(f"internal error (a bug in rgmc fit, nothing written): the generated {out.name} does not "
                     f"{problems}")
    for warning in warnings:
        print(f"rgmc fit: warning in the generated {out.name}:\n{warning}", file=sys.stderr)
    try:
        write_atomic(out, text, overwrite=True)
        if args.report:
            write_atomic(args.report, json.dumps(result.report, indent=2, default=float) + "\n", overwrite=True)
    except (OutputExists, OSError) as exc:
        return _fail(str(exc))
    for part in result.report["parts"]:
        line = f"{part['name']}: {part['category']} (confidence {part['confidence']:.2f}, runner-up {part['runner_up']})"
        if part.get("model") == "exact" and part.get("certificate"):
            dims = ", ".join(f"{k} = {v:.4f} mm" for k, v in part["params"].items())
            line += f"; {dims}; {_verdict(part['certificate'])}"
        print(line, file=sys.stderr)
        if part.get("placement_snapped"):
            print(f"  placement: {_snapped(part['placement_snapped'])}", file=sys.stderr)
        for patch in part.get("patches", []):
            if patch.get("certificate"):
                nu, nv = patch["control_net"]
                stop = f" (refinement stopped: {patch['stopped']})" if patch["stopped"] else ""
                print(f"  {patch['name']}: free-form NURBS {nu} x {nv} control points, {patch['loops']['holes']} "
                      f"hole(s), {patch['loops']['cuts']} cut(s); {_verdict(patch['certificate'])}{stop}",
                      file=sys.stderr)
    for note in result.report["notes"]:
        print(f"rgmc fit: note: {note}", file=sys.stderr)
    seams = result.report.get("seams", [])
    if seams:   # as `rgmc verify` measures the file: each face's edges to its neighbours' faces
        tol = float(args.tol)
        worst = max(seams, key=lambda s: s["max"])
        print(f"seams: {sum(s['max'] <= tol for s in seams)} of {len(seams)} within tol {tol:g} mm (G0, face to face "
              f"as written); worst {worst['max']:.4f} mm, {worst['a']} | {worst['b']}", file=sys.stderr)
    print(f"wrote {out}", file=sys.stderr)
    return 0 if result.parts else 1


def _snapped(info: dict) -> str:
    """One line on what `rgm.fitters.emit.snapped_placement` snapped (or was refused)."""
    if "rejected" in info:
        return f"not snapped ({info['why']})"
    said = []
    if "axis" in info:
        a = info["axis"]
        said.append(f"axis snapped to {a['to']} (off by {a['angle_deg']:.4f} deg, within 3 uncertainties "
                    f"{a['limit_deg']:.4f} deg)")
    if "offset" in info:
        said.append(f"offsets {', '.join(f'{k} {v:+.4f}' for k, v in info['offset'].items())} mm snapped to 0 "
                    f"(resolution {info['resolution']:g} mm)")
    return "; ".join(said) + ", certificate re-measured"


def _verdict(cert: dict) -> str:
    stat = cert["statistic"]
    state = "holds" if cert["holds"] else "DOES NOT HOLD"
    return f"{stat} {cert[stat]:.4f} mm {'<=' if cert['holds'] else '>'} tol {cert['tol']:g}: {state}"
