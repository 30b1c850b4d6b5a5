"""Localizers for the point-class truth tests: they report fixed point classes, so what the
store holds against the seen-before truth is the truth's own distribution."""

from __future__ import annotations

import numpy as np

from dynmap_sim.agent.localization.dead_reckoning import DeadReckoning as OdometryLocalizer
from dynmap_sim.types import PoseEstimate


class EverythingSemistatic(OdometryLocalizer):
    """Dead reckoning that calls every valid reading semi-static (code 2) and the others
    unknown: the confusion's column 2 is then the truth of the valid readings."""

    def update(self, odom, scan):
        e = super().update(odom, scan)
        pc = np.where(np.isfinite(scan.ranges_m), 2, 0).astype(np.int8)
        return PoseEstimate(mean=e.mean, cov=e.cov, extras={"point_classes": pc})


class WithLongTermMap(EverythingSemistatic):
    """As :class:`EverythingSemistatic`, and leaves a long-term map after each day the way
    H&W's model does: ten 50 mm slots of log-odds, the current one and the grid's origin."""

    def begin_run(self, prior):
        super().begin_run(prior)
        self._day = prior.day

    def day_artifacts(self):
        grid = np.full((10, 40, 30), -2.0)
        grid[self._day % 10, 5:35, 10] = 3.0  # a "wall" in the current slot
        return {
            "ltm": {
                "grids": grid,
                "current_slot": np.array(self._day % 10),
                "origin_m": np.array([0.5, 1.0]),
                "resolution_m": np.array(0.05),
            }
        }
