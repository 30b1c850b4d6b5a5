"""The odometry covariance ``C_O`` "acquired experimentally" (Biber & Duckett 2009, §4.3).

B&D's eq. 9 weighs a scan match against the odometry prediction with a covariance ``C_O``
of the odometry increment that "was acquired experimentally": a property of the robot.
Here it is acquired from a trajectory of the robot known better than its odometry (the poses
of the run a given map was made from, e.g. a log's corrected poses; in the simulator, the
truth of a calibration drive): over every window of ``window`` consecutive scans, the
odometry's increment is compared with the trajectory's, and the errors are expressed per
unit of motion, as ``C_O`` grows:

    e_xy = |Δodom_xy − Δpose_xy| / (d + a/2),    e_θ = |Δodom_θ − Δpose_θ| / (a + d/2)

(``d`` [m] and ``a`` [rad] the trajectory's translation and turn over the window). The
``quantile`` of each over the windows is the rate ``k`` of ``σ = σ0 + k (d + a/2)``.

Choices the paper leaves open (parameters of the callers): a window of 10 scans (1 s at the
URG's 10 Hz), long enough that the trajectory's own per-scan noise (a corrected log's few
centimetres) does not dominate the comparison, short enough that the odometry's systematic
drift does not; the 0.9 quantile, so that eq. 9's two-sigma region holds a correct match in
most windows while a wheel's slip on a few does not widen it; windows with less motion than
``min_motion`` [m + rad] are left out (their ratios divide by nearly nothing). The rates it
gives for the simulated robots and for a real log: ``docs/tuning/localization.md``
(``python benchmarks/odometry_rates.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from dynmap_sim import se2


@dataclass(frozen=True)
class OdometryRates:
    """Odometry error per unit of motion: ``k_xy`` [m per m (+ rad/2)], ``k_th`` [rad per rad
    (+ m/2)], from ``n_windows`` windows."""

    k_xy: float
    k_th: float
    n_windows: int


def odometry_error_rates(
    odometry: ArrayLike,
    poses: ArrayLike,
    window: int = 10,
    quantile: float = 0.9,
    min_motion: float = 0.05,
    min_windows: int = 30,
) -> OdometryRates | None:
    """The odometry's error rates against a trajectory (see the module docstring).

    ``odometry``, ``poses``: ``(N, 3)`` (x, y, θ) of the same ``N`` scans; a pose with NaN
    (unknown, e.g. a reference with gaps) leaves out the windows that start or end at it.
    ``window`` [scans] > 0; ``quantile`` in (0, 1]; ``min_motion``: a window counts when its
    ``d + |a|`` is at least this. ``None`` when fewer than ``min_windows`` windows count.
    """
    odo = np.asarray(odometry, dtype=np.float64).reshape(-1, 3)
    ref = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if len(odo) != len(ref):
        raise ValueError(f"odometry_error_rates: {len(odo)} odometry poses for {len(ref)} poses")
    if int(window) < 1:
        raise ValueError(f"odometry_error_rates: window must be >= 1 scan, got {window!r}")
    if not 0.0 < quantile <= 1.0:
        raise ValueError(f"odometry_error_rates: quantile must be in (0, 1], got {quantile!r}")
    window = int(window)
    if len(ref) <= window:
        return None
    d_odo = se2.between(odo[:-window], odo[window:])  # each window's increment
    d_ref = se2.between(ref[:-window], ref[window:])
    d = np.hypot(d_ref[:, 0], d_ref[:, 1])
    a = np.abs(d_ref[:, 2])
    ok = np.isfinite(d_ref).all(axis=1) & np.isfinite(d_odo).all(axis=1) & (d + a >= min_motion)
    if int(ok.sum()) < min_windows:
        return None
    d, a, d_odo, d_ref = d[ok], a[ok], d_odo[ok], d_ref[ok]
    e_xy = np.hypot(d_odo[:, 0] - d_ref[:, 0], d_odo[:, 1] - d_ref[:, 1]) / (d + 0.5 * a)
    e_th = np.abs(se2.wrap_angle(d_odo[:, 2] - d_ref[:, 2])) / (a + 0.5 * d)
    return OdometryRates(
        k_xy=float(np.quantile(e_xy, quantile)),
        k_th=float(np.quantile(e_th, quantile)),
        n_windows=int(ok.sum()),
    )
