"""What the route memory learns beyond the routes it tracks (H&W 2011 §5.2): new routes
recorded outside every corridor, and forgetting what was not used.

* :class:`RouteRecorder`: outside every corridor a **new route** is recorded (a waypoint every
  ``Δd`` or ``Δφ``) from the point where the robot left a corridor to the point where it
  re-enters one, and joined to the graph at both ends (the segments there are split).
* :func:`forget`: stretches not updated for longer than an age are removed, where the graph
  can do without them.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.navigation.route_tracking import RoutePosition, RouteTracker, _Passed, _Track
from dynmap_sim.agent.navigation.routes import Route, RouteSet, T, X, Y, build_graph
from dynmap_sim.agent.planning.route_graph import RouteGraph, reaching

FloatArray = NDArray[np.float64]


@dataclass
class _Recording:
    """A new route being recorded outside every corridor (§5.2)."""

    xy: list[tuple[float, float]]
    t_s: list[float]
    heading_rad: float
    #: ``(route_id, from_id, to_id, xy, t_s)`` where it left a corridor.
    exit: tuple[int, int, int, tuple[float, float], float] | None
    #: Where the robot itself was at the first waypoint's time (off the centre line) [m].
    robot_start_xy: tuple[float, float]


class RouteRecorder:
    """Records a new route outside every corridor (module doc) into ``route_set``; the
    ``tracker``'s short-term state tells where the robot left a corridor and is updated where
    it re-enters one."""

    def __init__(self, route_set: RouteSet, tracker: RouteTracker) -> None:
        self.route_set = route_set
        self.tracker = tracker
        self.params = route_set.params
        self.rec: _Recording | None = None

    def start(self, xy: FloatArray, heading: float, t_s: float) -> None:
        """Start recording at the robot's ``xy`` [m] (from the corridor it left, if any)."""
        if self.tracker.last_inside is not None:
            pos, t0, h0, xy0 = self.tracker.last_inside
            exit_ = (pos.route_id, pos.from_id, pos.to_id, pos.projection_xy, t0)
            self.rec = _Recording([pos.projection_xy], [t0], h0, exit_, (xy0[0], xy0[1]))
        else:
            start = (float(xy[0]), float(xy[1]))
            self.rec = _Recording([start], [t_s], heading, None, start)

    def step(self, xy: FloatArray, heading: float, t_s: float) -> None:
        """Add a waypoint every ``Δd``, or after a turn of ``Δφ`` (§5.2)."""
        rec = self.rec
        assert rec is not None
        d = float(np.hypot(*(xy - np.asarray(rec.xy[-1]))))
        turn = abs(math.remainder(heading - rec.heading_rad, 2 * math.pi))
        p = self.params
        if d >= p.record_spacing_m or (
            d >= p.record_min_spacing_m and turn >= p.record_heading_rad
        ):
            rec.xy.append((float(xy[0]), float(xy[1])))
            rec.t_s.append(t_s)
            rec.heading_rad = heading

    def finish(self, pos: RoutePosition, robot_xy: FloatArray, t_s: float) -> None:
        """Re-entering a corridor ends the recording: join the new route at both ends.

        A blocked segment split at the exit keeps its block after the exit point (the robot
        drove up to it), one split at the entry before the entry point (the robot re-enters
        behind the block, H&W §6.3 "returns ... behind the obstacle"). Should a robot come
        back before the block, it sees it again and blocks it again: one more encounter.
        """
        rec = self.rec
        assert rec is not None
        self.rec = None
        entry = pos.projection_xy
        if (
            len(rec.xy) > 1
            and np.hypot(*(np.subtract(entry, rec.xy[-1]))) < self.params.record_min_spacing_m
        ):
            rec.xy.pop()
            rec.t_s.pop()
        xy = np.array([*rec.xy, entry])
        times = np.array([*rec.t_s, t_s])
        # what the robot drove outside the corridors (the route's ends are on centre lines)
        driven = np.array([rec.robot_start_xy, *rec.xy[1:], robot_xy], float)
        if np.sum(np.hypot(*np.diff(driven, axis=0).T)) < self.params.min_new_route_m:
            if self.tracker.track is not None and self.tracker.track.route_id != pos.route_id:
                self.tracker.track = None
            return
        if rec.exit is not None:
            rid, from_id, to_id, exit_xy, t_exit = rec.exit
            try:
                c = self.route_set.split(rid, from_id, to_id, exit_xy, block_half="after")
            except (KeyError, ValueError):  # the segment was forgotten meanwhile
                c = None
            if c is not None:
                r = self.route_set.routes[rid]
                j = r.index(c)
                xy[0] = r.xy[j]
                if c != from_id:  # the robot drove from_id -> exit point: a pass
                    self.tracker.pass_waypoint(r, c, t_exit)
        r2 = self.route_set.routes[pos.route_id]
        j2, _ = self.route_set.nearest_on_route(r2, np.asarray(entry))
        d = self.route_set.split(
            r2.route_id, int(r2.ids[j2 - 1]), int(r2.ids[j2]), entry, block_half="before"
        )
        jd = r2.index(d)
        xy[-1] = r2.xy[jd]
        dt = np.concatenate([[np.nan], np.diff(times)])
        # The end segments were timed from where the robot was (at the corridor's edge), not
        # from the join points on the centre line: scale them at constant speed.
        ends = [1] if len(xy) == 2 else [1, len(xy) - 1]
        for k in ends:
            d_driven = float(np.hypot(*(driven[k] - driven[k - 1])))
            if d_driven > 1e-6:
                dt[k] *= float(np.hypot(*(xy[k] - xy[k - 1]))) / d_driven
        p = self.params
        self.route_set.add_route(xy, p.new_v_max_mps, p.new_half_width_m, t_s, travel_time_s=dt)
        self.tracker.pending.clear()
        self.tracker.track = _Track(r2.route_id, float(r2.cumulative_m()[jd]), t_s)
        self.tracker.passed = _Passed(d, float(r2.wp[jd, X]), float(r2.wp[jd, Y]), t_s)


def forget(
    route_set: RouteSet,
    tracker: RouteTracker,
    graph: Callable[[], RouteGraph],
    now_s: float,
    keep: Iterable[int] = (),
) -> int:
    """Forget stretches not updated for longer than ``forget_age_s`` (§5.2); returns the
    number of segments forgotten. ``graph``: the route set's graph (rebuilt when it changed);
    ``keep``: waypoint ids that must survive and stay
    reachable (the navigator's goal).

    Granularity: a maximal run of stale consecutive segments of a route, not always the
    whole route — a recorded route is driven (and so updated) as a whole, so for it this
    is the paper's "the route is removed"; the prior route, driven for years, must be
    able to lose just the part a detour replaced. Condition: a stale stretch is forgotten
    only if it is **bypassed** — without it, its end is still reachable from its start
    over passable edges — so forgetting never cuts the goal off (e.g. after days
    without runs, when everything is stale). A route cut in the middle becomes two
    routes; a piece of one waypoint is dropped. Dropping the end waypoints of a piece
    also drops the joins through them: so a stretch is also kept when forgetting it would
    remove a ``keep`` waypoint or leave a waypoint that reached one unable to reach it
    (a loop's goal reached only over a recorded route's end, which is joined to both the
    loop's end and its start: forgetting that route cut the goal off).
    """
    keep = {int(k) for k in keep}
    forgotten = 0
    changed = True
    while changed:
        changed = False
        for r in list(route_set.routes.values()):
            stale = now_s - r.wp[1:, T] > route_set.params.forget_age_s
            for a, b in _runs(stale):
                if _bypassed(graph(), r, a, b) and _keeps_reach(route_set, graph(), r, a, b, keep):
                    route_set.cut(r, a, b)
                    tracker.route_removed(r.route_id)
                    forgotten += b - a
                    changed = True
                    break
            if changed:
                break
    return forgotten


def _bypassed(g: RouteGraph, r: Route, a: int, b: int) -> bool:
    """Is waypoint ``b`` of ``r`` reachable in ``g`` from waypoint ``a`` without segments
    a..b, in the routes' direction (forgetting keeps what driving the routes as recorded
    needs)?"""
    gone = {int(i) for i in r.ids[a + 1 : b]}
    cut = {(int(r.ids[k - 1]), int(r.ids[k])) for k in range(a + 1, b + 1)}
    start, goal = int(r.ids[a]), int(r.ids[b])
    seen, todo = {start}, deque([start])
    while todo:
        n = todo.popleft()
        for e in g.out[n]:
            if (
                e.reverse
                or e.v in seen
                or e.v in gone
                or (e.u, e.v) in cut
                or not np.isfinite(e.travel_time_s)
            ):
                continue
            if e.v == goal:
                return True
            seen.add(e.v)
            todo.append(e.v)
    return False


def _keeps_reach(
    route_set: RouteSet, before: RouteGraph, r: Route, a: int, b: int, keep: set[int]
) -> bool:
    """Would cutting segments ``a+1..b`` of ``r`` keep every ``keep`` waypoint, and every
    remaining waypoint that reaches one in ``before`` (over passable edges) still reaching
    it?"""
    if not keep:
        return True
    removed = route_set.removed_by_cut(r, a, b)
    if removed & keep:
        return False
    targets = [k for k in keep if k in before.index]
    if not targets:
        return True
    trial = route_set.copy()
    trial.cut(trial.routes[r.route_id], a, b)
    after = build_graph(trial)
    return all(reaching(before, k) - removed <= reaching(after, k) for k in targets)


def _runs(mask: NDArray[np.bool_]) -> list[tuple[int, int]]:
    """Maximal runs of True in a per-segment mask, as waypoint index pairs ``(a, b)``: segments
    ``a+1..b`` (segment ``j`` ends at waypoint ``j``; ``mask[j-1]`` is segment ``j``)."""
    out, start = [], None
    for j, s in enumerate(mask.tolist(), start=1):
        if s and start is None:
            start = j
        if not s and start is not None:
            out.append((start - 1, j - 1))
            start = None
    if start is not None:
        out.append((start - 1, len(mask)))
    return out
