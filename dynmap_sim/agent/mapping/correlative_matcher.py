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

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from dynmap_sim.agent.mapping import correlative_numba

FloatArray = NDArray[np.float64]


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


def _lookup(table: FloatArray, ix: NDArray[np.intp], iy: NDArray[np.intp]) -> FloatArray:
    h, w = table.shape
    return table[np.clip(iy, 0, h - 1), np.clip(ix, 0, w - 1)]


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
    backend: str = "auto",
) -> CorrelativeResult:
    """Best pose of ``points_base`` ``(N, 2)`` (scan frame) in ``target``'s frame.

    Searches ``init_pose +- (window_xy_m, window_xy_m, window_theta_rad)``; translations on
    the table's grid, rotations every ``theta_step_rad`` (default: the angle that moves the
    farthest point by one cell, Olson 2009 §IV-A). ``block`` is the branch-and-bound block
    size in cells; at most ``max_blocks`` blocks are refined (the search is then approximate).
    ``backend`` (:data:`dynmap_sim.jit.KERNEL_BACKENDS`): ``"numba"`` (``"auto"`` when
    installed) sums the bounds and the blocks' scores in compiled loops
    (:mod:`.correlative_numba`, the same result bit for bit).
    """
    kernels = correlative_numba.kernels(backend)
    pts = np.asarray(points_base, dtype=np.float64).reshape(-1, 2)
    init = np.asarray(init_pose, dtype=np.float64).reshape(3)
    if len(pts) == 0:
        return CorrelativeResult(init.copy(), 0.0, 0)
    res = target.resolution_m
    if theta_step_rad is None:
        theta_step_rad = angular_step(pts, res)
    n_th = int(np.ceil(window_theta_rad / theta_step_rad))
    thetas = init[2] + theta_step_rad * np.arange(-n_th, n_th + 1)
    n_xy = int(np.ceil(window_xy_m / res))
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
    if kernels is not None:
        bounds_of, search = kernels
        bounds = bounds_of(coarse, ix0, iy0, boff)
        order = np.ascontiguousarray(np.argsort(bounds, axis=None)[::-1])
        score, t, oy_c, ox_c, n_eval = search(
            order, bounds, fine, ix0, iy0, boff, block, 2 * n_xy, max_blocks
        )
        return _result(init, thetas, start, res, (t, oy_c, ox_c), score, n_eval, len(pts))
    bounds = _lookup(
        coarse,
        ix0[:, :, None, None] + boff[None, None, None, :],
        iy0[:, :, None, None] + boff[None, None, :, None],
    ).sum(axis=1)  # (T, block_y, block_x): all rotations in one lookup
    order = np.argsort(bounds, axis=None)[::-1]
    best_score, best = -1.0, (0, 0, 0)
    n_eval = 0
    foff = np.arange(block)
    for flat in order[:max_blocks]:
        t, by, bx = np.unravel_index(flat, bounds.shape)
        if bounds[t, by, bx] <= best_score:
            break
        # The last block of a row may reach past the window: its cells beyond are left out
        # (the block's bound, over all its cells, stays an upper bound).
        ox = boff[bx] + foff[boff[bx] + foff <= 2 * n_xy]
        oy = boff[by] + foff[boff[by] + foff <= 2 * n_xy]
        vals = _lookup(
            fine,
            ix0[t][:, None, None] + ox[None, None, :],
            iy0[t][:, None, None] + oy[None, :, None],
        ).sum(axis=0)  # (block_y, block_x)
        n_eval += vals.size
        k = int(np.argmax(vals))
        if vals.flat[k] > best_score:
            best_score = float(vals.flat[k])
            best = (int(t), int(oy[k // len(ox)]), int(ox[k % len(ox)]))
    return _result(init, thetas, start, res, best, best_score, n_eval, len(pts))


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
