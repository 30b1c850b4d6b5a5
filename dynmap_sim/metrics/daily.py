"""Per-group summaries (per run, per day) of per-scan values (H&W §7, Fig. 7: the mean
localization error per day)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from dynmap_sim.metrics.lost import LOST_THRESHOLD_M, lost_fraction
from dynmap_sim.metrics.result import Result


@dataclass(frozen=True, eq=False)
class GroupSummary(Result):
    """Summary of one group of scans (one run or one day) for one localizer.

    ``mean_scan_loglik`` and ``mean_lambda_min`` are NaN when the localizer reports none.
    """

    n_scans: int
    mean_error_m: float
    max_error_m: float
    rmse_m: float
    lost_fraction: float
    mean_heading_error_rad: float
    mean_scan_loglik: float
    mean_lambda_min: float


def _nanmean(a: np.ndarray) -> float:
    a = a[np.isfinite(a)]
    return float(a.mean()) if a.size else float("nan")


def summarize(
    errors_m: ArrayLike,
    heading_errors_rad: ArrayLike | None = None,
    scan_loglik: ArrayLike | None = None,
    lambda_min: ArrayLike | None = None,
    lost_threshold_m: float = LOST_THRESHOLD_M,
) -> GroupSummary:
    """Mean / max / RMSE of position errors, lost fraction, and the means of optional extras
    (NaN entries mean "not reported" and are skipped)."""
    e = np.asarray(errors_m, dtype=np.float64).ravel()
    nan = float("nan")
    if e.size == 0:
        return GroupSummary(0, nan, nan, nan, nan, nan, nan, nan)
    finite = e[np.isfinite(e)]
    h = (
        np.asarray(heading_errors_rad, dtype=np.float64).ravel()
        if heading_errors_rad is not None
        else np.full(e.size, np.nan)
    )
    return GroupSummary(
        n_scans=int(e.size),
        mean_error_m=float(finite.mean()) if finite.size else nan,
        max_error_m=float(finite.max()) if finite.size else nan,
        rmse_m=float(np.sqrt(np.mean(finite**2))) if finite.size else nan,
        lost_fraction=lost_fraction(e, lost_threshold_m),
        mean_heading_error_rad=_nanmean(h),
        mean_scan_loglik=_nanmean(np.asarray(scan_loglik, dtype=np.float64).ravel())
        if scan_loglik is not None
        else nan,
        mean_lambda_min=_nanmean(np.asarray(lambda_min, dtype=np.float64).ravel())
        if lambda_min is not None
        else nan,
    )


def summarize_groups(
    keys: ArrayLike,
    errors_m: ArrayLike,
    heading_errors_rad: ArrayLike | None = None,
    scan_loglik: ArrayLike | None = None,
    lambda_min: ArrayLike | None = None,
) -> dict[int, GroupSummary]:
    """:func:`summarize` for each distinct integer key (e.g. the day of every scan)."""
    k = np.asarray(keys).ravel()
    e = np.asarray(errors_m, dtype=np.float64).ravel()

    def pick(a: ArrayLike | None, m: np.ndarray) -> np.ndarray | None:
        return None if a is None else np.asarray(a, dtype=np.float64).ravel()[m]

    out: dict[int, GroupSummary] = {}
    for key in np.unique(k):
        m = k == key
        out[int(key)] = summarize(
            e[m], pick(heading_errors_rad, m), pick(scan_loglik, m), pick(lambda_min, m)
        )
    return out
