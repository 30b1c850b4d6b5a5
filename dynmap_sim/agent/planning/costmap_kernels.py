"""The compiled kernels of :class:`~.costmap.Costmap`.

* :func:`mark_scan`: the obstacle layer's update by one scan (:meth:`.Costmap.update`) in one
  loop over the beams, each ray walked every half cell (float32 samples truncated to cells,
  ``rint`` for end points), skipping the samples in squares of blocks without marks.
* :func:`clearance_window` / :func:`window_clearance`: the exact Euclidean distance transform
  of the union of the static and the obstacle layer over a window of the grid (Felzenszwalb &
  Huttenlocher, "Distance transforms of sampled functions", ToC 2012: a column pass, then the
  lower envelope of parabolas per row) in integer squared cells, so each cell's
  ``sqrt(d2) * res`` is the exact distance to the nearest obstacle cell's centre.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: cells: keeps ray coordinates positive so that truncation is floor
OFFSET_CELLS = 1 << 16


#: side of the blocks [cells] whose lack of marks lets :func:`mark_scan` skip ray samples
#: (4: the fastest of 2, 3, 4 and 8 cells, see docs/tuning/navigation.md)
BLOCK = 4
#: skipped samples keep this far [cells] inside their block: 6x float32's error of a ray
#: sample's position near ``OFFSET_CELLS`` (half an ulp, 2^-8 cells, for each of two samples)
BLOCK_MARGIN_CELLS = 0.05


@compiled
def chessboard_distance(dist):  # type: ignore[no-untyped-def]
    """``dist`` ``(H, W)`` int64 in place: each entry := the least ``dist[q] + chessboard
    distance to q`` over all entries q (Rosenfeld & Pfaltz's two passes, 8-neighbours)."""
    h, w = dist.shape
    for i in range(h):
        for j in range(w):
            d = dist[i, j]
            if j > 0:
                d = min(d, dist[i, j - 1] + 1)
            if i > 0:
                for jj in range(max(j - 1, 0), min(j + 2, w)):
                    d = min(d, dist[i - 1, jj] + 1)
            dist[i, j] = d
    for i in range(h - 1, -1, -1):
        for j in range(w - 1, -1, -1):
            d = dist[i, j]
            if j + 1 < w:
                d = min(d, dist[i, j + 1] + 1)
            if i + 1 < h:
                for jj in range(max(j - 1, 0), min(j + 2, w)):
                    d = min(d, dist[i + 1, jj] + 1)
            dist[i, j] = d


@compiled
def _slab_clip(s_lo, s_hi, p, d, inv_d, lo, hi):  # type: ignore[no-untyped-def]
    """The travel interval ``[s_lo, s_hi]`` of a ray along one axis (position ``p``,
    direction ``d``, ``inv_d = 1 / d``) clipped to the slab ``lo <= p + s * d <= hi``; a ray
    parallel to the slab outside it gets ``s_hi = -1`` (no travel)."""
    if d > 0.0:
        return max(s_lo, (lo - p) * inv_d), min(s_hi, (hi - p) * inv_d)
    if d < 0.0:
        return max(s_lo, (hi - p) * inv_d), min(s_hi, (lo - p) * inv_d)
    if not lo <= p <= hi:
        return s_lo, -1.0
    return s_lo, s_hi


class GridFrame(NamedTuple):
    """Where a grid lies: the centre of its cell ``(0, 0)`` [m] and its cell size [m]."""

    origin_x_m: float
    origin_y_m: float
    res_m: float


class ScanLimits(NamedTuple):
    """The ranges [m] :func:`mark_scan` reads a scan with (:class:`.CostmapParams` and the
    laser's), and the most scans a mark survives (``max_persistence_scans``)."""

    range_min_m: float
    range_max_m: float
    raytrace_range_m: float
    inf_clear_range_m: float
    obstacle_range_m: float
    max_persistence: int


@compiled
def mark_scan(  # type: ignore[no-untyped-def]
    marks, frame, laser_xy, cos_th, sin_th, ranges_m, limits, robot_xy, footprint_cells, seen
):
    """Mark and clear ``marks`` (``(H, W)`` int8, in place) with one scan taken from
    ``laser_xy`` [m] on the grid ``frame`` (:class:`GridFrame`); True when a cell's obstacle
    state changed. ``cos_th``/``sin_th``: the beams' directions in the map frame;
    ``limits``: :class:`ScanLimits`; ``footprint_cells`` ``(K, 2)``: the (row, col) offsets
    of the cells around the robot's cell at ``robot_xy`` that are cleared; ``seen``
    ``(H * W,)`` uint8 is scratch, zero on entry and on return (no grid-sized allocation per
    scan)."""
    origin_x_m, origin_y_m, res_m = frame
    lp_x_m, lp_y_m = laser_xy
    robot_x_m, robot_y_m = robot_xy
    range_min_m, range_max_m = limits.range_min_m, limits.range_max_m
    raytrace_range_m, inf_clear_range_m = limits.raytrace_range_m, limits.inf_clear_range_m
    obstacle_range_m, max_persistence = limits.obstacle_range_m, limits.max_persistence
    h, w = marks.shape
    flat = marks.reshape(-1)
    # the ray origin in cells for truncation, offset to stay >= 0
    ray_origin_x32 = np.float32((lp_x_m - origin_x_m) / res_m + 0.5 + OFFSET_CELLS)
    ray_origin_y32 = np.float32((lp_y_m - origin_y_m) / res_m + 0.5 + OFFSET_CELLS)
    # the footprint's cells in the grid
    robot_row = np.int64(np.rint((robot_y_m - origin_y_m) / res_m))
    robot_col = np.int64(np.rint((robot_x_m - origin_x_m) / res_m))
    footprint_keys = np.empty(footprint_cells.shape[0], np.int64)
    n_foot = 0
    for k in range(footprint_cells.shape[0]):
        row = robot_row + footprint_cells[k, 0]
        col = robot_col + footprint_cells[k, 1]
        if 0 <= row < h and 0 <= col < w:
            footprint_keys[n_foot] = row * w + col
            n_foot += 1
    n_beams = ranges_m.shape[0]
    clear_m = np.zeros(n_beams)
    own_end = np.full(n_beams, -1, np.int64)
    marked = np.empty(n_beams, np.int64)
    n_marked = 0
    # seen: bit 1 passed, bit 2 marked
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
    # blocks of BLOCK x BLOCK cells around the laser; free[bi, bj]: the chessboard distance
    # [blocks] from a block to the nearest block with a mark (0: it has one) or outside the
    # region. The samples of a ray in the free square of blocks around its block need no look
    # (a cell without a mark stays without one)
    lr = np.int64(np.int32(ray_origin_y32)) - OFFSET_CELLS
    lc = np.int64(np.int32(ray_origin_x32)) - OFFSET_CELLS
    reach = n_samples // 2 + 2
    br0 = max(lr - reach, 0) // BLOCK
    bc0 = max(lc - reach, 0) // BLOCK
    nbr = max(min(lr + reach, h - 1) // BLOCK + 1, br0) - br0
    nbc = max(min(lc + reach, w - 1) // BLOCK + 1, bc0) - bc0
    free = np.empty((nbr, nbc), np.int64)
    for bi in range(nbr):
        for bj in range(nbc):
            free[bi, bj] = min(bi + 1, nbr - bi, bj + 1, nbc - bj)
    for i in range(br0 * BLOCK, min((br0 + nbr) * BLOCK, h)):
        for j in range(bc0 * BLOCK, min((bc0 + nbc) * BLOCK, w)):
            if flat[i * w + j] > 0:
                free[i // BLOCK - br0, j // BLOCK - bc0] = 0
    chessboard_distance(free)
    passed = np.empty(1024, np.int64)
    n_passed = 0
    for b in range(n_beams):
        # the samples i with float32(t_i * res) < clear_m (a prefix: t_i grows with i)
        n_b = min(n_samples, int(math.ceil(clear_m[b] / (0.5 * res_m))) + 1)
        while n_b > 0 and not np.float32(np.float32(0.5 * (n_b - 1)) * res32) < clear_m[b]:
            n_b -= 1
        dx32 = np.float32(cos_th[b])
        dy32 = np.float32(sin_th[b])
        # 1 / direction (only for the conservative skip: its rounding does not matter)
        inv_dx = 1.0 / float(dx32) if dx32 != 0.0 else math.inf
        inv_dy = 1.0 / float(dy32) if dy32 != 0.0 else math.inf
        last = -1
        i = 0
        while i < n_b:
            t32 = np.float32(0.5 * i)
            xf = np.float32(ray_origin_x32 + np.float32(t32 * dx32))
            yf = np.float32(ray_origin_y32 + np.float32(t32 * dy32))
            i += 1
            col = np.int64(np.int32(xf)) - OFFSET_CELLS
            row = np.int64(np.int32(yf)) - OFFSET_CELLS
            if row < 0 or row >= h or col < 0 or col >= w:
                continue
            bi, bj = row // BLOCK - br0, col // BLOCK - bc0
            k = free[bi, bj] if 0 <= bi < nbr and 0 <= bj < nbc else 0
            if k > 0:
                # skip the next samples that surely stay in the free square of blocks around
                # this one: those whose exact position is BLOCK_MARGIN_CELLS inside it (s:
                # travel [cells] from here)
                x, y = float(xf) - OFFSET_CELLS, float(yf) - OFFSET_CELLS
                lo_x = (bc0 + bj - k + 1) * BLOCK + BLOCK_MARGIN_CELLS
                hi_x = (bc0 + bj + k) * BLOCK - BLOCK_MARGIN_CELLS
                lo_y = (br0 + bi - k + 1) * BLOCK + BLOCK_MARGIN_CELLS
                hi_y = (br0 + bi + k) * BLOCK - BLOCK_MARGIN_CELLS
                s_lo, s_hi = _slab_clip(
                    -math.inf, 2.0 * BLOCK * (2 * k - 1), x, dx32, inv_dx, lo_x, hi_x
                )
                s_lo, s_hi = _slab_clip(s_lo, s_hi, y, dy32, inv_dy, lo_y, hi_y)
                if s_lo <= 0.49 and s_hi >= 0.5:  # the next sample and those up to s_hi
                    i += int(1.99 * s_hi)
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
    for k in range(n_passed):
        seen[passed[k]] = 0
    for k in range(n_marked):
        seen[marked[k]] = 0
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


@compiled
def _distance(static, marks, outer, inner, cap_cells, res_m, margin_m, out):  # type: ignore[no-untyped-def]
    """Distance [m] ``d`` from each cell of the window ``inner`` ``(a0, a1, b0, b1)`` (rows
    ``a0:a1``, columns ``b0:b1``) to the nearest obstacle cell (``static`` or ``marks > 0``)
    of the window ``outer`` ``(r0, r1, c0, c1)`` that holds it, written to ``out``
    (grid-sized) as ``d`` where ``d < margin_m``, else ``max(out, margin_m)`` (with
    ``margin_m = inf``: ``d``, inf without an obstacle). Obstacles more than ``cap_cells``
    away along their column are left out: ``d`` is exact up to ``cap_cells`` cells and never
    below the exact value."""
    r0, r1, c0, c1 = outer
    a0, a1, b0, b1 = inner
    h, w = r1 - r0, c1 - c0
    inf_cells = h + w + 1  # farther than any distance in the window
    g = np.empty((a1 - a0, w), np.int64)  # distance along the column [cells]
    last = np.full(w, -inf_cells, np.int64)  # the last obstacle row above, per column
    for i in range(r0, a1):
        for j in range(w):
            if static[i, c0 + j] or marks[i, c0 + j] > 0:
                last[j] = i
            if i >= a0:
                g[i - a0, j] = min(i - last[j], inf_cells)
    nxt = np.full(w, r1 + inf_cells, np.int64)  # the next obstacle row below
    for i in range(r1 - 1, a0 - 1, -1):
        for j in range(w):
            if static[i, c0 + j] or marks[i, c0 + j] > 0:
                nxt[j] = i
            if i < a1 and nxt[j] - i < g[i - a0, j]:
                g[i - a0, j] = nxt[j] - i
    v = np.empty(w, np.int64)  # columns of the parabolas of the lower envelope
    zn = np.empty(w + 1, np.int64)  # their left boundaries zn / zd (zd > 0)
    zd = np.empty(w + 1, np.int64)
    f = np.empty(w, np.int64)
    for i in range(a1 - a0):
        k = -1
        for q in range(w):
            if g[i, q] > cap_cells or g[i, q] >= inf_cells:
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
        for p in range(b0 - c0, b1 - c0):
            d = math.inf
            if n_env > 0:
                while k + 1 < n_env and zn[k + 1] < p * zd[k + 1]:
                    k += 1
                dq = p - v[k]
                d = math.sqrt(float(dq * dq + f[v[k]])) * res_m
            if d < margin_m:
                out[a0 + i, c0 + p] = d
            else:
                out[a0 + i, c0 + p] = max(out[a0 + i, c0 + p], margin_m)


def clearance_window(
    static: NDArray[np.bool_],
    marks: NDArray[np.int8],
    rows: tuple[int, int],
    cols: tuple[int, int],
    res_m: float,
) -> FloatArray:
    """The exact clearance [m] of the window ``rows x cols`` of the layers (obstacles inside
    it only; inf without one)."""
    (r0, r1), (c0, c1) = rows, cols
    out = np.zeros(static.shape)
    window = (r0, r1, c0, c1)
    _distance(static, marks, window, window, r1 - r0 + c1 - c0, res_m, math.inf, out)
    return out[r0:r1, c0:c1]


def window_clearance(
    static: NDArray[np.bool_],
    marks: NDArray[np.int8],
    outer: tuple[int, int, int, int],
    inner: tuple[int, int, int, int],
    res_m: float,
    margin_m: float,
    out: FloatArray,
) -> None:
    """:meth:`.Costmap.window_clearance`'s update of ``out`` in the window ``inner`` (rows,
    cols: ``a0, a1, b0, b1``) from the obstacles in ``outer`` (``r0, r1, c0, c1``): the exact
    distance where below ``margin_m`` [m], else ``max(out, margin_m)``."""
    cap_cells = int(math.ceil(margin_m / res_m)) + 1  # every distance < margin_m is exact
    _distance(static, marks, outer, inner, cap_cells, res_m, margin_m, out)
