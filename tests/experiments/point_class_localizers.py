"""Localizers for the point-class truth tests: they report fixed point classes, so what the
store holds against the seen-before truth is the truth's own distribution."""

from __future__ import annotations

import numpy as np

from dynmap_sim.agent.dead_reckoning import DeadReckoning as OdometryLocalizer
from dynmap_sim.types import PoseEstimate


class EverythingSemistatic(OdometryLocalizer):
    """Dead reckoning that calls every valid reading semi-static (code 2) and the others
    unknown: the confusion's column 2 is then the truth of the valid readings."""

    def update(self, odom, scan):
        e = super().update(odom, scan)
        pc = np.where(np.isfinite(scan.ranges_m), 2, 0).astype(np.int8)
        return PoseEstimate(mean=e.mean, cov=e.cov, extras={"point_classes": pc})
