"""``tour``: a scripted operator who steers the robot along the world's route.

The papers' robots were driven along a fixed route by a human operator (B&D §5; H&W §7). This
driver plays that operator. It sees the truth — the robot's true pose, the people, and the
current obstacles of the world — which is fine because it is part of the *simulation*, not of
the agent; the localizers never see any of it. It feeds that truth to the agent-side roles a
navigation stack uses, picked by name like every role:

* Planning (``planner``, default ``grid-dijkstra``): at the start of a run (and after a
  kidnapping) a collision-free polyline through the route's waypoints on a clearance grid of
  the true obstacles. A leg whose straight line is blocked by the schedule becomes a
  *detour*; a waypoint that is inside an obstacle or unreachable is *skipped*. Both are
  recorded as events.
* Following (``controller``, default ``pure-pursuit``): regulated pure pursuit on that path.
* The operator's own judgement: it stops and waits while a person stands in its way (a speed
  limit handed to the controller), and backs off for a moment when the bumper is pressed.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim import se2
from dynmap_sim.agent.control.controller import CONTROLLERS, Controller
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid, build_clearance_grid
from dynmap_sim.agent.planning.planner import PLANNERS, Planner
from dynmap_sim.experiments.drivers.driver import (
    Driver,
    DriverContext,
    RunStart,
    StepInput,
    register_driver,
)
from dynmap_sim.truth import ObstacleSnapshot
from dynmap_sim.types import BeamClass

FloatArray = NDArray[np.float64]


def clip_route(route: FloatArray, fraction: float) -> FloatArray:
    """The leading ``fraction`` of a polyline by arc length (``(K, 2)``, K >= 2)."""
    route = np.asarray(route, dtype=np.float64)
    if fraction >= 1.0:
        return route
    seg = np.hypot(*np.diff(route, axis=0).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    target = fraction * cum[-1]
    k = int(np.searchsorted(cum, target, side="right"))
    k = min(max(k, 1), len(route) - 1)
    u = (target - cum[k - 1]) / max(seg[k - 1], 1e-12)
    end = route[k - 1] + u * (route[k] - route[k - 1])
    return np.concatenate([route[:k], end[None]])


@dataclass(frozen=True)
class TourParams:
    """The operator's tunables (SI units); the scenario's ``[driver] params``."""

    #: wait while a person is in the way
    wait_for_people: bool = True
    #: extra clearance the path prefers beyond the robot's radius [m]
    clearance_m: float = 0.12
    #: the hard clearance is the robot's radius plus this [m]
    safety_margin_m: float = 0.05
    #: a person ahead closer than this stops the robot [m] ...
    person_stop_m: float = 0.9
    #: ... closer than this slows it down [m]
    person_slow_m: float = 1.8
    #: "ahead" is within this angle of the heading [rad]
    person_cone_rad: float = 1.0
    #: a waypoint inside an obstacle moves to free space within this distance [m]
    snap_waypoint_m: float = 0.4
    #: cell size of the clearance grid [m]
    grid_resolution_m: float = 0.05
    #: after a bump, back off for this long [s] ...
    backoff_s: float = 1.0
    #: ... at this speed [m/s]
    backoff_mps: float = 0.1
    #: the Planner role (registry name or ``module:Class``) and its own parameters
    planner: str = "grid-dijkstra"
    planner_params: dict[str, Any] | None = None
    #: the Controller role (registry name or ``module:Class``) and its own parameters
    controller: str = "pure-pursuit"
    controller_params: dict[str, Any] | None = None


@dataclass
class WaypointPlan:
    """A collision-free polyline through a route's waypoints: ``vertices`` ``(K, 2)``, the
    route waypoint each vertex leads towards, and ``notes`` in route order: ``("skip_waypoint",
    why)`` for a waypoint given up, ``("detour", how)`` for a leg around an obstacle."""

    vertices: FloatArray
    waypoint_of_vertex: NDArray[np.int64]
    notes: list[tuple[str, str]]

    @property
    def length_m(self) -> float:
        return float(np.hypot(*np.diff(self.vertices, axis=0).T).sum())


def plan_through_waypoints(
    route: FloatArray,
    first_wp: int,
    start_xy: FloatArray,
    grid: ClearanceGrid,
    planner: Planner,
    min_clearance_m: float,
    snap_m: float,
) -> WaypointPlan:
    """Plan from ``start_xy`` through ``route[first_wp:]`` in order: each waypoint moved to
    free space within ``snap_m`` (else skipped: inside an obstacle), each leg planned by
    ``planner`` on ``grid`` (else skipped: unreachable)."""
    here = grid.nearest_free(np.asarray(start_xy, dtype=np.float64), min_clearance_m, 1.0)
    if here is None:
        here = np.asarray(start_xy, dtype=np.float64).copy()
    verts = [here]
    owner = [first_wp]
    notes: list[tuple[str, str]] = []
    for k in range(first_wp, len(route)):
        goal = grid.nearest_free(route[k], min_clearance_m, snap_m)
        if goal is None:
            notes.append(("skip_waypoint", f"waypoint {k}: waypoint inside an obstacle"))
            continue
        leg = planner.plan(verts[-1], goal, grid)
        if leg is None:
            notes.append(("skip_waypoint", f"waypoint {k}: waypoint unreachable"))
            continue
        if len(leg) > 2:
            notes.append(("detour", f"waypoint {k}: {len(leg) - 2} extra vertices"))
        verts.extend(leg[1:])
        owner.extend([k] * (len(leg) - 1))
    return WaypointPlan(np.array(verts).reshape(-1, 2), np.array(owner, dtype=np.int64), notes)


@register_driver("tour")
class TourDriver(Driver):
    """The scripted operator (module doc); ``params``: :class:`TourParams` fields."""

    sees_truth = True

    def __init__(self, context: DriverContext, **params: Any) -> None:
        known = {f.name for f in fields(TourParams)}
        unknown = sorted(set(params) - known)
        super().__init__(context, **{k: params[k] for k in unknown})  # raises on unknown
        self.params = TourParams(**params)
        self.route = np.asarray(context.route, dtype=np.float64)
        p = self.params
        self.min_clearance_m = context.robot_radius_m + p.safety_margin_m
        self.planner: Planner = PLANNERS.get(p.planner)(
            self.min_clearance_m,
            context.robot_radius_m + p.clearance_m,
            **(p.planner_params or {}),
        )
        self.controller: Controller = CONTROLLERS.get(p.controller)(
            context.speed_mps, self.min_clearance_m, **(p.controller_params or {})
        )
        self._grid: ClearanceGrid | None = None
        self._plan: WaypointPlan | None = None
        self._last_path: FloatArray = np.zeros((0, 2))
        self._waiting = False
        self._step = 0
        self._backoff = 0

    # ----------------------------------------------------------------- planning
    def begin_run(self, start: RunStart) -> None:
        """Plan the run on the true obstacles from the true start pose."""
        assert start.obstacles is not None and start.start_pose is not None
        self.events = []
        self.skipped_waypoints = 0
        self._step = 0
        self._waiting = False
        self._backoff = 0
        self._grid = static_clearance_grid(start.obstacles, self.params.grid_resolution_m)
        self._replan(np.asarray(start.start_pose, dtype=np.float64), 0, t_s=0.0)

    def _replan(self, pose: FloatArray, first_wp: int, t_s: float) -> None:
        assert self._grid is not None
        plan = plan_through_waypoints(
            self.route,
            first_wp,
            pose[:2],
            self._grid,
            self.planner,
            self.min_clearance_m,
            self.params.snap_waypoint_m,
        )
        for kind, detail in plan.notes:
            self.skipped_waypoints += kind == "skip_waypoint"
            self.events.append((self._step, t_s, kind, detail))
        self._plan = plan
        self.controller.set_path(plan.vertices)

    def end_run(self) -> None:
        """Drop the run's grid and plan (they are rebuilt next run; keeps checkpoints small),
        keeping the last planned polyline for :meth:`run_artifacts`."""
        self._last_path = self.path()
        self._grid = None
        self._plan = None
        self.controller.set_path(None)

    def run_artifacts(self) -> dict[str, bytes]:
        """The run's last planned path (``(K, 2)`` float64 bytes), as the autonomous driver
        hands it: the report draws it and ``export --mcap`` writes it as ``/plan``."""
        path = self._last_path
        if not len(path):
            return {}
        return {"planned_path.f8": np.ascontiguousarray(path, dtype="<f8").tobytes()}

    def teleported(self, pose: FloatArray, t_s: float) -> None:
        """The true robot was moved (kidnapping): replan from there to the rest of the route."""
        assert self._plan is not None
        seg = self.controller.segment
        nxt = int(self._plan.waypoint_of_vertex[min(seg + 1, len(self._plan.vertices) - 1)])
        self._replan(np.asarray(pose, dtype=np.float64), nxt, t_s)

    # ----------------------------------------------------------------- driving
    @property
    def done(self) -> bool:
        return self._plan is None or self.controller.done

    def act(self, step: StepInput) -> NDArray[np.float32]:
        """The command for the true pose; waits for people ahead; backs off after a bump."""
        self._step += 1
        p = self.params
        if self.done:
            return np.zeros(2, dtype=np.float32)
        if step.bumped and self._backoff == 0:
            self._backoff = max(1, int(round(p.backoff_s / self.context.dt_s)))
            self.events.append((self._step, step.t_s, "bump", "bumper pressed; backing off"))
        if self._backoff > 0:
            self._backoff -= 1
            return np.array([-p.backoff_mps, 0.0], dtype=np.float32)
        assert self._grid is not None and step.pose is not None
        pose = np.asarray(step.pose, dtype=np.float64)
        people = np.zeros((0, 3)) if step.people is None else step.people

        def people_limit() -> float:
            if len(people):
                return self._people_factor(pose, people, step.t_s)
            self._waiting = False
            return 1.0

        return self.controller.command(pose, self._grid, people_limit)

    def _people_factor(self, pose: FloatArray, people: FloatArray, t_s: float) -> float:
        """1 with nobody ahead, 0 (wait) when someone is within the stop distance ahead."""
        p = self.params
        ppl = np.asarray(people, dtype=np.float64).reshape(-1, np.shape(people)[-1] or 3)
        ppl = ppl[np.isfinite(ppl[:, 0]) & np.isfinite(ppl[:, 1])]  # padding rows are inf
        factor = 1.0
        if p.wait_for_people and len(ppl):
            d = ppl[:, :2] - pose[:2]
            dist = np.hypot(d[:, 0], d[:, 1])
            bearing = np.abs(se2.wrap_angle(np.arctan2(d[:, 1], d[:, 0]) - pose[2]))
            ahead = bearing < p.person_cone_rad
            if np.any(ahead & (dist < p.person_stop_m)):
                factor = 0.0
            elif np.any(ahead & (dist < p.person_slow_m)):
                dmin = float(dist[ahead].min())
                factor = float(
                    np.clip((dmin - p.person_stop_m) / (p.person_slow_m - p.person_stop_m), 0.3, 1)
                )
        waiting = factor == 0.0
        if waiting and not self._waiting:
            self.events.append((self._step, t_s, "wait_for_person", "a person is in the way"))
        self._waiting = waiting
        return factor

    def path(self) -> FloatArray:
        """The planned polyline ``(K, 2)`` of the current run."""
        return np.zeros((0, 2)) if self._plan is None else self._plan.vertices.copy()


def static_clearance_grid(obstacles: ObstacleSnapshot, resolution_m: float) -> ClearanceGrid:
    """The clearance grid of the obstacles that stand still (people's legs left out)."""
    static_circles = obstacles.circles[obstacles.circle_class != BeamClass.PERSON]
    return build_clearance_grid(obstacles.segments, static_circles, resolution_m=resolution_m)
