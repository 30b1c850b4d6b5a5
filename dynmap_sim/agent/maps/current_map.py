"""Current-map synthesis with data-driven timescale selection (Biber & Duckett §4.3).

After the posterior pose of scan ``z_t`` is known, the point set used to localize the next
scan is built as follows:

1. the local maps within ``select_radius_m`` (4 m) of the pose are the *nearby* maps;
2. for each nearby map and each allowed timescale the scan log-likelihood is the sum of the
   per-reading ``log p(d)`` of the perceptual model (eq. 6–8), readings projected to the map's
   centre (§4.2);
3. the (map, timescale) with the best log-likelihood is selected and the map leaves the
   nearby set;
4. readings with a high likelihood under the selected model (``p(d) ≥ explained_density``)
   are removed;
5. repeat from 2 while at least ``min_readings`` (20) readings remain and nearby maps are left;
6. the selected sub-maps become points: medians of rays with ``σ ≤ sigma_max_m`` (5 cm).

If afterwards more than half of the readings have a low likelihood, *safe mode* uses the
most long-term timescale of all nearby maps instead.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.maps.dynamic_map import DynamicMap
from dynmap_sim.jit import compiled

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class SynthesisParams:
    """Thresholds of §4.3 (paper values where the paper gives them)."""

    select_radius_m: float = 4.0
    min_readings: int = 20
    sigma_max_m: float = 0.05
    #: Density [1/m] above which a reading counts as explained ("a threshold is used here").
    explained_density: float = 0.5
    #: Floors of the perceptual model (0 = the paper's model exactly), see ``SampleSets``.
    sigma_min_m: float = 0.01
    min_outlier_ratio: float = 0.0
    #: Lowest per-reading density [1/m] used in sums, so one reading cannot dominate.
    density_floor: float = 1e-3
    #: At most this many readings (evenly subsampled) enter the selection (0 = all).
    max_readings: int = 0


@dataclass
class CurrentMap:
    """The synthesized current map and what the selection did."""

    points: FloatArray
    selections: list[tuple[int, int]] = field(default_factory=list)  # (local map, level)
    safe_mode: bool = False
    scan_loglik: float = float("nan")  # mean per-reading log p under the best selected model
    scan_lik: float = float("nan")  # mean per-reading p (B&D Fig. 10)
    n_readings: int = 0
    n_explained: int = 0

    @property
    def timescale(self) -> int:
        """Level of the first (best-fitting) selection; -1 when nothing was selected."""
        return self.selections[0][1] if self.selections else -1


@compiled
def _select(logp, log_floor, log_explained, min_readings, good, rows, cols):  # type: ignore[no-untyped-def]
    """Steps 2-5: floor ``logp`` ``(M, L, N)`` (reading ``i`` under nearby map ``m`` at level
    ``l``) at ``log_floor`` in place, set ``good = logp >= log_explained`` (the readings each
    model explains), then select (map ``rows[k]``, level ``cols[k]``) with the best sum over
    the readings still unexplained (the first such on a tie), while at least
    ``min_readings`` are unexplained and maps are left; returns how many."""
    n_maps, n_levels, n = logp.shape
    for m in range(n_maps):
        for b in range(n_levels):
            for i in range(n):
                v = logp[m, b, i]
                if v < log_floor:
                    v = log_floor
                    logp[m, b, i] = v
                good[m, b, i] = v >= log_explained
    remaining = np.ones(n, dtype=np.bool_)
    available = np.ones(n_maps, dtype=np.bool_)
    n_remaining = n
    n_chosen = 0
    while n_remaining >= min_readings and n_chosen < n_maps:
        best = -math.inf
        best_k = -1
        for m in range(n_maps):
            if not available[m]:
                continue
            for b in range(n_levels):
                s = 0.0
                for i in range(n):
                    if remaining[i]:
                        s += logp[m, b, i]
                if best_k < 0 or s > best:
                    best = s
                    best_k = m * n_levels + b
        a = best_k // n_levels
        rows[n_chosen] = a
        cols[n_chosen] = best_k - a * n_levels
        n_chosen += 1
        available[a] = False
        n_remaining = 0
        for i in range(n):
            if good[a, best_k - a * n_levels, i]:
                remaining[i] = False
            if remaining[i]:
                n_remaining += 1
    return n_chosen


def select_timescales(
    logp: FloatArray, log_floor: float, log_explained: float, min_readings: int
) -> tuple[NDArray[np.bool_], list[tuple[int, int]]]:
    """``good`` ``(M, L, N)`` and the selections ``[(row of logp, column), ...]`` of
    :func:`_select` (``logp`` C-contiguous, floored in place)."""
    good = np.empty(logp.shape, dtype=np.bool_)
    rows = np.empty(len(logp), dtype=np.int64)
    cols = np.empty(len(logp), dtype=np.int64)
    k = _select(logp, float(log_floor), float(log_explained), int(min_readings), good, rows, cols)
    return good, list(zip(rows[:k].tolist(), cols[:k].tolist(), strict=True))


def synthesize_current_map(
    dmap: DynamicMap,
    pose: FloatArray,
    points_map: FloatArray,
    levels: Sequence[int],
    params: SynthesisParams | None = None,
) -> CurrentMap:
    """Run the §4.3 selection for the scan ``points_map`` (map frame) taken at ``pose``.

    ``levels`` are the timescales allowed (indices into the map's timescales, short to long).
    """
    prm = SynthesisParams() if params is None else params
    levels = sorted(levels)  # ascending: the last one is the most long-term
    nearby = dmap.near(pose, prm.select_radius_m)
    if prm.max_readings > 0 and len(points_map) > prm.max_readings:
        points_map = points_map[:: int(np.ceil(len(points_map) / prm.max_readings))]
    n = len(points_map)
    if nearby.size == 0 or not levels:
        return CurrentMap(points=np.zeros((0, 2)), n_readings=n)
    log_floor = np.log(prm.density_floor)
    # logp[m, l, i]: reading i under nearby map m at level l (all readings, computed once).
    logp = np.empty((nearby.size, len(levels), n))
    # the x and y columns once for all nearby maps (read by the compiled scoring)
    columns = (np.ascontiguousarray(points_map[:, 0]), np.ascontiguousarray(points_map[:, 1]))
    for a, i in enumerate(nearby.tolist()):
        dmap.local_maps[i].scan_log_likelihoods(
            levels,
            points_map,
            sigma_min_m=prm.sigma_min_m,
            min_outlier_ratio=prm.min_outlier_ratio,
            out=logp[a],
            columns=columns,
        )
    good, chosen = select_timescales(logp, log_floor, np.log(prm.explained_density),
                                     prm.min_readings)  # fmt: skip
    if chosen:
        rows = np.array([a for a, _ in chosen])
        cols = np.array([b for _, b in chosen])
        explained = good[rows, cols].any(axis=0)
        best = logp[rows, cols].max(axis=0)
    else:
        explained = np.zeros(n, dtype=bool)
        best = np.full(n, log_floor)
    safe = n > 0 and (~explained).sum() > 0.5 * n
    if safe:
        col = len(levels) - 1  # the most long-term allowed timescale
        chosen = [(a, col) for a in range(nearby.size)]
        best = logp[:, col].max(axis=0)
        explained = good[:, col].any(axis=0)
    pts = [dmap.local_maps[int(nearby[a])].points(levels[b], prm.sigma_max_m) for a, b in chosen]
    return CurrentMap(
        points=np.concatenate(pts) if pts else np.zeros((0, 2)),
        selections=[(int(nearby[a]), levels[b]) for a, b in chosen],
        safe_mode=bool(safe),
        scan_loglik=float(best.mean()) if n else float("nan"),
        scan_lik=float(np.exp(best).mean()) if n else float("nan"),
        n_readings=n,
        n_explained=int(explained.sum()),
    )
