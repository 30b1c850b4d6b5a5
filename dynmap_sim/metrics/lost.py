"""Lost and recovered: episodes of position error above a threshold (docs/architecture.md §6).

A localizer is *lost* at a scan when its position error exceeds ``threshold_m`` (0.5 m by
default). A lost episode is a maximal stretch of consecutive lost scans; it is *recovered*
when a scan that is not lost follows it within the same sequence, and its time to recover is
the time from its first lost scan to that first good scan.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.metrics.result import Result

#: Position error above which a localizer counts as lost [m].
LOST_THRESHOLD_M = 0.5


def lost_fraction(errors_m: ArrayLike, threshold_m: float = LOST_THRESHOLD_M) -> float:
    """Share of the scans whose position error exceeds ``threshold_m`` (NaN counts as lost;
    NaN for no scans)."""
    e = np.asarray(errors_m, dtype=np.float64).ravel()
    return float(np.mean(~(e <= threshold_m))) if e.size else float("nan")


@dataclass(frozen=True, eq=False)
class LostStats(Result):
    """Lost/recovered summary of one sequence (e.g. a run)."""

    n_scans: int
    lost_fraction: float
    n_episodes: int
    n_recovered: int
    mean_time_to_recover_s: float
    max_time_to_recover_s: float


def lost_episodes(lost: ArrayLike) -> NDArray[np.int64]:
    """``(E, 2)`` start and end (exclusive) indices of the runs of True in ``lost``."""
    flags = np.asarray(lost, dtype=bool).ravel()
    padded = np.concatenate([[False], flags, [False]]).astype(np.int8)
    d = np.diff(padded)
    starts = np.flatnonzero(d == 1)
    ends = np.flatnonzero(d == -1)
    return np.stack([starts, ends], axis=1).astype(np.int64)


def lost_stats(
    errors_m: ArrayLike, t_s: ArrayLike, threshold_m: float = LOST_THRESHOLD_M
) -> LostStats:
    """Lost fraction, episodes and recovery times of position errors ``errors_m`` at times
    ``t_s`` [s] (same length). NaN errors count as lost (no estimate is as bad as a wrong one).
    """
    e = np.asarray(errors_m, dtype=np.float64).ravel()
    t = np.asarray(t_s, dtype=np.float64).ravel()
    if e.shape != t.shape:
        raise ValueError(f"errors {e.shape} and times {t.shape} differ in shape")
    n = int(e.size)
    if n == 0:
        nan = float("nan")
        return LostStats(0, nan, 0, 0, nan, nan)
    lost = ~(e <= threshold_m)
    eps = lost_episodes(lost)
    recovered = eps[eps[:, 1] < n]
    times = t[recovered[:, 1]] - t[recovered[:, 0]]
    return LostStats(
        n_scans=n,
        lost_fraction=float(lost.mean()),
        n_episodes=int(len(eps)),
        n_recovered=int(len(recovered)),
        mean_time_to_recover_s=float(times.mean()) if times.size else float("nan"),
        max_time_to_recover_s=float(times.max()) if times.size else float("nan"),
    )
