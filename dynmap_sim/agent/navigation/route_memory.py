"""Route memory: Hentschel & Wagner 2011 §5 (eqs. 16-17, §5.1-5.2), agent side.

A :class:`RouteMemory` holds routes ``R = {r_i}`` (eq. 16), each a directed sequence of
waypoints ``w_ij = (x, y, v, l, t, Δt)`` (eq. 17): position [m], the maximal speed for
approaching the waypoint [m/s], the corridor half-width ``l`` of the segment
``w_i,j-1 -> w_ij`` [m] (the perpendicular distance from the centre line to the corridor's
edge), the last update time ``t`` [s] and the travel time ``Δt`` of that segment [s].

* **Short-term memory (§5.1)** — :meth:`RouteMemory.locate`: the robot's position relative to
  every segment of every route (vectorized); the segment with the minimal lateral distance
  wins, and the pose is "on the route" only inside that segment's corridor.
* **Long-term memory (§5.2)** — :meth:`RouteMemory.observe`, called every control step with
  the agent's pose estimate: inside a corridor, the waypoints' coordinates and, once a segment
  is passed, its travel time and update time are learned; outside every corridor, a **new
  route** is recorded (a waypoint every ``Δd`` or ``Δφ``) from the point where the robot left a
  corridor to the point where it re-enters one, joined to the graph at both ends.
  :meth:`RouteMemory.forget` removes what has not been updated for longer than an age.
* **Planning input (§6.2)** — :meth:`RouteMemory.graph`: a directed :class:`RouteGraph` whose
  nodes are waypoints and whose edges are segments costed by travel time (learned, else
  length / ``v``), plus join edges between nearby waypoints of different routes; blocked edges
  (:meth:`RouteMemory.block`, §6.3) cost ``inf`` until seen free. Cf. nav2_route's TimeScorer,
  which costs an edge by its measured traversal time, else length / speed limit.

The paper defers the update rules to its ref. [16] and gives no value for any of them; every
choice is a named field of :class:`RouteMemoryParams` with the reason for its default.

Everything is plain data (numpy arrays, dicts, sets), so a memory pickles as it is;
:meth:`RouteMemory.to_dict` / :meth:`RouteMemory.from_dict` give JSON-ready long-term memory
for figures and storage (the short-term state of a run in progress is not part of it).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections import deque
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.jit import compiled

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
#: Route id of join edges in a :class:`RouteGraph` (they belong to no route).
JOIN = -1


@dataclass(frozen=True)
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


class Edge(NamedTuple):
    """A directed edge of the :class:`RouteGraph`: a route segment or a join.

    ``travel_time_s`` is the planning cost: the learned travel time, else ``length_m`` over
    the end waypoint's ``v``; ``inf`` while blocked. ``route_id`` is :data:`JOIN` for joins.
    """

    u: int
    v: int
    length_m: float
    travel_time_s: float
    learned: bool
    half_width_m: float
    route_id: int


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


@dataclass
class RouteGraph:
    """The directed route graph H&W §6.2 plans on: nodes are waypoint ids with positions
    ``xy (N, 2)`` [m], ``v_max_mps (N,)`` and ``half_width_m (N,)`` (of the segment ending at
    the node); ``edges`` are segments and joins (:class:`Edge`)."""

    node_ids: IntArray
    xy: FloatArray
    v_max_mps: FloatArray
    half_width_m: FloatArray
    edges: list[Edge]
    index: dict[int, int] = field(init=False, repr=False)
    out: dict[int, list[Edge]] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        nodes = np.asarray(self.node_ids).tolist()  # (a list of ids works too)
        self.index = {n: i for i, n in enumerate(nodes)}
        self.out = {n: [] for n in nodes}
        for e in self.edges:
            self.out[e.u].append(e)

    def position(self, node_id: int) -> FloatArray:
        """Position ``(2,)`` [m] of a node."""
        return self.xy[self.index[node_id]]

    def nearest_node(self, xy: ArrayLike, exclude: int | None = None) -> int:
        """The node closest to ``xy`` [m] other than ``exclude`` (the graph must hold one)."""
        d = np.hypot(*(self.xy - np.asarray(xy, float)[:2]).T)
        if exclude is not None and exclude in self.index and len(d) > 1:
            d[self.index[exclude]] = np.inf
        return int(self.node_ids[int(np.argmin(d))])

    def edge_projection(
        self, xy: ArrayLike, u: int, v: int
    ) -> tuple[Edge, float, FloatArray] | None:
        """The passable route segment ``u -> v`` with ``xy`` projected onto it, as
        :meth:`nearest_edge` returns it; None when the graph has no such segment."""
        e = next(
            (
                e
                for e in self.out.get(int(u), [])
                if e.v == int(v) and e.route_id != JOIN and math.isfinite(e.travel_time_s)
            ),
            None,
        )
        if e is None:
            return None
        a, b = self.position(e.u)[None], self.position(e.v)[None]
        frac, proj, _ = _project(np.asarray(xy, float)[:2], a, b)
        return e, float(frac[0]), proj[0]

    def nearest_edge(
        self, xy: ArrayLike, exclude_to: int | None = None
    ) -> tuple[Edge, float, FloatArray] | None:
        """The passable route segment closest to ``xy``: ``(edge, progress ∈ [0, 1],
        projection (2,))``, or None when there is none. Joins are not candidates, nor
        segments ending at node ``exclude_to``."""
        segs = [
            e
            for e in self.edges
            if e.route_id != JOIN and math.isfinite(e.travel_time_s) and e.v != exclude_to
        ]
        if not segs:
            return None
        a = self.xy[[self.index[e.u] for e in segs]]
        b = self.xy[[self.index[e.v] for e in segs]]
        u, proj, dist = _project(np.asarray(xy, float)[:2], a, b)
        k = int(np.argmin(dist))
        return segs[k], float(u[k]), proj[k]


def _project(p: FloatArray, a: FloatArray, b: FloatArray) -> tuple[FloatArray, ...]:
    """Project point ``p`` onto segments ``a -> b`` ``(S, 2)``: clamped fraction ``u (S,)``,
    projections ``(S, 2)`` and distances ``(S,)`` [m]."""
    d = b - a
    len2 = np.einsum("ij,ij->i", d, d)
    u = np.clip(np.einsum("ij,ij->i", p - a, d) / np.maximum(len2, 1e-18), 0.0, 1.0)
    proj = a + u[:, None] * d
    return u, proj, np.hypot(*(p - proj).T)


class SegmentArrays(NamedTuple):
    """Every segment of every route for :func:`locate_segment`: starts and ends ``(S, 2)``
    [m], route ids ``(S,)``, the start's arc length on its route ``(S,)`` [m] and the
    lengths ``(S,)`` [m]."""

    a: FloatArray
    b: FloatArray
    rid: IntArray
    s0: FloatArray
    length: FloatArray


@compiled
def locate_segment(  # type: ignore[no-untyped-def]
    px, py, segs, prefer_route, prefer_along_m, use_prefer, use_along, window_m, continuity_m
):
    """:meth:`RouteMemory.locate`'s search over ``segs`` (:class:`SegmentArrays`) for the
    point ``(px, py)`` [m]: the index ``k`` of the segment picked, its clamped fraction ``u``,
    distance [m] and projection ``(qx, qy)`` [m]; ``k = -1`` without segments. With
    ``use_prefer`` route ``prefer_route``'s nearest segment wins a tie; with ``use_along``
    its segments within ``window_m`` of ``prefer_along_m`` along it win unless another is
    ``continuity_m`` [m] nearer. The first of equal minima wins."""
    a, b, rid, s0, seg_len = segs
    k, k2, k3 = -1, -1, -1
    best, best2, best3 = 0.0, 0.0, 0.0
    u_k, u_k2, u_k3 = 0.0, 0.0, 0.0
    for i in range(a.shape[0]):
        ax, ay = a[i, 0], a[i, 1]
        dx, dy = b[i, 0] - ax, b[i, 1] - ay
        len2 = dx * dx + dy * dy
        t = ((px - ax) * dx + (py - ay) * dy) / (len2 if len2 > 1e-18 else 1e-18)
        u = t if t > 0.0 else 0.0  # numpy's clip: max(t, 0), then min(., 1)
        u = u if u < 1.0 else 1.0
        dist = np.hypot(px - (ax + u * dx), py - (ay + u * dy))
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
    return k, u_k, best, ax + u_k * (b[k, 0] - ax), ay + u_k * (b[k, 1] - ay)


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


@dataclass
class _Segments:
    """All segments of all routes as flat arrays, and per route its arc lengths: what
    :meth:`RouteMemory.locate` and the tracking read every step, built once per geometry
    (see :meth:`RouteMemory._segments`)."""

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


class RouteMemory:
    """Routes, their learning and forgetting (H&W §5), and the graph for planning (§6.2).

    Build with :meth:`from_prior` (the prior route of H&W Fig. 4) or empty and
    :meth:`add_route`; call :meth:`observe` every control step with the pose estimate,
    :meth:`forget` at each long-term update (e.g. the end of a run), :meth:`graph` to plan.
    """

    def __init__(self, params: RouteMemoryParams | None = None) -> None:
        self.params = params or RouteMemoryParams()
        self.routes: dict[int, Route] = {}
        #: Blocked edges ``(from_id, to_id)``: infinite cost until seen free (§6.3).
        self.blocked: set[tuple[int, int]] = set()
        self._next_route_id = 0
        self._next_waypoint_id = 0
        #: the geometry cache: every change of a waypoint's position, a route's half-width or
        #: the set of routes sets it to None (code that edits ``routes`` must do so as well)
        self._segs: _Segments | None = None
        #: the last graph with the state it was built from (:meth:`graph`)
        self._graph: tuple[tuple[Any, ...], RouteGraph] | None = None
        self.reset_run()

    # ------------------------------------------------------------------ building
    @classmethod
    def from_prior(
        cls,
        route_xy: ArrayLike,
        v_max_mps: float | ArrayLike,
        half_width_m: float | ArrayLike,
        now_s: float,
        params: RouteMemoryParams | None = None,
        densify: bool = True,
    ) -> RouteMemory:
        """A memory holding the prior route (H&W Fig. 4): ``route_xy (K, 2)`` [m] in the
        direction of travel, never driven (travel times NaN), updated at ``now_s``.

        With ``densify`` every segment is cut into pieces of at most ``record_spacing_m``, so
        the prior's centre line can bend toward the driven line (coordinate adaptation moves
        waypoints, not points between them) and forgetting can drop just a bypassed part.
        Per-waypoint ``v_max_mps`` / ``half_width_m`` arrays ``(K,)`` are interpolated.
        """
        mem = cls(params)
        xy = np.asarray(route_xy, float).reshape(-1, 2)
        v = np.broadcast_to(np.asarray(v_max_mps, float), (len(xy),))
        w = np.broadcast_to(np.asarray(half_width_m, float), (len(xy),))
        if densify and len(xy) >= 2:
            pts, vv, ww = [xy[:1]], [v[:1]], [w[:1]]
            for k in range(1, len(xy)):
                n = max(1, math.ceil(np.hypot(*(xy[k] - xy[k - 1])) / mem.params.record_spacing_m))
                f = np.arange(1, n + 1) / n
                pts.append(xy[k - 1] + f[:, None] * (xy[k] - xy[k - 1]))
                vv.append(np.full(n, v[k]))
                ww.append(np.full(n, w[k]))
            xy, v, w = np.concatenate(pts), np.concatenate(vv), np.concatenate(ww)
        mem.add_route(xy, v, w, now_s, prior=True)
        return mem

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
        rid = self._new_route_id()
        ids = np.arange(self._next_waypoint_id, self._next_waypoint_id + m, dtype=np.int64)
        self._next_waypoint_id += m
        self.routes[rid] = Route(rid, ids, wp, prior)
        self._segs = None
        return rid

    def _new_route_id(self) -> int:
        self._next_route_id += 1
        return self._next_route_id - 1

    # ------------------------------------------------------------------ §5.1 locate
    def _segments(self) -> _Segments:
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

    def _cumulative(self, route_id: int) -> FloatArray:
        """``Route.cumulative_m()`` of a route, from the geometry cache (do not modify)."""
        return self._segments().cum[route_id]

    def locate(
        self,
        pose: ArrayLike,
        prefer_route: int | None = None,
        prefer_along_m: float | None = None,
    ) -> RoutePosition | None:
        """The robot's position relative to the routes (§5.1): over every segment of every
        route (vectorized), the one at minimal lateral distance; None for an empty memory.
        On a tie ``prefer_route`` wins (the route the robot is on, so a join does not flip);
        with ``prefer_along_m`` (its last arc length on that route) that route's segments
        within ``continuity_window_m`` of it along the route win unless another is
        ``continuity_m`` nearer (a route that passes a place twice keeps the robot's pass)."""
        p = np.asarray(pose, float)
        return self._locate_xy(float(p[0]), float(p[1]), prefer_route, prefer_along_m)

    def _locate_xy(
        self, px: float, py: float, prefer_route: int | None, prefer_along_m: float | None
    ) -> RoutePosition | None:
        """:meth:`locate` at ``(px, py)`` [m] (None at a non-finite one)."""
        s = self._segments()
        if not s.rows:
            return None
        if not math.isfinite(px + py):
            return None
        k, u_k, dist_k, qx, qy = locate_segment(
            px,
            py,
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

    # ------------------------------------------------------------------ §5.2 learning
    def reset_run(self) -> None:
        """Forget the short-term state (§5.1 STM): call at the start of every run. A route
        being recorded is dropped (it was never joined back to the graph)."""
        self._track: _Track | None = None
        self._rec: _Recording | None = None
        #: the last step inside a corridor: position, time, heading, robot (x, y)
        self._last_inside: tuple[RoutePosition, float, float, tuple[float, float]] | None = None
        self._passed: _Passed | None = None
        #: per waypoint id: the driven lateral offsets' weighted sums ``[Σwx, Σwy, Σw]``
        self._pending: dict[int, list[float]] = {}

    @property
    def recording(self) -> bool:
        """True while a new route is being recorded (the robot is outside every corridor)."""
        return self._rec is not None

    def observe(self, pose: ArrayLike, t_s: float) -> RoutePosition | None:
        """One learning step (§5.2) with the pose estimate ``(x, y, θ)`` [m, m, rad] at time
        ``t_s`` [s]; returns the robot's position relative to the routes after the update.

        Inside a corridor: passed segments learn their travel time (EMA) and update time,
        and are unblocked (having driven it is seeing it free); waypoints adapt toward the
        driven line. Outside every corridor: a new route is recorded and, on re-entering a
        corridor, joined to the graph at the exit and entry points (segments there are
        split). With an empty memory, nothing is learned (there is nothing to join to).
        """
        pose = np.asarray(pose, float)
        values = pose.tolist()
        px, py = values[0], values[1]
        heading = float(values[2]) if len(values) > 2 else 0.0
        xy = pose[:2]
        tr = self._track
        pos = (
            self._locate_xy(px, py, None, None)
            if tr is None
            else self._locate_xy(px, py, tr.route_id, tr.s_prev_m)
        )
        if pos is None:
            return None
        if pos.inside:
            if self._rec is not None:
                self._finish_recording(pos, xy, t_s)
                prefer = self._track.route_id if self._track is not None else None
                pos = self._locate_xy(px, py, prefer, None)
                assert pos is not None
            self._track_step(pos, px, py, t_s)
            self._last_inside = (pos, t_s, heading, (px, py))
            return pos
        if self._rec is None:
            self._start_recording(xy, heading, t_s)
        self._record_step(xy, heading, t_s)
        self._last_inside = None
        return pos

    def _track_step(self, pos: RoutePosition, px: float, py: float, t_s: float) -> None:
        r = self.routes[pos.route_id]
        tr = self._track
        if tr is None or tr.route_id != pos.route_id:
            if tr is not None:
                self._leave(tr)
            self._pending.clear()
            self._track = _Track(pos.route_id, pos.along_m, t_s)
            self._enter(r, pos, t_s)
        else:
            s0, s1 = tr.s_prev_m, pos.along_m
            # a jump along the route much longer than the robot moved is no drive past the
            # waypoints between: a loop route's end meets its start (H&W's), or a pose jumped
            last = self._last_inside
            moved = math.hypot(px - last[3][0], py - last[3][1]) if last is not None else math.inf
            if s1 - s0 > moved + self.params.join_distance_m:
                s0 = s1
            if s1 > s0:
                # the waypoints whose arc length lies in (s0, s1]: the route's end counts as
                # passed pass_tolerance_m before it (a robot stops at its goal within a
                # tolerance), timed as if it drove on at its speed; the marks ascend, so the
                # others are a range found by bisection
                cum = self._segments().cum_list[r.route_id]
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
                        self._pass(r, wid, tc)
            tr.s_prev_m, tr.t_prev_s = s1, t_s
        if 0.0 < pos.progress < 1.0:  # perpendicular offset only
            ox = px - pos.projection_xy[0]
            oy = py - pos.projection_xy[1]
            for wid, w in ((pos.from_id, 1.0 - pos.progress), (pos.to_id, pos.progress)):
                acc = self._pending.get(wid)
                if acc is None:
                    acc = self._pending[wid] = [0.0, 0.0, 0.0]
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
        r = self.routes.get(tr.route_id)
        if r is None:
            return
        cum = r.cumulative_m()
        mark = cum.copy()
        mark[-1] -= min(self.params.pass_tolerance_m, 0.5 * (cum[-1] - cum[-2]))
        ahead = np.flatnonzero(mark > tr.s_prev_m)
        if ahead.size and cum[ahead[0]] - tr.s_prev_m <= self.params.pass_tolerance_m:
            self._pass(r, int(r.ids[ahead[0]]), tr.t_prev_s)

    def _enter(self, r: Route, pos: RoutePosition, t_s: float) -> None:
        """Entering route ``r`` on segment ``pos.segment``: its start waypoint counts as passed
        if the last waypoint passed (on another route) joins it — a join carries the pass
        over — or, failing that, if the robot is within ``pass_tolerance_m`` of it along the
        route (the start of a run)."""
        start = r.xy[pos.segment - 1]
        last = self._passed
        if last is not None and last.waypoint_id == pos.from_id:
            return
        if (
            last is not None
            and math.hypot(last.x_m - start[0], last.y_m - start[1]) <= self.params.join_distance_m
        ):
            self._passed = _Passed(pos.from_id, float(start[0]), float(start[1]), last.t_s)
        elif (
            pos.along_m - self._cumulative(r.route_id)[pos.segment - 1]
            <= self.params.pass_tolerance_m
        ):
            self._passed = _Passed(pos.from_id, float(start[0]), float(start[1]), t_s)

    def _pass(self, r: Route, waypoint_id: int, t_s: float) -> None:
        """The robot passed waypoint ``waypoint_id`` of ``r`` at ``t_s``: learn the segment
        ending at it if its start was the last waypoint passed, adapt the waypoint behind."""
        j = r.index(waypoint_id)
        last = self._passed
        if j >= 1 and last is not None and last.waypoint_id == int(r.ids[j - 1]):
            self._learn(r, j, t_s - last.t_s, t_s)
        if j >= 1:
            self._adapt(r, int(r.ids[j - 1]), t_s)
        if j == len(r.ids) - 1:
            self._adapt(r, waypoint_id, t_s)
        self._passed = _Passed(waypoint_id, float(r.wp[j, X]), float(r.wp[j, Y]), t_s)

    def _learn(self, r: Route, j: int, dt_s: float, t_s: float) -> None:
        """Travel time of segment ``j`` (EMA, first value taken as it is), update time, and
        unblock it: a driven segment has been seen free."""
        old = r.wp[j, DT]
        a = self.params.travel_time_alpha
        r.wp[j, DT] = dt_s if not np.isfinite(old) else (1.0 - a) * old + a * dt_s
        r.wp[j, T] = t_s
        self.blocked.discard((int(r.ids[j - 1]), int(r.ids[j])))

    def _adapt(self, r: Route, waypoint_id: int, t_s: float) -> None:
        """Move a waypoint ``coord_alpha`` of the mean driven lateral offset (once per pass).
        Waypoints that join another route keep their place, so joins do not drift apart."""
        acc = self._pending.pop(waypoint_id, None)
        if acc is None or acc[2] <= 0.0:
            return
        j = r.index(waypoint_id)
        for other in self.routes.values():
            if other.route_id != r.route_id and np.any(
                np.hypot(*(other.xy - r.xy[j]).T) <= self.params.join_distance_m
            ):
                return
        r.wp[j, :2] += self.params.coord_alpha * np.array(acc[:2]) / acc[2]
        r.wp[j, T] = t_s
        self._segs = None

    def _start_recording(self, xy: FloatArray, heading: float, t_s: float) -> None:
        if self._last_inside is not None:
            pos, t0, h0, xy0 = self._last_inside
            exit_ = (pos.route_id, pos.from_id, pos.to_id, pos.projection_xy, t0)
            self._rec = _Recording([pos.projection_xy], [t0], h0, exit_, (xy0[0], xy0[1]))
        else:
            start = (float(xy[0]), float(xy[1]))
            self._rec = _Recording([start], [t_s], heading, None, start)

    def _record_step(self, xy: FloatArray, heading: float, t_s: float) -> None:
        """Add a waypoint every ``Δd``, or after a turn of ``Δφ`` (§5.2)."""
        rec = self._rec
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

    def _finish_recording(self, pos: RoutePosition, robot_xy: FloatArray, t_s: float) -> None:
        """Re-entering a corridor ends the recording: join the new route at both ends.

        A blocked segment split at the exit keeps its block after the exit point (the robot
        drove up to it), one split at the entry before the entry point (the robot re-enters
        behind the block, H&W §6.3 "returns ... behind the obstacle"). Should a robot come
        back before the block, it sees it again and blocks it again: one more encounter.
        """
        rec = self._rec
        assert rec is not None
        self._rec = None
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
            if self._track is not None and self._track.route_id != pos.route_id:
                self._track = None
            return
        if rec.exit is not None:
            rid, from_id, to_id, exit_xy, t_exit = rec.exit
            try:
                c = self._split(rid, from_id, to_id, exit_xy, block_half="after")
            except (KeyError, ValueError):  # the segment was forgotten meanwhile
                c = None
            if c is not None:
                r = self.routes[rid]
                j = r.index(c)
                xy[0] = r.xy[j]
                if c != from_id:  # the robot drove from_id -> exit point: a pass
                    self._pass(r, c, t_exit)
        r2 = self.routes[pos.route_id]
        j2, _ = self._nearest_on_route(r2, np.asarray(entry))
        d = self._split(
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
        self.add_route(xy, p.new_v_max_mps, p.new_half_width_m, t_s, travel_time_s=dt)
        self._pending.clear()
        self._track = _Track(r2.route_id, float(r2.cumulative_m()[jd]), t_s)
        self._passed = _Passed(d, float(r2.wp[jd, X]), float(r2.wp[jd, Y]), t_s)

    def _nearest_on_route(self, r: Route, xy: FloatArray) -> tuple[int, FloatArray]:
        """Segment index (of its end waypoint) and projection of ``xy`` on route ``r``."""
        _, proj, dist = _project(xy, r.xy[:-1], r.xy[1:])
        k = int(np.argmin(dist))
        return k + 1, proj[k]

    def _split(
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
        new_id = self._next_waypoint_id
        self._next_waypoint_id += 1
        r.wp = np.insert(r.wp, j, row, axis=0)
        r.ids = np.insert(r.ids, j, new_id)
        if (from_id, to_id) in self.blocked:
            self.blocked.discard((from_id, to_id))
            if block_half in ("before", "both"):
                self.blocked.add((from_id, new_id))
            if block_half in ("after", "both"):
                self.blocked.add((new_id, to_id))
        self._segs = None
        return new_id

    # ------------------------------------------------------------------ forgetting
    def forget(self, now_s: float, keep: Iterable[int] = ()) -> int:
        """Forget stretches not updated for longer than ``forget_age_s`` (§5.2); returns the
        number of segments forgotten. ``keep``: waypoint ids that must survive and stay
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
            for r in list(self.routes.values()):
                stale = now_s - r.wp[1:, T] > self.params.forget_age_s
                for a, b in _runs(stale):
                    if self._bypassed(r, a, b) and self._keeps_reach(r, a, b, keep):
                        self._cut(r, a, b)
                        forgotten += b - a
                        changed = True
                        break
                if changed:
                    break
        return forgotten

    def _bypassed(self, r: Route, a: int, b: int) -> bool:
        """Is waypoint ``b`` of ``r`` reachable from waypoint ``a`` without segments a..b?"""
        g = self.graph()
        gone = {int(i) for i in r.ids[a + 1 : b]}
        cut = {(int(r.ids[k - 1]), int(r.ids[k])) for k in range(a + 1, b + 1)}
        start, goal = int(r.ids[a]), int(r.ids[b])
        seen, todo = {start}, deque([start])
        while todo:
            n = todo.popleft()
            for e in g.out[n]:
                if (
                    e.v in seen
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

    def _removed_by_cut(self, r: Route, a: int, b: int) -> set[int]:
        """Waypoint ids :meth:`_cut` of segments ``a+1..b`` removes (a one-waypoint end
        piece goes with them)."""
        removed = {int(i) for i in r.ids[a + 1 : b]}
        if a < 1:
            removed.add(int(r.ids[0]))
        if b > len(r.ids) - 2:
            removed.add(int(r.ids[-1]))
        return removed

    def _keeps_reach(self, r: Route, a: int, b: int, keep: set[int]) -> bool:
        """Would cutting segments ``a+1..b`` of ``r`` keep every ``keep`` waypoint, and every
        remaining waypoint that reaches one (over passable edges) still reaching it?"""
        if not keep:
            return True
        removed = self._removed_by_cut(r, a, b)
        if removed & keep:
            return False
        before = self.graph()
        targets = [k for k in keep if k in before.index]
        if not targets:
            return True
        trial = RouteMemory(self.params)
        trial.routes = {
            q.route_id: Route(q.route_id, q.ids.copy(), q.wp.copy(), q.prior)
            for q in self.routes.values()
        }
        trial.blocked = set(self.blocked)
        trial._next_route_id = self._next_route_id
        trial._next_waypoint_id = self._next_waypoint_id
        trial._cut(trial.routes[r.route_id], a, b)
        after = trial.graph()
        return all(_reaching(before, k) - removed <= _reaching(after, k) for k in targets)

    def _cut(self, r: Route, a: int, b: int) -> None:
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
            rid = self._new_route_id()
            self.routes[rid] = Route(rid, r.ids[b:], tail, r.prior)
        else:
            removed.add(int(r.ids[-1]))
        seg = {(int(r.ids[k - 1]), int(r.ids[k])) for k in range(a + 1, b + 1)}
        self.blocked = {
            e for e in self.blocked if e not in seg and e[0] not in removed and e[1] not in removed
        }
        if self._track is not None and self._track.route_id == r.route_id:
            self._track = None
        self._segs = None

    # ------------------------------------------------------------------ graph, blocks
    def block(self, edge: tuple[int, int]) -> None:
        """Mark edge ``(from_id, to_id)`` blocked: infinite cost until :meth:`unblock` or until
        the robot drives it (H&W §6.3)."""
        self.blocked.add((int(edge[0]), int(edge[1])))

    def unblock(self, edge: tuple[int, int]) -> None:
        """The edge was seen free again."""
        self.blocked.discard((int(edge[0]), int(edge[1])))

    def graph(self) -> RouteGraph:
        """The directed route graph (§6.2): nodes are waypoints, edges the segments (cost:
        learned travel time, else length / ``v`` of the end waypoint; ``inf`` if blocked) and
        joins both ways between waypoints of different routes within ``join_distance_m``
        (cost: distance / the largest ``v`` of the memory).

        The graph is a function of the routes' ids and rows, their order, the blocks and
        the join distance: while those are the same (byte for byte) as at the last call,
        the last graph is returned (treat it as read-only)."""
        key = (
            tuple(
                (r.route_id, r.prior, r.ids.tobytes(), r.wp.tobytes()) for r in self.routes.values()
            ),
            frozenset(self.blocked),
            self.params.join_distance_m,
        )
        if self._graph is not None and self._graph[0] == key:
            return self._graph[1]
        g = self._build_graph()
        self._graph = (key, g)
        return g

    def _build_graph(self) -> RouteGraph:
        """:meth:`graph` built anew."""
        routes = list(self.routes.values())
        if not routes:
            z = np.zeros(0)
            return RouteGraph(np.zeros(0, np.int64), np.zeros((0, 2)), z, z, [])
        ids = np.concatenate([r.ids for r in routes])
        wp = np.concatenate([r.wp for r in routes])
        blocked = self.blocked
        edges: list[Edge] = []
        for r in routes:
            rids, rows, lengths = r.ids.tolist(), r.wp.tolist(), r.segment_lengths_m().tolist()
            for j in range(1, len(rids)):
                u, v, row, length = rids[j - 1], rids[j], rows[j], lengths[j - 1]
                learned = math.isfinite(row[DT])
                cost = row[DT] if learned else length / max(row[V], 1e-9)
                if (u, v) in blocked:
                    cost = math.inf
                edges.append(Edge(u, v, length, cost, learned, row[L], r.route_id))
        if len(routes) > 1:  # joins between waypoints of different routes
            owner = np.concatenate([np.full(len(r.ids), r.route_id) for r in routes])
            v_join = max(float(np.max(wp[:, V])), 1e-9)
            diff = wp[:, None, :2] - wp[None, :, :2]
            dist = np.hypot(diff[..., 0], diff[..., 1])
            near = (dist <= self.params.join_distance_m) & (owner[:, None] != owner[None, :])
            for i, k in zip(*np.nonzero(near), strict=True):
                u, v = int(ids[i]), int(ids[k])
                cost = math.inf if (u, v) in blocked else float(dist[i, k]) / v_join
                hw = float(min(wp[i, L], wp[k, L]))
                edges.append(Edge(u, v, float(dist[i, k]), cost, False, hw, JOIN))
        return RouteGraph(ids, wp[:, :2].copy(), wp[:, V].copy(), wp[:, L].copy(), edges)

    # ------------------------------------------------------------------ storage
    def to_dict(self) -> dict[str, Any]:
        """Long-term memory as JSON-ready plain data (the run's short-term state is not kept)."""
        return {
            "params": asdict(self.params),
            "routes": [
                {
                    "route_id": r.route_id,
                    "prior": r.prior,
                    "ids": r.ids.tolist(),
                    "waypoints": [
                        dict(zip(WAYPOINT_FIELDS, w, strict=True)) for w in r.waypoints()
                    ],
                }
                for r in self.routes.values()
            ],
            "blocked": sorted([list(e) for e in self.blocked]),
            "next_route_id": self._next_route_id,
            "next_waypoint_id": self._next_waypoint_id,
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RouteMemory:
        """Inverse of :meth:`to_dict`."""
        mem = cls(RouteMemoryParams(**data["params"]))
        for rd in data["routes"]:
            wp = np.array([[w[k] for k in WAYPOINT_FIELDS] for w in rd["waypoints"]], float)
            ids = np.asarray(rd["ids"], np.int64)
            mem.routes[int(rd["route_id"])] = Route(int(rd["route_id"]), ids, wp, bool(rd["prior"]))
        mem.blocked = {(int(u), int(v)) for u, v in data["blocked"]}
        mem._next_route_id = int(data["next_route_id"])
        mem._next_waypoint_id = int(data["next_waypoint_id"])
        return mem

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_segs"] = None  # caches
        state["_graph"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._segs = None  # caches
        self._graph = None


def _reaching(g: RouteGraph, target: int) -> set[int]:
    """Nodes of ``g`` from which ``target`` is reachable over passable edges (itself too)."""
    back: dict[int, list[int]] = {}
    for e in g.edges:
        if np.isfinite(e.travel_time_s):
            back.setdefault(e.v, []).append(e.u)
    seen, todo = {target}, deque([target])
    while todo:
        for u in back.get(todo.popleft(), []):
            if u not in seen:
                seen.add(u)
                todo.append(u)
    return seen


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
