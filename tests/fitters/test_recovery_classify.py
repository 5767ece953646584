"""Classification of generated boxes, cylinders, spheres, ellipsoids and free-form blobs (random sizes
and poses, 1 % noise, 5 % outliers), splitting of multipart clouds, and the pipeline's handling of parts
it has no exact builder for.  The accuracy over a larger set is reported by benchmarks/bench_superellipsoid.py."""
from __future__ import annotations

import numpy as np
import pytest

from recovery_scans import assert_rgm_clean, random_rotation, revolved_cloud, sample_primitive, turned_profile
from rgm.fitters.classify import QUALITY_FREE_FORM, CATEGORIES, category_scores, classify, split_parts
from rgm.fitters.pipeline import fit_points
from rgm.fitters.superellipsoid import Superellipsoid

KINDS = ("box", "cylinder", "sphere", "ellipsoid", "free_form")


@pytest.mark.parametrize("kind", KINDS)
def test_generated_shapes_are_classified(kind):
    results = [classify(sample_primitive(kind, np.random.default_rng(1000 + s), 2500)) for s in range(4)]
    assert sum(r.category == kind for r in results) >= 3, [(r.category, r.confidence) for r in results]
    for r in results:
        assert 0 < r.confidence <= 1 and r.runner_up != r.category and r.runner_up in CATEGORIES


def test_scores_follow_the_documented_rules():
    good = dict(rotation=np.eye(3), center=np.zeros(3), quality=0.005, inlier_fraction=0.95)
    box = category_scores(Superellipsoid(np.array([10.0, 20, 30]), np.array([0.1, 0.1]), **good))
    cyl = category_scores(Superellipsoid(np.array([10.0, 10, 30]), np.array([0.1, 1.0]), **good))
    sph = category_scores(Superellipsoid(np.array([10.0, 10, 10]), np.array([1.0, 1.0]), **good))
    bad = category_scores(Superellipsoid(np.array([10.0, 10, 10]), np.array([1.0, 1.0]),
                                         rotation=np.eye(3), center=np.zeros(3), quality=0.08, inlier_fraction=0.5))
    assert max(box, key=box.get) == "box" and max(cyl, key=cyl.get) == "cylinder"
    assert max(sph, key=sph.get) == "sphere" and max(bad, key=bad.get) == "free_form"


def test_two_separate_parts_are_split():
    rng = np.random.default_rng(5)
    a = sample_primitive("box", rng, 3000, outliers=0.0)
    b = sample_primitive("sphere", rng, 2000, outliers=0.0)
    b += a.mean(0) - b.mean(0) + np.array([400.0, 0, 0])
    parts = split_parts(np.vstack([a, b]))
    assert len(parts) == 2
    labels = {frozenset(np.where(idx < 3000, "a", "b")) for idx, _ in parts}
    assert labels == {frozenset({"a"}), frozenset({"b"})}
    assert sorted(classify(superellipsoid=se).category for _, se in parts) == ["box", "sphere"]


def _vase_cloud(rng, n=6000):
    """A bulged pin (recovery_scans.turned_profile with a bump) as a point cloud: random pose, 0.03 mm
    noise, 3 % outliers."""
    points, _ = revolved_cloud(turned_profile(27.15, 129.88, fillet=4.0, bump=(35, 105, 12)), n, rng, noise=0.03)
    points = points @ random_rotation(rng).T + rng.uniform(-200, 200, 3)
    bad = rng.random(n) < 0.03
    points[bad] += rng.normal(0, 10, (bad.sum(), 3))
    return points


def test_a_bulged_pin_no_superellipsoid_fits_is_other_revolution():
    for seed in range(2):
        result = classify(_vase_cloud(np.random.default_rng(20 + seed)))
        assert result.superellipsoid.quality > QUALITY_FREE_FORM          # the superellipsoid fits badly ...
        assert result.category == "other_revolution" and result.runner_up == "free_form"  # ... yet it is symmetric


def _ellipsoid(rng, n, axes, centre):
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d * np.asarray(axes, float) * (1 + rng.normal(0, 0.002, (n, 1))) + centre


def test_touching_parts_are_split_where_one_superellipsoid_fits_badly():
    """Two ellipsoids touching at x = 0 (one connected component, not rotationally symmetric), the long
    one twice as far from the contact with half the points, so that the cut through the centroid across
    the principal axis is the contact plane."""
    rng = np.random.default_rng(8)
    a = _ellipsoid(rng, 2000, (40.0, 15.0, 25.0), (-40.0, 0.0, 0.0))
    b = _ellipsoid(rng, 4000, (20.0, 40.0, 15.0), (20.0, 0.0, 0.0))
    rot, shift = random_rotation(rng), rng.uniform(-300, 300, 3)
    parts = split_parts(np.vstack([a, b]) @ rot.T + shift)
    assert len(parts) == 2
    for idx, se in parts:
        assert max(np.mean(idx < 2000), np.mean(idx >= 2000)) > 0.97     # each part is (almost) one ellipsoid
        truth = (40.0, 25.0, 15.0) if np.mean(idx < 2000) > 0.5 else (40.0, 20.0, 15.0)
        assert classify(superellipsoid=se).category == "ellipsoid"
        assert np.allclose(np.sort(se.size)[::-1], truth, atol=1.5)


def test_a_rotationally_symmetric_part_is_not_split():
    assert len(split_parts(_vase_cloud(np.random.default_rng(30)))) == 1


def test_sphere_is_one_arc_revolved_with_a_radius_param():
    rng = np.random.default_rng(4)
    d = rng.normal(size=(20000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    points = d * (30.0 + rng.normal(0, 0.03, (20000, 1))) @ random_rotation(rng).T + [100.0, -50.0, 20.0]
    result = fit_points(points, tol=0.1)
    part = result.report["parts"][0]
    assert part["category"] == "sphere" and part["certificate"]["holds"]
    assert abs(part["params"]["radius"] - 30.0) < 0.01
    assert "profile(arc(pt(0, 0, 0), pt(radius, radius, 0), pt(0, 2 * radius, 0)))" in result.text
    assert_rgm_clean(result.text)
    assert part["certificate"]["max"] < 0.2                                # closed at both poles


def test_free_form_part_is_modelled_as_certified_nurbs_patches():
    """A free-form sheet (scattered points of a smooth height field over 100 x 80 mm, 0.02 mm noise) is
    classified free form and goes to the free-form builder: trimmed NURBS in the .rgm whose certificate
    holds at 0.1 mm, its figures the closest-point distances of the points nearest to each patch,
    re-measured here on the file compiled from scratch."""
    import rgm
    from rgm.fitters.certificate import nearest_part, shape_from_model
    from rgm.model import TrimmedFace

    rng = np.random.default_rng(3)
    xy = rng.uniform([0, 0], [100, 80], (3000, 2))
    z = 6 * np.sin(xy[:, 0] / 22.0) * np.cos(xy[:, 1] / 27.0) + 0.02 * xy[:, 0] * xy[:, 1] / 10
    pts = np.c_[xy, z] + rng.normal(0, 0.02, (3000, 3))
    result = fit_points(pts, tol=0.1)
    part = result.report["parts"][0]
    assert part["category"] == "free_form" and part["model"] == "free_form" and result.parts
    assert all(c.holds for c in result.certificates)
    assert "bsurface(" in result.text and "trim(" in result.text and result.text.count("@fit(") == len(result.parts)
    model = rgm.loads(result.text)
    faces = [model.objects[p.name] for p in result.parts]
    assert all(isinstance(f, TrimmedFace) for f in faces)
    owner, dist = nearest_part([shape_from_model(f) for f in faces], pts)
    for k, (cert, info) in enumerate(zip(result.certificates, part["patches"])):
        d = dist[owner == k]
        assert cert.points == len(d) and np.isclose(cert.p95, np.percentile(d, 95), rtol=1e-9)
        assert np.isclose(cert.max, d.max(), rtol=1e-9) and info["certificate"]["p95"] == cert.p95
    assert sum(c.points for c in result.certificates) == len(pts)


def test_provenance_date_follows_source_date_epoch(monkeypatch):
    from rgm.fitters.emit import provenance_date

    monkeypatch.setenv("SOURCE_DATE_EPOCH", "0")
    assert provenance_date() == "1970-01-01T00:00:00Z"
