"""``grid-astar``: A* on the free cells of a clearance grid (Planner role), and H&W §6.3 detours.

A* (Hart, Nilsson & Raphael, "A formal basis for the heuristic determination of minimum cost
paths", IEEE Trans. SSC 4(2), 1968) over the 8-connected cells whose clearance is at least
``min_clearance_m`` (robot radius + margin), with the edge costs of ``grid-dijkstra``: an
edge costs its length times the mean of its two cells' penalties
``1 + 2 * clip((preferred - clearance) / preferred, 0, 1)`` (up to 3x near obstacles, so
paths keep off walls, like nav2 Smac 2D's ``cost_travel_multiplier``). The open list is a
binary heap (``heapq``) with a closed set; ties in f prefer the larger g (the node nearer the
goal), which expands fewer cells on open floors.

**Heuristic**: the octile distance ``res * (max(|di|, |dj|) + (sqrt2 - 1) * min(|di|, |dj|))``,
the length of the shortest 8-connected path on an empty grid. *Admissible*: every edge costs
at least its length (penalty >= 1) and no 8-connected path is shorter than the octile
distance. *Consistent*: for a move n -> n' of length l, the octile distance obeys the
triangle inequality ``h(n) <= l + h(n')`` and the move costs at least l. So the first time the
goal is popped its cost is optimal and no node is reopened (Hart et al. 1968, Theorems 1-3):
the path costs exactly what Dijkstra's does. The cell path is then string-pulled
(line-of-sight shortcuts, as ``grid-dijkstra`` does).

The search is one compiled kernel (:func:`_astar`, numba's ``heapq`` on a list).

:func:`plan_around` is Hentschel & Wagner's §6.3 global replanning: when the path
ahead is blocked, plan from the robot to the first point of the path that is free beyond the
block, then follow the rest of the path.
"""

from __future__ import annotations

import heapq
import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid, clearance_penalty
from dynmap_sim.agent.planning.planner import Planner, register_planner
from dynmap_sim.jit import compiled

FloatArray = NDArray[np.float64]

_SQRT2 = math.sqrt(2.0)


@compiled
def _astar(free, penalty, h, w, src, dst, step_m, g, parent, closed):  # type: ignore[no-untyped-def]
    """A* from flat cell ``src`` to ``dst`` on an ``h x w`` grid; returns the path cost [m]
    (``inf`` when unreachable). ``free``/``penalty`` per cell; ``g`` (inf), ``parent`` (-1)
    and ``closed`` (0) are work buffers, ``parent`` holds the tree on return."""
    di_goal, dj_goal = dst // w, dst % w
    diag = _SQRT2 - 1.0
    i0, j0 = src // w, src % w
    a, b = abs(i0 - di_goal), abs(j0 - dj_goal)
    h0 = step_m * (max(a, b) + diag * min(a, b))
    g[src] = 0.0
    heap = [(h0, -0.0, src)]
    while len(heap) > 0:
        _, neg_g, u = heapq.heappop(heap)
        if closed[u]:
            continue
        gu = -neg_g
        if u == dst:
            return gu
        closed[u] = 1
        i, j = u // w, u % w
        pu = penalty[u]
        for k in range(8):
            if k < 4:
                di = (0, 1, 0, -1)[k]
                dj = (1, 0, -1, 0)[k]
                length = step_m
            else:
                di = (1, 1, -1, -1)[k - 4]
                dj = (1, -1, 1, -1)[k - 4]
                length = step_m * _SQRT2
            ii, jj = i + di, j + dj
            if ii < 0 or ii >= h or jj < 0 or jj >= w:
                continue
            v = ii * w + jj
            if closed[v] or not free[v]:
                continue
            gv = gu + length * 0.5 * (pu + penalty[v])
            if gv < g[v]:
                g[v] = gv
                parent[v] = u
                a, b = abs(ii - di_goal), abs(jj - dj_goal)
                heapq.heappush(heap, (gv + step_m * (max(a, b) + diag * min(a, b)), -gv, v))
    return math.inf


def astar_cells(
    free: NDArray[np.bool_], penalty: FloatArray, resolution_m: float, src: int, dst: int
) -> tuple[NDArray[np.int64], float] | None:
    """A* on the 8-connected ``free`` cells ``(H, W)`` with per-cell ``penalty``: the flat
    cell indices of a least-cost path ``src -> dst`` and its cost [m], or None when ``dst``
    cannot be reached (or either end is not free)."""
    h, w = free.shape
    n = h * w
    if not (free.flat[src] and free.flat[dst]):
        return None
    g = np.full(n, np.inf)
    par = np.full(n, -1, dtype=np.int64)
    cost = _astar(
        free.ravel().astype(np.uint8), np.ascontiguousarray(penalty, float).ravel(),
        h, w, int(src), int(dst), float(resolution_m), g, par, np.zeros(n, np.uint8),
    )  # fmt: skip
    if not math.isfinite(cost):
        return None
    cells = [int(dst)]
    while cells[-1] != src:
        cells.append(int(par[cells[-1]]))
    return np.array(cells[::-1], dtype=np.int64), float(cost)


@register_planner("grid-astar")
class GridAStar(Planner):
    """A* on the 8-connected free cells of a :class:`ClearanceGrid`, string-pulled.

    The graph (free cells, edge costs) of ``grid-dijkstra``, searched by A* with the octile
    heuristic instead of a full Dijkstra: the same path cost, a fraction of the work. Free
    means ``clearance >= min_clearance_m``; paths prefer ``preferred_clearance_m``. The free
    mask and penalties of the last grid are cached by its identity (not pickled).
    """

    def __init__(self, min_clearance_m: float, preferred_clearance_m: float) -> None:
        super().__init__(min_clearance_m, preferred_clearance_m)
        self._layers_of: tuple[ClearanceGrid, NDArray[np.bool_], FloatArray] | None = None
        #: cost [m] of the last cell path found (None when the last plan was direct or failed)
        self.last_cost_m: float | None = None

    def __getstate__(self) -> dict[str, object]:
        return {**self.__dict__, "_layers_of": None}

    def _layers(self, grid: ClearanceGrid) -> tuple[NDArray[np.bool_], FloatArray]:
        """Free cells and penalties of ``grid`` (cached for the last grid object)."""
        if self._layers_of is None or self._layers_of[0] is not grid:
            free = grid.clearance_m >= self.min_clearance_m
            pen = clearance_penalty(grid.clearance_m, self.preferred_clearance_m)
            self._layers_of = (grid, free, pen)
        return self._layers_of[1], self._layers_of[2]

    def plan(self, start: FloatArray, goal: FloatArray, grid: ClearanceGrid) -> FloatArray | None:
        """A polyline ``(K, 2)`` [m] from ``start`` to ``goal`` (both free), or None if
        unreachable."""
        a = np.asarray(start, dtype=np.float64)
        b = np.asarray(goal, dtype=np.float64)
        self.last_cost_m = None
        if grid.segment_clear(a, b, self.min_clearance_m):
            return np.stack([a, b])
        free, pen = self._layers(grid)
        w = grid.shape[1]
        ia, ib = grid.cell_of(a), grid.cell_of(b)
        src, dst = int(ia[0] * w + ia[1]), int(ib[0] * w + ib[1])
        found = astar_cells(free, pen, grid.resolution_m, src, dst)
        if found is None:
            return None
        cells, self.last_cost_m = found
        ij = np.stack([cells // w, cells % w], axis=1)
        pts = np.concatenate([a[None], grid.center_of(ij)[1:-1], b[None]])
        return self._string_pull(pts, grid)

    def _string_pull(self, pts: FloatArray, grid: ClearanceGrid) -> FloatArray:
        """Line-of-sight shortcuts over the cell path ``pts`` ``(K, 2)``: from each kept
        vertex, on to the farthest point reachable in a straight line with the clearance.

        Only the turning points of the 8-connected path are tested one by one; within the
        straight run that ends the line of sight a bisection finds the last visible point.
        The result is (nearly) the full point-by-point pull of ``grid-dijkstra`` with far
        fewer line-of-sight tests (each costs ~50 us)."""
        n = len(pts)
        if n <= 2:
            return pts
        step = np.diff(grid.cell_of(pts), axis=0)
        turns = np.nonzero(np.any(step[1:] != step[:-1], axis=1))[0] + 1
        corners = np.unique(np.concatenate([turns, [1, n - 1]]))

        def visible(i: int, j: int) -> bool:
            return grid.segment_clear(pts[i], pts[j], self.min_clearance_m)

        out, i = [pts[0]], 0
        while i < n - 1:
            ahead = corners[corners > i]
            j, k = int(ahead[0]), 1
            while k < len(ahead) and visible(i, int(ahead[k])):
                j, k = int(ahead[k]), k + 1
            if k < len(ahead):  # bisect the run j .. ahead[k] for the last visible point
                hi = int(ahead[k])
                while hi - j > 1:
                    mid = (j + hi) // 2
                    j, hi = (mid, hi) if visible(i, mid) else (j, mid)
            out.append(pts[j])
            i = j
        return np.array(out)


def _densify(path_xy: FloatArray, step_m: float) -> tuple[FloatArray, FloatArray]:
    """Points every ``step_m`` along a polyline (its vertices kept) and their arc length [m]."""
    p = np.asarray(path_xy, dtype=np.float64).reshape(-1, 2)
    seg = np.hypot(*np.diff(p, axis=0).T)
    n = np.maximum(np.ceil(seg / step_m).astype(np.int64), 1)
    idx = np.repeat(np.arange(len(seg)), n)
    u = (np.arange(len(idx)) - np.repeat(np.cumsum(n) - n, n)) / n[idx]
    pts = np.concatenate([p[idx] + u[:, None] * (p[idx + 1] - p[idx]), p[-1:]])
    s0 = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.concatenate([s0[idx] + u * seg[idx], s0[-1:]])
    return pts, s


def plan_around(
    path_xy: FloatArray,
    start_xy: FloatArray,
    grid: ClearanceGrid,
    planner: Planner,
    snap_m: float = 0.5,
) -> FloatArray | None:
    """Hentschel & Wagner §6.3 global replanning: a path from ``start_xy`` around the first
    block on ``path_xy`` ``(K, 2)`` back onto it, then along it to its end.

    The path ahead of the robot (from the point nearest to ``start_xy``) is sampled every
    cell; the first stretch whose clearance is below ``planner.min_clearance_m`` is the
    block, and ``planner`` plans from the robot to the first free point behind it (to the
    next free stretch's first point if that one cannot be reached). When nothing blocks the
    path ahead, the result is the robot's position followed by the rest of the path, with a
    grid path to that nearest point when it is farther than ``snap_m`` and the straight line
    to it is not free (a robot on a detour, whose nearest path point may lie behind a
    wall). The
    start is moved to the nearest free cell within ``snap_m`` [m] when the robot stands in
    the inflated zone. None when the path cannot be rejoined (e.g. the block covers its end).
    """
    pts, s = _densify(path_xy, grid.resolution_m)
    here = np.asarray(start_xy, dtype=np.float64)
    k0 = int(np.argmin(np.hypot(*(pts - here).T)))
    ahead = pts[k0:]
    ok = grid.clearance_at(ahead) >= planner.min_clearance_m
    blocked = np.nonzero(~ok)[0]
    tail = [_vertices_after(path_xy, s[k0]), pts[-1:]]
    if len(blocked) == 0 and (
        float(np.hypot(*(pts[k0] - here))) <= snap_m
        or grid.segment_clear(here, pts[k0], planner.min_clearance_m)
    ):
        return np.concatenate([here[None], *tail])
    start = grid.nearest_free(here, planner.min_clearance_m, snap_m)
    if start is None:
        return None
    lead = here[None] if np.any(start != here) else np.zeros((0, 2))
    if len(blocked) == 0:
        # nothing blocks the path ahead, but the robot is away from it (on a detour) and
        # the straight way to its nearest point is not free: reach that point on the grid
        leg = planner.plan(start, pts[k0], grid)
        rest = tail if k0 < len(pts) - 1 else []
        return None if leg is None else np.concatenate([lead, leg, *rest])
    # first points of the free stretches behind the first block
    first_free = np.nonzero(ok[1:] & ~ok[:-1])[0] + 1
    for k in first_free[first_free > blocked[0]]:
        leg = planner.plan(start, ahead[k], grid)
        if leg is not None:
            tail = [_vertices_after(path_xy, s[k0 + k]), pts[-1:]] if k < len(ahead) - 1 else []
            return np.concatenate([lead, leg, *tail])
    return None


def _vertices_after(path_xy: FloatArray, s_m: float) -> FloatArray:
    """Interior vertices of the polyline strictly beyond arc length ``s_m`` (end excluded)."""
    p = np.asarray(path_xy, dtype=np.float64).reshape(-1, 2)
    s_vert = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(p, axis=0).T))])
    keep = s_vert > s_m + 1e-9
    keep[-1] = False
    return p[keep]
