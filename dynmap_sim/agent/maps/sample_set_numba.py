"""Optional numba backend of :func:`.sample_set.robust_estimates` (extra ``fast``).

The robust estimates of Biber & Duckett §3.3 -- median (eq. 4, the lower middle sample),
``σ = 1.48·MAD`` (eq. 5) and the share of samples beyond 3σ -- one ray at a time in a compiled
loop (insertion sort in place: a ray holds at most a few hundred samples), with the same
integer arithmetic and the same floating-point operations as the numpy code, so the results
are identical. :func:`numba_available` says whether it can be used.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, require_numba
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
