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

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.maps.current_map_numba import select_timescales
from dynmap_sim.agent.maps.dynamic_map import DynamicMap
from dynmap_sim.jit import kernel_backend

FloatArray = NDArray[np.float64]


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


def _select_numpy(
    logp: FloatArray, log_floor: float, prm: SynthesisParams
) -> tuple[NDArray[np.bool_], list[tuple[int, int]]]:
    """Steps 2-5 on ``logp[m, l, i]`` (floored in place): the readings each model explains
    and the selections (row of ``logp``, column) in order."""
    np.maximum(logp, log_floor, out=logp)
    good = logp >= np.log(prm.explained_density)
    n = logp.shape[2]
    remaining = np.ones(n, dtype=bool)
    n_remaining = n
    available = np.ones(len(logp), dtype=bool)
    chosen: list[tuple[int, int]] = []  # (row in nearby, column in levels)
    while n_remaining >= prm.min_readings and len(chosen) < len(logp):
        # (maps, levels); all readings: logp itself, the same contiguous rows as the copy
        score = (logp if n_remaining == n else logp[:, :, remaining]).sum(axis=2)
        score[~available] = -np.inf
        a, b = divmod(int(np.argmax(score)), logp.shape[1])
        chosen.append((a, b))
        available[a] = False
        remaining &= ~good[a, b]
        n_remaining = int(np.count_nonzero(remaining))
    return good, chosen


def synthesize_current_map(
    dmap: DynamicMap,
    pose: FloatArray,
    points_map: FloatArray,
    levels: Sequence[int],
    params: SynthesisParams | None = None,
    backend: str = "auto",
) -> CurrentMap:
    """Run the §4.3 selection for the scan ``points_map`` (map frame) taken at ``pose``.

    ``levels`` are the timescales allowed (indices into the map's timescales, short to long).
    ``backend`` (:data:`dynmap_sim.jit.KERNEL_BACKENDS`): ``"numba"`` (``"auto"`` when
    installed) or ``"python"`` selects in one loop (:mod:`.current_map_numba`), the same
    selections as the numpy code.
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
    kernel = kernel_backend(backend)
    if kernel is not None:  # steps 2-5 in one compiled loop, the same selections
        good, chosen = select_timescales(
            logp, log_floor, np.log(prm.explained_density), prm.min_readings, kernel == "python"
        )
    else:
        good, chosen = _select_numpy(logp, log_floor, prm)
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
