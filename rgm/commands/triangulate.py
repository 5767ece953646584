"""`rgmc triangulate SCAN --tol T -o mesh.ply [--report tri.json] [--no-filter] [--force]`.

Triangulates one view (a range image keeps its pixel grid; an unstructured view is projected on its
best-fit plane) by greedy insertion until every point lies within T of the mesh along the viewing
direction, then removes the vertices that are no longer needed, with no triangle across a depth
discontinuity or an invalid pixel.  T is in the scan's own units (the bunny is in metres: --tol 0.0004
is 0.4 mm).  Range images are RLTS-filtered first (outliers
dropped) unless --no-filter.  Prints vertex and triangle counts and the measured max and RMS error.
Exit codes: 0 written, 1 bad input, 2 usage.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # many small solves: BLAS threads only add contention
os.environ.setdefault("OMP_NUM_THREADS", "1")

import json
import sys
from pathlib import Path


def add_arguments(parser) -> None:
    parser.add_argument("scan", metavar="SCAN", help="a scan file (ply, npy, npz, grid, xyz, ...)")
    parser.add_argument("--tol", type=float, required=True, help="tolerance in the scan's units")
    parser.add_argument("-o", "--output", required=True, metavar="mesh.ply", help="the mesh to write (PLY)")
    parser.add_argument("--report", metavar="tri.json", help="also write counts and measured errors as JSON")
    parser.add_argument("--disc-slope", type=float, default=6.0,
                        help="depth change per lateral distance treated as a discontinuity (default 6 = 80 deg)")
    parser.add_argument("--no-filter", action="store_true", help="do not remove outliers first")
    parser.add_argument("--force", action="store_true", help="overwrite existing output files")


def _fail(message: str) -> int:
    print(f"rgmc triangulate: error: {message}", file=sys.stderr)
    return 1


def run(args) -> int:
    from rgm.atomic import OutputExists, write_atomic
    from rgm.errors import RgmError
    from rgm.fitters.filters import rlts_filter
    from rgm.fitters.io import read_scan, write_ply
    from rgm.fitters.triangulate import triangulate

    if not args.tol > 0:
        return _fail(f"--tol must be positive, got {args.tol}")
    for path in [Path(p) for p in (args.output, args.report) if p]:
        if path.resolve() == Path(args.scan).resolve():
            return _fail(f"{path} is the input; refusing to overwrite it")
        if path.exists() and not args.force:
            return _fail(f"{path} exists; pass --force to overwrite it")
    try:
        scan = read_scan(args.scan)
        if scan.grid is not None and not args.no_filter:
            scan = rlts_filter(scan, mode="drop").scan
        mesh = triangulate(scan, args.tol, disc_slope=args.disc_slope)
        write_ply(args.output, mesh.vertices, mesh.triangles)
        if args.report:
            write_atomic(args.report, json.dumps({"scan": args.scan, **mesh.report()}, indent=2) + "\n")
    except (RgmError, OutputExists, OSError) as exc:
        return _fail(str(exc))
    print(f"{args.output}: {len(mesh.vertices)} vertices, {len(mesh.triangles)} triangles from {mesh.n_points} "
          f"points; max error {mesh.max_error:.4g}, rms {mesh.rms_error:.4g} (tol {args.tol:g})"
          + (f"; {mesh.uncovered} isolated points left out" if mesh.uncovered else ""))
    return 0
