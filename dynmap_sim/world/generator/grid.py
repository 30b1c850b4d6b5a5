"""Grid geometry of a world for the generator's route and its checks (world side: truth).

Outlines are rasterized conservatively (a cell is occupied where an outline comes within half
a cell diagonal of its centre), the clearance of every free cell is its distance to the
nearest occupied cell [m], and :func:`astar` finds the cheapest 8-connected path over cells
with enough clearance, cheaper far from obstacles so that paths keep to the middle of
corridors and doorways.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import distance_transform_edt

from dynmap_sim.jit import compiled
from dynmap_sim.world.polygons import FloatArray, ccw

#: Cell size of the generator's grids [m].
CELL_M = 0.05
#: Clearance [m] beyond which a cell costs no more than open floor.
COMFORT_M = 0.9


@dataclass(frozen=True)
class Grid:
    """Occupancy and clearance of ``bounds`` at ``cell`` [m]; row ``i`` is ``y0 + (i+.5)c``."""

    x0: float
    y0: float
    cell: float
    occupied: np.ndarray  # (ny, nx) bool
    clearance: np.ndarray  # (ny, nx) float64 [m], 0 on occupied cells

    def index(self, x: float, y: float) -> tuple[int, int]:
        """Cell ``(row, col)`` of a point (clipped to the grid)."""
        ny, nx = self.occupied.shape
        i = int(np.clip((y - self.y0) / self.cell, 0, ny - 1))
        j = int(np.clip((x - self.x0) / self.cell, 0, nx - 1))
        return i, j

    def point(self, i: int, j: int) -> tuple[float, float]:
        """Centre [m] of cell ``(i, j)``."""
        return (self.x0 + (j + 0.5) * self.cell, self.y0 + (i + 0.5) * self.cell)

    def clearance_at(self, pts: FloatArray) -> FloatArray:
        """Clearance [m] at points ``(P, 2)`` (nearest cell)."""
        ny, nx = self.occupied.shape
        j = np.clip(((pts[:, 0] - self.x0) / self.cell).astype(np.int64), 0, nx - 1)
        i = np.clip(((pts[:, 1] - self.y0) / self.cell).astype(np.int64), 0, ny - 1)
        return self.clearance[i, j]

    def segment_clearance(self, a, b) -> float:
        """Smallest clearance [m] along the segment ``a``-``b`` (sampled at half cells)."""
        a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        n = max(2, int(np.hypot(*(b - a)) / (0.5 * self.cell)) + 1)
        t = np.linspace(0.0, 1.0, n)[:, None]
        return float(self.clearance_at(a + t * (b - a)).min())


def rasterize(bounds, polygons: list[FloatArray], cell: float = CELL_M) -> Grid:
    """A :class:`Grid` of ``bounds`` with the convex ``polygons`` occupied."""
    x0, y0, x1, y1 = (float(v) for v in bounds)
    nx, ny = int(np.ceil((x1 - x0) / cell)), int(np.ceil((y1 - y0) / cell))
    occ = np.zeros((ny, nx), dtype=bool)
    _fill(occ, x0, y0, cell, polygons)
    return Grid(x0, y0, cell, occ, distance_transform_edt(~occ) * cell)


def with_polygons(grid: Grid, polygons: list[FloatArray]) -> Grid:
    """``grid`` with ``polygons`` occupied too."""
    occ = grid.occupied.copy()
    _fill(occ, grid.x0, grid.y0, grid.cell, polygons)
    return Grid(grid.x0, grid.y0, grid.cell, occ, distance_transform_edt(~occ) * grid.cell)


def _fill(occ: np.ndarray, x0: float, y0: float, cell: float, polygons) -> None:
    """Mark the cells of ``occ`` that ``polygons`` come within half a cell diagonal of."""
    ny, nx = occ.shape
    pad = 0.5 * cell * np.sqrt(2.0)
    for poly in polygons:
        p = ccw(np.asarray(poly, dtype=np.float64))
        lo, hi = p.min(axis=0) - pad, p.max(axis=0) + pad
        j0, j1 = max(0, int((lo[0] - x0) / cell)), min(nx, int((hi[0] - x0) / cell) + 1)
        i0, i1 = max(0, int((lo[1] - y0) / cell)), min(ny, int((hi[1] - y0) / cell) + 1)
        if j1 <= j0 or i1 <= i0:
            continue
        xs = x0 + (np.arange(j0, j1) + 0.5) * cell
        ys = y0 + (np.arange(i0, i1) + 0.5) * cell
        gx, gy = np.meshgrid(xs, ys)
        e = np.roll(p, -1, axis=0) - p
        n = np.stack([e[:, 1], -e[:, 0]], axis=1)  # outward normals of a CCW polygon
        n /= np.maximum(np.hypot(n[:, 0], n[:, 1]), 1e-12)[:, None]
        off = np.einsum("kd,kd->k", n, p)
        signed = gx[..., None] * n[:, 0] + gy[..., None] * n[:, 1] - off  # (h, w, K)
        occ[i0:i1, j0:j1] |= signed.max(axis=-1) <= pad


@compiled
def _astar_kernel(cost, start, goal):  # pragma: no cover - compiled
    """Cheapest 8-connected path over cells of finite ``cost`` (per metre of cell step);
    flat cell indices from ``start`` to ``goal``, empty where there is none."""
    ny, nx = cost.shape
    n = ny * nx
    g = np.full(n, np.inf)
    came = np.full(n, -1, dtype=np.int64)
    done = np.zeros(n, dtype=np.bool_)
    gi, gj = goal // nx, goal % nx
    cmin = np.inf
    for v in cost.ravel():
        if v < cmin:
            cmin = v
    g[start] = 0.0
    heap = [(0.0, start)]
    di = np.array([-1, -1, -1, 0, 0, 1, 1, 1])
    dj = np.array([-1, 0, 1, -1, 1, -1, 0, 1])
    while heap:
        _, u = heapq.heappop(heap)
        if done[u]:
            continue
        done[u] = True
        if u == goal:
            break
        ui, uj = u // nx, u % nx
        for k in range(8):
            vi, vj = ui + di[k], uj + dj[k]
            if vi < 0 or vj < 0 or vi >= ny or vj >= nx:
                continue
            c = cost[vi, vj]
            if not np.isfinite(c):
                continue
            v = vi * nx + vj
            step = 1.4142135623730951 if di[k] != 0 and dj[k] != 0 else 1.0
            nd = g[u] + step * 0.5 * (c + cost[ui, uj])
            if nd < g[v]:
                g[v] = nd
                came[v] = u
                h = cmin * np.hypot(vi - gi, vj - gj)
                heapq.heappush(heap, (nd + h, v))
    if not done[goal]:
        return np.zeros(0, dtype=np.int64)
    path = [goal]
    while path[-1] != start:
        path.append(came[path[-1]])
    out = np.empty(len(path), dtype=np.int64)
    for k in range(len(path)):
        out[k] = path[len(path) - 1 - k]
    return out


def path_cost(grid: Grid, radius_m: float) -> np.ndarray:
    """Per-cell cost: infinite within ``radius_m`` of an obstacle, rising towards obstacles."""
    c = grid.clearance
    cost = 1.0 + 3.0 * np.clip((COMFORT_M - c) / COMFORT_M, 0.0, 1.0)
    return np.where(c > radius_m, cost, np.inf)


def astar(grid: Grid, cost: np.ndarray, a, b) -> FloatArray | None:
    """Cell-centre path ``(P, 2)`` [m] from point ``a`` to ``b``, or None without one."""
    ia, ib = grid.index(*a), grid.index(*b)
    nx = grid.occupied.shape[1]
    if not (np.isfinite(cost[ia]) and np.isfinite(cost[ib])):
        return None
    flat = _astar_kernel(cost, ia[0] * nx + ia[1], ib[0] * nx + ib[1])
    if len(flat) == 0:
        return None
    i, j = np.divmod(flat, nx)
    pts = np.stack([grid.x0 + (j + 0.5) * grid.cell, grid.y0 + (i + 0.5) * grid.cell], axis=1)
    pts[0], pts[-1] = a, b
    return pts


def simplify(grid: Grid, path: FloatArray, want_m: float) -> FloatArray:
    """Few straight legs along ``path``: from each kept point the furthest point (in steps
    of four cells) reachable by a shortcut whose clearance is at least ``want_m`` [m] or at
    least that of the stretch of path it replaces."""
    clear = grid.clearance_at(path)
    out = [path[0]]
    i, last = 0, len(path) - 1
    while i < last:
        best = i + 1
        j = min(i + 4, last)
        while True:
            need = min(want_m, float(clear[i : j + 1].min()) - 0.25 * grid.cell)
            if grid.segment_clearance(path[i], path[j]) < need:
                break
            best = j
            if j == last:
                break
            j = min(j + 4, last)
        out.append(path[best])
        i = best
    return np.array(out)
