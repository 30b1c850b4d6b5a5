"""``grid-dijkstra``: shortest collision-free paths on a clearance grid (Planner role).

The grid (:mod:`.clearance_grid`) holds each cell's distance to the nearest obstacle; paths
are found by Dijkstra (A* with a zero heuristic, Hart et al. 1968) over the 8-connected free
cells with ``scipy.sparse.csgraph``, then shortened by string pulling (line-of-sight
shortcuts). An edge costs its length, up to 3x more where the clearance is below the
preferred clearance.

The planner only sees the grid it is given: the ``tour`` operator builds one from the true
world, the agent's own navigation from its own map.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid, clearance_penalty
from dynmap_sim.agent.planning.planner import Planner, register_planner

FloatArray = NDArray[np.float64]


def _grid_graph(
    grid: ClearanceGrid, min_clearance_m: float, preferred_clearance_m: float
) -> csr_matrix:
    """8-connected graph over free cells; an edge costs its length, more near obstacles."""
    h, w = grid.shape
    free = grid.clearance_m >= min_clearance_m
    penalty = clearance_penalty(grid.clearance_m, preferred_clearance_m)
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


@register_planner("grid-dijkstra")
class GridDijkstra(Planner):
    """Dijkstra on the 8-connected free cells of a :class:`ClearanceGrid`, string-pulled.

    ``min_clearance_m`` is the hard limit (robot radius plus a safety margin); paths prefer
    ``preferred_clearance_m``. The search graph of the last grid is cached (not pickled).
    """

    def __init__(self, min_clearance_m: float, preferred_clearance_m: float) -> None:
        super().__init__(min_clearance_m, preferred_clearance_m)
        self._graph: csr_matrix | None = None
        self._graph_of: ClearanceGrid | None = None

    def __getstate__(self) -> dict[str, object]:
        return {**self.__dict__, "_graph": None, "_graph_of": None}

    def plan(self, start: FloatArray, goal: FloatArray, grid: ClearanceGrid) -> FloatArray | None:
        """A polyline ``(K, 2)`` from ``start`` to ``goal`` (both free), or None if unreachable."""
        a = np.asarray(start, dtype=np.float64)
        b = np.asarray(goal, dtype=np.float64)
        if grid.segment_clear(a, b, self.min_clearance_m):
            return np.stack([a, b])
        if self._graph is None or self._graph_of is not grid:
            self._graph = _grid_graph(grid, self.min_clearance_m, self.preferred_clearance_m)
            self._graph_of = grid
        w = grid.shape[1]
        ia, ib = grid.cell_of(a), grid.cell_of(b)
        src, dst = int(ia[0] * w + ia[1]), int(ib[0] * w + ib[1])
        dist, pred = dijkstra(self._graph, indices=src, return_predecessors=True)
        if not np.isfinite(dist[dst]):
            return None
        cells = [dst]
        while cells[-1] != src:
            cells.append(int(pred[cells[-1]]))
        cells.reverse()
        ij = np.stack([np.array(cells) // w, np.array(cells) % w], axis=1)
        pts = np.concatenate([a[None], grid.center_of(ij)[1:-1], b[None]])
        return self._string_pull(pts, grid)

    def _string_pull(self, pts: FloatArray, grid: ClearanceGrid) -> FloatArray:
        """Drop intermediate vertices while the straight shortcut stays clear."""
        out = [pts[0]]
        i, n = 0, len(pts)
        while i < n - 1:
            j = i + 1
            while j + 1 < n and grid.segment_clear(pts[i], pts[j + 1], self.min_clearance_m):
                j += 1
            out.append(pts[j])
            i = j
        return np.array(out)
