"""Your own navigation roles next to the built-in ones, picked by ``module:Class``.

* :class:`WallFollower` — a Driver that sees no truth: it keeps a wall on its right at a set
  distance from the laser scan alone (a proportional controller on the side distance, with a
  stop-and-turn when something is close ahead). ``examples/wall-follower.toml`` runs it.
* :class:`CautiousPursuit` — a Controller: the built-in regulated pure pursuit with a lower
  speed cap, for the ``tour`` operator (``[driver] params.controller``).
* :class:`HuggingDijkstra` — a Planner: the built-in grid Dijkstra without the preference for
  clearance (shortest paths that pass obstacles at the hard limit).
  ``examples/cautious-tour.toml`` runs both with the operator.

Run them with the folder on the import path, e.g.
``PYTHONPATH=examples dynmap-sim run examples/wall-follower.toml --report``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dynmap_sim.agent.control.pure_pursuit import PurePursuit
from dynmap_sim.agent.planning.grid_dijkstra import GridDijkstra
from dynmap_sim.experiments.drivers import Driver, DriverContext, RunStart, StepInput


class WallFollower(Driver):
    """Follow the wall on the right at ``distance_m`` [m] for ``duration_s`` [s]."""

    def __init__(
        self,
        context: DriverContext,
        distance_m: float = 0.6,
        gain_radps_per_m: float = 1.5,
        stop_ahead_m: float = 0.5,
        duration_s: float = 60.0,
    ) -> None:
        super().__init__(context)
        self.distance_m = distance_m
        self.gain = gain_radps_per_m
        self.stop_ahead_m = stop_ahead_m
        self.duration_s = duration_s
        self.angles_rad = context.laser.angles()  # beam angles in the laser frame
        self._elapsed_s = 0.0

    def begin_run(self, start: RunStart) -> None:
        self.events = []
        self._elapsed_s = 0.0

    @property
    def done(self) -> bool:
        return self._elapsed_s >= self.duration_s

    def act(self, step: StepInput) -> np.ndarray:
        self._elapsed_s += self.context.dt_s
        r = np.asarray(step.scan.ranges_m, dtype=np.float64)
        r = np.where(np.isfinite(r), r, 10.0)  # no return: far away
        angles = self.angles_rad
        ahead = r[np.abs(angles) < 0.3].min()
        right = r[np.abs(angles + math.pi / 2) < 0.2].min()
        if ahead < self.stop_ahead_m:  # something close ahead: turn left on the spot
            return np.array([0.0, 0.6], dtype=np.float32)
        omega = float(np.clip(self.gain * (self.distance_m - right), -0.8, 0.8))
        return np.array([self.context.speed_mps, omega], dtype=np.float32)


class CautiousPursuit(PurePursuit):
    """Regulated pure pursuit never faster than ``max_speed_mps`` [m/s]."""

    def __init__(
        self, speed_mps: float, min_clearance_m: float, max_speed_mps: float = 0.2, **params: Any
    ) -> None:
        super().__init__(min(speed_mps, max_speed_mps), min_clearance_m, **params)


class HuggingDijkstra(GridDijkstra):
    """Grid Dijkstra whose preferred clearance is the hard limit: the shortest paths."""

    def __init__(self, min_clearance_m: float, preferred_clearance_m: float) -> None:
        super().__init__(min_clearance_m, min_clearance_m)
