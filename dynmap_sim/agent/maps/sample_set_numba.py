"""Optional numba backend of :func:`.sample_set.robust_estimates` (extra ``fast``).

The robust estimates of Biber & Duckett §3.3 -- median (eq. 4, the lower middle sample),
``σ = 1.48·MAD`` (eq. 5) and the share of samples beyond 3σ -- one ray at a time in a compiled
loop (insertion sort in place: a ray holds at most a few hundred samples), with the same
integer arithmetic and the same floating-point operations as the numpy code, so the results
are identical. :func:`numba_available` says whether it can be used.

The bookkeeping of one §3.1 update step (:meth:`.sample_set.SampleSets.update`: the runs of
equal rays in the randomly ordered measurements, how many each ray takes, adds and replaces,
which slots they go to) is here too, in three kernels between which the numpy code draws its
random numbers and sorts the measurements (:func:`ray_runs`, :func:`plan_update`,
:func:`write_update`): the draws keep their order and count, the sort is numpy's, the slots
to replace are those of numpy's ``argsort`` of their random keys, the integer arithmetic is
the numpy code's, so the samples are identical.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, kernel_backend, require_numba
from dynmap_sim.jit import numba_available as numba_available  # re-exported


def _robust_rows_py(
    samples_mm: NDArray[np.uint16],
    count: NDArray[np.int64],
    rho_m: NDArray[np.float64],
    sigma_m: NDArray[np.float64],
    outlier: NDArray[np.float64],
) -> None:
    """Fill ``rho_m``, ``sigma_m`` and ``outlier`` for every row (first ``count`` valid)."""
    n = samples_mm.shape[1]
    srt = np.empty(n, dtype=np.int64)
    dev = np.empty(n, dtype=np.int64)
    dsrt = np.empty(n, dtype=np.int64)
    for r in range(samples_mm.shape[0]):
        c = count[r]
        if c <= 0:
            rho_m[r] = np.nan
            sigma_m[r] = np.nan
            outlier[r] = 0.0
            continue
        for k in range(c):  # insertion sort of the valid samples
            v = np.int64(samples_mm[r, k])
            p = k
            while p > 0 and srt[p - 1] > v:
                srt[p] = srt[p - 1]
                p -= 1
            srt[p] = v
        mid = (c - 1) // 2
        rho = srt[mid]  # lower middle: a measured value
        for k in range(c):
            d = abs(np.int64(samples_mm[r, k]) - rho)
            dev[k] = d
            p = k
            while p > 0 and dsrt[p - 1] > d:
                dsrt[p] = dsrt[p - 1]
                p -= 1
            dsrt[p] = d
        lo = float(dsrt[mid])
        hi = float(dsrt[min(c // 2, n - 1)])
        mad = lo if c % 2 == 1 else 0.5 * (lo + hi)
        sig = 1.48 * mad
        n_out = 0
        for k in range(c):
            if dev[k] > 3.0 * sig:
                n_out += 1
        rho_m[r] = rho / 1000.0
        sigma_m[r] = sig / 1000.0
        outlier[r] = n_out / c


_robust_rows = compiled(_robust_rows_py)


def robust_rows(
    samples_mm: NDArray[np.uint16], count: NDArray[np.int64]
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``(rho_m, sigma_m, outlier_ratio)`` of every row, compiled (needs numba)."""
    require_numba("backend")
    n_rays = samples_mm.shape[0]
    rho, sig, out = np.empty(n_rays), np.empty(n_rays), np.empty(n_rays)
    _robust_rows(np.ascontiguousarray(samples_mm), count, rho, sig, out)
    return rho, sig, out


def _sort_by_ray_py(
    ray: NDArray[np.int64],
    keys: NDArray[np.float64],
    val: NDArray[np.uint16],
    n_rays: int,
    r_s: NDArray[np.int64],
    v_s: NDArray[np.uint16],
    first: NDArray[np.int64],
) -> int:
    """The measurements ``(ray, val)`` in the order of ``np.argsort(keys)`` for the keys
    ``ray + U[0, 1)`` of :meth:`.sample_set.SampleSets.update` (``r_s``, ``v_s``) and the
    starts of their runs of equal rays (``first``); returns the number of runs, -1 when
    two keys are equal (the order of ties is the sort algorithm's: the caller sorts with
    numpy then), -2 when a ray is not in ``[0, n_rays)``.

    A counting sort by ray, then a sort by key within each ray (insertion sort; ``argsort``
    for more than 16 measurements, as the offline steps give): a key of ray ``r`` lies in
    ``[r, r + 1]``, so with distinct keys this is their one increasing order -- the
    permutation ``argsort`` returns."""
    m = ray.shape[0]
    for i in range(m):
        if ray[i] < 0 or ray[i] >= n_rays:
            return -2
    start = np.zeros(n_rays + 1, dtype=np.int64)
    for i in range(m):
        start[ray[i] + 1] += 1
    for r in range(n_rays):
        start[r + 1] += start[r]
    nxt = start[:-1].copy()
    ks = np.empty(m)
    for i in range(m):  # into the ray's bucket, in arrival order
        q = nxt[ray[i]]
        nxt[ray[i]] = q + 1
        ks[q] = keys[i]
        v_s[q] = val[i]
    for r in range(n_rays):  # each bucket by key: insertion sort, or argsort if long
        lo, hi = start[r], start[r + 1]
        if hi - lo > 16:
            o = np.argsort(ks[lo:hi]) + lo
            ks[lo:hi] = ks[o]
            v_s[lo:hi] = v_s[o]
            continue
        for p in range(lo + 1, hi):
            k = ks[p]
            v = v_s[p]
            q = p
            while q > lo and ks[q - 1] > k:
                ks[q] = ks[q - 1]
                v_s[q] = v_s[q - 1]
                q -= 1
            ks[q] = k
            v_s[q] = v
    n = 0
    for r in range(n_rays):
        if start[r + 1] > start[r]:
            first[n] = start[r]
            n += 1
        for q in range(start[r], start[r + 1]):
            r_s[q] = r
    for q in range(1, m):
        if ks[q] == ks[q - 1]:
            return -1
    return n


def _ray_runs_py(r_s: NDArray[np.int64], first: NDArray[np.int64]) -> int:
    """Starts of the runs of equal values in ``r_s`` (sorted by ray) into ``first``; their
    number."""
    n = 0
    for i in range(r_s.shape[0]):
        if i == 0 or r_s[i] != r_s[i - 1]:
            first[n] = i
            n += 1
    return n


def _plan_update_py(
    r_s: NDArray[np.int64],
    first: NDArray[np.int64],
    count: NDArray[np.uint16],
    initialized: NDArray[np.bool_],
    n_samples: int,
    fills_first_step: bool,
    fill: bool,
    initialize: bool,
    n_rule: NDArray[np.int64],
    n_new: NDArray[np.int64],
    n_add: NDArray[np.int64],
    rep_cnt: NDArray[np.int64],
) -> int:
    """Per run ``g`` (ray ``r_s[first[g]]``): ``n_new`` measurements taken, ``n_add`` of them
    into free slots, the rest replacing old samples; ``initialized`` set as the numpy code
    sets it. ``rep_cnt`` gets the old counts of the runs that replace, in order; returns how
    many do (the rows of random keys to draw)."""
    m = r_s.shape[0]
    n_groups = first.shape[0]
    n_rep_rows = 0
    for g in range(n_groups):
        ray = r_s[first[g]]
        end = first[g + 1] if g + 1 < n_groups else m
        m_per = end - first[g]
        cnt = np.int64(count[ray])
        free = n_samples - cnt
        if fill or (fills_first_step and not initialized[ray]):
            k = min(m_per, free)
        else:
            k = min(n_rule[g], m_per)
        if initialize or not fill:
            initialized[ray] = True
        a = min(k, free)
        n_new[g] = k
        n_add[g] = a
        if k - a > 0:
            rep_cnt[n_rep_rows] = cnt
            n_rep_rows += 1
    return n_rep_rows


def _write_update_py(
    r_s: NDArray[np.int64],
    v_s: NDArray[np.uint16],
    first: NDArray[np.int64],
    n_new: NDArray[np.int64],
    n_add: NDArray[np.int64],
    keys: NDArray[np.float64],
    samples_mm: NDArray[np.uint16],
    count: NDArray[np.uint16],
) -> None:
    """Each run's first ``n_add`` measurements into the next free slots, the next
    ``rep = n_new - n_add`` into its old slots ``[0, count)`` of the ``rep`` smallest random
    ``keys[row]`` in increasing order (``row``: the run's order among those that replace), and
    the new counts. Those slots are the first ``rep`` of the numpy code's ``argsort`` of the
    row with the keys of the free slots set to 2 (above every key): equal keys, which a
    generator's doubles practically never give, go lower slot first, as ``argsort`` orders
    the few keys of a short row."""
    n_groups = first.shape[0]
    slots = np.empty(samples_mm.shape[1], dtype=np.int64)
    row = 0
    for g in range(n_groups):
        start = first[g]
        ray = r_s[start]
        cnt = np.int64(count[ray])
        a = n_add[g]
        for j in range(a):
            samples_mm[ray, cnt + j] = v_s[start + j]
        rep = n_new[g] - a
        if rep > 0:
            n_kept = 0  # slots[:n_kept]: the smallest keys so far, increasing
            for q in range(cnt):
                kq = keys[row, q]
                if n_kept == rep and kq >= keys[row, slots[n_kept - 1]]:
                    continue
                p = n_kept if n_kept < rep else rep - 1
                while p > 0 and keys[row, slots[p - 1]] > kq:
                    slots[p] = slots[p - 1]
                    p -= 1
                slots[p] = q
                if n_kept < rep:
                    n_kept += 1
            for j in range(rep):
                samples_mm[ray, slots[j]] = v_s[start + a + j]
            row += 1
        count[ray] = np.uint16(cnt + a)


_sort_by_ray = compiled(_sort_by_ray_py)
_ray_runs = compiled(_ray_runs_py)
_plan_update = compiled(_plan_update_py)
_write_update = compiled(_write_update_py)


def update_kernels(backend: str) -> tuple | None:
    """The update kernels (:func:`_sort_by_ray_py`, then the three above), compiled
    (``"numba"``) or not (``"python"``), for a ``backend`` argument
    (:data:`dynmap_sim.jit.KERNEL_BACKENDS`); None: the numpy code."""
    kind = kernel_backend(backend)
    if kind is None:
        return None
    if kind == "numba":
        require_numba("sample-set backend")
        return _sort_by_ray, _ray_runs, _plan_update, _write_update
    return _sort_by_ray_py, _ray_runs_py, _plan_update_py, _write_update_py


def _table_rows_py(
    rho_m: NDArray[np.float64],
    sigma_m: NDArray[np.float64],
    outlier: NDArray[np.float64],
    count: NDArray[np.int64],
    sigma_floor_m: float,
    min_outlier_ratio: float,
    max_range_m: float,
    table: NDArray[np.float64],
    one_minus_po: NDArray[np.float64],
    sigma: NDArray[np.float64],
) -> None:
    """The arithmetic of :meth:`.sample_set.SampleSets.model_table` (eq. 6-8) but its logs:
    columns 0, 1 and 3 of ``table`` (``ρ``, ``1/(2σ²)``, ``p_o/maxRange``), and the floored
    ``σ`` and ``1 - p_o`` whose logs make column 2 (a ray without samples: ``σ = 1``,
    ``p_o = 1``) -- the numpy code's IEEE operations, so the same values."""
    for r in range(rho_m.shape[0]):
        if count[r] > 0:
            sg = sigma_m[r] if sigma_m[r] >= sigma_floor_m else sigma_floor_m
            po = outlier[r] if outlier[r] >= min_outlier_ratio else min_outlier_ratio
            table[r, 0] = rho_m[r]
        else:
            sg = 1.0
            po = 1.0
            table[r, 0] = 0.0
        sigma[r] = sg
        one_minus_po[r] = 1.0 - po
        table[r, 1] = 0.5 / (sg * sg)
        table[r, 3] = po / max_range_m


_table_rows = compiled(_table_rows_py)


def table_kernel(backend: str):
    """:func:`_table_rows_py` compiled (``"numba"``) or not (``"python"``) for a ``backend``
    argument (:data:`dynmap_sim.jit.KERNEL_BACKENDS`); None: the numpy code."""
    kind = kernel_backend(backend)
    if kind is None:
        return None
    if kind == "numba":
        require_numba("sample-set backend")
        return _table_rows
    return _table_rows_py
