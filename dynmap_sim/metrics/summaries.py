"""The summaries an experiment stores and reports: per run, per day and overall, per localizer.

Every number of ``run_summaries``, ``day_summaries``, the per-scan errors of ``estimates``,
``summary.md``'s overall table and the ``[expectations]`` checks comes from here:

* :func:`scan_errors` — the per-scan position and heading errors (the ``estimates`` rows);
* :func:`run_summary` — one run of one localizer (:class:`RunSummary`);
* :func:`day_summary` — all scans of one day of one localizer (:class:`DaySummary`);
* :func:`overall_summary` — a whole experiment of one localizer, evaluated run by run (lost
  episodes and RPE pairs never span two runs) (:class:`OverallSummary`).

Results are frozen dataclasses with ``to_dict``/``from_dict`` and ``to_json``/``from_json``
that load back equal (:class:`~.result.Result`). All errors are in the map frame without alignment
(:mod:`.pose_error`); a localizer is lost above :data:`~.lost.LOST_THRESHOLD_M`.

A scan whose truth is NaN (a replayed log where no reference pose matched it, or a log with
no ground truth at all) has no error: run and overall summaries score only the scans that
have truth (NaN figures when none has), while ``n_scans`` and the time per scan count all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.metrics.daily import GroupSummary, summarize
from dynmap_sim.metrics.lost import lost_fraction, lost_stats
from dynmap_sim.metrics.pose_error import ate, heading_errors, position_errors, rpe, rpe_label
from dynmap_sim.metrics.result import Result

#: The RPE of run summaries and reports: over 10 poses (1 s at the URG-04LX's 10 Hz, 2 s at
#: the LMS200's 5 Hz; the delta is in frames, so the label says frames).
RUN_RPE_DELTA = 10
#: Unit of :data:`RUN_RPE_DELTA` (see :data:`~.pose_error.RPE_UNITS`).
RUN_RPE_UNIT = "frames"


#: Summary of all scans of one day of one localizer (the ``day_summaries`` rows).
DaySummary = GroupSummary


@dataclass(frozen=True, eq=False)
class RunSummary(GroupSummary):
    """One run of one localizer (a ``run_summaries`` row without its keys): the fields of a
    :class:`DaySummary` over the run's scans, and more.

    Position errors [m] and the lost fraction as in :func:`~.daily.summarize`; lost episodes
    and recoveries as in :func:`~.lost.lost_stats`; ``rpe_m`` the RMSE of the RPE translation
    over :data:`RUN_RPE_DELTA` :data:`RUN_RPE_UNIT`; ``update_ms_per_scan`` the localizer's
    CPU time per ``update()`` (its thread's; NaN when not measured). NaN where undefined."""

    n_lost_episodes: int
    n_recovered: int
    mean_time_to_recover_s: float
    rpe_m: float
    update_ms_per_scan: float


@dataclass(frozen=True, eq=False)
class OverallSummary(Result):
    """A whole experiment of one localizer (``summary.md``'s overall row, the checks).

    ``ate_rmse_m``, ``mean_error_m``, ``max_error_m``: of all position errors (NaN ones
    skipped); ``worst_error_m``: the largest, infinite when a scan has no error (no
    estimate); ``rpe_rmse_m``: RMSE of the RPE translation over all runs' pairs, each run on
    its own, over ``rpe_delta`` ``rpe_unit``; ``lost_fraction`` of all scans; lost episodes,
    recoveries and their mean time summed over the runs; ``worst_time_to_recover_s``: the
    longest time to recover of any run (infinite when an episode never recovers, 0 without
    episodes) and ``worst_recovery_run`` that run's key (empty without episodes)."""

    n_scans: int
    ate_rmse_m: float
    mean_error_m: float
    max_error_m: float
    worst_error_m: float
    mean_heading_error_rad: float
    rpe_rmse_m: float
    rpe_delta: float
    rpe_unit: str
    lost_fraction: float
    lost_episodes: int
    recovered: int
    mean_time_to_recover_s: float
    worst_time_to_recover_s: float
    worst_recovery_run: tuple[int, ...]

    @property
    def rpe_label(self) -> str:
        """``"RPE 10 frames"``: the delta the RPE was taken over."""
        return rpe_label(self.rpe_delta, self.rpe_unit)


def has_truth(truth: ArrayLike) -> NDArray[np.bool_]:
    """``(T,)``: which scans have a truth pose (no NaN in ``truth`` ``(T, 3)``)."""
    return np.isfinite(np.asarray(truth, dtype=np.float64).reshape(-1, 3)).all(axis=1)


def scan_errors(
    truth: ArrayLike, estimate: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Per-scan position error [m] and absolute heading error [rad] of ``estimate``
    ``(T, 3)`` against ``truth`` ``(T, 3)`` (the ``err_m``, ``err_theta_rad`` columns)."""
    return position_errors(truth, estimate), heading_errors(truth, estimate)


def day_summary(
    errors_m: ArrayLike,
    heading_errors_rad: ArrayLike,
    scan_loglik: ArrayLike | None = None,
    lambda_min: ArrayLike | None = None,
) -> DaySummary:
    """:class:`DaySummary` of one day's per-scan errors (and optional per-scan likelihoods
    and certainties; NaN entries are "not reported")."""
    return summarize(errors_m, heading_errors_rad, scan_loglik, lambda_min)


def run_summary(
    truth: ArrayLike,
    estimate: ArrayLike,
    t_s: ArrayLike,
    scan_loglik: ArrayLike | None = None,
    lambda_min: ArrayLike | None = None,
    update_s: float | None = None,
) -> RunSummary:
    """:class:`RunSummary` of one run: truth and estimate ``(T, 3)`` at times ``t_s`` [s],
    the optional per-scan ``scan_loglik`` and ``lambda_min`` (NaN: not reported) and the
    wall time ``update_s`` [s] spent in ``update()``."""
    n = len(np.asarray(t_s).ravel())
    m = has_truth(truth)
    truth = np.asarray(truth, dtype=np.float64).reshape(-1, 3)[m]
    estimate = np.asarray(estimate, dtype=np.float64).reshape(-1, 3)[m]
    t = np.asarray(t_s, dtype=np.float64).ravel()[m]
    err, herr = scan_errors(truth, estimate)
    s = summarize(err, herr, scan_loglik, lambda_min)
    lost = lost_stats(err, t)
    r = rpe(truth, estimate, delta=RUN_RPE_DELTA, unit=RUN_RPE_UNIT, stamps_s=t)
    return RunSummary(
        **(s.to_dict() | {"n_scans": n}),
        n_lost_episodes=lost.n_episodes,
        n_recovered=lost.n_recovered,
        mean_time_to_recover_s=lost.mean_time_to_recover_s,
        rpe_m=r.translation.rmse,
        update_ms_per_scan=1e3 * float(update_s) / n if update_s is not None and n else math.nan,
    )


def overall_summary(
    truth: ArrayLike,
    estimate: ArrayLike,
    t_s: ArrayLike,
    runs: ArrayLike,
    rpe_delta: float = RUN_RPE_DELTA,
    rpe_unit: str = RUN_RPE_UNIT,
) -> OverallSummary:
    """:class:`OverallSummary` of all scans of one localizer: truth and estimate ``(N, 3)``
    at times ``t_s``, ``runs`` the key of each scan's run (``(N,)`` or ``(N, k)``, e.g.
    day and run), scans of a run in time order. Lost episodes, recoveries and RPE pairs are
    taken run by run, in the order of the sorted keys."""
    t = np.asarray(t_s, dtype=np.float64).ravel()
    truth = np.asarray(truth, dtype=np.float64).reshape(-1, 3)
    est = np.asarray(estimate, dtype=np.float64).reshape(-1, 3)
    keys = np.asarray(runs)
    keys = keys.reshape(len(t), -1) if keys.size else np.zeros((len(t), 1))
    n_all = len(t)
    m = has_truth(truth)
    truth, est, t, keys = truth[m], est[m], t[m], keys[m]
    err, herr = scan_errors(truth, est)
    n_ep = n_rec = 0
    rec_times: list[float] = []
    rpes: list[float] = []
    n_rpe = 0
    worst, worst_run = 0.0, ()
    for key in np.unique(keys, axis=0) if len(keys) else []:
        m = np.all(keys == key, axis=1)
        ls = lost_stats(err[m], t[m])
        n_ep += ls.n_episodes
        n_rec += ls.n_recovered
        if ls.n_recovered:
            rec_times.append(ls.mean_time_to_recover_s * ls.n_recovered)
        v = math.inf if ls.n_recovered < ls.n_episodes else (ls.max_time_to_recover_s or 0.0)
        if ls.n_episodes and (v > worst or not worst_run):
            worst, worst_run = v, tuple(int(x) for x in key)
        r = rpe(truth[m], est[m], delta=rpe_delta, unit=rpe_unit, stamps_s=t[m])
        if r.translation.n:
            rpes.append(r.translation.rmse**2 * r.translation.n)
            n_rpe += r.translation.n
    n = len(err)
    a = ate(truth, est) if n else None
    nan = math.nan
    return OverallSummary(
        n_scans=int(n_all),
        ate_rmse_m=a.rmse if a else nan,
        mean_error_m=a.mean if a else nan,
        max_error_m=a.max if a else nan,
        worst_error_m=(math.inf if np.isnan(err).any() else float(err.max())) if n else nan,
        mean_heading_error_rad=float(np.nanmean(herr)) if n else nan,
        rpe_rmse_m=math.sqrt(sum(rpes) / n_rpe) if n_rpe else nan,
        rpe_delta=rpe_delta,
        rpe_unit=rpe_unit,
        lost_fraction=lost_fraction(err) if n else nan,
        lost_episodes=n_ep,
        recovered=n_rec,
        mean_time_to_recover_s=sum(rec_times) / n_rec if n_rec else nan,
        worst_time_to_recover_s=worst,
        worst_recovery_run=worst_run,
    )


def mean_per_scan(per_run: ArrayLike, n_scans: ArrayLike) -> float:
    """The per-scan mean of per-run means ``per_run`` over runs of ``n_scans`` scans (runs
    with a NaN mean are left out; NaN without any)."""
    v = np.asarray(per_run, dtype=np.float64).ravel()
    n = np.asarray(n_scans, dtype=np.float64).ravel()
    ok = np.isfinite(v)
    total = float(n[ok].sum())
    return float(np.sum(v[ok] * n[ok])) / total if total else math.nan


def n_onsets(flags: ArrayLike) -> int:
    """How many times ``flags`` turns true (a run starting true counts once): e.g. the
    collisions of a run from its per-step collision flags."""
    f = np.asarray(flags, dtype=bool).ravel()
    if f.size == 0:
        return 0
    return int(f[0]) + int(np.count_nonzero(f[1:] & ~f[:-1]))
