"""Block handling of the navigation stack (H&W 2011 §6.3): finding where the corridor ahead
is cut, which route edges a block lies on, when a blocked edge is seen free again, and the
grid detour around a block back onto the path.

A station of the path ahead is **cut** when no lateral offset across the corridor ``[-l, l]``
keeps the hard clearance on the costmap (H&W §6.3: no offset inside the corridor avoids the
obstacle; the compiled check :func:`cut_probe`). A blocked edge is seen **free** when every
point of its centre line is in view within ``unblock_view_m``, a beam passes beyond it by
``unblock_margin_m``, and the costmap keeps the hard clearance there.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim import se2
from dynmap_sim.agent.navigation.stack_params import StackParams
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid
from dynmap_sim.agent.planning.costmap import samples_along
from dynmap_sim.agent.planning.grid_astar import GridAStar, plan_around
from dynmap_sim.agent.planning.route_graph import JOIN, RouteGraph
from dynmap_sim.jit import compiled
from dynmap_sim.types import LaserSpec, Scan

FloatArray = NDArray[np.float64]


class BlockHandling:
    """The stack's block checks (module doc) with its ``params``, ``laser``, hard clearance
    ``min_clearance_m`` [m] and grid ``planner`` for detours."""

    def __init__(
        self, params: StackParams, laser: LaserSpec, min_clearance_m: float, planner: GridAStar
    ) -> None:
        self.params = params
        self.laser = laser
        self.min_clearance_m = min_clearance_m
        self.planner = planner

    def cut_ahead(
        self,
        path: FloatArray | None,
        hw: FloatArray,
        grid: ClearanceGrid,
        pose: FloatArray,
        seg0: int,
    ) -> FloatArray | None:
        """The first cut stretch of the corridor of ``path`` (half-widths ``hw``) within
        ``cut_check_m`` ahead of the robot on segment ``seg0``: its centre-line points
        ``(M, 2)``, None when none is cut."""
        if path is None or len(path) < 2:
            return None
        p = self.params
        seg0 = min(seg0, len(path) - 2)
        verts = path[seg0:]
        a = verts[0] + _clamped_projection(verts[0], verts[1], pose[:2])
        verts = np.concatenate([a[None], verts[1:]])
        hw_seg = np.minimum(hw[seg0:-1], hw[seg0 + 1 :])
        # only the segments that start within cut_check_m (+ 1 m, far above rounding) of the
        # path's arc length: the samples' summed steps below equal the arc length, so no
        # later sample is within cut_check_m, and the kept samples are the same
        end_m = np.cumsum(np.hypot(*np.diff(verts, axis=0).T))  # arc length at segment ends
        n_seg = int(np.searchsorted(end_m, p.cut_check_m + 1.0, side="right")) + 1
        verts = verts[: n_seg + 1]
        lin = np.linspace(-1.0, 1.0, p.cut_offsets)
        pts, cut = cut_probe(
            verts,
            hw_seg,
            float(grid.resolution_m),
            float(p.cut_check_m),
            lin,
            grid.clearance_m,
            float(grid.origin[0]),
            float(grid.origin[1]),
            float(grid.resolution_m),
            float(self.min_clearance_m),
        )
        return first_cut_stretch(pts, cut)

    def follower_block_points(self, path: FloatArray, seg: int, pose: FloatArray) -> FloatArray:
        """Where the follower saw its block: the centre line of ``path`` from the robot's
        projection on segment ``seg`` up to the follower's probe distance ahead."""
        seg0 = min(seg, len(path) - 2)
        verts = path[seg0:]
        a = verts[0] + _clamped_projection(verts[0], verts[1], pose[:2])
        verts = np.concatenate([a[None], verts[1:]])
        pts, _ = samples_along(verts[:-1], verts[1:], 0.05, True)
        along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
        return pts[along <= self.params.follower.probe_ahead_m]

    def edges_through(
        self, g: RouteGraph, cut: FloatArray, tol_m: float
    ) -> list[tuple[int, int]] | None:
        """The passable route segments of ``g`` (not joins, in their own direction: a block
        holds both ways) that pass within ``tol_m`` of the cut points; None when ``g`` has
        no passable route segment."""
        segs = [
            e
            for e in g.edges
            if e.route_id != JOIN and not e.reverse and math.isfinite(e.travel_time_s)
        ]
        if not segs:
            return None
        a = g.xy[[g.index[e.u] for e in segs]]
        b = g.xy[[g.index[e.v] for e in segs]]
        hit = []
        for k, e in enumerate(segs):
            if distance_to_polyline(cut, np.stack([a[k], b[k]])).min() <= tol_m:
                hit.append((e.u, e.v))
        return hit

    def seen_free(
        self,
        g: RouteGraph,
        blocked: set[tuple[int, int]],
        pose: FloatArray,
        scan: Scan,
        grid: ClearanceGrid,
    ) -> list[tuple[int, int]]:
        """The ``blocked`` edges whose centre line the scan sees free (module doc)."""
        p = self.params
        lp = se2.compose(pose, np.asarray(self.laser.mount_pose, dtype=np.float64))
        ranges = np.asarray(scan.ranges_m, dtype=np.float64)
        freed = []
        for u, v in sorted(blocked):
            if u not in g.index or v not in g.index:
                continue
            a, b = g.position(u), g.position(v)
            pts, _ = samples_along(a[None], b[None], p.unblock_step_m, True)
            rel = pts - lp[:2]
            dist = np.hypot(*rel.T)
            if dist.max() > p.unblock_view_m:
                continue
            bearing = np.arctan2(rel[:, 1], rel[:, 0]) - lp[2]
            bearing = (bearing + math.pi) % (2.0 * math.pi) - math.pi
            beam = np.rint((bearing - self.laser.angle_min_rad) / self.laser.angle_increment_rad)
            if np.any(beam < 0) or np.any(beam >= self.laser.n_beams):
                continue
            r = ranges[beam.astype(np.int64)]
            with np.errstate(invalid="ignore"):
                seen = (r == np.inf) | (r >= dist + p.unblock_margin_m)
            if np.all(seen) and np.all(grid.clearance_at(pts) >= self.min_clearance_m):
                freed.append((u, v))
        return freed

    def detour(
        self, base: FloatArray, base_hw: FloatArray, pose: FloatArray, grid: ClearanceGrid
    ) -> tuple[FloatArray, FloatArray, int, float] | None:
        """Grid A* around the block from the robot back onto ``base`` (half-widths
        ``base_hw``): the detour's points, their corridor half-widths, the index of the
        segment from which it is back on ``base``, and its length to there [m]; None when
        there is no way round on the costmap."""
        det = plan_around(base, pose[:2], grid, self.planner)
        if det is None:
            return None
        off = distance_to_polyline(det, base) > 0.01
        rejoin = int(np.flatnonzero(off)[-1]) + 1 if off.any() else 0
        near = np.argmin(np.hypot(*(det[:, None, :] - base[None, :, :]).transpose(2, 0, 1)), 1)
        hw = np.where(off, self.params.detour_half_width_m, base_hw[near])
        hw[: rejoin + 1] = np.minimum(hw[: rejoin + 1], self.params.detour_half_width_m)
        length = float(np.sum(np.hypot(*np.diff(det[: rejoin + 1], axis=0).T)))
        return det, hw, rejoin, length


def distance_to_polyline(pts: FloatArray, poly: FloatArray) -> FloatArray:
    """Distance [m] of each point ``(N, 2)`` to the polyline ``(K, 2)``."""
    a, b = poly[:-1], poly[1:]
    d = b - a
    len2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-18)
    rel = pts[:, None, :] - a[None, :, :]
    u = np.clip(np.einsum("nki,ki->nk", rel, d) / len2, 0.0, 1.0)
    gap = rel - u[..., None] * d[None]
    return np.hypot(gap[..., 0], gap[..., 1]).min(axis=1)


@compiled
def cut_probe(  # type: ignore[no-untyped-def]
    verts, hw_seg, step_m, max_along_m, lin, clearance, ox, oy, res, min_clearance_m
):
    """The cut check's stations (:meth:`NavigationStack._cut_ahead`, H&W §6.3): samples every
    ``step_m`` along the polyline ``verts (S+1, 2)`` (each segment from its
    start, end excluded) whose summed steps are within ``max_along_m``: their points
    ``(K, 2)`` and whether every lateral offset ``lin * l`` (``l = hw_seg`` of the segment,
    along its left normal) has less than ``min_clearance_m`` in the grid ``clearance``
    (cell ``(0, 0)`` centred at ``(ox, oy)``, ``res`` [m])."""
    n_seg = verts.shape[0] - 1
    counts = np.empty(n_seg, np.int64)
    lengths = np.empty(n_seg)
    total = 0
    for i in range(n_seg):
        lengths[i] = np.hypot(verts[i + 1, 0] - verts[i, 0], verts[i + 1, 1] - verts[i, 1])
        c = np.int64(np.ceil(lengths[i] / step_m))
        counts[i] = c if c > 1 else 1
        total += counts[i]
    pts = np.empty((total, 2))
    cut = np.zeros(total, np.bool_)
    h, w = clearance.shape
    k = 0
    along = 0.0
    px, py = 0.0, 0.0
    for i in range(n_seg):
        ax, ay = verts[i, 0], verts[i, 1]
        dx, dy = verts[i + 1, 0] - ax, verts[i + 1, 1] - ay
        length = lengths[i]
        nrm = length if length > 1e-12 else 1e-12
        nx, ny = -(dy / nrm), dx / nrm
        for m in range(counts[i]):
            t = m * step_m
            u = t / length if length > 0 else 0.0
            x, y = ax + u * dx, ay + u * dy
            if k > 0:
                along += np.hypot(x - px, y - py)
                if not along <= max_along_m:
                    return pts[:k], cut[:k]
            px, py = x, y
            pts[k, 0], pts[k, 1] = x, y
            all_cut = True
            for j in range(lin.shape[0]):
                off = lin[j] * hw_seg[i]
                r = np.int64(np.rint((y + off * ny - oy) / res))
                col = np.int64(np.rint((x + off * nx - ox) / res))
                r = min(max(r, 0), h - 1)
                col = min(max(col, 0), w - 1)
                if not clearance[r, col] < min_clearance_m:
                    all_cut = False
                    break
            cut[k] = all_cut
            k += 1
    return pts[:k], cut[:k]


def first_cut_stretch(pts: FloatArray, cut: NDArray[np.bool_]) -> FloatArray | None:
    """The first run of consecutive cut stations of ``pts``, None when none is cut."""
    idx = np.flatnonzero(cut)
    if idx.size == 0:
        return None
    gaps = np.flatnonzero(np.diff(idx) > 1)
    end = idx[gaps[0]] if gaps.size else idx[-1]
    return pts[idx[0] : end + 1]


def _clamped_projection(a: FloatArray, b: FloatArray, xy: ArrayLike) -> FloatArray:
    """The offset from ``a`` of the projection of ``xy`` onto segment ``a -> b``."""
    d = b - a
    u = float(np.clip(np.dot(np.asarray(xy, float)[:2] - a, d) / max(float(d @ d), 1e-18), 0, 1))
    return u * d
