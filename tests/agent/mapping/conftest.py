"""Synthetic worlds for the mapping tests: a few wall segments and an exact ray caster."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_scans import LASER, polyline_path, raycast, room_segments

from dynmap_sim.types import LaserSpec


@pytest.fixture
def laser() -> LaserSpec:
    """A URG-04LX-like scanner with fewer beams (240 degrees, 5.6 m)."""
    return LASER


@pytest.fixture
def segments() -> np.ndarray:
    return room_segments()


@pytest.fixture
def cast():
    """The exact ray caster :func:`raycast` as a fixture."""
    return raycast


def loop_path(step_m: float = 0.05, turn_rad: float = 0.1, laps: int = 2) -> np.ndarray:
    """True poses ``(T, 3)`` along a rectangle around the pillar, turning in place at corners."""
    corners = np.array([[1.0, 1.0], [4.0, 1.0], [4.0, 3.8], [1.0, 3.8]])
    return polyline_path(np.tile(corners, (laps, 1)), step_m, turn_rad)


def drifting_odometry(truth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Odometry poses ``(T, 3)`` with systematic scale/heading drift and noise (odom frame)."""
    from dynmap_sim import se2

    odo = [np.zeros(3)]
    for k in range(1, len(truth)):
        d = se2.between(truth[k - 1], truth[k])
        dist = np.hypot(d[0], d[1])
        dn = d * np.array([1.02, 1.02, 1.03])
        dn[2] += 0.03 * dist + rng.normal(0, 0.002)
        dn[:2] += rng.normal(0, 0.002, 2)
        odo.append(se2.compose(odo[-1], dn))
    return np.array(odo)


@pytest.fixture
def path_fn():
    return loop_path


@pytest.fixture
def odo_fn():
    return drifting_odometry
