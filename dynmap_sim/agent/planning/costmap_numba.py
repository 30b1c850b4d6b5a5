"""Optional numba kernels of :class:`~.costmap.Costmap` (extra ``fast``).

* :func:`mark_scan`: the obstacle layer's update by one scan (:meth:`.Costmap.update`) in one
  loop over the beams, each ray walked sample by sample, instead of numpy's (beams x samples)
  arrays. The arithmetic is the numpy code's, operation for operation (the ray samples in
  float32, truncation to cells, ``rint`` for end points), so the marks are identical.
* :func:`clearance_window`: the exact Euclidean distance transform of the union of the static
  and the obstacle layer over a window of the grid (Felzenszwalb & Huttenlocher, "Distance
  transforms of sampled functions", ToC 2012: a column pass, then the lower envelope of
  parabolas per row), in integer squared cells with exact rational comparisons, so each
  cell's ``sqrt(d2) * res`` equals ``scipy.ndimage.distance_transform_edt``'s bit for bit.

Each kernel is plain Python (the reference the tests run against the numpy code), compiled
with :func:`dynmap_sim.jit.compiled` when numba is installed.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled
from dynmap_sim.jit import numba_available as numba_available  # re-exported

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: cells: keeps ray coordinates positive so that truncation is floor (as in :mod:`.costmap`)
OFFSET_CELLS = 1 << 16


def _mark_scan_py(  # type: ignore[no-untyped-def]
    marks,
    origin_x_m,
    origin_y_m,
    res_m,
    lp_x_m,
    lp_y_m,
    cos_th,
    sin_th,
    ranges_m,
    range_min_m,
    range_max_m,
    raytrace_range_m,
    inf_clear_range_m,
    obstacle_range_m,
    max_persistence,
    ray_origin_x32,
    ray_origin_y32,
    footprint_keys,
):
    """Mark and clear ``marks`` (``(H, W)`` int8, in place) with one scan; True when a cell's
    obstacle state changed. The beam directions, the laser pose and the ray origin in cells
    (float32, offset) come from the caller (numpy's trigonometry)."""
    h, w = marks.shape
    flat = marks.reshape(-1)
    n_beams = ranges_m.shape[0]
    clear_m = np.zeros(n_beams)
    own_end = np.full(n_beams, -1, np.int64)
    marked = np.empty(n_beams, np.int64)
    n_marked = 0
    seen = np.zeros(h * w, np.uint8)  # bit 1: passed, bit 2: marked
    max_clear_m = 0.0
    for b in range(n_beams):
        r = ranges_m[b]
        valid = math.isfinite(r) and r >= range_min_m
        hit = valid and r < range_max_m
        no_return = r == math.inf or (valid and not hit)
        c = min(r, raytrace_range_m) if hit else 0.0
        if no_return:
            c = min(inf_clear_range_m, raytrace_range_m)
        clear_m[b] = c
        max_clear_m = max(max_clear_m, c)
        end_r = r if hit else 0.0
        row = np.int64(np.rint((lp_y_m + sin_th[b] * end_r - origin_y_m) / res_m))
        col = np.int64(np.rint((lp_x_m + cos_th[b] * end_r - origin_x_m) / res_m))
        if hit and 0 <= row < h and 0 <= col < w:
            key = row * w + col
            own_end[b] = key
            if r <= obstacle_range_m and not seen[key] & 2:
                seen[key] |= 2
                marked[n_marked] = key
                n_marked += 1
    n_samples = int(math.ceil(max_clear_m / (0.5 * res_m)))
    res32 = np.float32(res_m)
    passed = np.empty(1024, np.int64)
    n_passed = 0
    for b in range(n_beams):
        # the samples i with float32(t_i * res) < clear_m (a prefix: t_i grows with i)
        n_b = min(n_samples, int(math.ceil(clear_m[b] / (0.5 * res_m))) + 1)
        while n_b > 0 and not np.float32(np.float32(0.5 * (n_b - 1)) * res32) < clear_m[b]:
            n_b -= 1
        dx32 = np.float32(cos_th[b])
        dy32 = np.float32(sin_th[b])
        last = -1
        for i in range(n_b):
            t32 = np.float32(0.5 * i)
            col = np.int64(np.int32(np.float32(ray_origin_x32 + np.float32(t32 * dx32))))
            row = np.int64(np.int32(np.float32(ray_origin_y32 + np.float32(t32 * dy32))))
            col -= OFFSET_CELLS
            row -= OFFSET_CELLS
            if row < 0 or row >= h or col < 0 or col >= w:
                continue
            key = row * w + col
            if key == last:
                continue
            last = key
            # a cell without a mark stays without one: only marked cells need passing
            if flat[key] <= 0 or key == own_end[b] or seen[key] & 1:
                continue
            seen[key] |= 1
            if n_passed == passed.shape[0]:
                grown = np.empty(2 * n_passed, np.int64)
                grown[:n_passed] = passed
                passed = grown
            passed[n_passed] = key
            n_passed += 1
    n_foot = footprint_keys.shape[0]
    before = np.empty(n_passed + n_marked + n_foot, np.bool_)
    for k in range(n_passed):
        before[k] = flat[passed[k]] > 0
    for k in range(n_marked):
        before[n_passed + k] = flat[marked[k]] > 0
    for k in range(n_foot):
        before[n_passed + n_marked + k] = flat[footprint_keys[k]] > 0
    for k in range(n_passed):
        flat[passed[k]] = max(flat[passed[k]] - 1, 0)
    for k in range(n_marked):
        flat[marked[k]] = min(flat[marked[k]] + 1, max_persistence)
    for k in range(n_foot):
        flat[footprint_keys[k]] = 0
    for k in range(n_passed):
        if before[k] != (flat[passed[k]] > 0):
            return True
    for k in range(n_marked):
        if before[n_passed + k] != (flat[marked[k]] > 0):
            return True
    for k in range(n_foot):
        if before[n_passed + n_marked + k] != (flat[footprint_keys[k]] > 0):
            return True
    return False


def _clearance_window_py(static, marks, r0, r1, c0, c1, res_m):  # type: ignore[no-untyped-def]
    """Distance [m] from each cell of the window ``[r0:r1, c0:c1]`` to the nearest cell of it
    that is ``static`` or has ``marks > 0`` (inf everywhere when none); exact EDT."""
    h, w = r1 - r0, c1 - c0
    inf_cells = h + w + 1  # farther than any distance in the window
    g = np.empty((h, w), np.int64)  # distance along the column [cells], rows in order
    any_occ = False
    for i in range(h):
        for j in range(w):
            if static[r0 + i, c0 + j] or marks[r0 + i, c0 + j] > 0:
                g[i, j] = 0
                any_occ = True
            elif i > 0 and g[i - 1, j] < inf_cells:
                g[i, j] = g[i - 1, j] + 1
            else:
                g[i, j] = inf_cells
    for i in range(h - 2, -1, -1):
        for j in range(w):
            if g[i + 1, j] + 1 < g[i, j]:
                g[i, j] = g[i + 1, j] + 1
    out = np.empty((h, w))
    if not any_occ:
        out[:] = math.inf
        return out
    v = np.empty(w, np.int64)  # columns of the parabolas of the lower envelope
    zn = np.empty(w + 1, np.int64)  # their left boundaries zn / zd (zd > 0)
    zd = np.empty(w + 1, np.int64)
    f = np.empty(w, np.int64)
    for i in range(h):
        k = -1
        for q in range(w):
            if g[i, q] >= inf_cells:
                continue
            fq = g[i, q] * g[i, q]
            f[q] = fq
            num, den = 0, 1
            while k >= 0:
                vk = v[k]
                num = (fq + q * q) - (f[vk] + vk * vk)
                den = 2 * (q - vk)
                if k > 0 and num * zd[k] <= zn[k] * den:
                    k -= 1
                    continue
                break
            k += 1
            v[k] = q
            zn[k], zd[k] = num, den  # k == 0: -inf, never read
        n_env = k + 1
        k = 0
        for p in range(w):
            while k + 1 < n_env and zn[k + 1] < p * zd[k + 1]:
                k += 1
            dq = p - v[k]
            out[i, p] = math.sqrt(float(dq * dq + f[v[k]])) * res_m
    return out


_mark_scan_nb = compiled(_mark_scan_py)
_clearance_window_nb = compiled(_clearance_window_py)


def mark_scan(*args: object, python: bool = False) -> bool:
    """:func:`_mark_scan_py` compiled (its arguments; ``python``: the uncompiled kernel)."""
    fn = _mark_scan_py if python or _mark_scan_nb is None else _mark_scan_nb
    return bool(fn(*args))


def clearance_window(
    static: NDArray[np.bool_],
    marks: NDArray[np.int8],
    rows: tuple[int, int],
    cols: tuple[int, int],
    res_m: float,
    python: bool = False,
) -> FloatArray:
    """The exact clearance [m] of the window ``rows x cols`` of the layers (kernel doc);
    ``python``: the uncompiled kernel."""
    fn = _clearance_window_py if python or _clearance_window_nb is None else _clearance_window_nb
    return fn(static, marks, int(rows[0]), int(rows[1]), int(cols[0]), int(cols[1]), float(res_m))
