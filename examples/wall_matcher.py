"""A user's own localizer, plugged in by ``module:Class`` (no change to dynmap_sim needed).

``WallMatcher`` predicts with odometry and corrects every ``every_n`` scans by matching the
scan against the wall segments the scenario grants (``[prior] map = "walls"``) with the
package's point-to-line ICP, using the odometry prediction as a Gaussian prior. Furniture and
people are outliers to it, so it shows how far the bare walls carry a localizer.

Run it (from the repository root)::

    PYTHONPATH=examples dynmap-sim run examples/wall-matcher.toml --report
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dynmap_sim import se2
from dynmap_sim.agent.localization.localizer import Localizer
from dynmap_sim.agent.mapping.scan_matcher import PointMap, match_scan
from dynmap_sim.agent.mapping.scan_points import scan_points_base
from dynmap_sim.types import LaserSpec, Odometry, PoseEstimate, Prior, Scan


def sample_segments(segments: np.ndarray, spacing_m: float) -> np.ndarray:
    """Points every ``spacing_m`` along segments ``(N, 4)``."""
    pts = []
    for x0, y0, x1, y1 in np.asarray(segments, float):
        n = max(2, int(np.ceil(np.hypot(x1 - x0, y1 - y0) / spacing_m)) + 1)
        u = np.linspace(0.0, 1.0, n)[:, None]
        pts.append(np.array([x0, y0]) + u * np.array([x1 - x0, y1 - y0]))
    return np.concatenate(pts)


class WallMatcher(Localizer):
    """Odometry prediction + ICP against the known walls every ``every_n`` scans."""

    def __init__(
        self,
        laser: LaserSpec,
        rng: np.random.Generator,
        every_n: int = 5,
        odom_sigma_per_m: float = 0.05,
        **params: Any,
    ) -> None:
        super().__init__(laser, rng, **params)
        self.every_n = int(every_n)
        self.odom_sigma_per_m = float(odom_sigma_per_m)
        self.target: PointMap | None = None
        self.pose = np.zeros(3)
        self.cov = np.eye(3) * 1e-4
        self.last_odom: np.ndarray | None = None
        self.n = 0

    def begin_run(self, prior: Prior) -> None:
        if prior.walls is None or prior.initial_pose is None:
            raise ValueError("WallMatcher needs [prior] map = 'walls' and a known initial pose")
        if self.target is None:
            self.target = PointMap(sample_segments(prior.walls, 0.05))
        self.pose = np.asarray(prior.initial_pose, dtype=np.float64).copy()
        self.cov = (
            np.asarray(prior.initial_pose_cov, float)
            if prior.initial_pose_cov is not None
            else np.eye(3) * 1e-4
        )
        self.last_odom = None
        self.n = 0

    def update(self, odom: Odometry, scan: Scan) -> PoseEstimate:
        o = np.asarray(odom.pose, dtype=np.float64)
        if self.last_odom is not None:
            delta = se2.between(self.last_odom, o)
            self.pose = se2.compose(self.pose, delta)
            step_m = float(np.hypot(delta[0], delta[1])) + 0.2 * abs(float(delta[2]))
            self.cov = self.cov + np.eye(3) * (self.odom_sigma_per_m * step_m) ** 2 + 1e-8
        self.last_odom = o
        self.n += 1
        if self.target is not None and self.n % self.every_n == 0:
            pts = scan_points_base(self.laser, scan.ranges_m)
            if len(pts) >= 20:
                res = match_scan(
                    pts,
                    self.target,
                    self.pose,
                    prior_mean=self.pose,
                    prior_info=np.linalg.inv(self.cov),
                    max_correspondence_m=0.3,
                )
                if res.converged and res.n_matched >= 20:
                    self.pose, self.cov = res.pose, res.cov
        return PoseEstimate(mean=self.pose.copy(), cov=self.cov.copy())
