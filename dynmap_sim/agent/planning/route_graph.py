"""The directed route graph that route A* plans on (H&W 2011 §6.2) and the navigation's route
memory builds (:meth:`~dynmap_sim.agent.navigation.route_memory.RouteMemory.graph`).

Nodes are waypoint ids with positions; edges are route segments and joins between nearby
waypoints of different routes, costed in seconds (learned travel time, else length / ``v``;
``inf`` while blocked, §6.3). The graph lives here, beside its planner, so that planning never
imports the navigation package that builds it.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Route id of join edges in a :class:`RouteGraph` (they belong to no route).
JOIN = -1


class Edge(NamedTuple):
    """A directed edge of the :class:`RouteGraph`: a route segment or a join.

    ``travel_time_s`` is the planning cost: the learned travel time, else ``length_m`` over
    the end waypoint's ``v``; ``inf`` while blocked. ``route_id`` is :data:`JOIN` for joins.
    ``reverse``: a route segment driven against its direction (``u`` is the segment's end
    waypoint), at a higher cost (``RouteMemoryParams.reverse_cost_factor``).
    """

    u: int
    v: int
    length_m: float
    travel_time_s: float
    learned: bool
    half_width_m: float
    route_id: int
    reverse: bool = False


def both_ways(edges: set[tuple[int, int]]) -> set[tuple[int, int]]:
    """``edges`` ``(u, v)`` with each one's reverse ``(v, u)``: a block holds both ways."""
    return edges | {(v, u) for u, v in edges}


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
        frac, proj, _ = project_onto_segments(np.asarray(xy, float)[:2], a, b)
        return e, float(frac[0]), proj[0]

    def nearest_edge(
        self, xy: ArrayLike, exclude_to: int | None = None
    ) -> tuple[Edge, float, FloatArray] | None:
        """The passable route segment closest to ``xy``: ``(edge, progress ∈ [0, 1],
        projection (2,))``, or None when there is none. Joins and reverse edges are not
        candidates (:meth:`reverse_of` finds the latter), nor segments ending at node
        ``exclude_to``."""
        segs = [
            e
            for e in self.edges
            if e.route_id != JOIN
            and not e.reverse
            and math.isfinite(e.travel_time_s)
            and e.v != exclude_to
        ]
        if not segs:
            return None
        a = self.xy[[self.index[e.u] for e in segs]]
        b = self.xy[[self.index[e.v] for e in segs]]
        u, proj, dist = project_onto_segments(np.asarray(xy, float)[:2], a, b)
        k = int(np.argmin(dist))
        return segs[k], float(u[k]), proj[k]

    def forward_only(self) -> RouteGraph:
        """The graph without its reverse edges (itself when it has none): the routes driven
        in their direction and the joins."""
        if not any(e.reverse for e in self.edges):
            return self
        edges = [e for e in self.edges if not e.reverse]
        return RouteGraph(self.node_ids, self.xy, self.v_max_mps, self.half_width_m, edges)

    def reverse_of(self, e: Edge) -> Edge | None:
        """The passable reverse edge of route segment ``e`` (``e.v -> e.u``), if any."""
        for r in self.out.get(e.v, []):
            if r.reverse and r.v == e.u and r.route_id == e.route_id:
                return r if math.isfinite(r.travel_time_s) else None
        return None


def project_onto_segments(p: FloatArray, a: FloatArray, b: FloatArray) -> tuple[FloatArray, ...]:
    """Project point ``p`` onto segments ``a -> b`` ``(S, 2)``: clamped fraction ``u (S,)``,
    projections ``(S, 2)`` and distances ``(S,)`` [m]."""
    d = b - a
    len2 = np.einsum("ij,ij->i", d, d)
    u = np.clip(np.einsum("ij,ij->i", p - a, d) / np.maximum(len2, 1e-18), 0.0, 1.0)
    proj = a + u[:, None] * d
    return u, proj, np.hypot(*(p - proj).T)


def reaching(g: RouteGraph, target: int) -> set[int]:
    """Nodes of ``g`` from which ``target`` is reachable over passable edges in the routes'
    direction (no reverse edges; itself too)."""
    back: dict[int, list[int]] = {}
    for e in g.edges:
        if np.isfinite(e.travel_time_s) and not e.reverse:
            back.setdefault(e.v, []).append(e.u)
    seen, todo = {target}, deque([target])
    while todo:
        for u in back.get(todo.popleft(), []):
            if u not in seen:
                seen.add(u)
                todo.append(u)
    return seen
