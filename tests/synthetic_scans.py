"""Synthetic geometry for agent-side tests: an exact numpy ray caster over a few segments.

Tests of ``dynmap_sim/agent`` and ``dynmap_sim/io`` use this instead of the simulator, so they
check the algorithms on closed-form geometry. Importable from any test (``pythonpath`` in
``pyproject.toml``).
"""

from __future__ import annotations

import numpy as np

from dynmap_sim.types import LaserSpec

#: A URG-04LX-like laser with its field of view but every third beam (241 beams).
LASER = LaserSpec(
    name="test-urg",
    n_beams=241,
    angle_min_rad=-2.0862,
    angle_increment_rad=(2.0923 + 2.0862) / 240,
    range_min_m=0.02,
    range_max_m=5.6,
    scan_period_s=0.1,
    time_increment_s=0.0,
)


def raycast(pose: np.ndarray, angles: np.ndarray, segs: np.ndarray, max_range: float) -> np.ndarray:
    """Exact ranges from ``pose`` along ``angles`` (robot frame) to the segments (+inf: none)."""
    th = pose[2] + angles
    d = np.stack([np.cos(th), np.sin(th)], axis=1)  # (B, 2)
    p0 = segs[:, :2]
    e = segs[:, 2:] - p0  # (S, 2)
    w = p0 - pose[:2]  # (S, 2)
    den = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]  # (B, S)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[None, :, 0] * e[None, :, 1] - w[None, :, 1] * e[None, :, 0]) / den
        u = (w[None, :, 0] * d[:, None, 1] - w[None, :, 1] * d[:, None, 0]) / den
    hit = (np.abs(den) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
    r = np.where(hit, t, np.inf).min(axis=1)
    r[r > max_range] = np.inf
    return r


def box(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    """The four sides of an axis-aligned rectangle as segments ``(4, 4)``."""
    c = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)
    return np.concatenate([c, np.roll(c, -1, axis=0)], axis=1)


def room_segments(cupboard: bool = True) -> np.ndarray:
    """An L-shaped 8 m x 6 m room with a pillar, a box and (optionally) a cupboard."""
    pts = np.array([[0, 0], [8, 0], [8, 3], [5, 3], [5, 6], [0, 6]], float)
    walls = np.concatenate([pts, np.roll(pts, -1, axis=0)], axis=1)
    parts = [walls, box(2.0, 2.0, 2.4, 2.4)]
    if cupboard:
        parts.append(np.array([[6.5, 0.0, 6.5, 0.6], [6.5, 0.6, 7.3, 0.6], [7.3, 0.6, 7.3, 0.0]]))
    parts.append(np.array([[1.0, 4.5, 1.8, 4.5], [1.8, 4.5, 1.8, 5.0], [1.8, 5.0, 1.0, 5.0]]))
    return np.concatenate(parts)
