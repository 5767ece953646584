"""Emitting recovered revolutions: named chamfers by their measured uncertainty, and placements snapped to
world axes and zero offsets only where the data cannot tell the difference and the re-measured
certificate still holds.  Exact synthetic profiles (mm) in known frames: the truth is the construction."""
from __future__ import annotations

import re

import numpy as np

from recovery_scans import PIN_LENGTH, PIN_RADIUS, assert_rgm_clean
from rgm.fitters.emit import emit_part, snapped_placement, write_rgm
from rgm.fitters.pipeline import _snap
from rgm.fitters.profile2d import Profile, Segment
from rgm.fitters.revolution import RevolutionFit, axis_frame, sample_revolution

SIGMA = 0.02      # mm, the profile's noise


def _pin(low, high, support=400):
    """A pin's (r, z) profile with 45 deg chamfers of `low` and `high` mm at its ends, each line `support`
    points (the faces 3000, the mantle 27000)."""
    r, length = PIN_RADIUS, PIN_LENGTH
    pts = [(0, 0), (r - low, 0), (r, low), (r, length - high), (r - high, length), (0, length)]
    counts = (3000, support, 27000, support, 3000)
    return Profile(tuple(Segment(np.array(a, float), np.array(b, float), support=n)
                         for a, b, n in zip(pts, pts[1:], counts)))


def _tilted(angle, offset=(0.0, 0.0, 0.0), axis_sigma=1e-5, profile=None):
    d = np.array([np.sin(angle), np.cos(angle), 0.0])
    origin = np.array([0.0, -PIN_LENGTH / 2, 0.0]) + offset
    return RevolutionFit(axis_frame(origin, d), profile or _pin(1.2, 1.2), SIGMA, axis_sigma)


def _text(part):
    return write_rgm([part], inputs=[], options={}, tol=0.1)


def test_chamfers_that_agree_within_their_uncertainty_share_one_param():
    part = emit_part(_tilted(0.0, profile=_pin(1.2, 1.203)), "pin", snap=0.01)
    params = {n: v for n, v, _ in part.params}
    assert set(params) == {"radius", "length", "chamfer"} and abs(params["chamfer"] - 1.2015) < 1e-4
    text = _text(part)
    for expr in ("pt(radius - chamfer, 0, 0)", "pt(radius, chamfer, 0)", "pt(radius, length - chamfer, 0)",
                 "pt(radius - chamfer, length, 0)"):
        assert expr in text, expr
    assert_rgm_clean(text)


def test_chamfers_that_differ_beyond_their_uncertainty_get_one_param_each():
    # 0.008 mm apart: under the dimensions' snap (tol / 10) but over 3 standard uncertainties (~0.006 mm)
    for high in (1.208, 1.5):
        part = emit_part(_tilted(0.0, profile=_pin(1.2, high)), "pin", snap=0.01)
        params = {n: v for n, v, _ in part.params}
        assert params["chamfer1"] == 1.2 and params["chamfer2"] == high and "chamfer" not in params
        text = _text(part)
        for expr in ("pt(radius - chamfer1, 0, 0)", "pt(radius, chamfer1, 0)", "pt(radius, length - chamfer2, 0)",
                     "pt(radius - chamfer2, length, 0)"):
            assert expr in text, (expr, text)
        assert_rgm_clean(text)


def _surface_points(fit, n, rng, noise=0.0):
    pts = sample_revolution(fit.profile, fit.frame, 1.0)
    pts = pts[rng.choice(len(pts), n, replace=False)]
    return pts + rng.normal(0, noise, pts.shape)


def test_an_axis_within_its_uncertainty_of_y_and_micrometre_offsets_are_snapped():
    rng = np.random.default_rng(0)
    truth = _tilted(0.0)
    fit = _tilted(2e-5, offset=(0.0015, 0.0, -0.002), axis_sigma=1e-5)   # the noise of a real fit
    pts = _surface_points(truth, 20000, rng, noise=SIGMA)
    part = emit_part(fit, "pin", snap=0.01)
    snapped_part, info = _snap(fit, part, "pin", "", pts, 0.1, "p95")
    assert info["axis"]["to"] == "y" and abs(info["axis"]["angle_deg"] - np.degrees(2e-5)) < 1e-9
    assert set(info["offset"]) == {"x", "z"} and info["p95"] <= 0.1
    assert np.allclose(snapped_part.ideal.frame[:3, :3], np.eye(3))
    middle = fit.frame[:3, 3] + PIN_LENGTH / 2 * fit.frame[:3, 1]       # turned about the part's middle
    assert abs(snapped_part.ideal.frame[1, 3] - (middle[1] - PIN_LENGTH / 2)) < 1e-4
    assert re.search(r"^pin := translate\(body, vec\(0, -64\.94, 0\)\);$", _text(snapped_part), re.M)


def test_an_axis_beyond_three_uncertainties_is_left_as_measured():
    _, info = snapped_placement(_tilted(1e-3, axis_sigma=1e-4), 0.01)
    assert "axis" not in info


def test_snapping_is_rejected_when_the_remeasured_certificate_would_fail():
    """A real 0.06 deg tilt, with a (wrongly) large stated uncertainty, on exact data and a 0.02 mm
    tolerance: snapping would move the ends by up to 0.065 mm, so the placement stays as measured."""
    rng = np.random.default_rng(1)
    fit = _tilted(1e-3, axis_sigma=1e-3)
    pts = _surface_points(fit, 20000, rng)
    part = emit_part(fit, "pin", snap=0.002)
    kept, info = _snap(fit, part, "pin", "", pts, 0.02, "p95")
    assert kept is part and info["rejected"]["axis"]["to"] == "y" and info["rejected"]["p95"] > 0.02
    assert "rotate(body" in _text(kept)
