"""Synthetic scans for the map tests: ray casting a few segments in numpy."""

from __future__ import annotations

import numpy as np
import pytest


def raycast(pose: np.ndarray, angles: np.ndarray, segs: np.ndarray, max_range: float) -> np.ndarray:
    """Exact ranges from ``pose`` along ``angles`` (robot frame) to the segments (+inf: none)."""
    th = pose[2] + angles
    d = np.stack([np.cos(th), np.sin(th)], axis=1)
    p0 = segs[:, :2]
    e = segs[:, 2:] - p0
    w = p0 - pose[:2]
    den = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[None, :, 0] * e[None, :, 1] - w[None, :, 1] * e[None, :, 0]) / den
        u = (w[None, :, 0] * d[:, None, 1] - w[None, :, 1] * d[:, None, 0]) / den
    hit = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
    r = np.where(hit, t, np.inf).min(axis=1)
    r[r > max_range] = np.inf
    return r


def box(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    """The four sides of an axis-aligned rectangle as segments ``(4, 4)``."""
    c = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    return np.concatenate([c, np.roll(c, -1, axis=0)], axis=1)


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
