"""Optional numba backend of the greedy timescale selection of :mod:`.current_map` (§4.3).

Steps 2–5 of the synthesis on the per-reading log-likelihoods ``logp[m, l, i]`` of the nearby
maps ``m`` at the allowed levels ``l``: floor them, mark the readings each model explains,
then repeatedly select the (map, level) with the best sum over the readings still
unexplained. The numpy code's operations in one compiled loop: ``np.maximum`` and ``>=``,
the sums as numpy's ``add.reduce`` forms them (from 0, pairwise in blocks of up to 128 with
eight accumulators: :func:`_pairwise_sum_py`) and ``argmax``'s choice (the first maximum, the
first NaN), so the same selections. :func:`numba_available` says whether it can be used.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, pick_kernel
from dynmap_sim.jit import numba_available as numba_available  # re-exported

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def _block_sum_py(a: FloatArray, lo: int, n: int) -> float:
    """``a[lo : lo + n]`` (``n <= 128``) summed as numpy's pairwise summation sums a block:
    in order from 0 when ``n < 8``, else in eight accumulators, then the rest in order."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    while i < n - n % 8:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


#: (compiled, or the plain function without numba: the plain kernels run either way)
_block_sum = compiled(_block_sum_py) or _block_sum_py


def _pairwise_sum_py(a: FloatArray, n: int) -> float:
    """``a[:n]`` summed as numpy's ``add.reduce`` sums a contiguous run: ``0 +`` the pairwise
    sum, which splits more than 128 values in two halves (the first a multiple of 8 long)
    and adds the halves' sums (here with an explicit stack instead of recursion)."""
    seg_lo = np.empty(64, dtype=np.int64)  # segments still to do: start, length, stage
    seg_n = np.empty(64, dtype=np.int64)
    stage = np.zeros(64, dtype=np.int64)
    vals = np.empty(64)  # sums of finished segments, in order
    seg_lo[0], seg_n[0], stage[0] = 0, n, 0
    sp, vp = 1, 0
    while sp > 0:
        lo, m = seg_lo[sp - 1], seg_n[sp - 1]
        half = m // 2 - (m // 2) % 8
        if m <= 128:
            vals[vp] = _block_sum(a, lo, m)
            vp += 1
            sp -= 1
        elif stage[sp - 1] == 0:  # the first half
            stage[sp - 1] = 1
            seg_lo[sp], seg_n[sp], stage[sp] = lo, half, 0
            sp += 1
        elif stage[sp - 1] == 1:  # the second half
            stage[sp - 1] = 2
            seg_lo[sp], seg_n[sp], stage[sp] = lo + half, m - half, 0
            sp += 1
        else:  # both done: their sum
            vals[vp - 2] = vals[vp - 2] + vals[vp - 1]
            vp -= 1
            sp -= 1
    return 0.0 + vals[0]


_pairwise_sum = compiled(_pairwise_sum_py) or _pairwise_sum_py


def _select_py(
    logp: FloatArray,
    log_floor: float,
    log_explained: float,
    min_readings: int,
    good: NDArray[np.bool_],
    rows: IntArray,
    cols: IntArray,
) -> int:
    """Floor ``logp`` ``(M, L, N)`` at ``log_floor`` in place, set ``good = logp >=
    log_explained``, and select (map ``rows[k]``, level ``cols[k]``) in turn while at least
    ``min_readings`` readings are unexplained and maps are left; returns how many."""
    n_maps, n_levels, n = logp.shape
    for m in range(n_maps):
        for b in range(n_levels):
            for i in range(n):
                v = logp[m, b, i]
                if v < log_floor:  # np.maximum: NaN stays
                    v = log_floor
                    logp[m, b, i] = v
                good[m, b, i] = v >= log_explained
    remaining = np.ones(n, dtype=np.bool_)
    available = np.ones(n_maps, dtype=np.bool_)
    buf = np.empty(n)
    n_remaining = n
    n_chosen = 0
    while n_remaining >= min_readings and n_chosen < n_maps:
        best = 0.0
        best_k = -1
        for m in range(n_maps):
            for b in range(n_levels):
                if available[m]:
                    k = 0
                    for i in range(n):
                        if remaining[i]:
                            buf[k] = logp[m, b, i]
                            k += 1
                    s = _pairwise_sum(buf, k)
                else:
                    s = -math.inf
                # argmax: the first maximum; the first NaN
                if best_k < 0 or (not math.isnan(best) and not s <= best):
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


_select = compiled(_select_py)


def select_timescales(
    logp: FloatArray,
    log_floor: float,
    log_explained: float,
    min_readings: int,
    python: bool = False,
) -> tuple[NDArray[np.bool_], list[tuple[int, int]]]:
    """``good`` ``(M, L, N)`` and the selections ``[(row of logp, column), ...]`` of
    :func:`_select_py` (``logp`` C-contiguous, floored in place; compiled, ``python``: the
    plain kernel)."""
    kernel = pick_kernel(_select_py, _select, python, "selection backend")
    good = np.empty(logp.shape, dtype=np.bool_)
    rows = np.empty(len(logp), dtype=np.int64)
    cols = np.empty(len(logp), dtype=np.int64)
    k = kernel(logp, float(log_floor), float(log_explained), int(min_readings), good, rows, cols)
    return good, list(zip(rows[:k].tolist(), cols[:k].tolist(), strict=True))
