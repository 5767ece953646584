"""Real data: the YCB cracker box (The YCB Object and Model Set, Calli et al. 2015, CC BY 4.0), read from
/work/shared/data/ycb/ (skipped when absent).  Scan-like views are sampled from its mesh (z-buffer of a
dense surface sample, six viewpoints, noise along the ray, 3 % outliers); the part must be classified as a
box whose three dimensions are within 1 mm of the mesh's own oriented bounding box, and the emitted
`.rgm` must check clean and evaluate."""
from __future__ import annotations

import numpy as np
import pytest

from recovery_scans import YCB, assert_rgm_clean, mesh_views

import rgm

BOX = YCB / "003_cracker_box_textured.obj"
pytestmark = pytest.mark.skipif(not BOX.exists(), reason=f"{BOX} not present (shared YCB data)")


@pytest.fixture(scope="module")
def box_fit():
    import trimesh

    from rgm.fitters.filters import statistical_outliers
    from rgm.fitters.pipeline import fit_points

    dirs = [(1, 0.3, 0.2), (-1, 0.2, -0.3), (0.2, 1, 0.3), (-0.3, -1, 0.1), (0.1, 0.2, 1), (0.2, -0.1, -1)]
    views, mesh = mesh_views(BOX, dirs, pitch=2.0, noise=0.3, outliers=0.03, seed=0)
    pts = np.vstack(views)
    pts = pts[~statistical_outliers(pts)]
    _, extents = trimesh.bounds.oriented_bounds(mesh)
    return fit_points(pts, tol=1.0, title="cracker_box"), np.sort(extents), pts


def test_cracker_box_is_a_box_with_its_obb_dimensions(box_fit):
    result, obb, _ = box_fit
    part = result.report["parts"][0]
    assert part["category"] == "box" and part["confidence"] > 0.5
    dims = np.sort([part["params"][k] for k in ("width", "depth", "height")])
    assert np.all(np.abs(dims - obb) < 1.0), (dims, obb)


def test_cracker_box_file_checks_and_evaluates(box_fit):
    from rgm.fitters.certificate import shape_from_model

    result, _, _ = box_fit
    assert_rgm_clean(result.text, "box.rgm")
    model = rgm.loads(result.text)
    shape = shape_from_model(model.objects["cracker_box"])
    assert np.allclose(np.sort(shape.dimensions), np.sort(result.parts[0].ideal.dimensions), atol=1e-3)


def test_verify_keeps_an_honest_failing_certificate_and_catches_an_edit(box_fit, tmp_path):
    """The carton bulges by up to ~7 mm, so the 1 mm certificate of its box does not hold and says so;
    `rgmc verify` accepts the file as fitted and rejects it once a dimension is edited by 2 mm."""
    import re

    from rgm.cli import main
    from rgm.fitters.io import write_ply

    result, _, pts = box_fit
    assert not result.certificates[0].holds and result.certificates[0].p95 > 1.0
    scan = tmp_path / "box.ply"
    write_ply(scan, pts)
    good, edited = tmp_path / "box.rgm", tmp_path / "edited.rgm"
    good.write_text(result.text)
    width = float(re.search(r"param width := ([0-9.]+)mm;", result.text).group(1))
    edited.write_text(result.text.replace(f"param width := {width:.4f}mm;", f"param width := {width + 2:.4f}mm;"))
    assert main(["verify", str(good), str(scan)]) == 0
    assert main(["verify", str(edited), str(scan)]) == 1
