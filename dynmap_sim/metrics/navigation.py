"""Navigation measures of a run and of a day, from the truth (the robot never sees these).

* :func:`clearances` — the true clearance of the robot's disc to segments and discs [m];
* :func:`nav_run_summary` — one run (:class:`NavRunSummary`): goal reached, time, path length,
  SPL, collisions, near misses with people, minimum clearance, and the driver's own counts
  (replans, recoveries, time stuck);
* :func:`nav_day_summary` — the runs of a day (:class:`NavDaySummary`, ``nav_per_day.csv``).

SPL is "success weighted by (normalized inverse) path length" (Anderson et al. 2018, "On
Evaluation of Embodied Navigation Agents", eq. 1): ``S * l / max(p, l)`` with ``S`` 1 when the
goal was reached, ``l`` the shortest path's length and ``p`` the length driven; a day's SPL is
the mean over its runs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.metrics.result import Result
from dynmap_sim.metrics.summaries import n_onsets

#: The goal counts as reached within this distance of the route's end [m] ...
GOAL_REACHED_M = 0.5
#: ... after this share of the route was followed (the env's own test is stricter: 0.3 m).
GOAL_PROGRESS = 0.95

#: :func:`route_progress_with_detours`: the robot is back on the route within this distance of
#: it [m] (the env's progress tracker has no such notion: it follows the route only segment
#: by segment, at most 2 m per step, so a detour that rejoins farther ahead stalls it).
REJOIN_M = 0.5
#: ... and a rejoin may skip at most this share of the route's length (the blocked stretch a
#: detour went round). Less than the share between a loop's start and its end, so a robot at a
#: loop's start is never taken to be at its end.
MAX_SKIP_FRACTION = 0.3

#: A person closer than this to the robot's disc [m] is a near miss (issue 15; the distance
#: at which nav2's Collision Monitor examples slow down for an obstacle).
NEAR_MISS_M = 0.3

FloatArray = NDArray[np.float64]


def clearances(
    xy: ArrayLike, radius_m: float, segments: ArrayLike, circles: ArrayLike
) -> FloatArray:
    """Distance [m] from the robot's disc (centre ``xy`` ``(2,)`` or ``(T, 2)``, radius
    ``radius_m``) to the nearest of ``segments`` ``(N, 4)`` and discs ``circles`` ``(M, 3)``
    ``x, y, r``; negative when overlapping, ``inf`` with nothing around. Shape ``(T,)``."""
    p = np.atleast_2d(np.asarray(xy, dtype=np.float64))[:, :2]
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    cir = np.asarray(circles, dtype=np.float64).reshape(-1, 3)
    best = np.full(len(p), np.inf)
    if len(seg):
        _, d = _project(p, seg[:, :2], seg[:, 2:] - seg[:, :2])
        best = np.minimum(best, d.min(axis=1))
    if len(cir):
        d = np.hypot(*(p[:, None, :] - cir[None, :, :2]).transpose(2, 0, 1)) - cir[None, :, 2]
        best = np.minimum(best, d.min(axis=1))
    return best - float(radius_m)


def _project(p: FloatArray, a: FloatArray, ab: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Points ``p`` ``(T, 2)`` onto segments ``a + u ab`` (``(S, 2)`` each): the clamped
    parameters ``u`` and the distances [m], both ``(T, S)``."""
    ab2 = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18)
    ap = p[:, None, :] - a[None]
    u = np.clip(np.einsum("tij,ij->ti", ap, ab) / ab2, 0.0, 1.0)
    return u, np.hypot(*(ap - u[..., None] * ab[None]).transpose(2, 0, 1))


def goal_reached(
    env_terminated: bool,
    route_progress: float,
    end_distance_m: float,
    track_xy: ArrayLike | None = None,
    route: ArrayLike | None = None,
) -> bool:
    """The run's goal, the end of its route, was reached (by the truth): the env ended the
    episode at the route's end, or the robot followed :data:`GOAL_PROGRESS` of the route and
    stopped within :data:`GOAL_REACHED_M` of its end. ``route_progress`` is the env's share;
    given the true track ``track_xy`` and the ``route``, a run that stopped at the end with
    less is judged again by :func:`route_progress_with_detours` (the env's tracker stalls
    behind a detour that rejoins the route farther ahead)."""
    if env_terminated:
        return True
    if end_distance_m > GOAL_REACHED_M:
        return False
    if route_progress >= GOAL_PROGRESS:
        return True
    if track_xy is None or route is None:
        return False
    return route_progress_with_detours(track_xy, route) >= GOAL_PROGRESS


def route_progress_with_detours(
    xy: ArrayLike,
    route: ArrayLike,
    rejoin_m: float = REJOIN_M,
    max_skip_fraction: float = MAX_SKIP_FRACTION,
    local_m: float = 2.0,
) -> float:
    """Share of ``route`` ``(K, 2)`` followed by the true track ``xy`` ``(T, 2+)`` [0..1], a
    detour around a block counting as followed. Each step the progress moves to the nearest
    route position ahead of it that lies within ``rejoin_m`` of the robot: at most
    ``local_m`` [m] ahead while the robot is on the route within ``local_m`` of its progress
    (as the env's tracker, which gains at most 2 m a step), at most ``max_skip_fraction`` of
    the route ahead when it is off it (a detour rejoining); none: it stays. The nearest
    position ahead, and the local reach while on the route, keep a place the route passes
    twice (a corridor driven out and back) on the pass being driven."""
    pts = np.asarray(route, dtype=np.float64).reshape(-1, 2)
    track = np.asarray(xy, dtype=np.float64).reshape(-1, np.shape(xy)[-1] if np.ndim(xy) else 2)
    if len(pts) < 2 or len(track) == 0:
        return 1.0 if len(pts) < 2 else 0.0
    a, ab = pts[:-1], np.diff(pts, axis=0)
    seg_len = np.hypot(*ab.T)
    total = float(seg_len.sum())
    if total <= 0.0:
        return 1.0
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])[:-1]
    u, dist = _project(track[:, :2], a, ab)  # (T, S)
    pos = cum[None] + u * seg_len[None]  # route position of each projection [m]
    near = dist <= rejoin_m
    max_skip = max_skip_fraction * total
    progress = 0.0
    for t in range(len(track)):
        on, p_t = near[t], pos[t]
        # on the route near the progress: follow it locally; off it (a detour): rejoin ahead
        here = np.any(on & (p_t >= progress - local_m) & (p_t <= progress + local_m))
        reach = local_m if here else max_skip
        cand = p_t[on & (p_t > progress) & (p_t <= progress + reach)]
        if cand.size:
            progress = float(cand.min())
    return min(1.0, progress / total)


def path_length_m(xy: ArrayLike) -> float:
    """Length of a polyline ``(T, 2+)`` [m]."""
    a = np.asarray(xy, dtype=np.float64).reshape(-1, np.shape(xy)[-1] if np.ndim(xy) else 2)
    return float(np.hypot(*np.diff(a[:, :2], axis=0).T).sum()) if len(a) > 1 else 0.0


def spl(success: bool, shortest_m: float, driven_m: float) -> float:
    """SPL of one episode (Anderson et al. 2018, eq. 1); NaN when the shortest path is unknown."""
    if not math.isfinite(shortest_m):
        return math.nan
    if not success:
        return 0.0
    return float(shortest_m / max(driven_m, shortest_m, 1e-12))


@dataclass(frozen=True, eq=False)
class NavRunSummary(Result):
    """One run's navigation: ``goal_reached`` (0/1), ``time_s`` (robot time), ``path_length_m``
    (driven, true), ``shortest_path_m`` (from start to goal around the run's true obstacles;
    NaN unknown), ``spl``, ``collisions`` (bumper onsets), ``near_misses`` (onsets of a person
    within :data:`NEAR_MISS_M`), ``min_clearance_m`` (to any obstacle, people included),
    ``replans``, ``recoveries``, ``stuck_s`` (the driver's counts; 0 for a driver that has
    none), ``gave_up`` (0/1)."""

    goal_reached: int
    time_s: float
    path_length_m: float
    shortest_path_m: float
    spl: float
    collisions: int
    near_misses: int
    min_clearance_m: float
    replans: int
    recoveries: int
    stuck_s: float
    gave_up: int


def nav_run_summary(
    truth: ArrayLike,
    t_s: ArrayLike,
    collision: ArrayLike,
    clearance_m: ArrayLike,
    person_clearance_m: ArrayLike,
    goal_reached: bool,
    shortest_path_m: float,
    driver_stats: dict[str, float] | None = None,
) -> NavRunSummary:
    """The run's :class:`NavRunSummary` from per-scan arrays: true poses ``(T, 3)``, stamps
    ``(T,)`` [s], bumper flags ``(T,)``, the true clearance to any obstacle and to the nearest
    person ``(T,)`` [m] (:func:`clearances`), and the driver's counts (``replans``,
    ``recoveries``, ``stuck_s``, ``gave_up``)."""
    pose = np.asarray(truth, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(t_s, dtype=np.float64)
    clear = np.asarray(clearance_m, dtype=np.float64)
    person = np.asarray(person_clearance_m, dtype=np.float64)
    stats = driver_stats or {}
    driven = path_length_m(pose)
    return NavRunSummary(
        goal_reached=int(bool(goal_reached)),
        time_s=float(t[-1] - t[0]) if len(t) else 0.0,
        path_length_m=driven,
        shortest_path_m=float(shortest_path_m),
        spl=spl(bool(goal_reached), float(shortest_path_m), driven),
        collisions=n_onsets(np.asarray(collision, dtype=bool)),
        near_misses=n_onsets(person < NEAR_MISS_M),
        min_clearance_m=float(clear.min()) if len(clear) else math.nan,
        replans=int(stats.get("replans", 0)),
        recoveries=int(stats.get("recoveries", 0)),
        stuck_s=float(stats.get("stuck_s", 0.0)),
        gave_up=int(bool(stats.get("gave_up", 0))),
    )


@dataclass(frozen=True, eq=False)
class NavDaySummary(Result):
    """A day's runs: ``runs``, ``goal_reached_fraction``, totals of ``collisions``,
    ``near_misses``, ``replans``, ``recoveries``, ``stuck_s``, the smallest
    ``min_clearance_m``, and means of ``path_length_m``, ``spl`` (NaN runs left out) and
    ``time_s`` per run."""

    runs: int
    goal_reached_fraction: float
    collisions: int
    near_misses: int
    min_clearance_m: float
    replans: int
    recoveries: int
    path_length_m: float
    spl: float
    time_s: float
    stuck_s: float


def nav_day_summary(runs: Sequence[NavRunSummary]) -> NavDaySummary:
    """Summary of a day's :class:`NavRunSummary` rows (NaN means with no runs)."""
    n = len(runs)

    def mean(vals: list[float]) -> float:
        v = [x for x in vals if math.isfinite(x)]
        return float(np.mean(v)) if v else math.nan

    return NavDaySummary(
        runs=n,
        goal_reached_fraction=mean([float(r.goal_reached) for r in runs]),
        collisions=sum(r.collisions for r in runs),
        near_misses=sum(r.near_misses for r in runs),
        min_clearance_m=min((r.min_clearance_m for r in runs), default=math.nan),
        replans=sum(r.replans for r in runs),
        recoveries=sum(r.recoveries for r in runs),
        path_length_m=mean([r.path_length_m for r in runs]),
        spl=mean([r.spl for r in runs]),
        time_s=mean([r.time_s for r in runs]),
        stuck_s=float(sum(r.stuck_s for r in runs)),
    )
