"""Optional numba kernels of :class:`.ltm_map.LTMMap` (extra ``fast``).

* :func:`explained`: §4.4's test (the complement of "semistatic") one point at a time, from
  the points and their covariances (the search radius from the covariance's largest
  eigenvalue, the point's cell and its offset in it, as the numpy code computes them), the
  3 x 3 cells around it first, then its whole search square, stopping at the first occupied
  cell within its circle; the numpy code builds ``(points x cells)`` arrays instead.
* :func:`update`: eq. 15's whole update (H&W §4.3) in a few calls instead of some forty
  numpy calls on a few dozen points: :func:`_stencil_py`, the stencil cells around each
  point with their squared Mahalanobis distances (the floored inverse covariance inline;
  the numpy code builds ``(points x cells)`` arrays and keeps the near ones);
  :func:`_free_rays_py`, each sampled beam's direction and where its free space stops;
  :func:`_fuse_py`, the occupied log-odds of the stencils added in the numpy code's order,
  then ``l_free`` once per cell along each sampled beam (walked sample by sample; the numpy
  code collects every ray sample, keeps one per (beam, cell) with ``np.unique`` and adds
  with ``np.add.at``), and the clamp and re-pin of the cells it changed.
* :func:`point_covariances`: eqs. 12-14's points and covariances after the cosines and
  sines (one loop instead of some twenty numpy calls).

The arithmetic is the numpy code's, operation for operation (the same float64 ray samples and
cell truncation, float32 sums, the threshold compared in float32 as numpy does with a float32
grid; ``sqrt`` and ``floor`` are exact IEEE operations), so the results are identical; the
tests check the plain-Python kernels (what numba compiles) and the compiled ones against the
numpy code. Transcendental functions (the stencil's ``exp``/``log``, the beams' ``cos``/``sin``)
stay in numpy, whose results the kernels take; ``np.hypot`` is the C library's in numba as
in numpy.
"""

from __future__ import annotations

import math
from typing import Any

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
    pinned,
    occ_flat,
    occ_add,
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
    l_min32,
    l_max32,
):
    """Add ``occ_add`` (float64, each rounded to float32 first) at the flat cells
    ``occ_flat`` in order, then (``do_free``) ``l_free32`` to every cell that beam ``j``'s
    samples ``laser + u_j t`` with ``t < stop_m[j]`` fall in, once per beam (a ray's
    samples in a cell are consecutive: the cell indices along a ray are monotone). Then
    the cells it added to are clamped (:func:`_clamp_cell_py`): the numpy code clamps the
    whole rectangle between the laser and the stencils, whose other cells are already
    within the clamps (every map starts so), which changes nothing there."""
    h, w = logodds.shape
    flat = logodds.reshape(-1)
    pin = pinned.reshape(-1)
    for i in range(occ_flat.shape[0]):
        flat[occ_flat[i]] += np.float32(occ_add[i])
    n_free = 0
    touched = np.empty(ux.shape[0] * t_m.shape[0] if do_free else 0, dtype=np.intp)
    if do_free:
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
                        touched[n_free] = c
                        n_free += 1
    for i in range(occ_flat.shape[0]):
        _clamp_cell(flat, pin, occ_flat[i], l_min32, l_max32)
    for i in range(n_free):
        _clamp_cell(flat, pin, touched[i], l_min32, l_max32)


def _clamp_cell_py(flat, pin, c, l_min32, l_max32):  # type: ignore[no-untyped-def]
    """``np.clip`` of cell ``c`` to ``[l_min32, l_max32]``, ``l_max32`` if ``pin[c]``
    (numpy's clip is ``min(max(v, lo), hi)``, each taking the bound unless ``v`` is strictly
    beyond it or NaN: the same zero's sign); idempotent."""
    if pin[c]:
        flat[c] = l_max32
    else:
        v = flat[c]
        v = v if v > l_min32 or v != v else l_min32
        flat[c] = v if v < l_max32 or v != v else l_max32


def _odds_py(e, p_hit):  # type: ignore[no-untyped-def]
    """In place: ``p = 0.5 + (p_hit - 0.5) e`` (``e``: ``exp(-m²/2)``, eq. 15's
    peak-normalized Gaussian), then its odds ``p / (1 - p)``."""
    for i in range(e.shape[0]):
        p = 0.5 + (p_hit - 0.5) * e[i]
        e[i] = p / (1.0 - p)


def _stencil_py(  # type: ignore[no-untyped-def]
    points, covs, floor2_m2, hit, origin_x_m, origin_y_m, res_m, k, h, w, flat, m2
):
    """Eq. 15's stencil: for point ``j`` (if ``hit[j]``) the cells ``(ix + ox, iy + oy)``,
    ``oy`` then ``ox`` from ``-k`` to ``k`` (the numpy code's raveled order), inside the
    ``h x w`` grid with the squared Mahalanobis distance ``m2 < 9`` of the cell centre
    under the inverse of ``covs[j]`` plus ``floor2_m2`` on the diagonal (in closed form, as
    :func:`.ltm_map.floored_inverse`); fills the first entries of ``flat`` (flat cell
    index) and ``m2`` (``-m²/2``: the exponent of eq. 15's Gaussian); returns how many."""
    n_out = 0
    for j in range(points.shape[0]):
        px = points[j, 0]
        py = points[j, 1]
        ix = int(math.floor((px - origin_x_m) / res_m))
        iy = int(math.floor((py - origin_y_m) / res_m))
        if not hit[j]:
            continue
        a = covs[j, 0, 0] + floor2_m2
        c = covs[j, 1, 1] + floor2_m2
        b = covs[j, 0, 1]
        det = a * c - b * b
        i_xx = c / det
        i_xy = -b / det
        i_yy = a / det
        two_xy = 2 * i_xy
        for oy in range(-k, k + 1):
            cy = iy + oy
            dy = origin_y_m + (cy + 0.5) * res_m - py
            for ox in range(-k, k + 1):
                cx = ix + ox
                dx = origin_x_m + (cx + 0.5) * res_m - px
                d2 = i_xx * dx * dx + two_xy * dx * dy
                d2 += i_yy * dy * dy
                if 0 <= cx < w and 0 <= cy < h and d2 < 9.0:
                    flat[n_out] = cy * w + cx
                    m2[n_out] = -0.5 * d2
                    n_out += 1
    return n_out


def _free_rays_py(  # type: ignore[no-untyped-def]
    points, covs, floor2_m2, laser_x_m, laser_y_m, free_stop_sigma, res_m, ux, uy, stop_m
):
    """The free space of eq. 15's update (:meth:`.ltm_map.LTMMap.update`): per point ``j``
    its beam's unit vector ``ux, uy`` from the laser and where the free space stops,
    ``stop_m[j]``: ``free_stop_sigma`` standard deviations (of the floored covariance
    along the beam) before the point, at least one cell ``res_m``; returns the largest
    ``stop_m`` (at least 0)."""
    top = 0.0
    for j in range(points.shape[0]):
        a = covs[j, 0, 0] + floor2_m2
        c = covs[j, 1, 1] + floor2_m2
        b = covs[j, 0, 1]
        d0 = points[j, 0] - laser_x_m
        d1 = points[j, 1] - laser_y_m
        r = np.hypot(d0, d1)
        dd = (a * d0 * d0 + 2.0 * b * d0 * d1) + c * d1 * d1  # dᵀ Σ d
        rm = r if r >= 1e-9 else 1e-9
        q = dd / (rm * rm)
        sig = math.sqrt(q if q >= 0.0 else 0.0)
        s = free_stop_sigma * sig
        stop = r - (s if s >= res_m else res_m)
        stop_m[j] = stop
        top = max(top, stop)
        ux[j] = d0 / rm
        uy[j] = d1 / rm
    return top


def _point_covariances_py(  # type: ignore[no-untyped-def]
    x, y, lx, ly, cov_pose, ranges, cb, sb, var_alpha, sigma_r, points, covs
):
    """Eqs. 12-14 (:func:`.ltm_map.point_covariances`) after the cosines and sines: the
    world points ``lx + r cb, ly + r sb`` of the readings from the laser at ``(lx, ly)``
    (the robot at ``(x, y)``) and their covariances, the terms of
    :func:`.ltm_map.point_covariance_terms` in its order, into ``points`` ``(n, 2)`` and
    ``covs`` ``(n, 2, 2)``."""
    p00 = cov_pose[0, 0]
    p01 = cov_pose[0, 1]
    p02 = cov_pose[0, 2]
    p11 = cov_pose[1, 1]
    p12 = cov_pose[1, 2]
    p20 = cov_pose[2, 0]
    p21 = cov_pose[2, 1]
    p22 = cov_pose[2, 2]
    for j in range(ranges.shape[0]):
        r = ranges[j]
        c = cb[j]
        s = sb[j]
        px = lx + r * c
        py = ly + r * s
        points[j, 0] = px
        points[j, 1] = py
        ax = -(py - y)
        ay = px - x
        var_r = sigma_r[j] * sigma_r[j]
        r0x = p00 + ax * p20
        r2x = p02 + ax * p22
        r1y = p11 + ay * p21
        r2y = p12 + ay * p22
        r1x = p01 + ax * p21
        rs = r * s
        rc = r * c
        ta = rs * var_alpha
        tr = c * var_r
        xy = (r1x + ay * r2x) + (s * tr - rc * ta)
        covs[j, 0, 0] = (r0x + ax * r2x) + (rs * ta + c * tr)
        covs[j, 0, 1] = xy
        covs[j, 1, 0] = xy
        covs[j, 1, 1] = (r1y + ay * r2y) + (rc * (rc * var_alpha) + s * (s * var_r))


_stencil = compiled(_stencil_py)
_point_covariances = compiled(_point_covariances_py)
_explained = compiled(_explained_py)
_clamp_cell = compiled(_clamp_cell_py) or _clamp_cell_py
_fuse = compiled(_fuse_py)
_free_rays = compiled(_free_rays_py)
_odds = compiled(_odds_py)


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


def update(
    logodds: NDArray[np.float32],
    pinned: NDArray[np.bool_],
    laser_xy: FloatArray,
    points: FloatArray,
    covs: FloatArray,
    hit: NDArray[np.bool_],
    origin_m: FloatArray,
    res_m: float,
    params: Any,
    python: bool = False,
) -> None:
    """Eq. 15's update of :meth:`.ltm_map.LTMMap.update` with the kernels (needs numba;
    ``python``: the plain kernels), in place on ``logodds`` (C-contiguous): the stencils
    (:func:`_stencil_py`), their log-odds (``exp`` and ``log`` in numpy, the odds between
    them by :func:`_odds_py`), the free space (``params.free_space``: :func:`_free_rays_py`,
    the ray samples from ``np.arange`` as the numpy code's) and :func:`_fuse_py`, which adds
    them and clamps and re-pins the cells it changed. ``params``: an ``LTMParams``."""
    stencil_k = pick_kernel(_stencil_py, _stencil, python, "long-term map")
    odds_k = pick_kernel(_odds_py, _odds, python, "long-term map")
    fuse_k = pick_kernel(_fuse_py, _fuse, python, "long-term map")
    h, w = logodds.shape
    n = len(points)
    k = int(params.stencil_cells)
    ox, oy, res = float(origin_m[0]), float(origin_m[1]), float(res_m)
    floor2 = float(params.cov_floor_m**2)
    pts = np.ascontiguousarray(points, dtype=np.float64)
    cv = np.ascontiguousarray(covs, dtype=np.float64)
    flat = np.empty(n * (2 * k + 1) ** 2, dtype=np.intp)
    add = np.empty(len(flat))
    m = stencil_k(pts, cv, floor2, hit, ox, oy, res, k, h, w, flat, add)
    add = add[:m]
    np.exp(add, out=add)
    odds_k(add, float(params.p_hit))
    np.log(add, out=add)
    lx, ly = float(laser_xy[0]), float(laser_xy[1])
    ux, uy, stop = np.empty(n), np.empty(n), np.empty(n)
    t = np.zeros(0)
    if params.free_space:
        free_k = pick_kernel(_free_rays_py, _free_rays, python, "long-term map")
        top = free_k(pts, cv, floor2, lx, ly, float(params.free_stop_sigma), res, ux, uy, stop)
        t = np.arange(0.0, top, 0.5 * res)
    fuse_k(logodds, pinned, flat[:m], add, len(t) > 0, lx, ly, ux, uy, stop, t, ox, oy, res,
           np.float32(params.l_free), np.float32(params.l_min),
           np.float32(params.l_max))  # fmt: skip


def point_covariances(
    x: float,
    y: float,
    lx: float,
    ly: float,
    cov_pose: FloatArray,
    ranges: FloatArray,
    cb: FloatArray,
    sb: FloatArray,
    var_alpha: float,
    sigma_r: FloatArray,
    python: bool = False,
) -> tuple[FloatArray, FloatArray]:
    """:func:`_point_covariances_py` compiled (needs numba; ``python``: the plain kernel):
    the points ``(n, 2)`` and their covariances ``(n, 2, 2)``."""
    kernel = pick_kernel(_point_covariances_py, _point_covariances, python, "long-term map")
    n = len(ranges)
    points, covs = np.empty((n, 2)), np.empty((n, 2, 2))
    f64 = np.float64
    kernel(float(x), float(y), float(lx), float(ly), np.ascontiguousarray(cov_pose, dtype=f64),
           np.ascontiguousarray(ranges, dtype=f64), cb, sb, float(var_alpha),
           np.ascontiguousarray(sigma_r, dtype=f64), points, covs)  # fmt: skip
    return points, covs
