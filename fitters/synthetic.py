"""Synthetic range images of analytic parts, with known truth, for tests and benchmarks.

A part is a signed-distance function (SDF, part units = mm, size ~100). `render` ray-casts it with an
orthographic sensor (sphere tracing, Hart 1996), adds Gaussian noise along the ray (default 0.2 % of the
part size) and gross outliers (default 5 % of the pixels, displaced along the ray by 1.5-15 % of the part
size, a random sign), all from a fixed seed. The returned `Scan` is in the sensor frame (the sensor looks
along its -z), with `pose` = the true sensor-to-part transform; `SyntheticView` also carries the
noise-free points, the outlier flags and an edge mask.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rgm.fitters.io import Scan

__all__ = ["PARTS", "SyntheticView", "render", "look_at", "box_sdf", "grooved_cylinder_sdf", "freeform_patch_sdf",
           "pin_sdf"]


def _corner_sdf(a, b):
    """Exact 2-D SDF of the quadrant {a < 0, b < 0} given the two signed offsets a, b (arrays)."""
    return np.hypot(np.maximum(a, 0), np.maximum(b, 0)) + np.minimum(np.maximum(a, b), 0)


def box_sdf(p, half=(50.0, 30.0, 20.0)):
    """Exact SDF of an axis-aligned box centred at the origin; p (n, 3) -> (n,)."""
    q = np.abs(p) - np.asarray(half)
    return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)


def grooved_cylinder_sdf(p, radius=25.0, length=100.0, groove_at=15.0, groove_width=12.0, groove_depth=5.0):
    """SDF bound of a capped cylinder (axis x) with a rectangular circumferential groove."""
    r = np.hypot(p[:, 1], p[:, 2])
    body = _corner_sdf(np.abs(p[:, 0]) - length / 2, r - radius)
    groove = _corner_sdf(np.abs(p[:, 0] - groove_at) - groove_width / 2, (radius - groove_depth) - r)
    return np.maximum(body, -groove)


def pin_sdf(p, radius=27.15, length=129.88, chamfer=1.2):
    """SDF bound of the paper's pin (Figure 7): a cylinder along y, centred at the origin, with 45 deg
    chamfers of `chamfer` mm at both ends (mm)."""
    r, h = np.hypot(p[:, 0], p[:, 2]), np.abs(p[:, 1]) - length / 2
    body = _corner_sdf(h, r - radius)
    return np.maximum(body, (r - radius + h + chamfer) / np.sqrt(2))


def _patch_height(x, y):
    """A free-form height field (mm) on [-50, 50]^2: two bumps, a dip and a gentle wave."""
    return (12 * np.exp(-((x - 15) ** 2 + (y - 10) ** 2) / 300) - 8 * np.exp(-((x + 20) ** 2 + (y + 15) ** 2) / 200)
            + 5 * np.sin(x / 9) * np.cos(y / 11) + 6 * np.exp(-((x + 10) ** 2 + (y - 25) ** 2) / 120))


def freeform_patch_sdf(p):
    """SDF bound of a 10 mm thick slab whose top is the free-form height field `_patch_height`."""
    top = (p[:, 2] - _patch_height(p[:, 0], p[:, 1])) / 1.6  # 1.6 >= sqrt(1 + max slope^2) = 1.49
    sides = np.maximum(np.abs(p[:, 0]) - 50, np.abs(p[:, 1]) - 50)
    return np.maximum(np.maximum(top, sides), -p[:, 2] - 25)


#: name -> (sdf, characteristic size in mm used for noise and tolerances)
PARTS = {"box": (box_sdf, 100.0), "cylinder": (grooved_cylinder_sdf, 100.0), "patch": (freeform_patch_sdf, 100.0),
         "pin": (pin_sdf, 140.0)}


@dataclass(frozen=True, eq=False)
class SyntheticView:
    """scan: the noisy range image (sensor frame, pose = truth); clean: (n, 3) noise-free points;
    outlier: (n,) bool; edge: (n,) bool, pixels within 2 px of a depth step or crease; size: part size."""

    scan: Scan
    clean: np.ndarray
    outlier: np.ndarray
    edge: np.ndarray
    size: float


def look_at(direction, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """(3, 3) sensor rotation whose -z column looks along `direction` (columns = sensor x, y, z in the
    part frame)."""
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    up = np.asarray(up, float)
    if abs(d @ up) > 0.99:
        up = np.array([0.0, 1.0, 0.0])
    x = np.cross(d, up)
    x /= np.linalg.norm(x)
    y = np.cross(-d, x)
    return np.column_stack([x, y, -d])


def render(part: str, direction=(0.0, 0.0, -1.0), *, shape=(160, 160), pitch=None, noise=0.002,
           outliers=0.05, seed=0, up=(0.0, 0.0, 1.0), center=(0.0, 0.0, 0.0)) -> SyntheticView:
    """Orthographic range image of `part` seen along `direction`.

    shape : (rows, cols); pitch : pixel spacing in mm (default: the image spans 1.3 x the part size).
    noise : Gaussian sigma along the ray as a fraction of the part size; outliers : fraction of pixels.
    """
    sdf, size = PARTS[part]
    rows, cols = shape
    pitch = pitch or 1.3 * size / max(rows, cols)
    rot = look_at(direction, up)
    d = -rot[:, 2]
    far = 2.0 * size
    r, c = np.mgrid[0:rows, 0:cols]
    lateral = np.stack([(c - (cols - 1) / 2) * pitch, (r - (rows - 1) / 2) * pitch], -1).reshape(-1, 2)
    origin = np.asarray(center, float) + lateral @ rot[:, :2].T - far * d
    t = np.zeros(len(origin))
    active = np.arange(len(origin))
    hit = np.zeros(len(origin), bool)
    for _ in range(400):  # sphere tracing, vectorised over the rays still marching
        dist = sdf(origin[active] + t[active, None] * d)
        done = dist < 1e-6 * size
        hit[active[done]] = True
        t[active] += np.where(done, 0.0, dist)
        active = active[~done & (t[active] < 2 * far)]
        if not len(active):
            break
    depth = np.where(hit, t, np.nan).reshape(rows, cols)
    rng = np.random.default_rng(seed)
    valid = np.isfinite(depth)
    idx = np.flatnonzero(valid.ravel())
    n = len(idx)
    clean_t = depth.ravel()[idx]
    noisy_t = clean_t + rng.normal(0, noise * size, n)
    outlier = rng.random(n) < outliers
    k = int(outlier.sum())
    noisy_t[outlier] = clean_t[outlier] + rng.choice([-1, 1], k) * rng.uniform(0.015, 0.15, k) * size
    lat = lateral[idx]

    def to_sensor(tt):  # sensor frame: x, y lateral, z = far - t (the sensor looks along -z)
        return np.column_stack([lat, far - tt])

    grid = np.full(rows * cols, -1, np.int64)
    grid[idx] = np.arange(n)
    grid = grid.reshape(rows, cols)
    pose = np.eye(4)
    pose[:3, :3] = rot
    pose[:3, 3] = center  # the sensor frame is centred on the part centre, z = 0 there
    scan = Scan(to_sensor(noisy_t), grid=grid, view_dir=np.array([0.0, 0.0, -1.0]), pose=pose,
                source=f"<synthetic {part}>")
    return SyntheticView(scan, to_sensor(clean_t), outlier, _edge_pixels(depth, pitch, idx), size)


def _edge_pixels(depth, pitch, idx) -> np.ndarray:
    """(n,) bool: valid pixels within 2 px of a depth step (jump > 3 pitch), a crease (second difference
    > pitch/2) or an invalid pixel, from the noise-free depth image."""
    from scipy import ndimage

    z = np.where(np.isfinite(depth), depth, np.nan)
    jump = np.zeros(z.shape, bool)
    for axis in (0, 1):
        dz = np.abs(np.diff(z, axis=axis))
        bad = ~(dz < 3 * pitch)  # NaN (invalid neighbour) counts as a step
        sl_a = [slice(None)] * 2
        sl_b = [slice(None)] * 2
        sl_a[axis], sl_b[axis] = slice(None, -1), slice(1, None)
        jump[tuple(sl_a)] |= bad
        jump[tuple(sl_b)] |= bad
        d2 = np.abs(np.diff(z, n=2, axis=axis))
        sl_c = [slice(None)] * 2
        sl_c[axis] = slice(1, -1)
        jump[tuple(sl_c)] |= d2 > pitch / 2
    near = ndimage.binary_dilation(jump, iterations=2)
    return near.ravel()[idx]
