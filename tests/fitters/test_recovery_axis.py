"""The axis of a surface of revolution from its normals (line geometry: every normal line meets the
axis), as a unit: a cylinder-and-cone part in random poses, with its exact normals and then with noise,
5 % outliers and normals estimated from the points (robust PCA), refined by the profile's spread."""
from __future__ import annotations

import numpy as np
import pytest

from recovery_scans import random_rotation, revolved_cloud
from rgm.fitters.normals import pca_normals
from rgm.fitters.revolution import axis_from_normals, refine_axis

PROFILE = np.array([[0, 0], [20, 0], [20, 40], [10, 60], [0, 60]], float)   # (r, z) mm: a cylinder and a cone


def _errors(point, direction, pose):
    """(angle to the true axis in degrees, distance of `point` from the true axis in mm)."""
    axis = pose[:3, 2]
    off = point - pose[:3, 3]
    return (np.degrees(np.arccos(min(1.0, abs(direction @ axis)))),
            float(np.linalg.norm(off - (off @ axis) * axis)))


@pytest.mark.parametrize("seed", range(4))
def test_axis_of_exact_normals_is_exact(seed):
    rng = np.random.default_rng(seed)
    points, normals = revolved_cloud(PROFILE, 4000, rng)
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = random_rotation(rng), rng.uniform(-300, 300, 3)
    angle, offset = _errors(*axis_from_normals(points @ pose[:3, :3].T + pose[:3, 3], normals @ pose[:3, :3].T), pose)
    assert angle < 1e-5 and offset < 1e-8


@pytest.mark.parametrize("seed", range(3))
def test_axis_from_noisy_points_with_outliers(seed):
    rng = np.random.default_rng(10 + seed)
    points, _ = revolved_cloud(PROFILE, 8000, rng, noise=0.03)
    pose = np.eye(4)
    pose[:3, :3], pose[:3, 3] = random_rotation(rng), rng.uniform(-300, 300, 3)
    points = points @ pose[:3, :3].T + pose[:3, 3]
    bad = rng.random(len(points)) < 0.05
    points[bad] += rng.normal(0, 5, (bad.sum(), 3))
    normals, _ = pca_normals(points)
    first = axis_from_normals(points, normals)
    point, direction, sigma, angle_sigma = refine_axis(points, normals, *first)
    angle, offset = _errors(point, direction, pose)
    assert angle < 0.1 and offset < 0.02, (angle, offset)
    assert abs(sigma - 0.03) < 0.015                 # the profile's noise, not its shape
    # the stated uncertainty of the direction covers its actual error (3 sigma) and is not vacuous
    assert angle <= 3 * np.degrees(angle_sigma) < 0.1, (angle, np.degrees(angle_sigma))
