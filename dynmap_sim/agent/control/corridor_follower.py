"""``corridor-follower``: Hentschel & Wagner's hybrid path controller (H&W 2011 §6.3).

H&W §6.3 follow the planned path ``P`` with "a hybrid feedback controller" that tracks the path
precisely and avoids obstacles *reactively* "by adjusting the lateral offset of the robot with
respect to the base trajectory of the path", the offset of each path segment bounded by the
corridor half-width ``l`` of the route (H&W §5, eq. 18); it reduces the speed "in dependence of
the distance to the perceived obstacles", and an obstacle that no offset inside the corridor
avoids is left to global replanning. This module is that controller:

* **Tracking**: the carrot of ``pure-pursuit`` (:func:`.pure_pursuit.carrot_on_segment`:
  ``lookahead_m`` ahead of the robot's projection on the current segment, never past its end),
  steered to with the pure-pursuit curvature ``2 sin(alpha) / L_d`` (Coulter 1992).
* **Reactive avoidance by a lateral offset**: ``n_offsets`` candidate offsets ``d`` in
  ``[-l, +l]`` shift the path sideways along each segment's normal. For each, the clearance
  grid is probed along the shifted path from the robot's projection ``probe_ahead_m`` ahead
  and on the straight line from the robot to the shifted carrot. An offset is *free* when
  every probe point keeps the hard clearance; of the free ones the follower takes the one with
  the most clearance, the clearance saturating at ``clearance_enough_m`` (beyond it more room
  buys nothing) and small costs on the offset (``offset_cost_per_m``: back to the base path
  when there is room, H&W's "precise tracking") and on changing it (``switch_cost_per_m``:
  no dithering between equal offsets). The corridor narrows to the goal point over the last
  ``l`` metres of the path, so the robot ends on the path's end, not beside it.
* **Blocked**: when no offset is free, :attr:`CorridorFollower.blocked` turns True and the
  command is zero: H&W's cue for global replanning.
* **Speed** (the regulation of nav2's Regulated Pure Pursuit): the clearance law
  :func:`speed_for_clearance` (``v_max * clip((d - d_stop) / (d_full - d_stop),
  0, 1)`` with a floor so a free offset is always driven), RPP's curvature regulation
  (``v * R / R_min`` below ``regulated_min_radius_m``), RPP's approach regulation on the last
  segment, and the external speed limit of :class:`.controller.Controller`.
* **Rotate to heading** (RPP's ``use_rotate_to_heading``): a heading error to the carrot above
  ``turn_in_place_rad`` turns on the spot (the robot is a disc: turning never sweeps new space).

The grid is whatever the stack gives it (its own costmap, scans included, so people near the
robot count as obstacles: the scan tells, not the truth).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.control.controller import Controller, SpeedLimit, register_controller
from dynmap_sim.agent.control.pure_pursuit import (
    advance_segment,
    carrot_on_segment,
    pursuit_turn_rate,
)
from dynmap_sim.agent.params import Int, NonNegative, Positive, params_dataclass
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid
from dynmap_sim.jit import compiled

FloatArray = NDArray[np.float64]


@params_dataclass("corridor-follower")
class CorridorFollowerParams:
    """Tunables (SI units) of :class:`CorridorFollower` (H&W §6.3 leave all of them open)."""

    #: cruise speed v_max [m/s]
    speed_mps: Positive = 0.35
    #: the hard clearance (robot radius + safety margin) [m]: no offset may go below it
    min_clearance_m: NonNegative = 0.25
    max_omega_radps: Positive = 0.8
    #: pure-pursuit lookahead [m] (the tour's value: tight tracking of short indoor segments)
    lookahead_m: Positive = 0.35
    #: rotate to heading above this heading error to the carrot [rad] (RPP uses 0.785)
    turn_in_place_rad: Positive = 0.6
    #: a vertex within this distance is reached [m]
    goal_tolerance_m: Positive = 0.12
    #: corridor half-width l where ``set_path`` gets none [m] (H&W's routes in a
    #: doorway-sized apartment)
    default_half_width_m: NonNegative = 0.35
    #: candidate offsets across ``[-l, l]`` (odd, so the base path itself is one)
    n_offsets: Int = 15
    #: how far ahead of the robot the offsets are probed [m]: about 3 s at 0.35 m/s, enough to
    #: start moving sideways before a box on the path is reached
    probe_ahead_m: Positive = 1.0
    #: spacing of the probe points [m] (the grid's usual 5 cm cells)
    probe_step_m: Positive = 0.05
    #: clearance beyond which an offset is not better for more room [m] (= the full-speed
    #: clearance of the speed law: more room would not make the robot faster)
    clearance_enough_m: Positive = 0.8
    #: cost of an offset [m of clearance per m of offset]: back to the path when free
    offset_cost_per_m: NonNegative = 0.3
    #: cost of changing the offset [m of clearance per m]: hysteresis (< offset cost, so the
    #: robot still returns to the path)
    switch_cost_per_m: NonNegative = 0.1
    #: clearance law: zero speed at ``min_clearance_m``, full speed from this on [m]
    full_speed_clearance_m: Positive = 0.8
    #: the clearance law looks this far ahead along the chosen offset [m]
    speed_probe_m: NonNegative = 0.5
    #: speed floor while a free offset is driven [m/s] (RPP's regulated minimum speed, scaled
    #: to this slower robot): the robot creeps past a box rather than stalling beside it
    min_speed_mps: NonNegative = 0.05
    #: RPP curvature regulation: slower on turns tighter than this radius [m] (RPP's 0.9;
    #: 0: none, as H&W §6.3, whose controller slows for obstacles only)
    regulated_min_radius_m: NonNegative = 0.9
    #: RPP approach regulation: slower within this distance of the path's end [m] ...
    approach_dist_m: Positive = 0.6
    #: ... but at least this [m/s] (RPP's ``min_approach_linear_velocity`` 0.05)
    approach_min_speed_mps: NonNegative = 0.05
    #: the turn rate is ``max(v, this) * curvature`` [m/s], so slow driving still steers
    min_steering_speed_mps: NonNegative = 0.1

    def __post_init__(self) -> None:
        if self.n_offsets < 1 or self.n_offsets % 2 == 0:
            raise ValueError(f"n_offsets must be odd and >= 1, got {self.n_offsets}")
        if self.full_speed_clearance_m <= self.min_clearance_m:
            raise ValueError("full_speed_clearance_m must exceed min_clearance_m")


def speed_for_clearance(clearance_m: float, p: CorridorFollowerParams) -> float:
    """The clearance law [m/s] (H&W §6.3 "speed reduced in dependence of the distance to the
    perceived obstacles"; the shape of RPP's proximity regulation):
    ``v_max * clip((d - d_stop) / (d_full - d_stop), 0, 1)`` with ``d_stop`` the hard
    clearance and ``d_full`` ``full_speed_clearance_m``, floored at ``min_speed_mps`` above
    ``d_stop`` (a free offset keeps ``d >= d_stop``, so it is always driven). Non-decreasing in
    ``clearance_m``; zero below the hard clearance."""
    d_stop = p.min_clearance_m
    if not clearance_m >= d_stop:
        return 0.0
    frac = min((clearance_m - d_stop) / (p.full_speed_clearance_m - d_stop), 1.0)
    return max(p.speed_mps * frac, min(p.min_speed_mps, p.speed_mps))


class CorridorPath(NamedTuple):
    """The path :func:`probe_offsets` probes: vertices ``(K, 2)`` [m], arc length at each
    vertex ``(K,)`` [m], unit tangents and left normals of the segments ``(K-1, 2)`` and
    their corridor half-widths ``(K-1,)`` [m]."""

    path: FloatArray
    cum: FloatArray
    tangent: FloatArray
    normal: FloatArray
    seg_hw: FloatArray


class ProbeAt(NamedTuple):
    """Where the offsets are probed from: the robot's segment, its arc length [m], the carrot
    and its arc length [m], the robot's position [m] and the current offset [m]."""

    seg: int
    s_robot: float
    carrot_x: float
    carrot_y: float
    s_carrot: float
    x_m: float
    y_m: float
    offset_m: float


class GridView(NamedTuple):
    """A clearance grid for the kernels: ``clear (H, W)`` [m], cell ``(0, 0)``'s centre and
    the cell size [m]."""

    clear: FloatArray
    origin_x_m: float
    origin_y_m: float
    res_m: float


class OffsetScore(NamedTuple):
    """:class:`CorridorFollowerParams`' fields that judge an offset [m, m per m]."""

    min_clearance_m: float
    speed_probe_m: float
    clearance_enough_m: float
    offset_cost_per_m: float
    switch_cost_per_m: float


@compiled
def probe_offsets(  # type: ignore[no-untyped-def]
    corridor, at, steps_m, unit_offsets, way_fractions, grid, score_p, offsets_out, clear_near_out
):
    """The follower's offset choice (:meth:`CorridorFollower._choose_offset`) on the path
    ``corridor`` (:class:`CorridorPath`) from ``at`` (:class:`ProbeAt`): fills the candidate
    offsets ``unit_offsets * l`` [m] and each one's least clearance within ``speed_probe_m``
    (along the shifted path at ``steps_m`` ahead, and on the way to the shifted carrot at
    ``way_fractions``, in ``grid``: :class:`GridView`); returns the best free offset's index
    (-1: none free) and the clearance at the robot [m]."""
    path, cum, tangent, normal, seg_hw = corridor
    seg, s_robot, carrot_x, carrot_y, s_carrot, x_m, y_m, offset_m = at
    clear, origin_x_m, origin_y_m, res_m = grid
    min_clearance_m, speed_probe_m, clearance_enough_m, offset_cost_per_m, switch_cost_per_m = (
        score_p
    )
    n_off = unit_offsets.shape[0]
    n_s = steps_m.shape[0]
    n_seg = seg_hw.shape[0]
    end_m = cum[cum.shape[0] - 1]
    hw_seg = seg_hw[seg]
    for o in range(n_off):
        offsets_out[o] = unit_offsets[o] * hw_seg
    h, w = clear.shape
    # clearance_at (nearest cell, clipped to the grid) of the robot's position
    row = min(max(np.int64(np.rint((y_m - origin_y_m) / res_m)), 0), h - 1)
    col = min(max(np.int64(np.rint((x_m - origin_x_m) / res_m)), 0), w - 1)
    here = clear[row, col]
    need_way = min(min_clearance_m, here)
    min_all = np.full(n_off, math.inf)
    free = np.ones(n_off, np.bool_)
    for o in range(n_off):
        clear_near_out[o] = math.inf
    # the shifted path ahead
    idx = 0  # searchsorted(cum, s, "right"), s non-decreasing
    for m in range(n_s):
        s = min(s_robot + steps_m[m], end_m)
        while idx < cum.shape[0] and cum[idx] <= s:
            idx += 1
        k = min(max(idx - 1, 0), n_seg - 1)
        u = s - cum[k]
        bx = path[k, 0] + u * tangent[k, 0]
        by = path[k, 1] + u * tangent[k, 1]
        nx, ny = normal[k, 0], normal[k, 1]
        hw = min(seg_hw[k], max(end_m - s, 0.0))
        near = s - s_robot <= speed_probe_m
        for o in range(n_off):
            d = min(max(offsets_out[o], -hw), hw)
            row = min(max(np.int64(np.rint((by + d * ny - origin_y_m) / res_m)), 0), h - 1)
            col = min(max(np.int64(np.rint((bx + d * nx - origin_x_m) / res_m)), 0), w - 1)
            c = clear[row, col]
            if c < min_all[o]:
                min_all[o] = c
            if not c >= min_clearance_m:
                free[o] = False
            if near and c < clear_near_out[o]:
                clear_near_out[o] = c
    # the way there: robot -> shifted carrot
    hw_c = min(seg_hw[seg], max(end_m - s_carrot, 0.0))
    nx, ny = normal[seg, 0], normal[seg, 1]
    for o in range(n_off):
        d = min(max(offsets_out[o], -hw_c), hw_c)
        tx = carrot_x + d * nx
        ty = carrot_y + d * ny
        min_way = math.inf
        for t in range(way_fractions.shape[0]):
            f = way_fractions[t]
            py = y_m + f * (ty - y_m)
            px = x_m + f * (tx - x_m)
            row = min(max(np.int64(np.rint((py - origin_y_m) / res_m)), 0), h - 1)
            col = min(max(np.int64(np.rint((px - origin_x_m) / res_m)), 0), w - 1)
            c = clear[row, col]
            if c < min_way:
                min_way = c
            if not c >= need_way:
                free[o] = False
        if here >= min_clearance_m and min_way < clear_near_out[o]:
            clear_near_out[o] = min_way
    best = -1
    best_score = -math.inf
    for o in range(n_off):
        if not free[o]:
            continue
        score = (
            min(min_all[o], clearance_enough_m)
            - offset_cost_per_m * abs(offsets_out[o])
            - switch_cost_per_m * abs(offsets_out[o] - offset_m)
        )
        if best < 0 or score > best_score:
            best, best_score = o, score
    return best, here


@register_controller("corridor-follower")
class CorridorFollower(Controller):
    """H&W §6.3's hybrid controller (module doc); ``params``: :class:`CorridorFollowerParams`
    fields. ``set_path(path, half_widths)`` takes per-vertex corridor half-widths ``l``.
    """

    def __init__(self, speed_mps: float, min_clearance_m: float, **params: float) -> None:
        super().__init__(speed_mps, min_clearance_m)
        self.params = CorridorFollowerParams(
            speed_mps=speed_mps, min_clearance_m=min_clearance_m, **params
        )
        k = self.params.n_offsets
        self._unit_offsets = np.linspace(-1.0, 1.0, k) if k > 1 else np.zeros(1)
        p = self.params
        #: arc lengths of the probe points ahead of the robot's projection [m]
        self._probe_steps_m = np.arange(0.0, p.probe_ahead_m + 1e-9, p.probe_step_m)
        #: fractions of the way robot -> shifted carrot at which it is probed (0 excluded)
        n_t = max(2, int(math.ceil(p.lookahead_m / p.probe_step_m)) + 1)
        self._way_fractions = np.linspace(0.0, 1.0, n_t)[1:]
        self._path: FloatArray | None = None
        self._n_seg = 0  # segments of the path (0: none)
        self._seg = 0
        self._offset_m = 0.0
        self._blocked = False
        self._clearance_ahead_m = math.inf

    # ----------------------------------------------------------------- path
    def set_path(self, path: FloatArray | None, half_widths: FloatArray | None = None) -> None:
        """Follow ``path`` ``(K, 2)`` [m]; ``half_widths`` ``(K,)`` [m] is the corridor
        half-width ``l`` at each vertex (None: ``default_half_width_m``). Segment ``i`` may be
        left by ``min(l_i, l_{i+1})`` (the narrower end bounds it, e.g. a doorway waypoint).
        Bad ``half_widths`` raise ``ValueError`` and leave no path."""
        self._seg = 0
        self._offset_m = 0.0
        self._blocked = False
        self._clearance_ahead_m = math.inf
        self._path, self._n_seg = None, 0
        if path is None:
            return
        verts = np.asarray(path, dtype=np.float64).reshape(-1, 2)
        if len(verts) < 2:
            return
        if half_widths is None:
            hw = np.full(len(verts), self.params.default_half_width_m)
        else:
            hw = np.asarray(half_widths, dtype=np.float64).reshape(-1)
            if hw.shape != (len(verts),) or not np.all(np.isfinite(hw) & (hw >= 0.0)):
                raise ValueError(
                    f"half_widths must be {len(verts)} finite values >= 0, got {half_widths!r}"
                )
        d = np.diff(verts, axis=0)
        length = np.hypot(d[:, 0], d[:, 1])
        self._seg_len = length
        self._tangent = d / np.maximum(length, 1e-12)[:, None]
        self._normal = np.stack([-self._tangent[:, 1], self._tangent[:, 0]], axis=1)  # left
        self._cum = np.concatenate([[0.0], np.cumsum(length)])
        self._seg_hw = np.minimum(hw[:-1], hw[1:])
        self._path, self._n_seg = verts, len(verts) - 1
        self._cache_floats()

    def _cache_floats(self) -> None:
        """The path's arrays as floats for the per-command scalar arithmetic (the same numbers
        without numpy scalars)."""
        assert self._path is not None
        self._path_list: list[list[float]] = self._path.tolist()
        self._cum_list: list[float] = self._cum.tolist()
        self._seg_hw_list: list[float] = self._seg_hw.tolist()
        self._seg_len_list: list[float] = self._seg_len.tolist()
        self._normal_list: list[list[float]] = self._normal.tolist()

    @property
    def segment(self) -> int:
        """Index of the segment being followed (its start vertex)."""
        return self._seg

    @property
    def done(self) -> bool:
        """True with no path (or a single vertex) and once its end is reached."""
        return self._seg >= self._n_seg

    @property
    def blocked(self) -> bool:
        """True when, at the last command, no lateral offset inside the corridor was free: the
        stack should replan globally (H&W §6.3)."""
        return self._blocked

    @property
    def offset_m(self) -> float:
        """The lateral offset chosen at the last command [m] (+ left of the path)."""
        return self._offset_m

    @property
    def clearance_ahead_m(self) -> float:
        """The clearance the speed law used at the last command [m] (inf before any)."""
        return self._clearance_ahead_m

    # ----------------------------------------------------------------- geometry
    def _along(self, x: float, y: float) -> tuple[float, float]:
        """Arc length of the robot's projection on the current segment and its signed lateral
        distance (+ left) from it [m]."""
        seg = self._seg
        ax, ay = self._path_list[seg]
        rel = np.array([x - ax, y - ay])
        u = min(max(float(rel @ self._tangent[seg]), 0.0), self._seg_len_list[seg])
        return self._cum_list[seg] + u, float(rel @ self._normal[seg])

    def _choose_offset(
        self,
        xy: FloatArray,
        s_robot: float,
        carrot: FloatArray,
        s_carrot: float,
        grid: ClearanceGrid,
    ) -> tuple[int | None, FloatArray, FloatArray, float]:
        """Index of the best free offset (None: none is free), the candidate offsets [m],
        each candidate's minimum clearance within ``speed_probe_m`` ahead (the way to its
        carrot included unless the robot stands inside the hard clearance: a free offset's
        value is then never below the hard clearance) and the clearance at the robot [m]."""
        p = self.params
        n = len(self._unit_offsets)
        offsets, clear_near = np.empty(n), np.empty(n)
        best, here = probe_offsets(
            CorridorPath(self._path, self._cum, self._tangent, self._normal, self._seg_hw),
            ProbeAt(
                self._seg,
                float(s_robot),
                float(carrot[0]),
                float(carrot[1]),
                float(s_carrot),
                float(xy[0]),
                float(xy[1]),
                self._offset_m,
            ),
            self._probe_steps_m,
            self._unit_offsets,
            self._way_fractions,
            GridView(
                grid.clearance_m,
                float(grid.origin[0]),
                float(grid.origin[1]),
                float(grid.resolution_m),
            ),
            OffsetScore(
                p.min_clearance_m,
                p.speed_probe_m,
                p.clearance_enough_m,
                p.offset_cost_per_m,
                p.switch_cost_per_m,
            ),
            offsets,
            clear_near,
        )
        return (None if best < 0 else int(best)), offsets, clear_near, float(here)

    # ----------------------------------------------------------------- control
    def command(
        self, pose: FloatArray, grid: ClearanceGrid, speed_limit: SpeedLimit | None = None
    ) -> NDArray[np.float32]:
        """The command ``[v_mps, omega_radps]`` at ``pose`` (map frame); zero when done or
        :attr:`blocked`."""
        p = self.params
        if self.done:
            self._blocked = False
            return np.zeros(2, dtype=np.float32)
        verts = self._path_list  # the path's floats (set_path)
        x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
        n_seg = self._n_seg
        cum, seg_hw = self._cum_list, self._seg_hw_list
        while True:
            self._seg = advance_segment(verts, self._seg, x, y, p.goal_tolerance_m)
            if self.done:
                self._blocked = False
                return np.zeros(2, dtype=np.float32)
            # with an offset the robot passes a vertex beside it: past the end of an inner
            # segment and inside its corridor is reached, too
            s_robot, lat = self._along(x, y)
            at_end = s_robot >= cum[self._seg + 1] - p.goal_tolerance_m
            inside = abs(lat) <= seg_hw[self._seg] + p.goal_tolerance_m
            if self._seg < n_seg - 1 and at_end and inside:
                self._seg += 1
                continue
            break
        seg = self._seg
        cx, cy = carrot_on_segment(verts[seg], verts[seg + 1], x, y, p.lookahead_m)
        carrot = np.array([cx, cy])
        ax, ay = verts[seg]
        s_carrot = cum[seg] + float(np.hypot(cx - ax, cy - ay))
        xy = np.array([x, y])
        best, offsets, clear_near, here = self._choose_offset(xy, s_robot, carrot, s_carrot, grid)
        if best is None:
            self._blocked = True
            self._clearance_ahead_m = float(clear_near.max())
            return np.zeros(2, dtype=np.float32)
        self._blocked = False
        self._offset_m = float(offsets[best])
        # the corridor's half-width at the carrot (narrowing over the path's last l metres)
        hw_c = min(seg_hw[seg], max(cum[-1] - s_carrot, 0.0))
        d_c = min(max(self._offset_m, -hw_c), hw_c)
        nx, ny = self._normal_list[seg]
        tx, ty = cx + d_c * nx, cy + d_c * ny
        # the shifted carrot in the robot frame
        c, sn = math.cos(th), math.sin(th)
        dx, dy = tx - x, ty - y
        rx, ry = c * dx + sn * dy, -sn * dx + c * dy
        alpha = math.atan2(ry, rx)
        dist = math.hypot(rx, ry)
        if abs(alpha) > p.turn_in_place_rad:  # rotate to heading
            return np.array([0.0, math.copysign(p.max_omega_radps, alpha)], dtype=np.float32)
        # speed: clearance law on the chosen offset (the robot's own spot counts unless it
        # is already inside the hard clearance: then it creeps out along the free offset)
        d_speed = float(clear_near[best])
        if here >= p.min_clearance_m:
            d_speed = min(d_speed, here)
        self._clearance_ahead_m = d_speed
        v = speed_for_clearance(d_speed, p)
        kappa = abs(2.0 * math.sin(alpha)) / max(dist, 1e-3)
        if kappa * p.regulated_min_radius_m > 1.0:  # RPP curvature regulation: v * R / R_min
            v = max(v / (kappa * p.regulated_min_radius_m), min(v, p.min_speed_mps))
        if self._seg == n_seg - 1:  # RPP approach regulation
            to_end = math.hypot(verts[-1][0] - x, verts[-1][1] - y)
            v = min(v, max(p.speed_mps * to_end / p.approach_dist_m, p.approach_min_speed_mps))
        if speed_limit is not None:
            v *= speed_limit()
        if v <= 0.0:
            return np.zeros(2, dtype=np.float32)
        omega = pursuit_turn_rate(alpha, dist, max(v, p.min_steering_speed_mps), p.max_omega_radps)
        return np.array([v, omega], dtype=np.float32)
