"""The navigation stack's own costmap: static layer, obstacle layer, inflation (as clearance).

Modelled on nav2's ``costmap_2d`` layered costmap (Marder-Eppstein et al. 2010; Lu, Hershberger
& Smart, "Layered costmaps for context-sensitive navigation", IROS 2014):

* **static layer** (``nav2_costmap_2d::StaticLayer``): what the robot is told or has mapped --
  the prior's wall segments (:meth:`Costmap.set_static_segments`) or an
  :class:`~dynmap_sim.agent.grid.OccupancyGrid` a localizer provides
  (:meth:`Costmap.set_static_grid`, e.g. the map a first-run SLAM is still building);
* **obstacle layer** (``nav2_costmap_2d::ObstacleLayer``): marks the end points of the laser
  beams within ``obstacle_range_m`` and clears the cells each beam passed through, up to
  ``raytrace_range_m`` (nav2's ``obstacle_max_range`` / ``raytrace_max_range``), at the
  *estimated* laser pose (robot pose estimate composed with the laser's mount pose), so that
  any localizer can drive; ``+inf`` readings (REP-117: nothing within range) clear up to
  ``inf_clear_range_m`` (nav2's ``inf_is_valid``). Each ray is sampled every half cell by
  the compiled kernel :func:`.costmap_kernels.mark_scan` (no per-beam Bresenham loop);
* **inflation**: instead of nav2's cost values, the exact Euclidean distance transform of the
  union of the layers (:func:`.costmap_kernels.clearance_window`), a
  :class:`~.clearance_grid.ClearanceGrid` (clearance [m] per cell), which the planners
  (``min_clearance_m`` = robot radius + margin) and controllers already use.

**Persistence of marks.** nav2's obstacle layer keeps a mark until one ray passes through its
cell. Here a cell holds a small count: each scan that hits it adds one (up to
``max_persistence_scans``), each scan whose beams pass through it (without hitting it) takes
one away; it is an obstacle while the count is positive. An obstacle seen once disappears
the first time the robot sees through it (a person who walked away), one seen for a while
survives a few grazing or noisy beams. Marks nothing sees again stay (e.g. behind the
robot's 240° field of view) until :meth:`Costmap.clear_obstacles` (nav2's
``ClearEntireCostmap`` recovery) or a later scan that sees through them. Cells within
``footprint_clear_radius_m`` of the robot are cleared at every update (nav2's
``footprint_clearing_enabled``): the robot cannot stand inside an obstacle. The static layer
is never cleared by scans; the obstacle layer only adds to it (nav2's maximum combination).

Cells follow :class:`ClearanceGrid`: ``origin`` is the centre of cell ``(0, 0)``, rows are y
and columns x.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim import se2
from dynmap_sim.agent.grid import OCCUPIED, UNKNOWN, OccupancyGrid
from dynmap_sim.agent.params import Positive, PositiveInt, params_dataclass
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid
from dynmap_sim.agent.planning.costmap_kernels import (
    GridFrame,
    ScanLimits,
    clearance_window,
    mark_scan,
)
from dynmap_sim.agent.planning.costmap_kernels import window_clearance as update_window
from dynmap_sim.types import LaserSpec, Prior, Scan

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@params_dataclass("costmap")
class CostmapParams:
    """Tunables of :class:`Costmap` (nav2 ``costmap_2d`` names where they exist)."""

    resolution_m: Positive = 0.05
    """Cell size [m]. H&W's replanning grid and the agent's maps use 5 cm (nav2's
    default); a 0.8 m doorway is 16 cells wide, enough for a 0.2 m robot radius."""

    margin_m: float = 1.0
    """Extra size beyond the prior's bounds on every side [m]: the robot may see (and drive) a
    little outside the walls' bounding box (nav2's global costmap likewise has a fixed size)."""

    obstacle_range_m: float = 2.5
    """Beam end points farther than this [m] are not marked (nav2 ``obstacle_max_range`` 2.5):
    far readings are noisy (URG-04LX: 1 % of the range) and pose errors grow with range."""

    raytrace_range_m: float = 3.0
    """Beams clear cells up to this range [m] (nav2 ``raytrace_max_range`` 3.0): longer than
    ``obstacle_range_m`` so that any mark can be seen through and removed again."""

    inf_clear_range_m: float = 3.0
    """A ``+inf`` reading (REP-117: no return within the sensor's range) clears its beam up to
    this range [m] (nav2 ``inf_is_valid``); 0 disables it, for a laser that also returns
    nothing from black or glossy surfaces."""

    max_persistence_scans: PositiveInt = 3
    """A mark survives up to this many scans that see through its cell: one scan that saw it
    once clears it (a person who left), a mark seen in several scans outlives a few grazing
    or noisy beams (nav2 keeps marks until a single ray clears them)."""

    footprint_clear_radius_m: float = 0.2
    """Obstacle marks within this radius [m] of the robot are cleared at every update (nav2
    ``footprint_clearing_enabled``); default: the simulated robot's radius (0.2 m). 0 turns
    it off."""

    unknown_is_obstacle: bool = False
    """Whether unknown cells of a static :class:`OccupancyGrid` count as obstacles. False by
    default (nav2 planners' ``allow_unknown``): a first-run map is unknown ahead of the robot,
    and the obstacle layer marks what is really there once it is in range."""

    no_map_half_size_m: float = 10.0
    """Half the side [m] of the square around the initial pose that :meth:`Costmap.for_prior`
    covers when the prior has neither bounds nor walls (a first run without a map): 20 m x
    20 m holds a flat or a lab floor (the apartment is 8 m x 10 m); 441 x 441 cells, 0.2 MB a
    layer."""


def samples_along(
    start_xy: FloatArray, end_xy: FloatArray, step_m: float, include_end: bool
) -> tuple[FloatArray, IntArray]:
    """Points every ``step_m`` along the segments ``start_xy -> end_xy`` (both ``(N, 2)``), all
    segments at once; with ``include_end`` each segment's end point is added. Returns the
    points ``(M, 2)`` [m] and the index ``(M,)`` of the segment each belongs to.
    """
    a = np.asarray(start_xy, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(end_xy, dtype=np.float64).reshape(-1, 2)
    length = np.hypot(*(b - a).T)
    count = np.ceil(length / step_m).astype(np.int64)  # samples at t = 0, step, ... < length
    count = np.maximum(count, 1)
    seg = np.repeat(np.arange(len(a)), count)
    first = np.cumsum(count) - count
    t = (np.arange(len(seg)) - np.repeat(first, count)) * step_m
    u = np.divide(t, length[seg], out=np.zeros_like(t), where=length[seg] > 0)
    pts = a[seg] + u[:, None] * (b - a)[seg]
    if include_end:
        pts = np.concatenate([pts, b])
        seg = np.concatenate([seg, np.arange(len(a))])
    return pts, seg


def laser_pose(
    pose: FloatArray, mount_pose: tuple[float, float, float]
) -> tuple[float, float, float]:
    """:func:`dynmap_sim.se2.compose` of one robot pose ``(3,)`` and the laser's mount pose,
    as floats (the laser's pose in the map frame, [m, m, rad])."""
    ax, ay, ath = pose.tolist()
    bx, by, bth = (float(v) for v in mount_pose)
    c, s = np.cos(ath), np.sin(ath)
    x = ax + c * bx - s * by
    y = ay + s * bx + c * by
    return float(x), float(y), float(se2.wrap_angle(ath + bth))


class Costmap:
    """Static + obstacle layers over a fixed window, inflated to a :class:`ClearanceGrid`.

    ``bounds = (xmin, ymin, xmax, ymax)`` [m] of the area (the prior's bounds); the grid
    covers it plus ``params.margin_m``. Picklable (plain arrays).
    """

    def __init__(
        self, params: CostmapParams | None, bounds: tuple[float, float, float, float]
    ) -> None:
        self.params = params or CostmapParams()
        if len(bounds) != 4:
            raise ValueError(f"bounds must be (xmin, ymin, xmax, ymax), got {bounds!r}")
        res, m = self.params.resolution_m, self.params.margin_m
        lo = np.array(bounds[:2], dtype=np.float64) - m
        hi = np.array(bounds[2:], dtype=np.float64) + m
        if not np.all(hi > lo):
            raise ValueError(f"empty bounds {bounds!r}")
        w, h = (np.ceil((hi - lo) / res).astype(int) + 1).tolist()
        #: centre of cell (0, 0) [m]
        self.origin = lo
        self.shape: tuple[int, int] = (h, w)
        #: static layer: True where the prior / the localizer's map has an obstacle
        self.static = np.zeros(self.shape, dtype=bool)
        #: obstacle layer: per cell, how many more scans seeing through it it survives
        self.marks = np.zeros(self.shape, dtype=np.int8)
        #: per cell, the time [s] of the update since which it has been marked (NaN: unmarked)
        self.marked_since_s = np.full(self.shape, np.nan)
        k = int(np.ceil(self.params.footprint_clear_radius_m / res))
        di, dj = np.mgrid[-k : k + 1, -k : k + 1]
        inside = np.hypot(di, dj) * res <= self.params.footprint_clear_radius_m
        self._footprint = np.stack([di[inside], dj[inside]], axis=1)
        self._beams: tuple[LaserSpec, FloatArray] | None = None  # laser -> beam angles
        self._clearance: ClearanceGrid | None = None
        self._occupied: NDArray[np.bool_] | None = None
        #: the last window_clearance: (its base, its window a0, a1, b0, b1, its array)
        self._window: tuple[ClearanceGrid, tuple[int, int, int, int], FloatArray] | None = None
        self._seen: NDArray[np.uint8] | None = None  # the scan kernel's scratch

    @classmethod
    def for_prior(cls, prior: Prior, params: CostmapParams | None = None) -> Costmap:
        """A costmap over ``prior.bounds`` (else the walls' extent) with the walls as static
        layer. A prior with neither gets ``no_map_half_size_m`` around its initial pose (a first
        run without a map); :class:`ValueError` when it has no initial pose either."""
        walls = None if prior.walls is None else np.asarray(prior.walls, float).reshape(-1, 4)
        if prior.bounds is not None:
            bounds = tuple(float(b) for b in prior.bounds)  # type: ignore[assignment]
        elif walls is not None and len(walls):
            pts = walls.reshape(-1, 2)
            bounds = (*pts.min(axis=0).tolist(), *pts.max(axis=0).tolist())
        elif prior.initial_pose is not None:
            x, y = np.asarray(prior.initial_pose, float)[:2]
            r = (params or CostmapParams()).no_map_half_size_m
            bounds = (x - r, y - r, x + r, y + r)
        else:
            raise ValueError("a costmap needs the prior's bounds, walls or initial pose")
        cmap = cls(params, bounds)
        if walls is not None and len(walls):
            cmap.set_static_segments(walls)
        return cmap

    # -- geometry ------------------------------------------------------------------------
    @property
    def resolution_m(self) -> float:
        return self.params.resolution_m

    def _keys(self, xy: FloatArray) -> tuple[IntArray, NDArray[np.bool_]]:
        """Flat cell indices of points ``(N, 2)`` and whether each lies in the grid."""
        ij = np.rint((xy[:, ::-1] - self.origin[::-1]) / self.resolution_m).astype(np.int64)
        h, w = self.shape
        inside = (ij[:, 0] >= 0) & (ij[:, 0] < h) & (ij[:, 1] >= 0) & (ij[:, 1] < w)
        return ij[:, 0] * w + ij[:, 1], inside

    def _changed(self) -> None:
        self._clearance = None
        self._occupied = None

    # -- static layer --------------------------------------------------------------------
    def set_static_segments(self, segments: ArrayLike) -> None:
        """Static layer := the cells the wall segments ``(N, 4)`` [m] pass through."""
        seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
        static = np.zeros(self.shape, dtype=bool)
        if len(seg):
            pts, _ = samples_along(seg[:, :2], seg[:, 2:], 0.25 * self.resolution_m, True)
            key, inside = self._keys(pts)
            static.flat[key[inside]] = True
        self.static = static
        self._changed()

    def set_static_grid(self, grid: OccupancyGrid) -> None:
        """Static layer := a localizer's occupancy grid, resampled to this costmap's cells:
        a cell is an obstacle when the grid cell under its centre is occupied (or unknown, with
        ``unknown_is_obstacle``), or when an occupied cell's centre falls in it (a finer grid's
        thin walls are not lost). Cells outside the grid are free."""
        h, w = self.shape
        jj, ii = np.meshgrid(np.arange(w), np.arange(h))
        centres = self.origin + np.stack([jj.ravel(), ii.ravel()], axis=1) * self.resolution_m
        gx, gy = grid.cell_of(centres)
        gh, gw = grid.shape
        ok = (gx >= 0) & (gx < gw) & (gy >= 0) & (gy < gh)
        val = np.full(h * w, 0, dtype=np.int8)
        val[ok] = grid.occupancy[gy[ok], gx[ok]]
        blocked = val == OCCUPIED
        if self.params.unknown_is_obstacle:
            blocked |= ok & (val == UNKNOWN)
        key, inside = self._keys(grid.occupied_points())
        blocked[key[inside]] = True
        self.static = blocked.reshape(self.shape)
        self._changed()

    # -- obstacle layer ------------------------------------------------------------------
    def _angles(self, laser: LaserSpec) -> FloatArray:
        if self._beams is None or self._beams[0] != laser:
            self._beams = (laser, laser.angles())
        return self._beams[1]

    def update(
        self, pose: ArrayLike, scan: Scan | ArrayLike, laser: LaserSpec, t_s: float | None = None
    ) -> bool:
        """Mark and clear the obstacle layer with one scan taken at the estimated robot
        ``pose`` ``(x_m, y_m, theta_rad)`` in the map frame at time ``t_s`` [s] (default: the
        scan's stamp; the marks' ages of :meth:`persistent_clearance` count from it). Returns
        True when an obstacle cell appeared or disappeared (the clearance is then recomputed
        on demand)."""
        p = self.params
        ranges = np.asarray(scan.ranges_m if isinstance(scan, Scan) else scan, dtype=np.float64)
        pose = np.asarray(pose, dtype=np.float64)
        lx, ly, lth = laser_pose(pose, laser.mount_pose)
        th = lth + self._angles(laser)
        limits = ScanLimits(
            float(laser.range_min_m),
            float(laser.range_max_m),
            float(p.raytrace_range_m),
            float(p.inf_clear_range_m),
            float(p.obstacle_range_m),
            int(p.max_persistence_scans),
        )
        changed = bool(
            mark_scan(
                self.marks,
                self._frame(),
                (lx, ly),
                np.cos(th),
                np.sin(th),
                ranges,
                limits,
                (float(pose[0]), float(pose[1])),
                self._footprint,
                self._seen_scratch(),
            )
        )
        if changed:
            self._changed()
            if t_s is None:
                t_s = scan.stamp_s if isinstance(scan, Scan) else 0.0
            rows, cols = self._scan_reach((lx, ly), pose)
            on = self.marks[rows, cols] > 0
            since = self.marked_since_s[rows, cols]  # a view: the ages of the cells a scan reaches
            since[on & np.isnan(since)] = float(t_s)
            since[~on] = np.nan
        return changed

    def _scan_reach(self, laser_xy: tuple[float, float], pose: FloatArray) -> tuple[slice, slice]:
        """The rows and columns of the cells one scan can mark or clear: within the longest
        of ``raytrace_range_m`` and ``obstacle_range_m`` of the laser (``inf_clear_range_m``
        is at most the former) or the footprint around the robot, a cell's rounding more."""
        p, res = self.params, self.resolution_m
        h, w = self.shape
        k = int(math.ceil(max(p.raytrace_range_m, p.obstacle_range_m) / res)) + 1
        f = int(math.ceil(p.footprint_clear_radius_m / res)) + 1
        (i_l, j_l), (i_r, j_r) = (
            np.rint((np.array(xy) - self.origin)[::-1] / res).astype(int).tolist()
            for xy in (laser_xy, (float(pose[0]), float(pose[1])))
        )
        rows = slice(max(min(i_l - k, i_r - f), 0), min(max(i_l + k, i_r + f) + 1, h))
        cols = slice(max(min(j_l - k, j_r - f), 0), min(max(j_l + k, j_r + f) + 1, w))
        return rows, cols

    def _frame(self) -> GridFrame:
        """The grid's place for the kernels."""
        return GridFrame(float(self.origin[0]), float(self.origin[1]), self.resolution_m)

    def _seen_scratch(self) -> NDArray[np.uint8]:
        """The scan kernel's per-cell scratch (zero between calls)."""
        seen = self._seen
        if seen is None or seen.size != self.marks.size:
            seen = self._seen = np.zeros(self.marks.size, dtype=np.uint8)
        return seen

    def clear_obstacles(self) -> None:
        """Forget every mark of the obstacle layer (nav2's ``ClearEntireCostmap`` recovery)."""
        self.marks[:] = 0
        self.marked_since_s[:] = np.nan
        self._changed()

    # -- outputs ---------------------------------------------------------------------------
    def occupied_mask(self) -> NDArray[np.bool_]:
        """``(H, W)`` True where the static or the obstacle layer has an obstacle (read-only)."""
        if self._occupied is None:
            occ = self.static | (self.marks > 0)
            occ.flags.writeable = False
            self._occupied = occ
        return self._occupied

    def obstacle_mask(self) -> NDArray[np.bool_]:
        """``(H, W)`` True where the obstacle layer (the scans) has a mark."""
        return self.marks > 0

    def clearance(self) -> ClearanceGrid:
        """The inflation output: distance [m] from each cell to the nearest obstacle of either
        layer (the grid is unbounded beyond its edge). Cached until a layer changes; treat it
        as read-only (planners cache their search graphs by its identity)."""
        if self._clearance is None:
            h, w = self.shape
            self._clearance = ClearanceGrid(
                self.origin.copy(), self.resolution_m, self._distance_m((0, h), (0, w))
            )
        return self._clearance

    def persistent_clearance(self, t_s: float, min_age_s: float) -> ClearanceGrid:
        """The clearance [m] of the static layer and the marks that have stood for at least
        ``min_age_s`` [s] at time ``t_s`` [s]: the obstacles that are not passing by (a
        person walking through the view is marked for a second or two). Computed anew at
        every call (the set of old marks changes with time alone)."""
        with np.errstate(invalid="ignore"):
            old = (t_s - self.marked_since_s) >= min_age_s
        marks = np.where(old, self.marks, np.int8(0))
        h, w = self.shape
        dist = clearance_window(self.static, marks, (0, h), (0, w), self.resolution_m)
        return ClearanceGrid(self.origin.copy(), self.resolution_m, dist)

    def _window_buffer(self, base: ClearanceGrid) -> FloatArray:
        """A copy of ``base``'s clearance for :meth:`window_clearance`: the last call's array
        with its window restored from ``base`` when it had the same ``base``."""
        last = self._window
        if last is not None and last[0] is base:
            (a0, a1, b0, b1), clear = last[1], last[2]
            clear[a0:a1, b0:b1] = base.clearance_m[a0:a1, b0:b1]
            return clear
        self._window = None
        return base.clearance_m.copy()

    def _distance_m(self, rows: tuple[int, int], cols: tuple[int, int]) -> FloatArray:
        """Distance [m] from each cell of the window ``rows x cols`` to the nearest obstacle
        of either layer inside it (inf when it has none): the exact Euclidean distance
        transform."""
        return clearance_window(self.static, self.marks, rows, cols, self.resolution_m)

    def window_clearance(
        self, base: ClearanceGrid, centre_xy: FloatArray, window_m: float, margin_m: float
    ) -> ClearanceGrid:
        """``base`` (a clearance of this costmap's cells, e.g. the last plan's) with the window
        of half-size ``window_m`` [m] around ``centre_xy`` recomputed from the current layers
        (nav2's rolling local costmap): exact where below ``margin_m`` [m] (obstacles up to
        ``margin_m`` outside the window are looked at), elsewhere in the window at least
        ``margin_m`` (``base``'s value when larger). ``base`` is not changed. The grid's array
        is reused by the next call with the same ``base`` (only the last window is restored
        from ``base``, no copy of the whole grid): use the grid before calling again.

        When ``base`` is this costmap's :meth:`clearance` and no obstacle cell changed since,
        ``base`` itself is returned: it is the answer (where the exact distance is below
        ``margin_m`` the window has it; elsewhere ``base`` is at least ``margin_m``)."""
        if base is self._clearance:
            return base
        res = base.resolution_m
        h, w = base.shape
        i, j = base.cell_index(float(centre_xy[0]), float(centre_xy[1]))
        k_in = int(math.ceil(window_m / res))
        k_out = k_in + int(math.ceil(margin_m / res))
        r0, r1 = max(i - k_out, 0), min(i + k_out + 1, h)
        c0, c1 = max(j - k_out, 0), min(j + k_out + 1, w)
        a0, a1 = max(i - k_in, 0), min(i + k_in + 1, h)
        b0, b1 = max(j - k_in, 0), min(j + k_in + 1, w)
        clear = self._window_buffer(base)
        update_window(
            self.static, self.marks, (r0, r1, c0, c1), (a0, a1, b0, b1), res, margin_m, clear
        )
        self._window = (base, (a0, a1, b0, b1), clear)
        return ClearanceGrid(base.origin, res, clear)

    def __getstate__(self) -> dict[str, object]:
        return {
            **self.__dict__,
            "_clearance": None,
            "_occupied": None,
            "_beams": None,
            "_window": None,
            "_seen": None,
        }
