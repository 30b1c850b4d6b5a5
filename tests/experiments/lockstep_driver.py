"""A driver that steers on a localizer's estimate (importable by name, also from a spawned
worker): it drives towards a point 1 m ahead of where the estimate says it started, and
keeps every estimate it was handed."""

from __future__ import annotations

import math

import numpy as np

from dynmap_sim.experiments.drivers import Driver


class EstimateFollower(Driver):
    needs_estimate = True

    def __init__(self, context, distance_m: float = 1.0):
        super().__init__(context)
        self.distance_m = distance_m
        self.seen: list[list[float]] = []
        self._goal = None

    def begin_run(self, start):
        self.events = []
        self._goal = None
        self.seen.append([])  # one list per run

    @property
    def done(self):
        return False

    def act(self, step):
        est = np.asarray(step.estimate.mean, dtype=float)
        self.seen[-1].append(est.tolist())
        if self._goal is None:
            self._goal = est[:2] + self.distance_m * np.array([math.cos(est[2]), math.sin(est[2])])
        left = float(np.hypot(*(self._goal - est[:2])))
        return np.array([min(0.3, left), 0.0], dtype=np.float32)
