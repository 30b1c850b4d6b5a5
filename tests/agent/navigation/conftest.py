"""A robot that drives a polyline at constant speed and tells the route memory (H&W §5.2)."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim.agent.navigation import RouteMemory


def drive(mem: RouteMemory, polyline, speed_mps: float, t0_s: float, dt_s: float = 0.1) -> float:
    """Drive ``polyline (K, 2)`` [m] at ``speed_mps``, observing every ``dt_s``; returns the
    time at the end [s]. Poses are exact (the memory sees what a perfect localizer says)."""
    pts = np.asarray(polyline, float)
    seg = np.diff(pts, axis=0)
    lengths = np.hypot(*seg.T)
    cum = np.concatenate([[0.0], np.cumsum(lengths)])
    n = int(np.floor(cum[-1] / (speed_mps * dt_s) + 1e-9))
    for k in range(n + 1):
        s = k * speed_mps * dt_s
        j = min(int(np.searchsorted(cum, s, side="right")) - 1, len(seg) - 1)
        f = (s - cum[j]) / lengths[j]
        xy = pts[j] + f * seg[j]
        mem.observe([xy[0], xy[1], np.arctan2(seg[j][1], seg[j][0])], t0_s + k * dt_s)
    return t0_s + n * dt_s


@pytest.fixture
def drive_fn():
    return drive
