"""Route memory: Hentschel & Wagner 2011 §5 (eqs. 16-17, §5.1-5.2), agent side.

A :class:`RouteMemory` holds routes ``R = {r_i}`` (eq. 16) of waypoints (eq. 17,
:mod:`.routes`) and learns them from the agent's pose estimate, composed of four rooms:

* :mod:`.routes` — the routes, their blocked edges and the edits learning makes (add, split,
  cut), and the directed :class:`~dynmap_sim.agent.planning.route_graph.RouteGraph` built
  from them (§6.2): nodes are waypoints, edges segments costed by travel time (learned, else
  length / ``v``) plus join edges between nearby waypoints of different routes and each
  segment's reverse at a higher cost; blocked edges (:meth:`RouteMemory.block`, §6.3) cost
  ``inf`` both ways until seen free. Cf. nav2_route's
  TimeScorer, which costs an edge by its measured traversal time, else length / speed limit.
* :mod:`.route_tracking` — **short-term memory (§5.1)**: the robot's position relative to
  every segment of every route (:meth:`RouteMemory.locate`), and inside a corridor the
  waypoints passed: travel times, update times and coordinates learned.
* :mod:`.route_learning` — **long-term memory (§5.2)**: outside every corridor a **new
  route** is recorded and joined to the graph where the robot re-enters one;
  :meth:`RouteMemory.forget` removes what has not been updated for longer than an age.
* this module — :meth:`RouteMemory.observe`, called every control step, which hands each
  step to tracking or recording; the graph cache; storage.

The paper defers the update rules to its ref. [16] and gives no value for any of them; every
choice is a named field of :class:`~.routes.RouteMemoryParams` with the reason for its default.

Everything is plain data (numpy arrays, dicts, sets), so a memory pickles as it is;
:meth:`RouteMemory.to_dict` / :meth:`RouteMemory.from_dict` give JSON-ready long-term memory
for figures and storage (the short-term state of a run in progress is not part of it).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import asdict
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from dynmap_sim.agent.navigation.route_learning import RouteRecorder, forget
from dynmap_sim.agent.navigation.route_tracking import RoutePosition, RouteTracker
from dynmap_sim.agent.navigation.routes import (
    WAYPOINT_FIELDS,
    Route,
    RouteMemoryParams,
    RouteSet,
    build_graph,
)
from dynmap_sim.agent.planning.route_graph import RouteGraph


class RouteMemory:
    """Routes, their learning and forgetting (H&W §5), and the graph for planning (§6.2).

    Build with :meth:`from_prior` (the prior route of H&W Fig. 4) or empty and
    :meth:`add_route`; call :meth:`observe` every control step with the pose estimate,
    :meth:`forget` at each long-term update (e.g. the end of a run), :meth:`graph` to plan.
    """

    def __init__(self, params: RouteMemoryParams | None = None) -> None:
        self.params = params or RouteMemoryParams()
        self.route_set = RouteSet(self.params)
        self.tracker = RouteTracker(self.route_set)
        self.recorder = RouteRecorder(self.route_set, self.tracker)
        #: the last graph with the state it was built from (:meth:`graph`)
        self._graph: tuple[tuple[Any, ...], RouteGraph] | None = None

    @property
    def routes(self) -> dict[int, Route]:
        """The routes by id."""
        return self.route_set.routes

    @property
    def blocked(self) -> set[tuple[int, int]]:
        """Blocked edges ``(from_id, to_id)``: infinite cost until seen free (§6.3)."""
        return self.route_set.blocked

    @blocked.setter
    def blocked(self, edges: set[tuple[int, int]]) -> None:
        self.route_set.blocked = edges

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
        mem.route_set.add_route(xy, v, w, now_s, prior=True)
        return mem

    def add_route(self, *args: Any, **kwargs: Any) -> int:
        """Add a route; returns its id (:meth:`.routes.RouteSet.add_route`, its arguments)."""
        return self.route_set.add_route(*args, **kwargs)

    # ------------------------------------------------------------------ §5.1, §5.2
    def locate(
        self,
        pose: ArrayLike,
        prefer_route: int | None = None,
        prefer_along_m: float | None = None,
    ) -> RoutePosition | None:
        """The robot's position relative to the routes (§5.1): over every segment of every
        route, the one at minimal lateral distance; None for an empty memory. On a tie
        ``prefer_route`` wins (the route the robot is on, so a join does not flip); with
        ``prefer_along_m`` (its last arc length on that route) that route's segments within
        ``continuity_window_m`` of it along the route win unless another is ``continuity_m``
        nearer (a route that passes a place twice keeps the robot's pass)."""
        p = np.asarray(pose, float).ravel()
        heading = float(p[2]) if p.size > 2 else math.nan
        return self.tracker.locate_xy(
            float(p[0]), float(p[1]), prefer_route, prefer_along_m, heading
        )

    def reset_run(self) -> None:
        """Forget the short-term state (§5.1 STM): call at the start of every run. A route
        being recorded is dropped (it was never joined back to the graph)."""
        self.tracker.reset()
        self.recorder.rec = None

    @property
    def recording(self) -> bool:
        """True while a new route is being recorded (the robot is outside every corridor)."""
        return self.recorder.rec is not None

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
        known = float(values[2]) if len(values) > 2 else math.nan  # the heading, if given
        heading = 0.0 if math.isnan(known) else known
        xy = pose[:2]
        tr = self.tracker.track
        if tr is not None:
            pos = self.tracker.locate_xy(px, py, tr.route_id, tr.s_prev_m, known)
        elif self.tracker.at_run_start and (first := self._first_prior_route()) is not None:
            # a run starts where its route starts: at a loop's start, where the route also
            # ends, the robot is on its beginning
            pos = self.tracker.locate_xy(px, py, first, 0.0, known)
        else:
            pos = self.tracker.locate_xy(px, py, None, None, known)
        self.tracker.at_run_start = False
        if pos is None:
            return None
        if pos.inside:
            if self.recorder.rec is not None:
                self.recorder.finish(pos, xy, t_s)
                track = self.tracker.track
                prefer = track.route_id if track is not None else None
                pos = self.tracker.locate_xy(px, py, prefer, None, known)
                if (
                    track is not None
                    and pos is not None
                    and pos.route_id == track.route_id
                    and abs(pos.along_m - track.s_prev_m) > self.params.continuity_window_m
                ):
                    # the entry's route at another pass (it passes this place twice, e.g.
                    # a doorway driven out and back): the pass the robot entered on
                    pos = self.tracker.locate_xy(px, py, prefer, track.s_prev_m, known)
                assert pos is not None
            self.tracker.step(pos, px, py, t_s)
            self.tracker.last_inside = (pos, t_s, heading, (px, py))
            return pos
        if self.recorder.rec is None:
            self.recorder.start(xy, heading, t_s)
        self.recorder.step(xy, heading, t_s)
        self.tracker.last_inside = None
        return pos

    def _first_prior_route(self) -> int | None:
        """The id of the prior route's first piece (the one holding its lowest waypoint id;
        forgetting may have cut it), None without one."""
        pieces = [r for r in self.routes.values() if r.prior and len(r.ids)]
        if not pieces:
            return None
        return min(pieces, key=lambda r: int(r.ids[0])).route_id

    def forget(self, now_s: float, keep: Iterable[int] = ()) -> int:
        """Forget stretches not updated for longer than ``forget_age_s`` (§5.2; the rules:
        :func:`.route_learning.forget`); returns the number of segments forgotten. ``keep``:
        waypoint ids that must survive and stay reachable (the navigator's goal)."""
        return forget(self.route_set, self.tracker, self.graph, now_s, keep)

    # ------------------------------------------------------------------ graph, blocks
    def block(self, edge: tuple[int, int]) -> None:
        """Mark edge ``(from_id, to_id)`` blocked, both ways: infinite cost until
        :meth:`unblock` or until the robot drives it (H&W §6.3)."""
        self.blocked.add((int(edge[0]), int(edge[1])))

    def unblock(self, edge: tuple[int, int]) -> None:
        """The edge was seen free again (both ways)."""
        self.blocked.discard((int(edge[0]), int(edge[1])))
        self.blocked.discard((int(edge[1]), int(edge[0])))

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
        g = build_graph(self.route_set)
        self._graph = (key, g)
        return g

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
            "next_route_id": self.route_set.next_route_id,
            "next_waypoint_id": self.route_set.next_waypoint_id,
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
        mem.route_set.next_route_id = int(data["next_route_id"])
        mem.route_set.next_waypoint_id = int(data["next_waypoint_id"])
        return mem

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_graph": None}  # the cache
