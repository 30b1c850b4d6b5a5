"""Optional numba backends of :func:`.scan_points.first_per_cell` and
:func:`.scan_points.scan_points_base` (extra ``fast``).

The thinning of a point set to the first point of each square cell: the cell keys as the
numpy code computes them (``floor(x / cell)``, as int64, ``kx * 1,000,003 + ky``), and the
first point of each key -- from a dense table of the cells seen so far when the points'
cells span a small box, else from a stable sort of the keys. Which points are kept is a
property of the keys alone (the lowest index of each key), so the result is the numpy code's.

:func:`_scan_points_py` is ``scan_points_base`` with precomputed beam directions in one loop:
the valid readings times the beams' cosines and sines, moved by the laser's mount pose with
the operations of :func:`dynmap_sim.se2.transform_points` in their order: the same points.
:func:`numba_available` says whether it can be used.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, kernel_backend, pick_kernel
from dynmap_sim.jit import numba_available as numba_available  # re-exported

FloatArray = NDArray[np.float64]


#: Most cells of the bounding box for which :func:`_first_per_cell_py` marks the seen cells in
#: a dense table (beyond: ``4 * N`` more), instead of sorting the keys.
_DENSE_CELLS = 1 << 18
#: Cell indices up to this size keep ``kx * 1,000,003 + ky`` clear of int64 overflow.
_SAFE_INDEX = 1 << 40
#: The key's multiplier: cells whose y indices differ by less than this have distinct keys.
_KEY_STRIDE = 1_000_003


def _first_per_cell_py(
    px: FloatArray, py: FloatArray, cell_m: float, keep: NDArray[np.bool_]
) -> None:
    """``keep[i]``: point ``i`` is the first (lowest index) of its cell (``keep`` all False
    on entry).

    When the cells' bounding box is small (at most ``4 N + 2^18`` cells, fewer than
    1,000,003 rows, so no two of its cells share a key), the points are visited in order
    and a dense table of seen cells keeps the first of each; else the keys are sorted (a
    stable sort: the first of each run of equal keys). Both keep the lowest index of each
    key."""
    m = px.shape[0]
    if m == 0:
        return
    kxs = np.empty(m, dtype=np.int64)
    kys = np.empty(m, dtype=np.int64)
    for i in range(m):
        kxs[i] = np.int64(math.floor(px[i] / cell_m))
        kys[i] = np.int64(math.floor(py[i] / cell_m))
    x0, x1, y0, y1 = kxs.min(), kxs.max(), kys.min(), kys.max()
    small = max(-x0, x1, -y0, y1) < _SAFE_INDEX
    if small and y1 - y0 < _KEY_STRIDE and (x1 - x0 + 1) * (y1 - y0 + 1) <= 4 * m + _DENSE_CELLS:
        ny = y1 - y0 + 1
        seen = np.zeros((x1 - x0 + 1) * ny, dtype=np.bool_)
        for i in range(m):
            c = (kxs[i] - x0) * ny + (kys[i] - y0)
            if not seen[c]:
                seen[c] = True
                keep[i] = True
        return
    key = np.empty(m, dtype=np.int64)
    for i in range(m):
        key[i] = kxs[i] * _KEY_STRIDE + kys[i]
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


def _scan_points_py(
    ranges_m: FloatArray,
    cos: FloatArray,
    sin: FloatArray,
    range_min_m: float,
    range_max_m: float,
    mount: FloatArray,
    out: FloatArray,
) -> int:
    """Points ``out[:k]`` (robot frame) of the ``k`` valid readings (finite, in
    ``[range_min_m, range_max_m)``), in beam order; ``mount`` is ``(x, y, cos, sin)`` of
    the laser's mount pose. Returns ``k``."""
    mx, my, mc, ms = mount[0], mount[1], mount[2], mount[3]
    k = 0
    for i in range(ranges_m.shape[0]):
        r = ranges_m[i]
        if math.isfinite(r) and r >= range_min_m and r < range_max_m:
            x = r * cos[i]
            y = r * sin[i]
            out[k, 0] = mx + mc * x - ms * y
            out[k, 1] = my + ms * x + mc * y
            k += 1
    return k


_scan_points = compiled(_scan_points_py)


def scan_points_kernel(backend: str):
    """:func:`_scan_points_py` compiled (``"numba"``) or not (``"python"``) for a
    ``backend`` argument (:data:`dynmap_sim.jit.KERNEL_BACKENDS`); None: the numpy code."""
    kind = kernel_backend(backend)
    if kind is None:
        return None
    return pick_kernel(_scan_points_py, _scan_points, kind == "python", "scan-points backend")
