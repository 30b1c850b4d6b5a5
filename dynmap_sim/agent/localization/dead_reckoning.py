"""``odometry``: dead reckoning, the weakest possible localizer (a floor for comparisons).

It composes the odometry increments onto the initial pose the prior grants; its error is
exactly the odometry drift (Borenstein's systematic E_d / E_b errors plus noise).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dynmap_sim import se2
from dynmap_sim.agent.localization.localizer import Localizer, register_localizer
from dynmap_sim.types import LaserSpec, Odometry, PoseEstimate, Prior, Scan


@register_localizer("odometry")
class DeadReckoning(Localizer):
    """Pose = initial pose ⊕ (odometry since the start of the run).

    The covariance grows linearly with the distance travelled, ``var_per_m`` [m²/m] for
    position and ``var_rad2_per_m`` for heading, a crude but honest uncertainty.
    """

    def __init__(
        self,
        laser: LaserSpec,
        rng: np.random.Generator,
        var_per_m: float = 1e-3,
        var_rad2_per_m: float = 1e-3,
        **params: Any,
    ) -> None:
        super().__init__(laser, rng, **params)
        self.var_per_m = float(var_per_m)
        self.var_rad2_per_m = float(var_rad2_per_m)
        self._origin = np.zeros(3)
        self._odom0: np.ndarray | None = None
        self._last: np.ndarray | None = None
        self._dist_m = 0.0

    def begin_run(self, prior: Prior) -> None:
        self._origin = (
            np.zeros(3) if prior.initial_pose is None else np.asarray(prior.initial_pose, float)
        )
        self._odom0 = None
        self._last = None
        self._dist_m = 0.0

    def update(self, odom: Odometry, scan: Scan) -> PoseEstimate:
        pose = np.asarray(odom.pose, dtype=np.float64)
        if self._odom0 is None:
            self._odom0 = pose.copy()
            self._last = pose.copy()
        self._dist_m += float(np.hypot(*(pose[:2] - self._last[:2])))
        self._last = pose.copy()
        mean = se2.compose(self._origin, se2.between(self._odom0, pose))
        cov = np.diag(
            [self.var_per_m * self._dist_m] * 2 + [self.var_rad2_per_m * self._dist_m]
        ) + np.diag([1e-6, 1e-6, 1e-6])
        return PoseEstimate(mean=mean, cov=cov)
