"""Routes (H&W 2011 §5, eqs. 16-17) and the set of them a route memory holds.

A :class:`Route` is a directed sequence of waypoints ``w_ij = (x, y, v, l, t, Δt)`` (eq. 17):
position [m], the maximal speed for approaching the waypoint [m/s], the corridor half-width
``l`` of the segment ``w_i,j-1 -> w_ij`` [m] (the perpendicular distance from the centre line
to the corridor's edge), the last update time ``t`` [s] and the travel time ``Δt`` of that
segment [s]. A :class:`RouteSet` holds the routes ``R = {r_i}`` (eq. 16), the blocked edges,
the id counters and the cached geometry of all segments, and makes the edits the learning
needs (add a route, split a segment, cut a stretch out); :func:`build_graph` turns it into the
:class:`~dynmap_sim.agent.planning.route_graph.RouteGraph` route A* plans on (§6.2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.params import params_dataclass
from dynmap_sim.agent.planning.route_graph import (
    JOIN,
    Edge,
    RouteGraph,
    both_ways,
    project_onto_segments,
)

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Columns of a route's ``(m, 6)`` waypoint array, in the order of eq. 17.
X, Y, V, L, T, DT = range(6)
#: Column names of eq. 17 with their units.
WAYPOINT_FIELDS: tuple[str, ...] = (
    "x_m",
    "y_m",
    "v_max_mps",
    "half_width_m",
    "last_update_s",
    "travel_time_s",
)


@params_dataclass("route-memory")
class RouteMemoryParams:
    """Everything H&W §5 leaves open, with a default and the reason for it.

    Distances in metres, angles in radians, times in seconds, speeds in m/s.
    """

    #: ``Δd`` (§5.2): a new waypoint when the robot is this far from the last one. 0.5 m is
    #: about one robot length: a doorway (≈ 0.9-1.2 m) gets two or three waypoints, so the
    #: recorded line follows the detour's shape, while a 10 m corridor costs only 20 nodes.
    record_spacing_m: float = 0.5
    #: ``Δφ`` (§5.2): a new waypoint when the heading turned this far since the last one.
    #: 20° keeps the chord of a turn within ~2 cm of the arc at 0.5 m spacing.
    record_heading_rad: float = math.radians(20.0)
    #: The ``Δφ`` rule needs at least this distance from the last waypoint: a turn in place
    #: would otherwise stack waypoints on one spot, segments too short to time. Also the snap
    #: distance at which a join reuses an existing waypoint instead of splitting a segment.
    record_min_spacing_m: float = 0.1
    #: Corridor half-width ``l`` of recorded routes. 0.35 m: a doorway of ≈ 1.2 m minus a
    #: robot of ≈ 0.35 m diameter leaves ± 0.35 m of lateral freedom around its centre line,
    #: so reactive avoidance (§6.3, bounded by ``l``) never pushes into a door frame.
    new_half_width_m: float = 0.35
    #: ``v`` of recorded routes. 0.2 m/s: the paper's Roomba pace (§7.1); a recorded route has
    #: been driven at that speed at most, so planning with it is not optimistic.
    new_v_max_mps: float = 0.2
    #: Travel-time averaging: ``Δt ← (1-α) Δt + α Δt_measured`` (the first measurement is
    #: taken as it is). 0.3 remembers about three runs: one slow pass (a person in the way)
    #: moves the estimate by 30 %, a lasting change is learned within ~5 runs. ``α = 1`` keeps
    #: only the last time, as nav2_route's TimeMarker does; that lets one disturbed run flip
    #: the plan between two routes of similar cost.
    travel_time_alpha: float = 0.3
    #: Coordinate adaptation: once per pass, a waypoint moves this fraction of the mean
    #: lateral offset at which the robot drove past it (perpendicular only, so lengths and
    #: travel times stay comparable). 0.1 per pass: the centre line follows a lasting shift
    #: over ~10 runs but one avoidance manoeuvre moves it by < 4 cm.
    coord_alpha: float = 0.1
    #: Forgetting age (§5.2): a stretch not updated for longer than this is forgotten (if the
    #: graph can do without it, see :meth:`RouteMemory.forget`). 3 days: with one run a day a
    #: route survives two missed days, and a stretch bypassed since day 22 of a 28-day
    #: experiment is gone well before its end.
    forget_age_s: float = 3 * 86_400.0
    #: Waypoints of different routes this close are joined in the graph (both directions).
    #: 0.5 m = ``Δd``: a recorded route's ends lie on the centre line they left, and any
    #: two waypoints this close are within each other's corridors (≥ 0.35 m) plus a margin.
    join_distance_m: float = 0.5
    #: A route segment may be driven against its direction at its travel time times this
    #: (H&W's routes are directed): a route that returns through a doorway it passed, or a
    #: block whose way round is the route's own later part driven backwards, has a plan.
    #: 1.5 is a judgement of how much worse a leg driven backwards is than the same
    #: corridor forwards (never timed that way, it starts with a turn): the robot keeps to
    #: the routes' direction unless going back saves a third of the time. A loop is still
    #: closed forwards: a plan that passes a via point behind its target is planned again
    #: without reverse edges (route planning's route order). ``inf`` (the default):
    #: directed routes only, as H&W's. Off because on a generated loop route whose waypoints
    #: carry no via points the robot went back to its start (the route's end) after a quarter
    #: of the route, and that counts as the goal reached: 1.5 is the value to try with a
    #: scenario's ``route_memory`` table where a route returns through a doorway.
    reverse_cost_factor: float = math.inf
    #: A recorded route is dropped when the robot drove less than this outside the corridors
    #: (from where it left one to where it re-entered one, not counting the legs to the
    #: centre lines): an excursion of less than one ``Δd`` is localization noise or an
    #: avoidance wobble at a corridor's edge, not a new way.
    min_new_route_m: float = 0.5
    #: On first entering a route (start of a run), a segment's start waypoint counts as passed
    #: when the robot is within this distance along the route from it, and a route's last
    #: waypoint when the robot comes this close (it stops at its goal within a tolerance), so
    #: the first and last segments' times are learned. 0.2 m ≈ two localization errors (H&W
    #: §7.3: 0.11 m); larger would time a partial segment as a whole one.
    pass_tolerance_m: float = 0.2
    #: §5.1 places the robot on the segment at minimal lateral distance. Where a route passes
    #: a place twice (into a room and back out the same doorway) that is ambiguous, and the
    #: position can flip to the other pass, sending the robot round the room's loop again
    #: (docs/tuning/navigation.md). So the tracked route's segments within
    #: this arc length [m] of the last tracked position (either way) are preferred: the
    #: nearest of them wins unless another segment is ``continuity_m`` nearer. 2 m is far
    #: more than a robot drives between two scans, far less than a room's loop.
    continuity_window_m: float = 2.0
    #: ... by this much [m]: the corridor half-width, inside which both passes lie.
    continuity_m: float = 0.35


class Waypoint(NamedTuple):
    """One waypoint of eq. 17; ``half_width_m`` and ``travel_time_s`` describe the segment
    ending at it (``travel_time_s`` is NaN while it was never driven)."""

    x_m: float
    y_m: float
    v_max_mps: float
    half_width_m: float
    last_update_s: float
    travel_time_s: float


@dataclass
class Route:
    """A directed waypoint sequence (eq. 17): ``ids (m,)`` stable waypoint ids and ``wp
    (m, 6)`` rows in the column order of :data:`WAYPOINT_FIELDS`. ``prior`` marks the
    route a scenario grants (H&W Fig. 4) and what remains of it."""

    route_id: int
    ids: IntArray
    wp: FloatArray
    prior: bool = False

    @property
    def xy(self) -> FloatArray:
        """Waypoint positions ``(m, 2)`` [m]."""
        return self.wp[:, :2]

    def segment_lengths_m(self) -> FloatArray:
        """Lengths of the ``m - 1`` segments [m]."""
        return np.hypot(*np.diff(self.xy, axis=0).T)

    def cumulative_m(self) -> FloatArray:
        """Arc length from the route's start to every waypoint ``(m,)`` [m]."""
        return np.concatenate([[0.0], np.cumsum(self.segment_lengths_m())])

    def index(self, waypoint_id: int) -> int:
        """Index of a waypoint id in this route (``ValueError`` if absent)."""
        hit = np.flatnonzero(self.ids == waypoint_id)
        if hit.size == 0:
            raise ValueError(f"waypoint {waypoint_id} is not on route {self.route_id}")
        return int(hit[0])

    def waypoints(self) -> list[Waypoint]:
        """The rows as :class:`Waypoint` tuples."""
        return [Waypoint(*map(float, row)) for row in self.wp]


class SegmentArrays(NamedTuple):
    """Every segment of every route for :func:`locate_segment`: starts and ends ``(S, 2)``
    [m], route ids ``(S,)``, the start's arc length on its route ``(S,)`` [m] and the
    lengths ``(S,)`` [m]."""

    a: FloatArray
    b: FloatArray
    rid: IntArray
    s0: FloatArray
    length: FloatArray


@dataclass
class _Segments:
    """All segments of all routes as flat arrays, and per route its arc lengths: what
    :meth:`RouteMemory.locate` and the tracking read every step, built once per geometry
    (see :meth:`RouteSet.segments`)."""

    a: FloatArray  # (S, 2) segment starts [m]
    b: FloatArray  # (S, 2) segment ends [m]
    l: FloatArray  # (S,) half-widths [m]
    rid: IntArray  # (S,) route ids
    seg: IntArray  # (S,) index of the end waypoint in its route
    fr: IntArray  # (S,) start waypoint ids
    to: IntArray  # (S,) end waypoint ids
    s0: FloatArray  # (S,) arc length of the start waypoint on its route [m]
    length: FloatArray  # (S,) segment lengths [m]
    #: per route id: ``Route.cumulative_m()`` as an array and as a list of floats
    cum: dict[int, FloatArray]
    cum_list: dict[int, list[float]]
    #: per segment: ``(rid, seg, from, to, ax, ay, bx, by, s0, length, l)`` as Python numbers
    rows: list[tuple[Any, ...]]
    #: the arrays :func:`locate_segment` searches
    arrays: SegmentArrays


class RouteSet:
    """The routes of a route memory, its blocked edges ``(from_id, to_id)`` (infinite cost
    until seen free, §6.3), the id counters and the cached geometry of all segments. Every
    change of a waypoint's position, a route's half-width or the set of routes must call
    :meth:`changed` (the edits here do)."""

    def __init__(self, params: RouteMemoryParams) -> None:
        self.params = params
        self.routes: dict[int, Route] = {}
        self.blocked: set[tuple[int, int]] = set()
        self.next_route_id = 0
        self.next_waypoint_id = 0
        self._segs: _Segments | None = None

    def changed(self) -> None:
        """Drop the geometry cache (a waypoint moved, a route came or went)."""
        self._segs = None

    def copy(self) -> RouteSet:
        """An independent copy (routes, blocks, counters; no cache)."""
        other = RouteSet(self.params)
        other.routes = {
            q.route_id: Route(q.route_id, q.ids.copy(), q.wp.copy(), q.prior)
            for q in self.routes.values()
        }
        other.blocked = set(self.blocked)
        other.next_route_id = self.next_route_id
        other.next_waypoint_id = self.next_waypoint_id
        return other

    def new_route_id(self) -> int:
        self.next_route_id += 1
        return self.next_route_id - 1

    def add_route(
        self,
        xy: ArrayLike,
        v_max_mps: float | ArrayLike,
        half_width_m: float | ArrayLike,
        now_s: float,
        travel_time_s: ArrayLike | None = None,
        prior: bool = False,
    ) -> int:
        """Add a route through ``xy (m, 2)`` [m]; returns its id. ``travel_time_s (m,)`` per
        segment ending at each waypoint (entry 0 unused), NaN where never driven. The first
        waypoint's half-width copies the first segment's, so every waypoint has one."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        m = len(xy)
        if m < 2:
            raise ValueError("a route needs at least two waypoints")
        wp = np.empty((m, 6))
        wp[:, :2] = xy
        wp[:, V] = np.broadcast_to(np.asarray(v_max_mps, float), (m,))
        wp[:, L] = np.broadcast_to(np.asarray(half_width_m, float), (m,))
        wp[0, L] = wp[1, L]
        wp[:, T] = now_s
        wp[:, DT] = np.nan if travel_time_s is None else np.asarray(travel_time_s, float)
        wp[0, DT] = np.nan
        rid = self.new_route_id()
        ids = np.arange(self.next_waypoint_id, self.next_waypoint_id + m, dtype=np.int64)
        self.next_waypoint_id += m
        self.routes[rid] = Route(rid, ids, wp, prior)
        self._segs = None
        return rid

    def segments(self) -> _Segments:
        """All segments of all routes as flat arrays (cached until the geometry changes)."""
        if self._segs is None:
            a, b, hw, rid, seg, fr, to, s0 = [], [], [], [], [], [], [], []
            cum: dict[int, FloatArray] = {}
            for r in self.routes.values():
                m = len(r.ids)
                c = r.cumulative_m()
                cum[r.route_id] = c
                a.append(r.xy[:-1])
                b.append(r.xy[1:])
                hw.append(r.wp[1:, L])
                rid.append(np.full(m - 1, r.route_id))
                seg.append(np.arange(1, m))
                fr.append(r.ids[:-1])
                to.append(r.ids[1:])
                s0.append(c[:-1])
            cat = lambda x, k: np.concatenate(x) if x else np.zeros(k)  # noqa: E731
            aa, bb = cat(a, (0, 2)), cat(b, (0, 2))
            sg = _Segments(
                a=aa,
                b=bb,
                l=cat(hw, 0),
                rid=cat(rid, 0).astype(np.int64),
                seg=cat(seg, 0).astype(np.int64),
                fr=cat(fr, 0).astype(np.int64),
                to=cat(to, 0).astype(np.int64),
                s0=cat(s0, 0),
                length=np.hypot(*(bb - aa).T),
                cum=cum,
                cum_list={k: c.tolist() for k, c in cum.items()},
                rows=[],
                arrays=SegmentArrays(aa, bb, np.zeros(0, np.int64), np.zeros(0), np.zeros(0)),
            )
            sg.arrays = SegmentArrays(aa, bb, sg.rid, sg.s0, sg.length)
            cols = (sg.rid, sg.seg, sg.fr, sg.to, aa[:, 0], aa[:, 1], bb[:, 0], bb[:, 1])
            sg.rows = list(zip(*(c.tolist() for c in (*cols, sg.s0, sg.length, sg.l)), strict=True))
            self._segs = sg
        return self._segs

    def cumulative(self, route_id: int) -> FloatArray:
        """``Route.cumulative_m()`` of a route, from the geometry cache (do not modify)."""
        return self.segments().cum[route_id]

    def nearest_on_route(self, r: Route, xy: FloatArray) -> tuple[int, FloatArray]:
        """Segment index (of its end waypoint) and projection of ``xy`` on route ``r``."""
        _, proj, dist = project_onto_segments(xy, r.xy[:-1], r.xy[1:])
        k = int(np.argmin(dist))
        return k + 1, proj[k]

    def split(
        self,
        route_id: int,
        from_id: int,
        to_id: int,
        xy: tuple[float, float],
        block_half: str = "both",
    ) -> int:
        """Insert a waypoint at ``xy`` into segment ``from_id -> to_id``; returns its id. Within
        ``record_min_spacing_m`` of an end, that end is reused. The travel time is shared in
        proportion to length. A blocked segment passes its block to the half ``block_half``
        ("after" the new waypoint, "before" it, or "both")."""
        r = self.routes[route_id]
        j = r.index(to_id)
        a, b = r.xy[j - 1].copy(), r.xy[j].copy()
        p = np.asarray(xy, float)
        snap = self.params.record_min_spacing_m
        if np.hypot(*(p - a)) <= snap:
            return from_id
        if np.hypot(*(p - b)) <= snap:
            return to_id
        f = float(np.clip(np.hypot(*(p - a)) / max(np.hypot(*(b - a)), 1e-12), 0.0, 1.0))
        row = r.wp[j].copy()
        row[:2] = p
        row[DT] = r.wp[j, DT] * f
        r.wp[j, DT] *= 1.0 - f
        new_id = self.next_waypoint_id
        self.next_waypoint_id += 1
        r.wp = np.insert(r.wp, j, row, axis=0)
        r.ids = np.insert(r.ids, j, new_id)
        if (from_id, to_id) in self.blocked or (to_id, from_id) in self.blocked:
            self.blocked.discard((from_id, to_id))
            self.blocked.discard((to_id, from_id))
            if block_half in ("before", "both"):
                self.blocked.add((from_id, new_id))
            if block_half in ("after", "both"):
                self.blocked.add((new_id, to_id))
        self._segs = None
        return new_id

    def removed_by_cut(self, r: Route, a: int, b: int) -> set[int]:
        """Waypoint ids :meth:`cut` of segments ``a+1..b`` removes (a one-waypoint end
        piece goes with them)."""
        removed = {int(i) for i in r.ids[a + 1 : b]}
        if a < 1:
            removed.add(int(r.ids[0]))
        if b > len(r.ids) - 2:
            removed.add(int(r.ids[-1]))
        return removed

    def cut(self, r: Route, a: int, b: int) -> None:
        """Remove segments ``a+1..b`` of ``r``: keep ``[0..a]`` (as ``r``) and ``[b..]``."""
        del self.routes[r.route_id]
        removed = {int(i) for i in r.ids[a + 1 : b]}
        if a >= 1:
            self.routes[r.route_id] = Route(r.route_id, r.ids[: a + 1], r.wp[: a + 1], r.prior)
        else:
            removed.add(int(r.ids[0]))
        if b <= len(r.ids) - 2:
            tail = r.wp[b:].copy()
            tail[0, DT] = np.nan
            tail[0, L] = tail[1, L]
            rid = self.new_route_id()
            self.routes[rid] = Route(rid, r.ids[b:], tail, r.prior)
        else:
            removed.add(int(r.ids[-1]))
        seg = {(int(r.ids[k - 1]), int(r.ids[k])) for k in range(a + 1, b + 1)}
        seg = both_ways(seg)
        self.blocked = {
            e for e in self.blocked if e not in seg and e[0] not in removed and e[1] not in removed
        }
        self._segs = None

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_segs": None}  # the cache


def build_graph(route_set: RouteSet) -> RouteGraph:
    """The directed route graph (§6.2) of ``route_set``: nodes are waypoints, edges the
    segments (cost: learned travel time, else length / ``v`` of the end waypoint; ``inf`` if
    blocked either way), joins both ways between waypoints of different routes within
    ``join_distance_m`` (cost: distance / the largest ``v`` of the set), and last each
    segment's reverse edge (cost: ``reverse_cost_factor`` times the segment's)."""
    routes = list(route_set.routes.values())
    if not routes:
        z = np.zeros(0)
        return RouteGraph(np.zeros(0, np.int64), np.zeros((0, 2)), z, z, [])
    ids = np.concatenate([r.ids for r in routes])
    wp = np.concatenate([r.wp for r in routes])
    blocked = both_ways(route_set.blocked)
    factor = route_set.params.reverse_cost_factor
    edges: list[Edge] = []
    reverse: list[Edge] = []
    for r in routes:
        rids, rows, lengths = r.ids.tolist(), r.wp.tolist(), r.segment_lengths_m().tolist()
        for j in range(1, len(rids)):
            u, v, row, length = rids[j - 1], rids[j], rows[j], lengths[j - 1]
            learned = math.isfinite(row[DT])
            cost = row[DT] if learned else length / max(row[V], 1e-9)
            if (u, v) in blocked:
                cost = math.inf
            edges.append(Edge(u, v, length, cost, learned, row[L], r.route_id))
            if math.isfinite(factor):
                reverse.append(Edge(v, u, length, cost * factor, learned, row[L], r.route_id, True))
    if len(routes) > 1:  # joins between waypoints of different routes
        owner = np.concatenate([np.full(len(r.ids), r.route_id) for r in routes])
        v_join = max(float(np.max(wp[:, V])), 1e-9)
        diff = wp[:, None, :2] - wp[None, :, :2]
        dist = np.hypot(diff[..., 0], diff[..., 1])
        near = (dist <= route_set.params.join_distance_m) & (owner[:, None] != owner[None, :])
        for i, k in zip(*np.nonzero(near), strict=True):
            u, v = int(ids[i]), int(ids[k])
            cost = math.inf if (u, v) in blocked else float(dist[i, k]) / v_join
            hw = float(min(wp[i, L], wp[k, L]))
            edges.append(Edge(u, v, float(dist[i, k]), cost, False, hw, JOIN))
    edges += reverse
    return RouteGraph(ids, wp[:, :2].copy(), wp[:, V].copy(), wp[:, L].copy(), edges)
