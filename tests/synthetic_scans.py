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


def polyline_path(corners: np.ndarray, step_m: float, turn_step_rad: float) -> np.ndarray:
    """Poses ``(T, 3)`` driving a closed polyline: turn in place at each corner in steps of at
    most ``turn_step_rad``, then straight to the next corner in steps of ``step_m``."""
    poses, th = [], 0.0
    for c in range(len(corners)):
        a, b = corners[c].astype(float), corners[(c + 1) % len(corners)].astype(float)
        heading = np.arctan2(b[1] - a[1], b[0] - a[0])
        dth = (heading - th + np.pi) % (2 * np.pi) - np.pi
        for k in range(int(np.ceil(abs(dth) / turn_step_rad))):
            th += np.sign(dth) * min(turn_step_rad, abs(dth) - k * turn_step_rad)
            poses.append([a[0], a[1], th])
        th = heading
        n = int(np.hypot(*(b - a)) / step_m)
        poses += [[*(a + (b - a) * (k + 1) / n), th] for k in range(n)]
    return np.array(poses)


def drifting_stream(truth, segs, laser, rng, extra_segments=None):
    """``(Odometry, Scan)`` pairs along ``truth``: odometry with a 2 % scale and 3 % heading
    error plus noise (it drifts), scans with 1 cm noise; ``extra_segments(k)`` adds moving
    geometry (e.g. a walking person) to scan ``k``."""
    from dynmap_sim import se2
    from dynmap_sim.types import Odometry, Scan

    odo = [np.zeros(3)]
    for k in range(1, len(truth)):
        d = se2.between(truth[k - 1], truth[k])
        dn = d * np.array([1.02, 1.02, 1.03])
        dn[2] += 0.03 * np.hypot(d[0], d[1]) + rng.normal(0, 0.002)
        dn[:2] += rng.normal(0, 0.002, 2)
        odo.append(se2.compose(odo[-1], dn))
    out = []
    for k, pose in enumerate(truth):
        s = segs if extra_segments is None else np.concatenate([segs, extra_segments(k)])
        r = raycast(pose, laser.angles(), s, laser.range_max_m)
        r = (r + rng.normal(0, 0.01, r.shape)).astype(np.float32)
        out.append((Odometry(odo[k], 0.1 * k), Scan(r, 0.1 * k)))
    return out
