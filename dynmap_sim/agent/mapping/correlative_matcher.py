"""Correlative scan matching: exhaustive multi-resolution search over (x, y, theta).

Olson 2009 ("Real-time correlative scan matching", §III-IV) scores a candidate pose by the
sum, over the scan's points, of a rasterized likelihood of the target,

    score(x) = sum_i L(T(x) p_i),   L(c) = exp(-d(c)^2 / (2 sigma^2)),

with ``d(c)`` the distance from cell ``c`` to the nearest target point, and finds the
best pose by brute force inside a search window, so it needs no good initial guess (unlike
ICP, whose basin is about the correspondence distance). The search is made fast by a
two-level branch and bound (Olson 2009 §IV-B; Hess et al. 2016 §V): a low-resolution table
``M[c] = max L`` over the ``B x B`` block of fine cells starting at ``c`` gives, for each
block of ``B x B`` translations, an upper bound of the fine score of every translation in
the block; blocks are expanded best bound first and the search stops as soon as the best
fine score found is at least the next block's bound, so the result is the exact optimum of
the fine grid.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from dynmap_sim.jit import compiled

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]


@dataclass(frozen=True)
class CorrelativeResult:
    """Best pose ``(3,)`` of the scan's frame in the target frame and its normalized score
    (mean likelihood per point, in ``[0, 1]``); ``n_evaluated`` fine translations scored."""

    pose: FloatArray
    score: float
    n_evaluated: int


class LikelihoodTable:
    """Rasterized likelihood ``L`` of a target point set ``(M, 2)`` [m] (Olson 2009 §III).

    ``margin_m`` pads the grid beyond the points' bounding box; cells hold
    ``exp(-d^2 / (2 sigma_m^2))`` of the distance ``d`` [m] to the nearest target point.
    """

    def __init__(
        self,
        points: ArrayLike,
        resolution_m: float = 0.05,
        sigma_m: float = 0.05,
        margin_m: float = 1.0,
    ) -> None:
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if len(pts) == 0:
            raise ValueError("LikelihoodTable needs at least one target point")
        if resolution_m <= 0 or sigma_m <= 0:
            raise ValueError("resolution_m and sigma_m must be > 0")
        self.resolution_m = float(resolution_m)
        self.origin = pts.min(axis=0) - margin_m
        size = np.ceil((pts.max(axis=0) + margin_m - self.origin) / resolution_m).astype(int) + 1
        hit = np.ones((size[1], size[0]), dtype=bool)
        ix, iy = self.cell_of(pts)
        hit[iy, ix] = False
        d_m = ndimage.distance_transform_edt(hit) * resolution_m
        self.table = np.exp(-0.5 * (d_m / sigma_m) ** 2)
        self.table[0, :] = self.table[-1, :] = 0.0  # a zero border: clipped lookups score 0
        self.table[:, 0] = self.table[:, -1] = 0.0

    def cell_of(self, xy: FloatArray) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Cell indices ``(ix, iy)`` of points ``(N, 2)`` (may be outside the table)."""
        c = np.floor((xy - self.origin) / self.resolution_m).astype(np.intp)
        return c[:, 0], c[:, 1]

    def block_max(self, block: int) -> FloatArray:
        """``M[iy, ix] = max table[iy : iy + block, ix : ix + block]`` (Hess et al. §V-A)."""
        if block <= 1:
            return self.table
        # maximum_filter centres its window; shift it so that the window starts at the cell.
        off = -(block // 2)
        return ndimage.maximum_filter(
            self.table, size=block, mode="constant", cval=0.0, origin=(off, off)
        )


@compiled
def _bounds(coarse: FloatArray, ix0: IntArray, iy0: IntArray, boff: IntArray) -> FloatArray:
    """``out[t, by, bx]``: the sum over points ``i`` of ``coarse`` at ``(iy0[t, i] +
    boff[by], ix0[t, i] + boff[bx])``, clipped to the table (whose border is zero)."""
    h, w = coarse.shape
    n_t, n_p = ix0.shape
    nb = boff.shape[0]
    out = np.zeros((n_t, nb, nb))
    for t in range(n_t):
        for i in range(n_p):
            for by in range(nb):
                y = min(max(iy0[t, i] + boff[by], 0), h - 1)
                for bx in range(nb):
                    x = min(max(ix0[t, i] + boff[bx], 0), w - 1)
                    out[t, by, bx] += coarse[y, x]
    return out


class _Window(NamedTuple):
    """The fine search of :func:`_search`: ``fine`` table, each rotation's point cells
    ``ix0``/``iy0`` ``(T, N)`` at the window's start, block offsets ``boff`` [cells], the
    block size, the last translation offset, the most blocks refined."""

    fine: FloatArray
    ix0: IntArray
    iy0: IntArray
    boff: IntArray
    block: int
    last: int
    max_blocks: int


@compiled
def _search(order: IntArray, bounds: FloatArray, win: _Window) -> tuple:
    """The blocks in ``order`` (flat indices of ``bounds``), at most ``max_blocks``, until a
    bound is no better than the best fine score: ``(best score, rotation, y offset, x
    offset, fine translations scored)``; translation offsets beyond ``last`` are left out
    (the block's bound, over all its cells, stays an upper bound)."""
    fine, ix0, iy0, boff, block = win.fine, win.ix0, win.iy0, win.boff, win.block
    h, w = fine.shape
    n_p = ix0.shape[1]
    nb = bounds.shape[1]
    vals = np.empty((block, block))
    best_score = -1.0
    best_t = best_y = best_x = 0
    n_eval = 0
    for j in range(min(win.max_blocks, order.shape[0])):
        flat = order[j]
        t = flat // (nb * nb)
        by = (flat // nb) % nb
        bx = flat % nb
        if bounds[t, by, bx] <= best_score:
            break
        oy0 = boff[by]
        ox0 = boff[bx]
        ny = min(block, win.last - oy0 + 1)
        nx = min(block, win.last - ox0 + 1)
        vals[:ny, :nx] = 0.0
        for i in range(n_p):
            for a in range(ny):
                y = min(max(iy0[t, i] + oy0 + a, 0), h - 1)
                for b in range(nx):
                    x = min(max(ix0[t, i] + ox0 + b, 0), w - 1)
                    vals[a, b] += fine[y, x]
        n_eval += ny * nx
        ka = kb = 0
        for a in range(ny):  # the first maximum in row-major order
            for b in range(nx):
                if vals[a, b] > vals[ka, kb]:
                    ka, kb = a, b
        if vals[ka, kb] > best_score:
            best_score = vals[ka, kb]
            best_t, best_y, best_x = t, oy0 + ka, ox0 + kb
    return best_score, best_t, best_y, best_x, n_eval


def angular_step(points_base: ArrayLike, resolution_m: float) -> float:
    """The rotation step [rad] that moves the farthest of ``points_base`` ``(N, 2)`` by one
    cell of side ``resolution_m`` (Olson 2009 §IV-A): :func:`correlative_match`'s default."""
    pts = np.asarray(points_base, dtype=np.float64).reshape(-1, 2)
    r_max = max(float(np.max(np.hypot(pts[:, 0], pts[:, 1]))) if len(pts) else 0.0, resolution_m)
    return float(np.arccos(max(1.0 - resolution_m**2 / (2.0 * r_max**2), -1.0)))


def correlative_match(
    points_base: ArrayLike,
    target: LikelihoodTable,
    init_pose: ArrayLike,
    window_xy_m: float = 1.0,
    window_theta_rad: float = 0.3,
    theta_step_rad: float | None = None,
    block: int = 8,
    max_blocks: int = 400,
) -> CorrelativeResult:
    """Best pose of ``points_base`` ``(N, 2)`` (scan frame) in ``target``'s frame.

    Searches ``init_pose +- (window_xy_m, window_xy_m, window_theta_rad)``; translations on
    the table's grid, rotations every ``theta_step_rad`` (default: the angle that moves the
    farthest point by one cell, Olson 2009 §IV-A). ``block`` is the branch-and-bound block
    size in cells; at most ``max_blocks`` blocks are refined (the search is then approximate).
    """
    pts = np.asarray(points_base, dtype=np.float64).reshape(-1, 2)
    init = np.asarray(init_pose, dtype=np.float64).reshape(3)
    if len(pts) == 0:
        return CorrelativeResult(init.copy(), 0.0, 0)
    res = target.resolution_m
    if theta_step_rad is None:
        theta_step_rad = angular_step(pts, res)
    n_th = int(np.ceil(window_theta_rad / theta_step_rad))
    thetas = init[2] + theta_step_rad * np.arange(-n_th, n_th + 1)
    n_xy = int(np.ceil(window_xy_m / res - 1e-9))  # a whole number of cells is exact
    block = max(1, int(block))
    n_blocks = int(np.ceil((2 * n_xy + 1) / block))
    start = -n_xy  # translation offsets [cells] of block b: start + b*block + (0..block-1)
    coarse = target.block_max(block)
    fine = target.table
    # Fine cells of every point at every rotation, with the translation at the window start.
    c, s = np.cos(thetas)[:, None], np.sin(thetas)[:, None]
    wx = c * pts[:, 0] - s * pts[:, 1] + init[0]
    wy = s * pts[:, 0] + c * pts[:, 1] + init[1]
    ix0 = np.floor((wx - target.origin[0]) / res).astype(np.intp) + start  # (T, N)
    iy0 = np.floor((wy - target.origin[1]) / res).astype(np.intp) + start
    # Upper bounds of every (rotation, block_y, block_x): sum over points of M.
    boff = np.arange(n_blocks) * block
    bounds = _bounds(coarse, ix0, iy0, boff)
    order = np.ascontiguousarray(np.argsort(bounds, axis=None)[::-1])
    win = _Window(fine, ix0, iy0, boff, block, 2 * n_xy, int(max_blocks))
    score, t, oy_c, ox_c, n_eval = _search(order, bounds, win)
    return _result(init, thetas, start, res, (t, oy_c, ox_c), score, n_eval, len(pts))


def _result(
    init: FloatArray,
    thetas: FloatArray,
    start: int,
    res: float,
    best: tuple[int, int, int],
    best_score: float,
    n_eval: int,
    n_points: int,
) -> CorrelativeResult:
    """The pose of the best (rotation, y offset, x offset) [cells from ``start``] and its
    score per point."""
    t, oy_c, ox_c = (int(v) for v in best)
    pose = np.array(
        [init[0] + (start + ox_c) * res, init[1] + (start + oy_c) * res, thetas[t]],
        dtype=np.float64,
    )
    return CorrelativeResult(pose, float(best_score) / n_points, int(n_eval))
