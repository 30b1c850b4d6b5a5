"""The live state of the people of a run (:class:`Crowd`) and how many are present."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.world.polygons import FloatArray


def profile_fraction(profile: tuple[tuple[float, float], ...], time_s: float) -> float:
    """Fraction of a population present at ``time_s`` seconds since midnight."""
    hours = np.array([h for h, _ in profile])
    frac = np.array([f for _, f in profile])
    return float(np.interp(time_s / 3600.0, hours, frac))


@dataclass
class Crowd:
    """Live state of all people of a run. Arrays have one row per person."""

    pos: FloatArray
    vel: FloatArray
    goal: FloatArray
    v0: FloatArray
    radius: FloatArray
    population: NDArray[np.int64]
    phase: FloatArray
    stuck_s: FloatArray
    ids: tuple[str, ...]
    waypoint: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    """Index of the route waypoint each person heads for (-1: no route, free goals)."""
    best_goal_m: FloatArray = field(default_factory=lambda: np.zeros(0))
    """Closest each person has come to its current goal [m] (progress for stuck detection)."""

    @property
    def n(self) -> int:
        """Number of people."""
        return len(self.pos)
