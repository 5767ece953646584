"""`rgmc register VIEW... [--poses FILE.conf] -o merged.ply [--report reg.json] [--poses-out out.conf]`.

Reads the views (scan files, or one Stanford .conf), removes outliers (RLTS filter on range images,
statistical removal on clouds; --no-filter to skip), registers every view incrementally against the
views placed so far (coarse search when no pose is known, then robust point-to-plane ICP; views that fail
are tried again once the model has grown), refines all poses together (simultaneous point-to-plane least
squares, the first view fixed), and writes the merged cloud in the first view's frame.  A table on
stdout gives each view's status; views that are not to be trusted (low overlap, an unconstrained
direction, a residual far above the noise) are named on stderr.  Exit codes: 0 written, 1 bad input or
(with --strict) an untrusted view, 2 usage.
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # many small solves: BLAS threads only add contention
os.environ.setdefault("OMP_NUM_THREADS", "1")

import json
import sys
from pathlib import Path


def add_arguments(parser) -> None:
    parser.add_argument("views", nargs="+", metavar="VIEW", help="scan files (ply, xyz, npy, ...) or one .conf")
    parser.add_argument("--poses", metavar="FILE.conf", help="initial poses of the views (Stanford .conf)")
    parser.add_argument("-o", "--output", required=True, metavar="merged.ply", help="merged cloud to write")
    parser.add_argument("--report", metavar="reg.json", help="per-view transforms, residuals and statuses")
    parser.add_argument("--poses-out", metavar="out.conf", help="write the registered poses as a .conf")
    parser.add_argument("--no-filter", action="store_true", help="register the raw points (no outlier removal)")
    parser.add_argument("--no-refine", action="store_true", help="skip the global refinement of all poses")
    parser.add_argument("--strict", action="store_true", help="exit 1 if any view is not to be trusted")
    parser.add_argument("--force", action="store_true", help="overwrite existing output files")


def _fail(message: str) -> int:
    print(f"rgmc register: error: {message}", file=sys.stderr)
    return 1


def _clean(scan):
    """Outliers out: RLTS on range images, statistical removal on clouds."""
    from rgm.fitters.filters import rlts_filter, statistical_outliers

    if scan.grid is not None:
        return rlts_filter(scan, mode="drop").scan
    return scan.select(~statistical_outliers(scan.points))


def run(args) -> int:
    import numpy as np

    from rgm.atomic import OutputExists, write_atomic
    from rgm.errors import RgmError
    from rgm.fitters.io import read_views, write_conf, write_ply
    from rgm.fitters.register import register_views

    outputs = [Path(p) for p in (args.output, args.report, args.poses_out) if p]
    inputs = {Path(v).resolve() for v in args.views} | ({Path(args.poses).resolve()} if args.poses else set())
    for path in outputs:
        if path.resolve() in inputs:
            return _fail(f"{path} is an input; refusing to overwrite it")
        if path.exists() and not args.force:
            return _fail(f"{path} exists; pass --force to overwrite it")
    try:
        scans = read_views(args.views, poses=args.poses)
        known = bool(args.poses) or (len(args.views) == 1 and args.views[0].lower().endswith(".conf"))
        if len(scans) < 2:
            return _fail("at least two views are needed to register")
        if not args.no_filter:
            scans = [_clean(s) for s in scans]
        reports = register_views(scans, use_poses=known, refine=not args.no_refine)
        merged = np.concatenate([s.points @ r.transform[:3, :3].T + r.transform[:3, 3]
                                 for s, r in zip(scans, reports)])
        write_ply(args.output, merged)
        if args.report:
            body = {"views": [r.to_json() for r in reports], "initial_poses": "given" if known else "coarse search"}
            write_atomic(args.report, json.dumps(body, indent=2) + "\n")
        if args.poses_out:
            write_conf(args.poses_out, scans, [r.transform for r in reports])
    except (RgmError, OutputExists, OSError) as exc:
        return _fail(str(exc))
    print(f"{'view':32s} {'status':14s} {'rms':>10s} {'overlap':>8s} {'inliers':>8s} {'iter':>5s}")
    for r in reports:
        print(f"{Path(r.source).name:32s} {r.status:14s} {r.rms:10.4g} {r.overlap:8.0%} {r.inliers:8.0%} {r.iterations:5d}")
    untrusted = [r for r in reports if r.status not in ("ok", "reference")]
    for r in untrusted:
        print(f"rgmc register: warning: {Path(r.source).name}: do not trust this pose: {'; '.join(r.reasons)}",
              file=sys.stderr)
    print(f"wrote {args.output} ({len(merged)} points from {len(scans)} views)")
    return 1 if untrusted and args.strict else 0
