"""Shortest paths on a coarse occupancy grid of the current world snapshot (the driver's map).

This belongs to the *simulation* (the scripted operator sees the truth), not to the agent.
The grid is built by rasterizing the static segments and round obstacles, its clearance comes
from a Euclidean distance transform, and paths are found by Dijkstra (A* with a zero
heuristic, Hart et al. 1968) over the 8-connected free cells with ``scipy.sparse.csgraph``,
then shortened by string pulling (line-of-sight shortcuts).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

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

    def center_of(self, ij: NDArray[np.int64]) -> FloatArray:
        """Cell indices ``(..., 2)`` -> cell centres ``(..., 2)`` in metres (x, y)."""
        return self.origin + np.asarray(ij, dtype=np.float64)[..., ::-1] * self.resolution_m

    def clearance_at(self, xy: FloatArray) -> FloatArray:
        """Clearance [m] at points (nearest cell)."""
        ij = self.cell_of(xy)
        return self.clearance_m[ij[..., 0], ij[..., 1]]

    def segment_clear(self, a: FloatArray, b: FloatArray, min_clearance_m: float) -> bool:
        """True when every grid cell on the straight line a->b has at least the clearance."""
        n = max(2, int(np.ceil(np.hypot(*(b - a)) / (0.5 * self.resolution_m))) + 1)
        pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        return bool(np.all(self.clearance_at(pts) >= min_clearance_m))


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
        length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
        n = np.maximum(2, np.ceil(length / (0.4 * resolution_m)).astype(int) + 1)
        idx = np.repeat(np.arange(len(seg)), n)
        u = np.concatenate([np.linspace(0.0, 1.0, k) for k in n])
        p = seg[idx, :2] + u[:, None] * (seg[idx, 2:] - seg[idx, :2])
        ij = grid.cell_of(p)
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


def _grid_graph(
    grid: ClearanceGrid, min_clearance_m: float, preferred_clearance_m: float
) -> csr_matrix:
    """8-connected graph over free cells; an edge costs its length, more near obstacles."""
    h, w = grid.shape
    free = grid.clearance_m >= min_clearance_m
    penalty = 1.0 + 2.0 * np.clip(
        (preferred_clearance_m - grid.clearance_m) / max(preferred_clearance_m, 1e-9), 0.0, 1.0
    )
    ids = np.arange(h * w).reshape(h, w)
    rows, cols, costs = [], [], []
    for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1)):
        j0, j1 = max(0, -dj), w - max(0, dj)
        a = ids[0 : h - di, j0:j1]
        b = ids[di:h, j0 + dj : j1 + dj]
        fa = free.ravel()[a.ravel()]
        fb = free.ravel()[b.ravel()]
        ok = fa & fb
        step = grid.resolution_m * (np.sqrt(2.0) if di and dj else 1.0)
        c = step * 0.5 * (penalty.ravel()[a.ravel()] + penalty.ravel()[b.ravel()])
        rows += [a.ravel()[ok], b.ravel()[ok]]
        cols += [b.ravel()[ok], a.ravel()[ok]]
        costs += [c[ok], c[ok]]
    return csr_matrix(
        (np.concatenate(costs), (np.concatenate(rows), np.concatenate(cols))), shape=(h * w,) * 2
    )


class GridPlanner:
    """Plans collision-free polylines on a :class:`ClearanceGrid`.

    ``min_clearance_m`` is the hard limit (robot radius plus a safety margin); paths prefer
    ``preferred_clearance_m``.
    """

    def __init__(
        self, grid: ClearanceGrid, min_clearance_m: float, preferred_clearance_m: float
    ) -> None:
        self.grid = grid
        self.min_clearance_m = float(min_clearance_m)
        self.preferred_clearance_m = float(max(preferred_clearance_m, min_clearance_m))
        self._graph: csr_matrix | None = None

    def is_free(self, xy: FloatArray) -> bool:
        return bool(self.grid.clearance_at(np.asarray(xy, float)) >= self.min_clearance_m)

    def nearest_free(self, xy: FloatArray, max_dist_m: float) -> FloatArray | None:
        """The free cell centre nearest to ``xy`` within ``max_dist_m``, or None."""
        if self.is_free(xy):
            return np.asarray(xy, dtype=np.float64)
        g = self.grid
        ij = g.cell_of(np.asarray(xy, float))
        k = int(np.ceil(max_dist_m / g.resolution_m))
        r0, r1 = max(0, ij[0] - k), min(g.shape[0], ij[0] + k + 1)
        c0, c1 = max(0, ij[1] - k), min(g.shape[1], ij[1] + k + 1)
        win = g.clearance_m[r0:r1, c0:c1] >= self.min_clearance_m
        if not win.any():
            return None
        rr, cc = np.nonzero(win)
        d = np.hypot(rr + r0 - ij[0], cc + c0 - ij[1])
        j = int(np.argmin(d))
        if d[j] * g.resolution_m > max_dist_m:
            return None
        return g.center_of(np.array([rr[j] + r0, cc[j] + c0]))

    def plan(self, a: FloatArray, b: FloatArray) -> FloatArray | None:
        """A polyline ``(K, 2)`` from ``a`` to ``b`` (both free), or None if unreachable."""
        a = np.asarray(a, dtype=np.float64)
        b = np.asarray(b, dtype=np.float64)
        if self.grid.segment_clear(a, b, self.min_clearance_m):
            return np.stack([a, b])
        if self._graph is None:
            self._graph = _grid_graph(self.grid, self.min_clearance_m, self.preferred_clearance_m)
        w = self.grid.shape[1]
        ia, ib = self.grid.cell_of(a), self.grid.cell_of(b)
        src, dst = int(ia[0] * w + ia[1]), int(ib[0] * w + ib[1])
        dist, pred = dijkstra(self._graph, indices=src, return_predecessors=True)
        if not np.isfinite(dist[dst]):
            return None
        cells = [dst]
        while cells[-1] != src:
            cells.append(int(pred[cells[-1]]))
        cells.reverse()
        ij = np.stack([np.array(cells) // w, np.array(cells) % w], axis=1)
        pts = np.concatenate([a[None], self.grid.center_of(ij)[1:-1], b[None]])
        return self._string_pull(pts)

    def _string_pull(self, pts: FloatArray) -> FloatArray:
        """Drop intermediate vertices while the straight shortcut stays clear."""
        out = [pts[0]]
        i, n = 0, len(pts)
        while i < n - 1:
            j = i + 1
            while j + 1 < n and self.grid.segment_clear(pts[i], pts[j + 1], self.min_clearance_m):
                j += 1
            out.append(pts[j])
            i = j
        return np.array(out)
