"""Optional numba kernels of :class:`.ltm_map.LTMMap` (extra ``fast``).

* :func:`explained`: §4.4's test (the complement of "semistatic") one point at a time, from
  the points and their covariances (the search radius from the covariance's largest
  eigenvalue, the point's cell and its offset in it, as the numpy code computes them), the
  3 x 3 cells around it first, then its whole search square, stopping at the first occupied
  cell within its circle; the numpy code builds ``(points x cells)`` arrays instead.
* :func:`stencil`: eq. 15's stencil cells around each point with their squared Mahalanobis
  distances (the numpy code builds ``(points x cells)`` arrays and keeps the near ones);
* :func:`fuse`: the end of eq. 15's update: the occupied log-odds of the stencils added in
  the numpy code's order, then ``l_free`` once per cell along each sampled beam (the free
  space before the point, walked sample by sample); the numpy code collects every ray
  sample, keeps one per (beam, cell) with ``np.unique`` and adds with ``np.add.at``.

The arithmetic is the numpy code's, operation for operation (the same float64 ray samples and
cell truncation, float32 sums, the threshold compared in float32 as numpy does with a float32
grid; ``sqrt`` and ``floor`` are exact IEEE operations), so the results are identical; the
tests check the plain-Python kernels (what numba compiles) and the compiled ones against the
numpy code. Transcendental functions (the stencil's ``exp``/``log``, ``hypot``) stay in
numpy, whose results the kernels take.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, pick_kernel
from dynmap_sim.jit import numba_available as numba_available  # re-exported

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


def _explained_py(  # type: ignore[no-untyped-def]
    logodds,
    l_occupied32,
    points,
    covs,
    origin_x_m,
    origin_y_m,
    res_m,
    floor2_m2,
    n_sigma,
    rho_max_m,
    ix,
    iy,
    fx,
    fy,
    rho_m,
    out,
):
    """``out[j]``: an occupied cell (``logodds >= l_occupied32``) of the ``(2 k + 1)^2``
    cells around point ``j`` (``k = max(k_max, 1)``; indices clipped to the grid, as the
    numpy code does) has its centre within ``rho_m[j]`` of the point. First, per point: its
    cell ``ix, iy``, its offset ``fx, fy`` [cells] from the cell's centre and ``rho_m``,
    ``n_sigma`` standard deviations along the widest axis of ``covs[j]`` plus ``floor2_m2``
    on the diagonal, within ``[1.5 res_m, rho_max_m]`` (the scratch arrays ``ix`` ... ``rho_m``
    are filled); ``k_max`` from the largest ``rho_m``."""
    h, w = logodds.shape
    n = points.shape[0]
    rho_top = -math.inf
    for j in range(n):
        a = covs[j, 0, 0] + floor2_m2
        c = covs[j, 1, 1] + floor2_m2
        b = covs[j, 0, 1]
        d = a - c
        lam = 0.5 * (a + c) + math.sqrt(0.25 * (d * d) + b * b)
        rho = min(max(n_sigma * math.sqrt(lam), 1.5 * res_m), rho_max_m)
        rho_m[j] = rho
        rho_top = max(rho_top, rho)
        gx = (points[j, 0] - origin_x_m) / res_m
        gy = (points[j, 1] - origin_y_m) / res_m
        ix[j] = int(math.floor(gx))
        iy[j] = int(math.floor(gy))
        fx[j] = gx - ix[j] - 0.5
        fy[j] = gy - iy[j] - 0.5
    k_max = int(math.ceil(rho_top / res_m))
    k1 = 1
    for j in range(n):
        r2 = rho_m[j] * rho_m[j]
        hit = False
        # the 3 x 3 cells first (a return on a mapped wall), then the rest of the square
        for ring in range(2):
            k = k1 if ring == 0 else k_max
            if ring == 1 and k_max <= k1:
                break
            for oy in range(-k, k + 1):
                cy = min(max(iy[j] + oy, 0), h - 1)
                dy = oy - fy[j]
                for ox in range(-k, k + 1):
                    if ring == 1 and -k1 <= ox <= k1 and -k1 <= oy <= k1:
                        continue
                    cx = min(max(ix[j] + ox, 0), w - 1)
                    if logodds[cy, cx] >= l_occupied32:
                        dx = ox - fx[j]
                        d2 = dx * dx + dy * dy
                        if d2 * res_m * res_m <= r2:
                            hit = True
                            break
                if hit:
                    break
            if hit:
                break
        out[j] = hit


def _fuse_py(  # type: ignore[no-untyped-def]
    logodds,
    occ_flat,
    occ_add32,
    do_free,
    laser_x_m,
    laser_y_m,
    ux,
    uy,
    stop_m,
    t_m,
    origin_x_m,
    origin_y_m,
    res_m,
    l_free32,
):
    """Add ``occ_add32`` at the flat cells ``occ_flat`` in order, then (``do_free``)
    ``l_free32`` to every cell that beam ``j``'s samples ``laser + u_j t`` with
    ``t < stop_m[j]`` fall in, once per beam (a ray's samples in a cell are consecutive: the
    cell indices along a ray are monotone)."""
    h, w = logodds.shape
    flat = logodds.reshape(-1)
    for i in range(occ_flat.shape[0]):
        flat[occ_flat[i]] += occ_add32[i]
    if not do_free:
        return
    for j in range(ux.shape[0]):
        prev = -1
        for i in range(t_m.shape[0]):
            t = t_m[i]
            if not t < stop_m[j]:
                break
            fx = laser_x_m + ux[j] * t
            fy = laser_y_m + uy[j] * t
            cx = int(math.floor((fx - origin_x_m) / res_m))
            cy = int(math.floor((fy - origin_y_m) / res_m))
            if 0 <= cx < w and 0 <= cy < h:
                c = cy * w + cx
                if c != prev:
                    flat[c] += l_free32
                    prev = c


def _stencil_py(  # type: ignore[no-untyped-def]
    points, i_xx, i_xy, i_yy, hit, origin_x_m, origin_y_m, res_m, k, h, w, ix, iy, flat, m2
):
    """Eq. 15's stencil: for point ``j`` (if ``hit[j]``) the cells ``(ix + ox, iy + oy)``,
    ``oy`` then ``ox`` from ``-k`` to ``k`` (the numpy code's raveled order), inside the
    ``h x w`` grid with the squared Mahalanobis distance ``m2 < 9`` of the cell centre
    under the inverse covariance ``(i_xx, i_xy, i_yy)``; fills ``ix, iy`` (each point's
    cell) and the first entries of ``flat`` (flat cell index) and ``m2``, returns how many."""
    n_out = 0
    for j in range(points.shape[0]):
        px = points[j, 0]
        py = points[j, 1]
        ix[j] = int(math.floor((px - origin_x_m) / res_m))
        iy[j] = int(math.floor((py - origin_y_m) / res_m))
        if not hit[j]:
            continue
        two_xy = 2 * i_xy[j]
        for oy in range(-k, k + 1):
            cy = iy[j] + oy
            dy = origin_y_m + (cy + 0.5) * res_m - py
            for ox in range(-k, k + 1):
                cx = ix[j] + ox
                dx = origin_x_m + (cx + 0.5) * res_m - px
                d2 = i_xx[j] * dx * dx + two_xy * dx * dy
                d2 += i_yy[j] * dy * dy
                if 0 <= cx < w and 0 <= cy < h and d2 < 9.0:
                    flat[n_out] = cy * w + cx
                    m2[n_out] = d2
                    n_out += 1
    return n_out


_stencil = compiled(_stencil_py)
_explained = compiled(_explained_py)
_fuse = compiled(_fuse_py)


def explained(
    logodds: NDArray[np.float32],
    l_occupied: float,
    points: FloatArray,
    covs: FloatArray,
    origin_m: FloatArray,
    res_m: float,
    floor2_m2: float,
    n_sigma: float,
    rho_max_m: float,
    python: bool = False,
) -> NDArray[np.bool_]:
    """:func:`_explained_py` compiled (needs numba; ``python``: the plain kernel) on points
    ``(n, 2)`` [m] with covariances ``(n, 2, 2)`` [m²] (float64)."""
    kernel = pick_kernel(_explained_py, _explained, python, "long-term map")
    n = len(points)
    out = np.zeros(n, dtype=np.bool_)
    ix, iy = np.empty(n, dtype=np.intp), np.empty(n, dtype=np.intp)
    fx, fy, rho = np.empty(n), np.empty(n), np.empty(n)
    kernel(logodds, np.float32(l_occupied), np.ascontiguousarray(points, dtype=np.float64),
           np.ascontiguousarray(covs, dtype=np.float64), float(origin_m[0]),
           float(origin_m[1]), float(res_m), float(floor2_m2), float(n_sigma),
           float(rho_max_m), ix, iy, fx, fy, rho, out)  # fmt: skip
    return out


def fuse(
    logodds: NDArray[np.float32],
    occ_flat: IntArray,
    occ_add32: NDArray[np.float32],
    free: tuple[float, float, FloatArray, FloatArray, FloatArray, FloatArray] | None,
    origin_m: FloatArray,
    res_m: float,
    l_free: float,
    python: bool = False,
) -> None:
    """:func:`_fuse_py` compiled (needs numba; ``python``: the plain kernel), in place on
    ``logodds`` (C-contiguous); ``free``: ``(laser_x_m, laser_y_m, ux, uy, stop_m, t_m)`` or
    None."""
    kernel = pick_kernel(_fuse_py, _fuse, python, "long-term map")
    lx, ly, ux, uy, stop, t = free if free is not None else (0.0, 0.0, *([np.zeros(0)] * 4))
    kernel(logodds, occ_flat, occ_add32, free is not None, float(lx), float(ly), ux, uy, stop,
           t, float(origin_m[0]), float(origin_m[1]), float(res_m),
           np.float32(l_free))  # fmt: skip


def stencil(
    points: FloatArray,
    i_xx: FloatArray,
    i_xy: FloatArray,
    i_yy: FloatArray,
    hit: NDArray[np.bool_],
    origin_m: FloatArray,
    res_m: float,
    k: int,
    h: int,
    w: int,
    python: bool = False,
) -> tuple[IntArray, FloatArray, IntArray, IntArray]:
    """:func:`_stencil_py` compiled (needs numba; ``python``: the plain kernel): the flat
    cells and squared Mahalanobis distances of the kept stencil cells, and each point's
    cell ``ix, iy``."""
    kernel = pick_kernel(_stencil_py, _stencil, python, "long-term map")
    n = len(points)
    ix, iy = np.empty(n, dtype=np.intp), np.empty(n, dtype=np.intp)
    flat = np.empty(n * (2 * k + 1) ** 2, dtype=np.intp)
    m2 = np.empty(len(flat))
    m = kernel(np.ascontiguousarray(points, dtype=np.float64), i_xx, i_xy, i_yy, hit,
               float(origin_m[0]), float(origin_m[1]), float(res_m), int(k), int(h), int(w),
               ix, iy, flat, m2)  # fmt: skip
    return flat[:m], m2[:m], ix, iy
