"""Optional numba backend of one ICP iteration of :func:`.scan_matcher.match_scan` (extra ``fast``).

The same computation as the numpy path -- transform the scan by the current pose, find each
point's nearest target point within ``max_correspondence_m``, and accumulate the weighted
point-to-line normal equations (Censi 2008, eq. 6, Huber weights) -- fused into one compiled
loop. The exact nearest neighbour comes from a uniform bucket grid whose cells are as large
as the search radius (:class:`BucketGrid`): every target point closer than the radius lies
in the 3x3 cells around the query, so the answer is the KD-tree's (up to exactly equal
distances, which the voxel-filtered maps of the agent do not have). Sums run in a different
order than BLAS, so results agree with the numpy path to rounding.
Install with ``pip install "dynmap-sim[fast]"``; :func:`numba_available` says whether it can
be used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

try:  # pragma: no cover - depends on the optional extra
    import numba
except ImportError:  # pragma: no cover
    numba = None

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def numba_available() -> bool:
    """True when numba is installed (the ``fast`` extra)."""
    return numba is not None


@dataclass(frozen=True)
class BucketGrid:
    """Target points sorted into square cells of ``cell_m`` (map frame).

    Cell ``(cx, cy)`` (``cx = floor(x / cell_m) - x0``) holds the points
    ``order[start[k] : start[k + 1]]`` with ``k = cx * ny + cy``; ``xs``/``ys`` are the point
    coordinates in that order.
    """

    cell_m: float
    x0: int
    y0: int
    nx: int
    ny: int
    start: IntArray
    order: IntArray
    xs: FloatArray
    ys: FloatArray

    @classmethod
    def build(cls, points: FloatArray, cell_m: float) -> BucketGrid:
        cx = np.floor(points[:, 0] / cell_m).astype(np.int64)
        cy = np.floor(points[:, 1] / cell_m).astype(np.int64)
        x0, y0 = int(cx.min()), int(cy.min())
        nx, ny = int(cx.max()) - x0 + 1, int(cy.max()) - y0 + 1
        key = (cx - x0) * ny + (cy - y0)
        order = np.argsort(key, kind="stable")
        start = np.zeros(nx * ny + 1, dtype=np.int64)
        np.cumsum(np.bincount(key, minlength=nx * ny), out=start[1:])
        return cls(
            float(cell_m),
            x0,
            y0,
            nx,
            ny,
            start,
            order.astype(np.int64),
            np.ascontiguousarray(points[order, 0]),
            np.ascontiguousarray(points[order, 1]),
        )


def _icp_terms_py(
    px: FloatArray,
    py: FloatArray,
    pw: FloatArray,
    c: float,
    s: float,
    tx: float,
    ty: float,
    radius_m: float,
    cell_m: float,
    x0: int,
    y0: int,
    nx: int,
    ny: int,
    start: IntArray,
    order: IntArray,
    xs: FloatArray,
    ys: FloatArray,
    packed: FloatArray,
    usable: NDArray[np.bool_],
    huber_m: float,
    out: FloatArray,
) -> int:
    """One iteration's sums; ``out`` gets ``h00 h01 h02 h11 h12 h22 g0 g1 g2 sum_r2``.

    Returns the number of points whose nearest target point (within ``radius_m``) is usable.
    """
    for k in range(10):
        out[k] = 0.0
    r2_max = radius_m * radius_m
    n_matched = 0
    for i in range(px.shape[0]):
        rx = c * px[i] - s * py[i]
        ry = s * px[i] + c * py[i]
        wx = rx + tx
        wy = ry + ty
        cx_lo = max(int(math.floor((wx - radius_m) / cell_m)) - x0, 0)
        cx_hi = min(int(math.floor((wx + radius_m) / cell_m)) - x0, nx - 1)
        cy_lo = max(int(math.floor((wy - radius_m) / cell_m)) - y0, 0)
        cy_hi = min(int(math.floor((wy + radius_m) / cell_m)) - y0, ny - 1)
        ccx = int(math.floor(wx / cell_m)) - x0
        ccy = int(math.floor(wy / cell_m)) - y0
        best = r2_max
        best_j = -1
        # The query's own cell first; then the others, unless the cell's box (widened by
        # 1 nm against rounding of the binning) is no closer than the best point so far.
        if cx_lo <= ccx <= cx_hi and cy_lo <= ccy <= cy_hi:
            kk = ccx * ny + ccy
            for m in range(start[kk], start[kk + 1]):
                dx = xs[m] - wx
                dy = ys[m] - wy
                d2 = dx * dx + dy * dy
                if d2 < best:
                    best = d2
                    best_j = order[m]
        for gx in range(cx_lo, cx_hi + 1):
            lo_x = (gx + x0) * cell_m
            bx = max(max(lo_x - wx, wx - (lo_x + cell_m)) - 1e-9, 0.0)
            for gy in range(cy_lo, cy_hi + 1):
                if gx == ccx and gy == ccy:
                    continue
                lo_y = (gy + y0) * cell_m
                by = max(max(lo_y - wy, wy - (lo_y + cell_m)) - 1e-9, 0.0)
                if bx * bx + by * by >= best:
                    continue
                kk = gx * ny + gy
                for m in range(start[kk], start[kk + 1]):
                    dx = xs[m] - wx
                    dy = ys[m] - wy
                    d2 = dx * dx + dy * dy
                    if d2 < best:
                        best = d2
                        best_j = order[m]
        if best_j < 0 or not usable[best_j]:
            continue
        n_matched += 1
        n0 = packed[best_j, 0]
        n1 = packed[best_j, 1]
        r = n0 * (wx - packed[best_j, 2]) + n1 * (wy - packed[best_j, 3])
        j2 = n1 * rx - n0 * ry
        a = abs(r)
        w = min(huber_m / max(a, 1e-12), 1.0) * pw[i]
        out[0] += n0 * n0 * w
        out[1] += n0 * n1 * w
        out[2] += n0 * j2 * w
        out[3] += n1 * n1 * w
        out[4] += n1 * j2 * w
        out[5] += j2 * j2 * w
        out[6] += n0 * w * r
        out[7] += n1 * w * r
        out[8] += j2 * w * r
        out[9] += r * r
    return n_matched


_icp_terms = numba.njit(cache=True, nogil=True)(_icp_terms_py) if numba is not None else None


def icp_terms(
    px: FloatArray,
    py: FloatArray,
    pw: FloatArray,
    c: float,
    s: float,
    tx: float,
    ty: float,
    radius_m: float,
    grid: BucketGrid,
    packed: FloatArray,
    usable: NDArray[np.bool_],
    huber_m: float,
    out: FloatArray,
) -> int:
    """Compiled :func:`_icp_terms_py` on a :class:`BucketGrid` (``grid.cell_m >= radius_m``)."""
    if _icp_terms is None:
        raise RuntimeError('the numba ICP backend needs numba: pip install "dynmap-sim[fast]"')
    return int(
        _icp_terms(
            px,
            py,
            pw,
            c,
            s,
            tx,
            ty,
            radius_m,
            grid.cell_m,
            grid.x0,
            grid.y0,
            grid.nx,
            grid.ny,
            grid.start,
            grid.order,
            grid.xs,
            grid.ys,
            packed,
            usable,
            huber_m,
            out,
        )
    )


def _knn_py(
    k: int,
    cell_m: float,
    x0: int,
    y0: int,
    nx: int,
    ny: int,
    start: IntArray,
    order: IntArray,
    xs: FloatArray,
    ys: FloatArray,
    out: IntArray,
) -> None:
    """``out[i]`` = indices of the ``k`` points nearest to point ``i`` (itself included),
    nearest first (equal distances: lower index first); rings of cells around the point's
    cell are searched until the next ring cannot hold anything nearer than the k-th."""
    n = xs.shape[0]
    best_d = np.empty(k)
    best_j = np.empty(k, dtype=np.int64)
    for p in range(n):
        qx = xs[p]
        qy = ys[p]
        cx = int(math.floor(qx / cell_m)) - x0
        cy = int(math.floor(qy / cell_m)) - y0
        n_found = 0
        ring = 0
        while True:
            for gx in range(cx - ring, cx + ring + 1):
                if gx < 0 or gx >= nx:
                    continue
                edge_x = gx == cx - ring or gx == cx + ring
                for gy in range(cy - ring, cy + ring + 1):
                    if gy < 0 or gy >= ny:
                        continue
                    if not edge_x and gy != cy - ring and gy != cy + ring:
                        continue  # inside the ring: done before
                    if n_found == k:  # skip a cell whose box (+1 nm) is farther than the k-th
                        lo_x = (gx + x0) * cell_m
                        lo_y = (gy + y0) * cell_m
                        bx = max(max(lo_x - qx, qx - (lo_x + cell_m)) - 1e-9, 0.0)
                        by = max(max(lo_y - qy, qy - (lo_y + cell_m)) - 1e-9, 0.0)
                        if bx * bx + by * by > best_d[k - 1]:
                            continue
                    kk = gx * ny + gy
                    for m in range(start[kk], start[kk + 1]):
                        dx = xs[m] - qx
                        dy = ys[m] - qy
                        d2 = dx * dx + dy * dy
                        j = order[m]
                        if n_found == k and (
                            d2 > best_d[k - 1] or (d2 == best_d[k - 1] and j > best_j[k - 1])
                        ):
                            continue
                        # insert (d2, j) into the sorted list
                        pos = n_found if n_found < k else k - 1
                        while pos > 0 and (
                            best_d[pos - 1] > d2 or (best_d[pos - 1] == d2 and best_j[pos - 1] > j)
                        ):
                            if pos < k:
                                best_d[pos] = best_d[pos - 1]
                                best_j[pos] = best_j[pos - 1]
                            pos -= 1
                        best_d[pos] = d2
                        best_j[pos] = j
                        if n_found < k:
                            n_found += 1
            # Anything in ring + 1 or beyond is at least ring * cell_m away (less 1 nm).
            reach = ring * cell_m - 1e-9
            if n_found == k and reach > 0.0 and best_d[k - 1] < reach * reach:
                break
            if cx - ring <= 0 and cy - ring <= 0 and cx + ring >= nx - 1 and cy + ring >= ny - 1:
                break  # the whole grid is searched
            ring += 1
        src = order[p]
        for t in range(k):
            out[src, t] = best_j[t]


_knn = numba.njit(cache=True, nogil=True)(_knn_py) if numba is not None else None


def knn_indices(grid: BucketGrid, k: int) -> IntArray:
    """``(M, k)`` indices of each point's ``k`` nearest points of the grid (itself first).

    Needs numba. ``k`` must not exceed the number of points.
    """
    if _knn is None:
        raise RuntimeError('the numba kNN backend needs numba: pip install "dynmap-sim[fast]"')
    out = np.empty((len(grid.xs), k), dtype=np.int64)
    _knn(k, grid.cell_m, grid.x0, grid.y0, grid.nx, grid.ny, grid.start, grid.order, grid.xs,
         grid.ys, out)  # fmt: skip
    return out
