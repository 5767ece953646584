"""Classification of generated boxes, cylinders, spheres, ellipsoids and free-form blobs (random sizes
and poses, 1 % noise, 5 % outliers), splitting of multipart clouds, and the pipeline's handling of parts
it has no exact builder for.  The accuracy over a larger set is reported by benchmarks/bench_superellipsoid.py."""
from __future__ import annotations

import numpy as np
import pytest

from recovery_scans import sample_primitive
from rgm.fitters.classify import CATEGORIES, category_scores, classify, split_parts
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


def test_free_form_part_is_reported_not_modelled():
    pts = sample_primitive("free_form", np.random.default_rng(3), 4000, outliers=0.0)
    result = fit_points(pts, tol=0.5)
    assert result.parts == [] and "free_form" in result.report["notes"][0]
    assert "not modelled" in result.text


def test_provenance_date_follows_source_date_epoch(monkeypatch):
    from rgm.fitters.emit import provenance_date

    monkeypatch.setenv("SOURCE_DATE_EPOCH", "0")
    assert provenance_date() == "1970-01-01T00:00:00Z"
