"""Optional numba backend of :func:`.scan_points.first_per_cell` (extra ``fast``).

The thinning of a point set to the first point of each square cell: the cell keys as the
numpy code computes them (``floor(x / cell)``, as int64, ``kx * 1,000,003 + ky``), a stable
sort of the keys, the first point of each run of equal keys. Which points are kept is a
property of the keys alone (the lowest index of each key), so the result is the numpy code's.
:func:`numba_available` says whether it can be used.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, pick_kernel
from dynmap_sim.jit import numba_available as numba_available  # re-exported

FloatArray = NDArray[np.float64]


def _first_per_cell_py(
    px: FloatArray, py: FloatArray, cell_m: float, keep: NDArray[np.bool_]
) -> None:
    """``keep[i]``: point ``i`` is the first (lowest index) of its cell (``keep`` all False
    on entry)."""
    m = px.shape[0]
    key = np.empty(m, dtype=np.int64)
    for i in range(m):
        kx = np.int64(math.floor(px[i] / cell_m))
        ky = np.int64(math.floor(py[i] / cell_m))
        key[i] = kx * 1_000_003 + ky
    order = np.argsort(key, kind="mergesort")
    for j in range(m):
        if j == 0 or key[order[j]] != key[order[j - 1]]:
            keep[order[j]] = True


_first_per_cell = compiled(_first_per_cell_py)


def first_per_cell_mask(
    points: FloatArray, cell_m: float, python: bool = False
) -> NDArray[np.bool_]:
    """``(N,)`` mask of the first point of each ``cell_m`` cell of ``points`` ``(N, 2)``
    (compiled; ``python``: the plain kernel)."""
    keep = np.zeros(len(points), dtype=bool)
    kernel = pick_kernel(_first_per_cell_py, _first_per_cell, python, "thinning backend")
    kernel(
        np.ascontiguousarray(points[:, 0], dtype=np.float64),
        np.ascontiguousarray(points[:, 1], dtype=np.float64),
        float(cell_m),
        keep,
    )
    return keep
