"""Where the robot is on its routes, and what it learns from driving them (H&W 2011 §5.1,
§5.2): the short-term memory of a run.

:meth:`RouteTracker.locate_xy` places the robot relative to every segment of every route (the
compiled search :func:`locate_segment`): the segment with the minimal lateral distance wins,
and the pose is "on the route" only inside that segment's corridor. :meth:`RouteTracker.step`,
inside a corridor, counts the waypoints passed; a passed segment learns its travel time (EMA)
and update time and is unblocked (having driven it is seeing it free), and waypoints adapt
toward the driven line.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.navigation.routes import DT, Route, RouteSet, T, X, Y
from dynmap_sim.agent.planning.route_graph import both_ways
from dynmap_sim.jit import compiled

FloatArray = NDArray[np.float64]


class RoutePosition(NamedTuple):
    """The robot relative to the route memory (H&W §5.1): the closest segment of all routes.

    The segment runs ``from_id -> to_id`` (waypoint ids) and ends at index ``segment`` of
    route ``route_id``. ``progress`` ∈ [0, 1] is the projection's fraction of the segment,
    ``along_m`` its arc length from the route's start, ``projection_xy`` the projected point
    on the centre line; ``distance_m`` is the distance to the segment (the lateral distance
    when 0 < progress < 1), ``lateral_m`` the signed perpendicular offset (left of the
    direction of travel > 0). ``inside`` says ``distance_m <= half_width_m``.
    """

    route_id: int
    segment: int
    from_id: int
    to_id: int
    progress: float
    along_m: float
    distance_m: float
    lateral_m: float
    half_width_m: float
    inside: bool
    projection_xy: tuple[float, float]


@compiled
def locate_segment(  # type: ignore[no-untyped-def]
    px, py, heading, segs, prefer_route, prefer_along_m, use_prefer, use_along, window_m,
    continuity_m,
):  # fmt: skip
    """:meth:`.route_memory.RouteMemory.locate`'s search over ``segs``
    (:class:`SegmentArrays`) for the point ``(px, py)`` [m]: the index ``k`` of the segment
    picked, its clamped fraction ``u``, distance [m] and projection ``(qx, qy)`` [m];
    ``k = -1`` without segments. A segment that runs against the robot's ``heading`` [rad]
    (more than 90° off; NaN: none known) counts ``continuity_m`` farther, so of two passes
    of a place in opposite directions the one the robot drives along wins. With
    ``use_prefer`` route ``prefer_route``'s nearest segment wins a tie; with ``use_along``
    its segments within ``window_m`` of ``prefer_along_m`` along it win unless another is
    ``continuity_m`` [m] nearer. The first of equal minima wins."""
    a, b, rid, s0, seg_len = segs
    k, k2, k3 = -1, -1, -1
    best, best2, best3 = 0.0, 0.0, 0.0
    u_k, u_k2, u_k3 = 0.0, 0.0, 0.0
    use_heading = heading == heading
    hx, hy = (np.cos(heading), np.sin(heading)) if use_heading else (0.0, 0.0)
    for i in range(a.shape[0]):
        ax, ay = a[i, 0], a[i, 1]
        dx, dy = b[i, 0] - ax, b[i, 1] - ay
        len2 = dx * dx + dy * dy
        t = ((px - ax) * dx + (py - ay) * dy) / (len2 if len2 > 1e-18 else 1e-18)
        u = t if t > 0.0 else 0.0  # numpy's clip: max(t, 0), then min(., 1)
        u = u if u < 1.0 else 1.0
        dist = np.hypot(px - (ax + u * dx), py - (ay + u * dy))
        if use_heading and dx * hx + dy * hy < 0.0:
            dist += continuity_m
        if k < 0 or dist < best:
            k, best, u_k = i, dist, u
        if use_prefer and rid[i] == prefer_route:
            if k2 < 0 or dist < best2:
                k2, best2, u_k2 = i, dist, u
            if use_along and abs(s0[i] + u * seg_len[i] - prefer_along_m) <= window_m:
                if k3 < 0 or dist < best3:
                    k3, best3, u_k3 = i, dist, u
    if k2 >= 0 and best2 <= best + 1e-9:
        k, best, u_k = k2, best2, u_k2
    if k3 >= 0 and best3 <= best + continuity_m:
        k, best, u_k = k3, best3, u_k3
    if k < 0:
        return -1, 0.0, 0.0, 0.0, 0.0
    ax, ay = a[k, 0], a[k, 1]
    qx, qy = ax + u_k * (b[k, 0] - ax), ay + u_k * (b[k, 1] - ay)
    return k, u_k, np.hypot(px - qx, py - qy), qx, qy


@dataclass
class _Track:
    """Short-term state on one route: the last arc length [m] and time [s] on it."""

    route_id: int
    s_prev_m: float
    t_prev_s: float


class _Passed(NamedTuple):
    """The last waypoint the robot passed (on any route): id, position [m], time [s]."""

    waypoint_id: int
    x_m: float
    y_m: float
    t_s: float


class RouteTracker:
    """The short-term state on the routes of ``route_set`` (module doc): the route being
    tracked, the last waypoint passed, the last step inside a corridor and the driven lateral
    offsets not yet applied. :meth:`reset` at the start of every run."""

    def __init__(self, route_set: RouteSet) -> None:
        self.route_set = route_set
        self.params = route_set.params
        self.reset()

    def reset(self) -> None:
        """Forget the run's short-term state (§5.1 STM)."""
        self.track: _Track | None = None
        #: the last step inside a corridor: position, time, heading, robot (x, y)
        self.last_inside: tuple[RoutePosition, float, float, tuple[float, float]] | None = None
        self.passed: _Passed | None = None
        #: per waypoint id: the driven lateral offsets' weighted sums ``[Σwx, Σwy, Σw]``
        self.pending: dict[int, list[float]] = {}
        #: no pose observed yet in this run (the first is placed at the prior route's start)
        self.at_run_start = True

    def route_removed(self, route_id: int) -> None:
        """Route ``route_id`` was cut: stop tracking it."""
        if self.track is not None and self.track.route_id == route_id:
            self.track = None

    def locate_xy(
        self,
        px: float,
        py: float,
        prefer_route: int | None,
        prefer_along_m: float | None,
        heading: float = math.nan,
    ) -> RoutePosition | None:
        """The robot's position at ``(px, py)`` [m] with ``heading`` [rad] (NaN: unknown)
        relative to the routes (§5.1, :meth:`.route_memory.RouteMemory.locate`); None for no
        routes or a non-finite position."""
        s = self.route_set.segments()
        if not s.rows:
            return None
        if not math.isfinite(px + py):
            return None
        k, u_k, dist_k, qx, qy = locate_segment(
            px,
            py,
            float(heading),
            s.arrays,
            -1 if prefer_route is None else prefer_route,
            0.0 if prefer_along_m is None else prefer_along_m,
            prefer_route is not None,
            prefer_along_m is not None,
            self.params.continuity_window_m,
            self.params.continuity_m,
        )
        rid, seg, fr, to, ax, ay, bx, by, s0, length, hw = s.rows[k]
        lateral = ((bx - ax) * (py - ay) - (by - ay) * (px - ax)) / length if length > 0 else 0.0
        # RoutePosition's fields in order (positional: this runs every step)
        return RoutePosition(
            rid, seg, fr, to, u_k, s0 + u_k * length, dist_k, lateral, hw, dist_k <= hw, (qx, qy)
        )

    def step(self, pos: RoutePosition, px: float, py: float, t_s: float) -> None:
        """One step inside the corridor of ``pos`` at ``(px, py)`` [m], time ``t_s`` [s]: the
        waypoints passed since the last step are passed (module doc), and the driven lateral
        offset is accumulated for the waypoints' adaptation."""
        r = self.route_set.routes[pos.route_id]
        tr = self.track
        if tr is None or tr.route_id != pos.route_id:
            if tr is not None:
                self._leave(tr)
            self.pending.clear()
            self.track = _Track(pos.route_id, pos.along_m, t_s)
            self._enter(r, pos, t_s)
        else:
            s0, s1 = tr.s_prev_m, pos.along_m
            # a jump along the route much longer than the robot moved is no drive past the
            # waypoints between: a loop route's end meets its start (H&W's), or a pose jumped
            last = self.last_inside
            moved = math.hypot(px - last[3][0], py - last[3][1]) if last is not None else math.inf
            if s1 - s0 > moved + self.params.join_distance_m:
                s0 = s1
            if s1 > s0:
                # the waypoints whose arc length lies in (s0, s1]: the route's end counts as
                # passed pass_tolerance_m before it (a robot stops at its goal within a
                # tolerance), timed as if it drove on at its speed; the marks ascend, so the
                # others are a range found by bisection
                cum = self.route_set.segments().cum_list[r.route_id]
                n = len(cum)
                early = min(self.params.pass_tolerance_m, 0.5 * (cum[-1] - cum[-2]))
                end_mark = cum[-1] - early
                crossed = list(
                    range(bisect_right(cum, s0, 0, n - 1), bisect_right(cum, s1, 0, n - 1))
                )
                if s0 < end_mark <= s1:
                    crossed.append(n - 1)
                if crossed:
                    speed = (s1 - s0) / max(t_s - tr.t_prev_s, 1e-9)
                    ids = r.ids.tolist()
                    passes = []
                    for j in crossed:
                        tc = tr.t_prev_s + ((end_mark if j == n - 1 else cum[j]) - s0) / speed
                        if j == n - 1:
                            tc += early / speed
                        passes.append((ids[j], tc))
                    for wid, tc in passes:
                        self.pass_waypoint(r, wid, tc)
            tr.s_prev_m, tr.t_prev_s = s1, t_s
        if 0.0 < pos.progress < 1.0:  # perpendicular offset only
            ox = px - pos.projection_xy[0]
            oy = py - pos.projection_xy[1]
            for wid, w in ((pos.from_id, 1.0 - pos.progress), (pos.to_id, pos.progress)):
                acc = self.pending.get(wid)
                if acc is None:
                    acc = self.pending[wid] = [0.0, 0.0, 0.0]
                acc[0] += w * ox
                acc[1] += w * oy
                acc[2] += w

    def _leave(self, tr: _Track) -> None:
        """The robot switched from route ``tr.route_id`` to another one (inside both
        corridors, e.g. where a recorded route starts at a waypoint of this one): the
        waypoint it was about to reach counts as passed if it was within
        ``pass_tolerance_m`` along the route, as at a run's start and a route's end.
        Otherwise the segment ending there would never be learned nor its update time
        renewed when the switch happens just before it (a robot cutting the corner onto
        the other route), and forgetting would drop a stretch driven every day."""
        r = self.route_set.routes.get(tr.route_id)
        if r is None:
            return
        cum = r.cumulative_m()
        mark = cum.copy()
        mark[-1] -= min(self.params.pass_tolerance_m, 0.5 * (cum[-1] - cum[-2]))
        ahead = np.flatnonzero(mark > tr.s_prev_m)
        if ahead.size and cum[ahead[0]] - tr.s_prev_m <= self.params.pass_tolerance_m:
            self.pass_waypoint(r, int(r.ids[ahead[0]]), tr.t_prev_s)

    def _enter(self, r: Route, pos: RoutePosition, t_s: float) -> None:
        """Entering route ``r`` on segment ``pos.segment``: its start waypoint counts as passed
        if the last waypoint passed (on another route) joins it — a join carries the pass
        over — or, failing that, if the robot is within ``pass_tolerance_m`` of it along the
        route (the start of a run)."""
        start = r.xy[pos.segment - 1]
        last = self.passed
        if last is not None and last.waypoint_id == pos.from_id:
            return
        if (
            last is not None
            and math.hypot(last.x_m - start[0], last.y_m - start[1]) <= self.params.join_distance_m
        ):
            self.passed = _Passed(pos.from_id, float(start[0]), float(start[1]), last.t_s)
        elif (
            pos.along_m - self.route_set.cumulative(r.route_id)[pos.segment - 1]
            <= self.params.pass_tolerance_m
        ):
            self.passed = _Passed(pos.from_id, float(start[0]), float(start[1]), t_s)

    def pass_waypoint(self, r: Route, waypoint_id: int, t_s: float) -> None:
        """The robot passed waypoint ``waypoint_id`` of ``r`` at ``t_s``: learn the segment
        ending at it if its start was the last waypoint passed, adapt the waypoint behind."""
        j = r.index(waypoint_id)
        last = self.passed
        if j >= 1 and last is not None and last.waypoint_id == int(r.ids[j - 1]):
            self._learn(r, j, t_s - last.t_s, t_s)
        if j >= 1:
            self._adapt(r, int(r.ids[j - 1]), t_s)
        if j == len(r.ids) - 1:
            self._adapt(r, waypoint_id, t_s)
        self.passed = _Passed(waypoint_id, float(r.wp[j, X]), float(r.wp[j, Y]), t_s)

    def _learn(self, r: Route, j: int, dt_s: float, t_s: float) -> None:
        """Travel time of segment ``j`` (EMA, first value taken as it is), update time, and
        unblock it: a driven segment has been seen free."""
        old = r.wp[j, DT]
        a = self.params.travel_time_alpha
        r.wp[j, DT] = dt_s if not np.isfinite(old) else (1.0 - a) * old + a * dt_s
        r.wp[j, T] = t_s
        self.route_set.blocked -= both_ways({(int(r.ids[j - 1]), int(r.ids[j]))})

    def _adapt(self, r: Route, waypoint_id: int, t_s: float) -> None:
        """Move a waypoint ``coord_alpha`` of the mean driven lateral offset (once per pass).
        Waypoints that join another route keep their place, so joins do not drift apart."""
        acc = self.pending.pop(waypoint_id, None)
        if acc is None or acc[2] <= 0.0:
            return
        j = r.index(waypoint_id)
        for other in self.route_set.routes.values():
            if other.route_id != r.route_id and np.any(
                np.hypot(*(other.xy - r.xy[j]).T) <= self.params.join_distance_m
            ):
                return
        r.wp[j, :2] += self.params.coord_alpha * np.array(acc[:2]) / acc[2]
        r.wp[j, T] = t_s
        self.route_set.changed()
