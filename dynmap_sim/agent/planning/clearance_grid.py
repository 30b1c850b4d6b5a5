"""A clearance grid: the distance to the nearest obstacle [m] on a regular grid.

Obstacles (segments and discs) are rasterized and a Euclidean distance transform gives each
cell its clearance; planners search it and controllers regulate their speed by it (nav2's
inflation layer plays this part in a costmap).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from dynmap_sim.agent.grid import points_on_segments

FloatArray = NDArray[np.float64]


@dataclass
class ClearanceGrid:
    """Distance to the nearest obstacle [m] on a regular grid; ``origin`` is the centre of
    cell ``(0, 0)``, rows are y and columns x."""

    origin: FloatArray
    resolution_m: float
    clearance_m: FloatArray  # (H, W)

    @property
    def shape(self) -> tuple[int, int]:
        return self.clearance_m.shape  # type: ignore[return-value]

    def cell_of(self, xy: FloatArray) -> NDArray[np.int64]:
        """``(..., 2)`` points -> ``(..., 2)`` (row, col) indices, clipped to the grid."""
        xy = np.asarray(xy, dtype=np.float64)
        ij = np.rint((xy[..., ::-1] - self.origin[::-1]) / self.resolution_m).astype(np.int64)
        return np.clip(ij, 0, np.array(self.shape) - 1)

    def cell_index(self, x_m: float, y_m: float) -> tuple[int, int]:
        """:meth:`cell_of` of one point ``(x_m, y_m)`` as ``(row, col)`` ints (the same
        arithmetic on floats: round half to even, clipped to the grid)."""
        h, w = self.clearance_m.shape
        ox, oy = self.origin.tolist()
        row = round((float(y_m) - oy) / self.resolution_m)
        col = round((float(x_m) - ox) / self.resolution_m)
        return min(max(row, 0), h - 1), min(max(col, 0), w - 1)

    def center_of(self, ij: NDArray[np.int64]) -> FloatArray:
        """Cell indices ``(..., 2)`` -> cell centres ``(..., 2)`` in metres (x, y)."""
        return self.origin + np.asarray(ij, dtype=np.float64)[..., ::-1] * self.resolution_m

    def clearance_at(self, xy: FloatArray) -> FloatArray:
        """Clearance [m] at points (nearest cell)."""
        ij = self.cell_of(xy)
        return self.clearance_m[ij[..., 0], ij[..., 1]]

    def segment_clear(self, a: FloatArray, b: FloatArray, min_clearance_m: float) -> bool:
        """True when every grid cell on the straight line a->b has at least the clearance. A
        non-finite end is never clear; the samples are capped at four per grid row and column
        (a segment inside the grid needs at most half that), so an end far off the grid costs
        no more than the grid itself."""
        a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        length = float(np.hypot(*(b - a)))
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b)) and np.isfinite(length)):
            return False
        cap = 4 * (self.shape[0] + self.shape[1])
        n = max(2, int(min(np.ceil(length / (0.5 * self.resolution_m)) + 1.0, cap)))
        pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        return bool(np.all(self.clearance_at(pts) >= min_clearance_m))

    def is_free(self, xy: FloatArray, min_clearance_m: float) -> bool:
        """True when the cell of ``xy`` has at least ``min_clearance_m``."""
        return bool(self.clearance_at(np.asarray(xy, float)) >= min_clearance_m)

    def nearest_free(
        self, xy: FloatArray, min_clearance_m: float, max_dist_m: float
    ) -> FloatArray | None:
        """The cell centre nearest to ``xy`` (within ``max_dist_m``) with at least
        ``min_clearance_m``; ``xy`` itself when it is free; None when there is none."""
        if self.is_free(xy, min_clearance_m):
            return np.asarray(xy, dtype=np.float64)
        ij = self.cell_of(np.asarray(xy, float))
        k = int(np.ceil(max_dist_m / self.resolution_m))
        r0, r1 = max(0, ij[0] - k), min(self.shape[0], ij[0] + k + 1)
        c0, c1 = max(0, ij[1] - k), min(self.shape[1], ij[1] + k + 1)
        win = self.clearance_m[r0:r1, c0:c1] >= min_clearance_m
        if not win.any():
            return None
        rr, cc = np.nonzero(win)
        d = np.hypot(rr + r0 - ij[0], cc + c0 - ij[1])
        j = int(np.argmin(d))
        if d[j] * self.resolution_m > max_dist_m:
            return None
        return self.center_of(np.array([rr[j] + r0, cc[j] + c0]))


def build_clearance_grid(
    segments: FloatArray,
    circles: FloatArray,
    resolution_m: float = 0.05,
    margin_m: float = 1.0,
) -> ClearanceGrid:
    """Rasterize segments ``(N, 4)`` and circles ``(M, 3)`` (x, y, r) and compute clearance."""
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    circ = np.asarray(circles, dtype=np.float64).reshape(-1, 3)
    pts = [seg[:, :2], seg[:, 2:]]
    if len(circ):
        pts += [circ[:, :2] - circ[:, 2:3], circ[:, :2] + circ[:, 2:3]]
    allp = np.concatenate(pts) if len(seg) or len(circ) else np.zeros((1, 2))
    lo = allp.min(axis=0) - margin_m
    hi = allp.max(axis=0) + margin_m
    shape = tuple((np.ceil((hi - lo) / resolution_m)).astype(int)[::-1] + 1)
    grid = ClearanceGrid(lo, resolution_m, np.zeros(shape))
    occ = np.zeros(shape, dtype=bool)
    if len(seg):
        ij = grid.cell_of(points_on_segments(seg, 0.4 * resolution_m))
        occ[ij[:, 0], ij[:, 1]] = True
    for x, y, r in circ:
        ij = grid.cell_of(np.array([x, y]))
        k = int(np.ceil(r / resolution_m)) + 1
        rr, cc = np.mgrid[-k : k + 1, -k : k + 1]
        inside = np.hypot(rr, cc) * resolution_m <= r
        rr, cc = rr[inside] + ij[0], cc[inside] + ij[1]
        ok = (rr >= 0) & (rr < shape[0]) & (cc >= 0) & (cc < shape[1])
        occ[rr[ok], cc[ok]] = True
    # a cell holding an obstacle point has clearance ~0; others the distance to the nearest
    grid.clearance_m = ndimage.distance_transform_edt(~occ) * resolution_m
    return grid


def clearance_penalty(clearance_m: FloatArray, preferred_clearance_m: float) -> FloatArray:
    """Per-cell cost factor in ``[1, 3]``: 1 at ``preferred_clearance_m`` or more, 3 at an
    obstacle (the preference of ``grid-dijkstra``)."""
    pref = max(preferred_clearance_m, 1e-9)
    return 1.0 + 2.0 * np.clip((preferred_clearance_m - clearance_m) / pref, 0.0, 1.0)
