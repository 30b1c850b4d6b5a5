"""A* on the route graph, minimizing travel time: Hentschel & Wagner 2011 §6.2 (eq. 18).

The graph is :class:`.route_graph.RouteGraph` (built by the route memory): nodes are waypoints,
edges are route segments and joins costed in seconds (learned travel time, else length /
``v``; ``inf`` while blocked, §6.3). ``g`` sums those costs; ``h`` is the straight-line
distance to the goal over a speed ``v_h`` (H&W: "the straight-line distance divided by the
maximum robot velocity").

**Admissibility.** ``v_h`` is the largest of the given robot speed, every node's ``v`` and
every finite edge's effective speed ``length / cost``. Then every edge costs at least its
length / ``v_h``, a path costs at least its length / ``v_h``, and its length is at least the
straight-line distance (triangle inequality): ``h`` never overestimates. It is also
consistent (``h(a) <= c(a, b) + h(b)``), so a node is never expanded twice. Taking the
robot's speed alone would not do: a learned travel time can be shorter than length / v
(a segment whose waypoints drifted apart after it was timed, or a robot that was faster).

The result (eq. 18) is the path's waypoints with the corridor half-width of the edge that
reaches each (the first point takes the first edge's), i.e. the base trajectory and the
corridor the controller may use for reactive avoidance (§6.3). Graphs are small (hundreds of
nodes), so a binary heap is plenty.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.planning.route_graph import Edge, RouteGraph

FloatArray = NDArray[np.float64]

#: Id of the virtual start node of :func:`plan_route` (waypoint ids are >= 0).
START = -1


@dataclass(frozen=True)
class PlannedPath:
    """A planned path P (eq. 18): ``xy (m, 2)`` [m] base trajectory, ``half_width_m (m,)``
    corridor half-width of the edge ending at each point, ``v_max_mps (m,)`` the speed limit
    approaching it, ``node_ids`` the graph nodes (:data:`START` for a projected start point;
    a join of coincident waypoints shows only its far end), ``travel_time_s`` the summed cost
    [s], ``edges`` every edge taken as ``(from_id, to_id)`` (joins included; what to
    :meth:`~dynmap_sim.agent.navigation.RouteMemory.block` when one is seen blocked)."""

    node_ids: tuple[int, ...]
    xy: FloatArray
    half_width_m: FloatArray
    v_max_mps: FloatArray
    travel_time_s: float
    edges: tuple[tuple[int, int], ...] = ()


def heuristic_speed_mps(graph: RouteGraph, v_max_mps: float | None = None) -> float:
    """``v_h`` of the module docstring [m/s]: at least every edge's effective speed, so
    ``h = distance / v_h`` is admissible; ``inf`` (``h = 0``, Dijkstra) if some edge of
    positive length costs nothing."""
    v = max([float(v_max_mps or 0.0), *graph.v_max_mps.tolist(), 1e-9])
    for e in graph.edges:
        if math.isfinite(e.travel_time_s) and e.length_m > 0.0:
            if e.travel_time_s <= 0.0:
                return math.inf
            v = max(v, e.length_m / e.travel_time_s)
    return v


def astar(
    graph: RouteGraph,
    start: int,
    goal: int,
    v_max_mps: float | None = None,
    start_edges: list[Edge] | None = None,
    start_xy: ArrayLike | None = None,
    leave_goal_m: float = 0.0,
    v_h: float | None = None,
) -> tuple[float, list[int], list[Edge]] | None:
    """Least-travel-time path from node ``start`` to node ``goal`` (H&W §6.2): ``(cost [s],
    node ids, edges taken)``, or None when the goal is unreachable (blocked edges never are
    taken). ``start_edges`` / ``start_xy`` add a virtual start node (see :func:`plan_route`).

    With ``leave_goal_m > 0`` the path must first reach a node farther than that from the
    goal (or start there) before it may end at the goal: A* runs on the graph's nodes paired
    with a flag "has left the goal" (a node is expanded at most once per flag). ``h`` is the
    same for both, so it stays admissible and consistent. Reverse edges are not taken then:
    the task is to drive round the loop in its direction, not out and back along it.
    ``v_h``: the graph's
    :func:`heuristic_speed_mps` when the caller has it already."""
    if v_h is None:
        v_h = heuristic_speed_mps(graph, v_max_mps)
    goal_xy = graph.position(goal)
    # per node: h, and whether it is farther than leave_goal_m from the goal
    to_goal = np.hypot(*(graph.xy - goal_xy).T).tolist()
    dist_m = dict(zip(graph.node_ids.tolist(), to_goal, strict=True))
    if start == START and start_xy is not None:
        dist_m[START] = float(np.hypot(*(np.asarray(start_xy, float)[:2] - goal_xy)))
    h_of = {n: 0.0 if math.isinf(v_h) else d / v_h for n, d in dist_m.items()}
    away = {n: leave_goal_m <= 0.0 or d > leave_goal_m for n, d in dist_m.items()}

    leaving = leave_goal_m > 0.0
    s0 = (start, away[start])
    g: dict[tuple[int, bool], float] = {s0: 0.0}
    came: dict[tuple[int, bool], tuple[Edge, tuple[int, bool]]] = {}
    done: set[tuple[int, bool]] = set()
    heap: list[tuple[float, int, tuple[int, bool]]] = [(h_of[start], 0, s0)]
    tie = 1
    while heap:
        _, _, state = heapq.heappop(heap)
        if state in done:
            continue
        n, left = state
        if n == goal and left:
            nodes, edges = [n], []
            while state != s0:
                e, state = came[state]
                edges.append(e)
                nodes.append(state[0])
            return g[(goal, True)], nodes[::-1], edges[::-1]
        done.add(state)
        out = start_edges if (n == START and start_edges is not None) else graph.out.get(n, [])
        g_n = g[state]
        for e in out:
            nxt = (e.v, left or away[e.v])
            if not math.isfinite(e.travel_time_s) or nxt in done or (e.reverse and leaving):
                continue
            cand = g_n + e.travel_time_s
            if cand < g.get(nxt, math.inf):
                g[nxt] = cand
                came[nxt] = (e, state)
                heapq.heappush(heap, (cand + h_of[e.v], tie, nxt))
                tie += 1
    return None


def _nearest_node_edge(graph: RouteGraph, p: FloatArray, v_h: float, avoid: int | None) -> Edge:
    """The virtual start edge straight from ``p`` [m] to the nearest node other than
    ``avoid``, costed at its length / ``v_h`` [s]."""
    near = graph.nearest_node(p, exclude=avoid)
    d = float(np.hypot(*(graph.position(near) - p)))
    hw_near = float(graph.half_width_m[graph.index[near]])
    return Edge(START, near, d, 0.0 if math.isinf(v_h) else d / v_h, False, hw_near, -1)


def _projection_edges(
    graph: RouteGraph, hit: tuple[Edge, float, FloatArray], avoid: int | None, leave_goal_m: float
) -> list[Edge]:
    """The virtual start edges from the robot's projection at fraction ``u`` along segment
    ``e`` (``hit``): on to its end for the rest of its travel time, and back to its start at
    the reverse edge's cost (not towards ``avoid``, nor when the plan must leave the goal)."""
    e, u, _ = hit
    rest_m, rest_s = (1.0 - u) * e.length_m, (1.0 - u) * e.travel_time_s
    out = [Edge(START, e.v, rest_m, rest_s, e.learned, e.half_width_m, e.route_id)]
    back = graph.reverse_of(e)
    if back is not None and back.v != avoid and leave_goal_m <= 0.0:  # back, at its cost
        out.append(
            Edge(START, e.u, u * e.length_m, u * back.travel_time_s, back.learned,
                 e.half_width_m, e.route_id, True)
        )  # fmt: skip
    return out


def _path_of(
    graph: RouteGraph, start_point: FloatArray, cost: float, edges: list[Edge]
) -> PlannedPath:
    """The :class:`PlannedPath` from ``start_point`` [m] along ``edges`` (cost [s]); a join of
    coincident waypoints shows only its far end."""
    taken = tuple((e.u, e.v) for e in edges if e.u != START)
    rows = [graph.index[e.v] for e in edges]
    q = graph.xy[rows]
    step = np.hypot(*(q - np.concatenate([np.asarray(start_point)[None], q[:-1]])).T)
    if not np.any(step < 1e-9):  # no join of coincident waypoints: a point per edge
        return PlannedPath(
            (START, *(e.v for e in edges)),
            np.concatenate([np.asarray(start_point)[None], q]),
            np.array([edges[0].half_width_m, *(e.half_width_m for e in edges)]),
            graph.v_max_mps[[rows[0], *rows]],
            float(cost),
            taken,
        )
    xy = [start_point]
    hw = [edges[0].half_width_m]
    v = [float(graph.v_max_mps[graph.index[edges[0].v]])]
    ids = [START]
    for e in edges:
        q = graph.position(e.v)
        if np.hypot(*(q - xy[-1])) < 1e-9:  # a join of coincident waypoints
            ids[-1] = e.v
            continue
        xy.append(q)
        hw.append(e.half_width_m)
        v.append(float(graph.v_max_mps[graph.index[e.v]]))
        ids.append(e.v)
    return PlannedPath(tuple(ids), np.array(xy), np.array(hw), np.array(v), float(cost), taken)


def plan_route(
    graph: RouteGraph,
    start_xy: ArrayLike,
    goal_xy: ArrayLike,
    v_max_mps: float | None = None,
    goal_id: int | None = None,
    leave_goal_m: float = 0.0,
    start_on: tuple[int, int] | None = None,
    avoid_entry: int | None = None,
) -> PlannedPath | None:
    """Plan from the robot's position ``start_xy`` to the node nearest ``goal_xy`` [m] (or to
    node ``goal_id`` when given: a loop route's end coincides with its start).

    The robot enters the graph at its projection onto the nearest passable segment (heading
    on along the segment's direction, for the remaining fraction of its travel time) or at
    the nearest node (straight-line distance / ``v_h``), or back along the segment to its
    start at the reverse edge's cost, whichever A* finds cheaper; so a robot in the middle of
    a segment does not turn back to its start waypoint unless that is cheaper. Returns None
    when the graph is empty or the goal unreachable. With ``leave_goal_m > 0`` (a robot at
    the start of a loop route, which ends where it starts) the plan must get farther than
    that from the goal before it ends there (:func:`astar`), and no virtual start edge ends
    at the goal: so the plan drives the loop instead of standing still — also when the
    loop's start and end waypoints belong to two routes (the loop cut by forgetting) and a
    zero-length join connects them. ``start_on`` ``(u, v)``: the segment the robot is tracked
    on (:meth:`RouteMemory.observe`); the plan then enters the graph along it alone, so a
    route that passes the robot's place twice is continued on the pass it is on, not
    restarted on the other. ``avoid_entry``: a node the robot must not enter the graph at
    (a loop's end, which lies on its start, while heading for a via point).
    """
    if graph.node_ids.size == 0:
        return None
    p = np.asarray(start_xy, float)[:2]
    goal = graph.nearest_node(goal_xy) if goal_id is None else int(goal_id)
    if goal not in graph.index:
        return None
    avoid = goal if leave_goal_m > 0.0 else avoid_entry
    v_h = heuristic_speed_mps(graph, v_max_mps)
    hit = None if start_on is None else graph.edge_projection(p, *start_on)
    if hit is not None and hit[0].v != avoid:
        starts = []  # along the tracked segment only
    else:
        starts = [_nearest_node_edge(graph, p, v_h, avoid)]
        hit = graph.nearest_edge(p, exclude_to=avoid)
    projected = [] if hit is None else _projection_edges(graph, hit, avoid, leave_goal_m)
    starts += projected
    found = astar(
        graph,
        START,
        goal,
        v_max_mps,
        start_edges=starts,
        start_xy=p,
        leave_goal_m=leave_goal_m,
        v_h=v_h,
    )
    if found is None:
        return None
    cost, _, edges = found
    on_projection = any(edges[0] is s for s in projected)  # only when there is a hit
    start_point = hit[2] if hit is not None and on_projection else p
    return _path_of(graph, start_point, cost, edges)
