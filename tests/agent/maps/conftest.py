"""Synthetic scans for the map tests: ray casting a few segments in numpy."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_scans import box, raycast


def scan_points(pose, segs, rng, n_beams=361, fov=2 * np.pi, sigma=0.01, max_range=8.0):
    """Map-frame points of a noisy 360° (or ``fov``) scan from ``pose``."""
    pose = np.asarray(pose, float)
    ang = -fov / 2 + fov * np.arange(n_beams) / n_beams
    r = raycast(pose, ang, segs, max_range) + sigma * rng.standard_normal(n_beams)
    ok = np.isfinite(r)
    th = pose[2] + ang[ok]
    return np.stack([pose[0] + r[ok] * np.cos(th), pose[1] + r[ok] * np.sin(th)], axis=1)


@pytest.fixture
def room():
    """A 6 m x 4 m room with a pillar."""
    return np.concatenate([box(0, 0, 6, 4), box(4.0, 2.5, 4.4, 2.9)])


@pytest.fixture
def scan_fn():
    return scan_points


@pytest.fixture
def box_fn():
    return box
