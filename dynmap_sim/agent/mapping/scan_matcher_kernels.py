"""Compiled kernels of :mod:`.scan_matcher`: the bucket grid, exact nearest neighbours, the
points' line normals and the Gauss-Newton iterations of point-to-line ICP.

The nearest neighbour comes from a uniform bucket grid (:class:`BucketGrid`): every target
point within the search radius lies in the cells the radius' box touches, so the answer is
exact whatever the cell size; cells about as large as the radius make the search cheap.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, jitable

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


class BucketGrid(NamedTuple):
    """Points sorted into square cells of ``cell_m`` (map frame).

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


class ScanArrays(NamedTuple):
    """A scan's points in the robot frame [m] and their relative weights ``(N,)`` each."""

    px: FloatArray
    py: FloatArray
    pw: FloatArray


class TargetRows(NamedTuple):
    """``packed`` ``(M + 1, 4)`` rows ``[n_x, n_y, q_x, q_y]`` and the ``(M + 1,)`` mask of
    usable rows of a target (:meth:`.scan_matcher.PointMap.packed`)."""

    packed: FloatArray
    usable: NDArray[np.bool_]


class IcpParams(NamedTuple):
    """Scalars of the ICP iterations (:func:`.scan_matcher.match_scan`'s arguments):
    correspondence radius and Huber threshold [m], squared residual floor [m²], the scan
    information's divisor, the step tolerances [m, rad], the iteration cap."""

    radius_m: float
    huber_m: float
    floor2: float
    inflation: float
    tol_m: float
    tol_rad: float
    max_iterations: int


@compiled
def grid_build(px: FloatArray, py: FloatArray, cell_m: float) -> tuple:
    """``(start, order, xs, ys, x0, y0, nx, ny)`` of :class:`BucketGrid` for the points:
    cell keys, then a counting sort by key (stable: equal keys keep their index order)."""
    m = px.shape[0]
    cxs = np.empty(m, dtype=np.int64)
    cys = np.empty(m, dtype=np.int64)
    for i in range(m):
        cxs[i] = np.int64(math.floor(px[i] / cell_m))
        cys[i] = np.int64(math.floor(py[i] / cell_m))
    x0 = cxs.min()
    y0 = cys.min()
    nx = cxs.max() - x0 + 1
    ny = cys.max() - y0 + 1
    start = np.zeros(nx * ny + 1, dtype=np.int64)
    key = np.empty(m, dtype=np.int64)
    for i in range(m):
        k = (cxs[i] - x0) * ny + (cys[i] - y0)
        key[i] = k
        start[k + 1] += 1
    for k in range(nx * ny):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    order = np.empty(m, dtype=np.int64)
    xs = np.empty(m)
    ys = np.empty(m)
    for i in range(m):
        k = key[i]
        p = fill[k]
        fill[k] = p + 1
        order[p] = i
        xs[p] = px[i]
        ys[p] = py[i]
    return start, order, xs, ys, x0, y0, nx, ny


@jitable
def _cell_gap2(g: BucketGrid, gx: int, gy: int, qx: float, qy: float) -> float:
    """Squared distance [m²] from ``(qx, qy)`` to the box of cell ``(gx, gy)``, less 1 nm
    on each axis against the rounding of the binning (a lower bound)."""
    lo_x = (gx + g.x0) * g.cell_m
    lo_y = (gy + g.y0) * g.cell_m
    bx = max(max(lo_x - qx, qx - (lo_x + g.cell_m)) - 1e-9, 0.0)
    by = max(max(lo_y - qy, qy - (lo_y + g.cell_m)) - 1e-9, 0.0)
    return bx * bx + by * by


@jitable
def nearest_within(g: BucketGrid, wx: float, wy: float, radius_m: float) -> int:
    """Index of the grid point nearest to ``(wx, wy)`` closer than ``radius_m``, or -1."""
    cx_lo = max(int(math.floor((wx - radius_m) / g.cell_m)) - g.x0, 0)
    cx_hi = min(int(math.floor((wx + radius_m) / g.cell_m)) - g.x0, g.nx - 1)
    cy_lo = max(int(math.floor((wy - radius_m) / g.cell_m)) - g.y0, 0)
    cy_hi = min(int(math.floor((wy + radius_m) / g.cell_m)) - g.y0, g.ny - 1)
    best = radius_m * radius_m
    best_j = -1
    for gx in range(cx_lo, cx_hi + 1):
        for gy in range(cy_lo, cy_hi + 1):
            if _cell_gap2(g, gx, gy, wx, wy) >= best:
                continue
            kk = gx * g.ny + gy
            for m in range(g.start[kk], g.start[kk + 1]):
                dx = g.xs[m] - wx
                dy = g.ys[m] - wy
                d2 = dx * dx + dy * dy
                if d2 < best:
                    best = d2
                    best_j = g.order[m]
    return best_j


@compiled
def icp_terms(
    scan: ScanArrays,
    c: float,
    s: float,
    tx: float,
    ty: float,
    grid: BucketGrid,
    target: TargetRows,
    params: IcpParams,
    out: FloatArray,
) -> int:
    """One iteration's normal equations of the scan at pose ``(tx, ty)`` with heading cosine
    and sine ``(c, s)``: ``out`` gets ``h00 h01 h02 h11 h12 h22 g0 g1 g2 sum_r2`` of the
    Huber-weighted point-to-line residuals (Censi 2008, eq. 6). Returns the number of points
    whose nearest target point (within ``params.radius_m``) is usable."""
    for k in range(10):
        out[k] = 0.0
    n_matched = 0
    packed = target.packed
    for i in range(scan.px.shape[0]):
        rx = c * scan.px[i] - s * scan.py[i]
        ry = s * scan.px[i] + c * scan.py[i]
        wx = rx + tx
        wy = ry + ty
        j = nearest_within(grid, wx, wy, params.radius_m)
        if j < 0 or not target.usable[j]:
            continue
        n_matched += 1
        n0 = packed[j, 0]
        n1 = packed[j, 1]
        r = n0 * (wx - packed[j, 2]) + n1 * (wy - packed[j, 3])
        j2 = n1 * rx - n0 * ry
        w = min(params.huber_m / max(abs(r), 1e-12), 1.0) * scan.pw[i]
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


@jitable
def _knn_insert(best_d: FloatArray, best_j: IntArray, n_found: int, d2: float, j: int) -> int:
    """Insert ``(d2, j)`` into the ascending list ``best_*[:n_found]`` (capacity ``k``;
    equal distances: lower index first); returns the new count."""
    k = best_d.shape[0]
    if n_found == k and (d2 > best_d[k - 1] or (d2 == best_d[k - 1] and j > best_j[k - 1])):
        return n_found
    pos = n_found if n_found < k else k - 1
    while pos > 0 and (best_d[pos - 1] > d2 or (best_d[pos - 1] == d2 and best_j[pos - 1] > j)):
        if pos < k:
            best_d[pos] = best_d[pos - 1]
            best_j[pos] = best_j[pos - 1]
        pos -= 1
    best_d[pos] = d2
    best_j[pos] = j
    return n_found + 1 if n_found < k else n_found


@compiled
def knn_kernel(g: BucketGrid, k: int, out: IntArray) -> None:
    """``out[i]`` = indices of the ``k`` grid points nearest to point ``i`` (itself included),
    nearest first (equal distances: lower index first); rings of cells around the point's
    cell are searched until the next ring cannot hold anything nearer than the k-th."""
    best_d = np.empty(k)
    best_j = np.empty(k, dtype=np.int64)
    for p in range(g.xs.shape[0]):
        qx = g.xs[p]
        qy = g.ys[p]
        cx = int(math.floor(qx / g.cell_m)) - g.x0
        cy = int(math.floor(qy / g.cell_m)) - g.y0
        n_found = 0
        ring = 0
        while True:
            for gx in range(max(cx - ring, 0), min(cx + ring, g.nx - 1) + 1):
                edge_x = gx == cx - ring or gx == cx + ring
                for gy in range(max(cy - ring, 0), min(cy + ring, g.ny - 1) + 1):
                    if not edge_x and gy != cy - ring and gy != cy + ring:
                        continue  # inside the ring: done before
                    if n_found == k and _cell_gap2(g, gx, gy, qx, qy) > best_d[k - 1]:
                        continue
                    kk = gx * g.ny + gy
                    for m in range(g.start[kk], g.start[kk + 1]):
                        dx = g.xs[m] - qx
                        dy = g.ys[m] - qy
                        n_found = _knn_insert(
                            best_d, best_j, n_found, dx * dx + dy * dy, g.order[m]
                        )
            # Anything in ring + 1 or beyond is at least ring * cell_m away (less 1 nm).
            reach = ring * g.cell_m - 1e-9
            if n_found == k and reach > 0.0 and best_d[k - 1] < reach * reach:
                break
            if (
                cx - ring <= 0
                and cy - ring <= 0
                and cx + ring >= g.nx - 1
                and cy + ring >= g.ny - 1
            ):
                break  # the whole grid is searched
            ring += 1
        src = g.order[p]
        for t in range(k):
            out[src, t] = best_j[t]


@compiled
def normals_kernel(
    px: FloatArray, py: FloatArray, idx: IntArray, normals: FloatArray, planarity: FloatArray
) -> None:
    """Line normals ``(M, 2)`` and planarity ``(M,)`` (``1 - lambda_min / lambda_max``) of
    the points from the covariance of their neighbours ``idx`` ``(M, k)``: the normal is
    perpendicular to the principal axis of the neighbours' scatter."""
    k = idx.shape[1]
    for m in range(idx.shape[0]):
        mx = 0.0
        my = 0.0
        for j in range(k):
            mx += px[idx[m, j]]
            my += py[idx[m, j]]
        mx /= k
        my /= k
        sxx = syy = sxy = 0.0
        for j in range(k):
            dx = px[idx[m, j]] - mx
            dy = py[idx[m, j]] - my
            sxx += dx * dx
            syy += dy * dy
            sxy += dx * dy
        h = (sxx - syy) * 0.5
        disc = math.sqrt(max(h * h + sxy * sxy, 0.0))
        lam_min = (sxx + syy) * 0.5 - disc
        lam_max = (sxx + syy) * 0.5 + disc
        phi = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
        normals[m, 0] = -math.sin(phi)
        normals[m, 1] = math.cos(phi)
        planarity[m] = 1.0 - lam_min / lam_max if lam_max > 1e-12 else 0.0


#: Condition estimate above which :func:`solve3` uses the closed form (else SVD and LU).
WELL_CONDITIONED = 1e-6


@jitable
def _condition3(h: FloatArray) -> float:
    """``|lambda|_min / |lambda|_max`` of a symmetric 3x3 ``h`` (0 for ``h = 0``, NaN if not
    finite), from the trigonometric solution of the characteristic cubic (Smith 1961)."""
    a00, a01, a02 = h[0, 0], h[0, 1], h[0, 2]
    a11, a12, a22 = h[1, 1], h[1, 2], h[2, 2]
    if not math.isfinite(a00 + a01 + a02 + a11 + a12 + a22):
        return math.nan
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    q = (a00 + a11 + a22) / 3.0
    if p1 == 0.0:
        e1, e2, e3 = a00, a11, a22
    else:
        b00, b11, b22 = a00 - q, a11 - q, a22 - q
        p = math.sqrt((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1) / 6.0)
        det_b = (
            b00 * (b11 * b22 - a12 * a12)
            - a01 * (a01 * b22 - a12 * a02)
            + a02 * (a01 * a12 - b11 * a02)
        )
        phi = math.acos(min(max(det_b / (2.0 * p**3), -1.0), 1.0)) / 3.0
        e1 = q + 2.0 * p * math.cos(phi)
        e3 = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
        e2 = 3.0 * q - e1 - e3
    lo = min(abs(e1), abs(e2), abs(e3))
    hi = max(abs(e1), abs(e2), abs(e3))
    return lo / hi if hi > 0.0 else 0.0


@jitable
def solve3(h: FloatArray, g: FloatArray) -> bool:
    """``g <- -h^-1 g`` for a symmetric 3x3 ``h``; False (``g`` untouched) when ``h`` is rank
    deficient by :func:`numpy.linalg.matrix_rank`'s criterion (a singular value below
    ``3 eps s_max``). A clearly regular ``h`` is solved in closed form (adjugate), the rest
    -- rare: degenerate geometry without a prior -- by SVD and LU."""
    if _condition3(h) > WELL_CONDITIONED:
        a00, a01, a02 = h[0, 0], h[0, 1], h[0, 2]
        a11, a12, a22 = h[1, 1], h[1, 2], h[2, 2]
        c00 = a11 * a22 - a12 * a12
        c01 = a02 * a12 - a01 * a22
        c02 = a01 * a12 - a02 * a11
        c11 = a00 * a22 - a02 * a02
        c12 = a01 * a02 - a00 * a12
        c22 = a00 * a11 - a01 * a01
        det = a00 * c00 + a01 * c01 + a02 * c02
        g0, g1, g2 = g[0], g[1], g[2]
        g[0] = -(c00 * g0 + c01 * g1 + c02 * g2) / det
        g[1] = -(c01 * g0 + c11 * g1 + c12 * g2) / det
        g[2] = -(c02 * g0 + c12 * g1 + c22 * g2) / det
        return True
    if not np.all(np.isfinite(h)):
        return False
    sv = np.linalg.svd(h)[1]
    if not sv[2] > sv[0] * 3.0 * np.finfo(np.float64).eps:
        return False
    d = np.linalg.solve(h, g.copy())
    for a in range(3):
        g[a] = -d[a]
    return True


@compiled
def icp_loop(
    scan: ScanArrays,
    pose: FloatArray,
    prior: FloatArray,
    grid: BucketGrid,
    target: TargetRows,
    params: IcpParams,
    h_scan: FloatArray,
    state: FloatArray,
) -> None:
    """The Gauss-Newton iterations of ``match_scan``; ``pose`` ``(3,)`` is updated in place.

    ``prior`` ``(4, 3)``: its first row the prior mean, the other three its information
    (all zero: no prior). Stops when the step is below the tolerances, after
    ``max_iterations``, or at a rank-deficient matrix. ``state`` gets ``[iterations done,
    n_matched, rmse, converged]``; ``h_scan`` the last scan information (unscaled).
    """
    sums = np.empty(10)
    h = np.empty((3, 3))
    g = np.empty(3)
    two_pi = 2.0 * math.pi
    n_matched = 0
    rmse = math.inf
    converged = 0.0
    it = 0
    while it < params.max_iterations:
        c = math.cos(pose[2])
        s = math.sin(pose[2])
        n_matched = icp_terms(scan, c, s, pose[0], pose[1], grid, target, params, sums)
        if n_matched >= 3:
            rmse = math.sqrt(sums[9] / n_matched)
            h_scan[0, 0], h_scan[0, 1], h_scan[0, 2] = sums[0], sums[1], sums[2]
            h_scan[1, 0], h_scan[1, 1], h_scan[1, 2] = sums[1], sums[3], sums[4]
            h_scan[2, 0], h_scan[2, 1], h_scan[2, 2] = sums[2], sums[4], sums[5]
            g0, g1, g2 = sums[6], sums[7], sums[8]
        else:
            rmse = math.inf
            h_scan[:, :] = 0.0
            g0 = g1 = g2 = 0.0
        sigma2 = max(rmse * rmse if math.isfinite(rmse) else 0.0, params.floor2)
        sigma2 *= params.inflation
        e0 = pose[0] - prior[0, 0]
        e1 = pose[1] - prior[0, 1]
        e2 = (pose[2] - prior[0, 2] + math.pi) % two_pi - math.pi
        for a in range(3):
            for b in range(3):
                h[a, b] = h_scan[a, b] / sigma2 + prior[1 + a, b]
        g[0] = g0 / sigma2 + prior[1, 0] * e0 + prior[1, 1] * e1 + prior[1, 2] * e2
        g[1] = g1 / sigma2 + prior[2, 0] * e0 + prior[2, 1] * e1 + prior[2, 2] * e2
        g[2] = g2 / sigma2 + prior[3, 0] * e0 + prior[3, 1] * e1 + prior[3, 2] * e2
        if not solve3(h, g):
            break
        d0, d1, d2 = g[0], g[1], g[2]
        pose[0] += d0
        pose[1] += d1
        pose[2] = (pose[2] + d2 + math.pi) % two_pi - math.pi
        it += 1
        if math.hypot(d0, d1) < params.tol_m and abs(d2) < params.tol_rad:
            converged = 1.0
            break
    state[0] = it
    state[1] = n_matched
    state[2] = rmse
    state[3] = converged
