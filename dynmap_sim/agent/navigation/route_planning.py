"""Route planning of the navigation stack (H&W 2011 §6.2): where the robot heads and the route
A* plan that takes it there.

* :class:`Targets`: the run's goal (the end of the prior's route) and, for a route that ends
  where it starts (a loop), the via points it is driven through in order (nav2's
  NavigateThroughPoses), passed when the estimate comes within ``via_tolerance_m`` or once
  the robot is tracked beyond them; the goal counts only once the robot has been
  ``goal_arm_m`` away from it.
* :class:`RoutePlanning`: route A* (:func:`~dynmap_sim.agent.planning.route_astar.plan_route`)
  from the estimate to the current target's node, and, when the graph cannot reach it, the
  graph plus **bridges** from its dead ends to the goal planned with grid A* on the costmap.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.navigation.route_tracking import RoutePosition
from dynmap_sim.agent.navigation.routes import Route
from dynmap_sim.agent.navigation.stack_params import StackParams
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid
from dynmap_sim.agent.planning.grid_astar import GridAStar
from dynmap_sim.agent.planning.route_astar import PlannedPath, plan_route
from dynmap_sim.agent.planning.route_graph import Edge, RouteGraph

FloatArray = NDArray[np.float64]

#: Route id of a bridge edge (:meth:`RoutePlanning.bridged_plan`): grid A* on the costmap
#: from a dead end of the route graph to the goal; also the node id of its interior points.
BRIDGE = -2


class Targets:
    """The goal and a loop's via points (module doc): set from the prior route on the first
    run (:meth:`set_route`), kept across runs; :meth:`new_run` restarts the run's progress."""

    def __init__(self, params: StackParams) -> None:
        self.params = params
        self.goal_xy: FloatArray | None = None
        self.goal_id: int | None = None
        #: a loop's via points ``[xy, waypoint id]``, in order (kept across runs)
        self.vias: list[tuple[FloatArray, int]] = []
        #: arc length [m] of the prior route's waypoints, whose ids are 0..len-1 in order
        self.prior_cum_m = np.zeros(0)
        self.new_run()

    def new_run(self) -> None:
        #: via points passed in this run
        self.via_k = 0
        #: whether the robot has been ``goal_arm_m`` away from the goal in this run
        self.armed = False

    def set_route(self, prior_route: Route, goal_xy: FloatArray) -> None:
        """The goal := the prior route's end; a loop's via points along it."""
        self.goal_id = int(prior_route.ids[-1])
        self.goal_xy = goal_xy.copy()
        self.vias = self._loop_vias(prior_route)
        self.prior_cum_m = prior_route.cumulative_m()

    def move_goal(self, goal_xy: FloatArray) -> None:
        """A later prior's route ends elsewhere: its end is the goal (its node resolved on the
        graph)."""
        if not np.allclose(goal_xy, self.goal_xy):
            self.goal_xy = goal_xy.copy()
            self.goal_id = None

    def _loop_vias(self, prior_route: Route) -> list[tuple[FloatArray, int]]:
        """The via points of a loop: the prior route's waypoints nearest every
        ``loop_via_spacing_m`` of its length (none within half a spacing of its end); none
        for a route that is no loop."""
        xy, spacing = prior_route.xy, self.params.loop_via_spacing_m
        if spacing <= 0.0 or np.hypot(*(xy[-1] - xy[0])) > self.params.goal_arm_m:
            return []
        cum = prior_route.cumulative_m()
        at = np.arange(spacing, cum[-1] - 0.5 * spacing, spacing)
        idx = sorted({int(np.argmin(np.abs(cum - s))) for s in at})
        return [(xy[k].copy(), int(prior_route.ids[k])) for k in idx]

    def pass_vias(self, pose: FloatArray, pos: RoutePosition | None) -> int:
        """Count the via points passed (``via_tolerance_m``): the next one reached, or those
        behind the prior route's waypoint the robot is tracked on (``pos``) by at most two via
        spacings (a detour round a block rejoined after them; never the whole loop when its
        end is seen at its start). Returns how many were passed now."""
        k, n = self.via_k, len(self.vias)
        if k < n:
            vx, vy = self.vias[k][0].tolist()
            if np.hypot(float(pose[0]) - vx, float(pose[1]) - vy) <= self.params.via_tolerance_m:
                k += 1
        if k < n and self.armed and pos is not None and pos.inside:
            here = pos.from_id
            if here < len(self.prior_cum_m):
                cum, reach = self.prior_cum_m, 2.0 * self.params.loop_via_spacing_m
                while (
                    k < n and self.vias[k][1] <= here and cum[here] - cum[self.vias[k][1]] <= reach
                ):
                    k += 1
        passed, self.via_k = k - self.via_k, k
        return passed

    def target(self) -> tuple[FloatArray, int | None, bool]:
        """What the robot heads for now: ``(xy, waypoint id, is_via)``; the next via point
        of a loop, else the goal."""
        if self.via_k < len(self.vias):
            xy, wid = self.vias[self.via_k]
            return xy, wid, True
        assert self.goal_xy is not None
        return self.goal_xy, self.goal_id, False

    def at_last(self) -> bool:
        """Whether every via point is passed (the goal is the target)."""
        return self.via_k == len(self.vias)

    def avoid_entry(self, g: RouteGraph) -> int | None:
        """While heading for a loop's via point, its end (on its start) is no entry to the
        graph: from there no route leads on, and the robot would go round to get back."""
        if not self.target()[2] or self.goal_xy is None:
            return None
        return node_of(g, self.goal_xy, self.goal_id)

    def leave_target_m(self) -> float:
        """``leave_goal_m`` of the planners: a loop's start must be left before it can end the
        run (not for a via point, which lies away from the start)."""
        if self.target()[2] or self.armed:
            return 0.0
        return self.params.goal_arm_m

    def target_node(self, g: RouteGraph) -> int:
        """The current target's node on ``g`` (:meth:`target`): the prior route's end or a
        via point, else the node nearest it."""
        xy, waypoint_id, _ = self.target()
        return node_of(g, xy, waypoint_id)

    def behind_nodes(self, g: RouteGraph) -> set[int]:
        """The nodes a plan to the current target must not pass (route order): a loop's via
        points already passed in this run and, while a via point is the target, the loop's
        end (on its start). A plan through one of them drives the loop backwards."""
        behind = {node_of(g, xy, wid) for xy, wid in self.vias[: self.via_k]}
        if self.target()[2]:
            behind.add(node_of(g, self.goal_xy, self.goal_id))
        return behind

    def goes_back(self, g: RouteGraph, plan: PlannedPath) -> bool:
        """Whether ``plan`` passes a node behind the target in route order
        (:meth:`behind_nodes`)."""
        behind = self.behind_nodes(g)
        return any(n in behind for n in plan.node_ids)

    def nodes(self, g: RouteGraph) -> list[int]:
        """The goal's and the via points' nodes on ``g`` (they must stay reachable)."""
        keep = [node_of(g, self.goal_xy, self.goal_id)]
        return keep + [node_of(g, xy, wid) for xy, wid in self.vias]


def node_of(g: RouteGraph, xy: FloatArray | None, waypoint_id: int | None) -> int:
    """A target's node on ``g``: its waypoint while the graph has it, else the node nearest
    its position."""
    if waypoint_id is not None and waypoint_id in g.index:
        return waypoint_id
    return g.nearest_node(xy)


class RoutePlanning:
    """Route A* to the targets (module doc) with the stack's ``params``, its hard clearance
    ``min_clearance_m`` [m] and grid ``planner`` for the bridges. Each plan returns with the
    number of plans it computed (the stack's ``plans`` counter)."""

    def __init__(self, params: StackParams, min_clearance_m: float, planner: GridAStar) -> None:
        self.params = params
        self.min_clearance_m = min_clearance_m
        self.planner = planner

    def route_plan(
        self, g: RouteGraph, pose: FloatArray, pos: RoutePosition | None, targets: Targets
    ) -> tuple[PlannedPath | None, int]:
        """Route A* on ``g`` from the estimate ``pose`` to the target's node (H&W §6.2): from
        the segment the robot is tracked on (``pos``); failing that (the way on is blocked,
        the way back is not), from wherever the graph is nearest. A plan must make progress
        in route order: one that passes a node behind the target (:meth:`Targets.goes_back`)
        is planned again without reverse edges, so a loop is closed forwards, through or
        round a block on it (seen again, gone round) rather than driven back to its start;
        reverse edges serve where they take the robot back over no passed target (a route
        out of a room and back, a block's way round along the route's later part)."""
        if g.node_ids.size == 0:
            return None, 0
        plan = self._route_plan_on(g, pose, pos, targets)
        forward = g.forward_only()
        if forward is not g and plan is not None and targets.goes_back(g, plan):
            return self._route_plan_on(forward, pose, pos, targets), 2
        return plan, 1

    def _route_plan_on(
        self, g: RouteGraph, pose: FloatArray, pos: RoutePosition | None, targets: Targets
    ) -> PlannedPath | None:
        """:meth:`route_plan` on ``g`` as it is."""
        target_xy = targets.target()[0]
        on = (pos.from_id, pos.to_id) if pos is not None and pos.inside else None
        for start_on in (on, None) if on is not None else (None,):
            plan = plan_route(
                g,
                pose[:2],
                target_xy,
                self.params.speed_mps,
                goal_id=targets.target_node(g),
                leave_goal_m=targets.leave_target_m(),
                start_on=start_on,
                avoid_entry=targets.avoid_entry(g),
            )
            if plan is not None:
                return plan
        return None

    def bridged_plan(
        self, g: RouteGraph, pose: FloatArray, grid: ClearanceGrid, targets: Targets
    ) -> tuple[PlannedPath | None, int]:
        """Route A* when the route graph cannot reach the goal (e.g. forgetting dropped the
        stretch or the join that led to it): the graph plus a **bridge** from each dead end
        (a node without a passable way on in the routes' direction) to the goal node, grid
        A* on the costmap's clearance, costed at ``speed_mps``. So the robot drives what is
        left of its routes and crosses the gap on the costmap, and a loop's start still
        leaves the goal (``leave_goal_m`` as for any route plan). The bridges' grid paths
        are in the plan's ``xy`` (their interior points have node id :data:`BRIDGE`); None
        when no dead end has a grid path to the goal or the graph none to a dead end. A
        plan that goes back in route order is planned again without reverse edges, as in
        :meth:`route_plan`."""
        if g.node_ids.size == 0:
            return None, 0
        p = self.params
        goal = targets.target_node(g)
        goal_xy = g.position(goal)
        end = grid.nearest_free(goal_xy, self.min_clearance_m, 0.5)
        if end is None:
            return None, 0
        legs, bridges = self._bridges(g, goal, goal_xy, end, grid)
        if not bridges:
            return None, 0

        def plan_on(edges: list[Edge]) -> PlannedPath | None:
            return plan_route(
                RouteGraph(g.node_ids, g.xy, g.v_max_mps, g.half_width_m, [*edges, *bridges]),
                pose[:2],
                goal_xy,
                p.speed_mps,
                goal_id=goal,
                leave_goal_m=targets.leave_target_m(),
                avoid_entry=targets.avoid_entry(g),
            )

        plan, n = plan_on(g.edges), 1
        forward = g.forward_only()
        if forward is not g and plan is not None and targets.goes_back(g, plan):
            plan, n = plan_on(forward.edges), 2
        if plan is None or not any(e in legs for e in plan.edges):
            return plan, n
        return self._with_legs(plan, legs), n

    def _bridges(
        self, g: RouteGraph, goal: int, goal_xy: FloatArray, end: FloatArray, grid: ClearanceGrid
    ) -> tuple[dict[tuple[int, int], FloatArray], list[Edge]]:
        """Grid A* from each dead end of ``g`` to the goal's free cell ``end``: the legs'
        points by edge and the bridge edges."""
        p = self.params
        legs: dict[tuple[int, int], FloatArray] = {}
        bridges = []
        for n in g.node_ids.tolist():
            if n == goal or any(math.isfinite(e.travel_time_s) and not e.reverse for e in g.out[n]):
                continue
            xy = g.position(n)
            start = grid.nearest_free(xy, self.min_clearance_m, 0.5)
            path = None if start is None else self.planner.plan(start, end, grid)
            if path is None:
                continue
            leg = np.concatenate([xy[None], path, goal_xy[None]])
            leg = leg[np.r_[True, np.hypot(*np.diff(leg, axis=0).T) > 1e-9]]
            length = float(np.sum(np.hypot(*np.diff(leg, axis=0).T)))
            legs[(n, goal)] = leg
            bridges.append(
                Edge(n, goal, length, length / p.speed_mps, False, p.detour_half_width_m, BRIDGE)
            )
        return legs, bridges

    def _with_legs(self, plan: PlannedPath, legs: dict[tuple[int, int], FloatArray]) -> PlannedPath:
        """``plan`` with each bridge edge's grid path inserted (node id :data:`BRIDGE`)."""
        p = self.params
        ids, xy, hw, v = (
            [plan.node_ids[0]],
            [plan.xy[0]],
            [plan.half_width_m[0]],
            [plan.v_max_mps[0]],
        )
        for k in range(1, len(plan.node_ids)):
            leg = legs.get((plan.node_ids[k - 1], plan.node_ids[k]))
            if leg is not None:
                inner = leg[1:-1]
                ids += [BRIDGE] * len(inner)
                xy += list(inner)
                hw += [p.detour_half_width_m] * len(inner)
                v += [p.speed_mps] * len(inner)
            ids.append(plan.node_ids[k])
            xy.append(plan.xy[k])
            hw.append(plan.half_width_m[k])
            v.append(plan.v_max_mps[k])
        return PlannedPath(
            tuple(ids), np.array(xy), np.array(hw), np.array(v), plan.travel_time_s, plan.edges
        )
