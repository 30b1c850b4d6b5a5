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

from dynmap_sim.jit import compiled, kernel_backend, require_numba
from dynmap_sim.jit import numba_available as numba_available  # re-exported

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


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
    def build(cls, points: FloatArray, cell_m: float, backend: str = "auto") -> BucketGrid:
        """The grid of ``points`` ``(M, 2)``; ``backend`` ``"numba"`` (``"auto"`` when
        installed) or ``"python"`` builds it in one loop (:func:`_grid_build_py`: a counting
        sort, which is the stable argsort of the cell keys), the same arrays."""
        kind = kernel_backend(backend)
        if kind is not None and len(points):
            if kind == "numba":
                require_numba("grid backend")
            build = _grid_build if kind == "numba" else _grid_build_py
            m = len(points)
            px = np.ascontiguousarray(points[:, 0], dtype=np.float64)
            py = np.ascontiguousarray(points[:, 1], dtype=np.float64)
            key, order = np.empty(m, dtype=np.int64), np.empty(m, dtype=np.int64)
            xs, ys = np.empty(m), np.empty(m)
            start, x0, y0, nx, ny = build(px, py, float(cell_m), key, order, xs, ys)
            return cls(float(cell_m), int(x0), int(y0), int(nx), int(ny), start, order, xs, ys)
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


def _grid_build_py(
    px: FloatArray,
    py: FloatArray,
    cell_m: float,
    key: IntArray,
    order: IntArray,
    xs: FloatArray,
    ys: FloatArray,
) -> tuple[IntArray, int, int, int, int]:
    """:meth:`BucketGrid.build` in one loop: cell keys as the numpy code computes them, the
    points counting-sorted by key (the stable order); returns ``start, x0, y0, nx, ny``."""
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
    for i in range(m):
        k = (cxs[i] - x0) * ny + (cys[i] - y0)
        key[i] = k
        start[k + 1] += 1
    for k in range(nx * ny):
        start[k + 1] += start[k]
    fill = start[:-1].copy()
    for i in range(m):
        k = key[i]
        p = fill[k]
        fill[k] = p + 1
        order[p] = i
        xs[p] = px[i]
        ys[p] = py[i]
    return start, x0, y0, nx, ny


_grid_build = compiled(_grid_build_py)


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


_icp_terms = compiled(_icp_terms_py)


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
    require_numba("ICP backend")
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


_knn = compiled(_knn_py)


def knn_indices(grid: BucketGrid, k: int) -> IntArray:
    """``(M, k)`` indices of each point's ``k`` nearest points of the grid (itself first).

    Needs numba. ``k`` must not exceed the number of points.
    """
    require_numba("kNN backend")
    out = np.empty((len(grid.xs), k), dtype=np.int64)
    _knn(k, grid.cell_m, grid.x0, grid.y0, grid.nx, grid.ny, grid.start, grid.order, grid.xs,
         grid.ys, out)  # fmt: skip
    return out


def _normals_py(
    px: FloatArray,
    py: FloatArray,
    idx: IntArray,
    normals: FloatArray,
    planarity: FloatArray,
) -> None:
    """Line normals ``(M, 2)`` and planarity ``(M,)`` of points ``(px, py)`` from the
    covariance of their neighbours ``idx`` ``(M, k)`` (:class:`.scan_matcher.PointMap`): the
    numpy code's operations in its order -- the neighbours' mean summed from 0 in index
    order (``add.reduce``), the moment sums of ``einsum`` in its two lanes (even and odd
    neighbours, an odd count's last lane padded with ``0 * 0``), ``libm``'s ``atan2``,
    ``sin`` and ``cos``, which numpy's call -- so the same values."""
    k = idx.shape[1]
    dx = np.empty(k)
    dy = np.empty(k)
    for m in range(idx.shape[0]):
        sx = 0.0
        sy = 0.0
        for j in range(k):
            sx += px[idx[m, j]]
            sy += py[idx[m, j]]
        mx = sx / k
        my = sy / k
        for j in range(k):
            dx[j] = px[idx[m, j]] - mx
            dy[j] = py[idx[m, j]] - my
        xx0 = xx1 = yy0 = yy1 = xy0 = xy1 = 0.0
        for j in range(0, k, 2):
            xx0 += dx[j] * dx[j]
            yy0 += dy[j] * dy[j]
            xy0 += dx[j] * dy[j]
            if j + 1 < k:
                xx1 += dx[j + 1] * dx[j + 1]
                yy1 += dy[j + 1] * dy[j + 1]
                xy1 += dx[j + 1] * dy[j + 1]
            else:
                xx1 += 0.0 * 0.0
                yy1 += 0.0 * 0.0
                xy1 += 0.0 * 0.0
        sxx = xx0 + xx1
        syy = yy0 + yy1
        sxy = xy0 + xy1
        # closed-form eigenvalues of [[sxx, sxy], [sxy, syy]]
        tr = sxx + syy
        h = (sxx - syy) * 0.5
        v = h * h + sxy * sxy
        disc = math.sqrt(0.0 if v < 0.0 else v)
        lam_min = tr * 0.5 - disc
        lam_max = tr * 0.5 + disc
        phi = 0.5 * math.atan2(2.0 * sxy, sxx - syy)
        normals[m, 0] = -math.sin(phi)
        normals[m, 1] = math.cos(phi)
        if lam_max > 1e-12:
            planarity[m] = 1.0 - lam_min / (lam_max if lam_max >= 1e-12 else 1e-12)
        else:
            planarity[m] = 0.0


_normals = compiled(_normals_py)


def point_normals(
    points: FloatArray, idx: IntArray, python: bool = False
) -> tuple[FloatArray, FloatArray]:
    """``(normals (M, 2), planarity (M,))`` of :func:`_normals_py` for the points ``(M, 2)``
    and their neighbours ``idx`` ``(M, k)`` (compiled; ``python``: the plain kernel)."""
    if not python:
        require_numba("normals backend")
    normals = np.empty((len(points), 2))
    planarity = np.empty(len(points))
    (_normals_py if python else _normals)(
        np.ascontiguousarray(points[:, 0]),
        np.ascontiguousarray(points[:, 1]),
        np.ascontiguousarray(idx, dtype=np.int64),
        normals,
        planarity,
    )
    return normals, planarity


def _condition3_py(h: FloatArray) -> float:
    """``|lambda|_min / |lambda|_max`` of a symmetric 3x3 (as ``scan_matcher._sym3_condition``)."""
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
        half = min(max(det_b / (2.0 * p**3), -1.0), 1.0)
        phi = math.acos(half) / 3.0
        e1 = q + 2.0 * p * math.cos(phi)
        e3 = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
        e2 = 3.0 * q - e1 - e3
    lo = min(abs(e1), abs(e2), abs(e3))
    hi = max(abs(e1), abs(e2), abs(e3))
    return lo / hi if hi > 0.0 else 0.0


_condition3 = compiled(_condition3_py)


def _icp_loop_py(
    px: FloatArray,
    py: FloatArray,
    pw: FloatArray,
    pose: FloatArray,
    has_prior: bool,
    mu: FloatArray,
    lam: FloatArray,
    max_iterations: int,
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
    floor2: float,
    inflation: float,
    tol_m: float,
    tol_rad: float,
    well_conditioned: float,
    h_scan: FloatArray,
    state: FloatArray,
) -> int:
    """The Gauss-Newton iterations of ``match_scan`` (compiled; ``pose`` updated in place).

    Stops when converged, after ``max_iterations``, or -- returning 1 -- before the step of an
    iteration whose matrix is not clearly regular (condition estimate ``<=
    well_conditioned``): the caller redoes that iteration with ``matrix_rank`` and LU.
    ``state`` gets ``[iterations done, n_matched, rmse, converged]``; ``h_scan`` the last
    scan information (unscaled). Returns 0 otherwise.
    """
    sums = np.empty(10)
    h = np.empty((3, 3))
    two_pi = 2.0 * math.pi
    n_matched = 0
    rmse = math.inf
    converged = 0.0
    status = 0
    it = 0
    while it < max_iterations:
        c = math.cos(pose[2])
        s = math.sin(pose[2])
        n_matched = _icp_terms(
            px, py, pw, c, s, pose[0], pose[1], radius_m, cell_m, x0, y0, nx, ny, start,
            order, xs, ys, packed, usable, huber_m, sums,
        )  # fmt: skip
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
        sigma2 = max(rmse * rmse if math.isfinite(rmse) else 0.0, floor2) * inflation
        for a in range(3):
            for b in range(3):
                h[a, b] = h_scan[a, b] / sigma2
        g0 /= sigma2
        g1 /= sigma2
        g2 /= sigma2
        if has_prior:
            e0 = pose[0] - mu[0]
            e1 = pose[1] - mu[1]
            e2 = (pose[2] - mu[2] + math.pi) % two_pi - math.pi
            for a in range(3):
                for b in range(3):
                    h[a, b] += lam[a, b]
            g0 += lam[0, 0] * e0 + lam[0, 1] * e1 + lam[0, 2] * e2
            g1 += lam[1, 0] * e0 + lam[1, 1] * e1 + lam[1, 2] * e2
            g2 += lam[2, 0] * e0 + lam[2, 1] * e1 + lam[2, 2] * e2
        if not _condition3(h) > well_conditioned:
            status = 1
            break
        a00, a01, a02 = h[0, 0], h[0, 1], h[0, 2]
        a11, a12, a22 = h[1, 1], h[1, 2], h[2, 2]
        c00 = a11 * a22 - a12 * a12
        c01 = a02 * a12 - a01 * a22
        c02 = a01 * a12 - a02 * a11
        c11 = a00 * a22 - a02 * a02
        c12 = a01 * a02 - a00 * a12
        c22 = a00 * a11 - a01 * a01
        det = a00 * c00 + a01 * c01 + a02 * c02
        d0 = -(c00 * g0 + c01 * g1 + c02 * g2) / det
        d1 = -(c01 * g0 + c11 * g1 + c12 * g2) / det
        d2 = -(c02 * g0 + c12 * g1 + c22 * g2) / det
        pose[0] += d0
        pose[1] += d1
        pose[2] = (pose[2] + d2 + math.pi) % two_pi - math.pi
        it += 1
        if math.hypot(d0, d1) < tol_m and abs(d2) < tol_rad:
            converged = 1.0
            break
    state[0] = it
    state[1] = n_matched
    state[2] = rmse
    state[3] = converged
    return status


_icp_loop = compiled(_icp_loop_py)


def icp_loop(
    px: FloatArray,
    py: FloatArray,
    pw: FloatArray,
    pose: FloatArray,
    mu: FloatArray | None,
    lam: FloatArray | None,
    max_iterations: int,
    radius_m: float,
    grid: BucketGrid,
    packed: FloatArray,
    usable: NDArray[np.bool_],
    huber_m: float,
    floor2: float,
    inflation: float,
    tol_m: float,
    tol_rad: float,
    well_conditioned: float,
) -> tuple[int, int, int, float, bool, FloatArray]:
    """Compiled :func:`_icp_loop_py`; ``pose`` is updated in place. Returns ``(status,
    iterations done, n_matched, rmse, converged, h_scan)``."""
    require_numba("ICP backend")
    has_prior = lam is not None
    state = np.empty(4)
    h_scan = np.zeros((3, 3))
    status = _icp_loop(
        px, py, pw, pose, has_prior,
        np.ascontiguousarray(mu, dtype=np.float64) if has_prior else np.zeros(3),
        np.ascontiguousarray(lam, dtype=np.float64) if has_prior else np.zeros((3, 3)),
        int(max_iterations), float(radius_m), grid.cell_m, grid.x0, grid.y0, grid.nx, grid.ny,
        grid.start, grid.order, grid.xs, grid.ys, packed, usable, float(huber_m),
        float(floor2), float(inflation), float(tol_m), float(tol_rad), float(well_conditioned),
        h_scan, state,
    )  # fmt: skip
    return int(status), int(state[0]), int(state[1]), float(state[2]), bool(state[3]), h_scan
