"""The navigation stack: route memory, planning, control and safety composed (H&W 2011 §5-6).

:class:`NavigationStack` turns the agent's pose estimate, scans and odometry into a velocity
command, every scan, the way Hentschel & Wagner's robot drove its apartment (§6-7) and the way
nav2 composes its servers:

1. **Costmap** (:class:`~dynmap_sim.agent.planning.costmap.Costmap`): the static layer from
   the prior's walls (or a localizer's own map, :meth:`NavigationStack.set_static_map`), the
   obstacle layer marked and cleared by each scan at the *estimated* pose, inflated to a
   clearance grid.
2. **Route memory** (:class:`~.route_memory.RouteMemory`, H&W §5): built from the prior's
   route on the first run and kept across runs; every step it learns from the estimate
   (travel times, coordinates, a **new route** when the robot drives outside every corridor,
   e.g. around a block), and :meth:`NavigationStack.end_run` forgets what was not used.
3. **Route planning** (:func:`~dynmap_sim.agent.planning.route_astar.plan_route`, §6.2): A* on
   the route graph by travel time from the estimate to the goal (the end of the prior's route),
   at most every ``replan_period_s`` (nav2's behaviour tree replans at 1 Hz). The corridor of
   the route (the half-width ``l`` of each segment) is what the follower may use to avoid
   obstacles reactively.
4. **Control** (:class:`~dynmap_sim.agent.control.corridor_follower.CorridorFollower`, §6.3):
   pure-pursuit tracking with a lateral offset inside the corridor, a clearance speed law.
5. **Global replanning** (§6.3): when the follower reports ``blocked`` (no offset inside the
   corridor is free) or the corridor is cut on the costmap within ``cut_check_m`` ahead (at a
   replan), the route edges of the cut stretch are **blocked** in the route memory (infinite
   cost), route A* is asked again (another route may exist, e.g. the detour recorded on an
   earlier day), and failing that a **detour** is planned with grid A* on the costmap's
   clearance around the block back onto the path
   (:func:`~dynmap_sim.agent.planning.grid_astar.plan_around`). The robot drives it; the route
   memory records it as a new route joined to the graph; once the robot is back on the path,
   route planning takes over again. A blocked edge is **unblocked** when the scan sees its
   centre line free (every point of it in view, a beam passing beyond it, and the costmap
   clear there), or when the robot drives it (the route memory does that).
6. **Recovery** (:class:`~dynmap_sim.agent.control.recovery.Recovery`): stuck detection on the
   odometry pose, then wait, back up, replan (with the costmap's obstacle layer cleared, nav2's
   first recovery), and a recorded give-up (:attr:`NavigationStack.gave_up`).
7. **Collision monitor** (:class:`~dynmap_sim.agent.control.collision_monitor.
   CollisionMonitor`): every command, the recovery's included, is filtered by the raw scan in
   the robot frame, so a wrong estimate or a controller bug cannot drive into an obstacle.

The run ends for the stack when the estimate is within ``goal_tolerance_m`` of the goal
(:attr:`NavigationStack.done`); a route that ends where it starts (a loop) is driven through
via points (every ``loop_via_spacing_m`` of it, passed within ``via_tolerance_m`` or once
the robot is tracked beyond them) before its end counts, and the end only once the robot
has been ``goal_arm_m`` away from it.
Everything here sees only what the agent sees: estimate, scan, odometry, the prior.

Time: ``t_s`` of :meth:`NavigationStack.step` is the time within the run's day [s] (seconds
since midnight, or since the run started: anything below a day); the route memory's clock is
``prior.day * 86400 + t_s``, so its forgetting ages count in days as the calendar does.

The stack pickles (the experiment runner checkpoints it after every run): plain data, no
lambdas; the cached route graph is dropped.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim import se2
from dynmap_sim.agent.control.collision_monitor import CollisionMonitor, CollisionMonitorParams
from dynmap_sim.agent.control.corridor_follower import CorridorFollower, CorridorFollowerParams
from dynmap_sim.agent.control.recovery import Recovery, RecoveryParams
from dynmap_sim.agent.grid import OccupancyGrid
from dynmap_sim.agent.navigation.route_memory import (
    JOIN,
    Edge,
    Route,
    RouteGraph,
    RouteMemory,
    RouteMemoryParams,
    RoutePosition,
)
from dynmap_sim.agent.params import config_from_params
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid
from dynmap_sim.agent.planning.costmap import Costmap, CostmapParams, samples_along
from dynmap_sim.agent.planning.grid_astar import GridAStar, plan_around
from dynmap_sim.agent.planning.route_astar import PlannedPath, plan_route
from dynmap_sim.jit import compiled
from dynmap_sim.types import LaserSpec, Odometry, PoseEstimate, Prior, Scan

FloatArray = NDArray[np.float64]

#: Seconds per day: the route memory's clock is ``prior.day * DAY_S + t_s``.
DAY_S = 86_400.0

#: What the stack is following: a route A* path, a grid detour back onto it, or a grid path
#: to the goal when the route graph has none.
ROUTE, DETOUR, GRID = "route", "detour", "grid"

#: Route id of a bridge edge (:meth:`NavigationStack._bridged_plan`): grid A* on the costmap
#: from a dead end of the route graph to the goal; also the node id of its interior points.
BRIDGE = -2


@dataclass(frozen=True)
class StackParams:
    """Every choice of :class:`NavigationStack`, with the reason for its default (SI units)."""

    #: Cruise speed [m/s]: the corridor follower's and the prior route's ``v_max``. 0.35 m/s is
    #: the follower's (and the tour operator's) pace; H&W's Roomba drove ≈ 0.2-0.3 m/s.
    speed_mps: float = 0.35
    #: Corridor half-width ``l`` of the prior's route [m]: the route memory's width for
    #: recorded routes (a ≈ 1.2 m doorway minus a 0.4 m robot leaves ± 0.35 m).
    route_half_width_m: float = 0.35
    #: Hard clearance = robot radius + this [m], for the follower and grid A*: 5 cm covers
    #: the costmap's cell size, so no plan or offset touches an inflated obstacle cell.
    safety_margin_m: float = 0.05
    #: Grid A* prefers clearance robot radius + this [m] (the tour's 0.12 m plus a little):
    #: detours keep off furniture where there is room.
    preferred_margin_m: float = 0.15
    #: Planning period [s] (nav2's behaviour tree replans at 1 Hz): route A*, the cut check,
    #: the unblock check. Also the least time between two global replans on ``blocked``.
    replan_period_s: float = 1.0
    #: The goal is reached when the estimate is this close [m]: above the follower's vertex
    #: tolerance (0.12 m) so its stop at the path's end counts, below the env's 0.3 m so the
    #: true pose is within the env's tolerance with a 0.1 m localization error.
    goal_tolerance_m: float = 0.2
    #: A loop route ends at its start: the goal counts only after the robot has been this far
    #: from it [m] (also while it is nearer, planning leaves the goal: no zero-length plan).
    goal_arm_m: float = 1.0
    #: A loop (a prior route whose end is within ``goal_arm_m`` of its start) is driven
    #: through via points every this many metres of it, in order, then to its end (nav2's
    #: NavigateThroughPoses); 0: the goal only. Without them the run's task is "reach the
    #: start again", and route A* takes any recorded route that joins the loop's end to its
    #: start as a shortcut; too few via points let the shortest way to the next one skip
    #: part of the loop (docs/tuning/navigation.md). 5 m is shorter than any stretch a
    #: recorded route could cut off with profit, and longer than a block the robot must go
    #: round (a via point there is passed by the rule below). The paper's routes had a start
    #: and an end (§7.1).
    loop_via_spacing_m: float = 5.0
    #: A via point is passed when the estimate comes this close [m] (wider than the goal's
    #: tolerance: a via point only fixes the way round, a detour may pass it aside), when the
    #: robot is tracked on the prior route beyond it (a detour round a block rejoined after
    #: it), or skipped when nothing can reach it.
    via_tolerance_m: float = 0.5
    #: How far along the path ahead the corridor is checked for a cut at each replan [m]: the
    #: costmap marks obstacles up to 2.5 m, so a block is planned around before the follower
    #: (which probes 1 m) has to stop in front of it.
    cut_check_m: float = 2.0
    #: The costmap's obstacle layer is updated at most this often [s] (nav2's local costmap
    #: updates at 5 Hz): ray tracing a scan is the costmap's largest cost, and a robot at
    #: 0.35 m/s moves 7 cm in 0.2 s, less than the controller's margins.
    costmap_period_s: float = 0.2
    #: Half-size [m] of the window around the robot whose clearance is recomputed after each
    #: costmap update (nav2's rolling local costmap); elsewhere the clearance of the last plan
    #: (1 Hz) serves. The follower probes ≤ 1 m + its 0.35 m lookahead ahead.
    local_window_m: float = 1.6
    #: Clearance in the window is exact up to this [m] (obstacles farther outside the window
    #: are not looked at): the follower's speed law and offset choice saturate at 0.8 m.
    local_margin_m: float = 0.8
    #: Lateral samples across the corridor of the cut check (odd: the centre line is one).
    cut_offsets: int = 9
    #: Corridor half-width of a grid detour's own vertices [m]: grid A* already keeps the
    #: hard clearance, so a little room suffices for reactive avoidance (a person) while the
    #: robot stays on the planned way through a gap.
    detour_half_width_m: float = 0.2
    #: A blocked edge is seen free only within this range [m] (the costmap's obstacle range:
    #: farther readings are too noisy to vouch for a free corridor).
    unblock_view_m: float = 2.5
    #: Spacing of the points checked on a blocked edge [m]: less than an obstacle's size.
    unblock_step_m: float = 0.1
    #: A point counts as seen free when a beam passes it by at least this [m] (range noise).
    unblock_margin_m: float = 0.1
    #: Clear the costmap's obstacle layer before the recovery's replan (nav2's
    #: ``ClearEntireCostmap``): stale marks, e.g. of a person gone, may be what blocks.
    clear_costmap_on_replan: bool = True
    #: The recovery's replan during a detour round a block that is still blocked plans the
    #: detour again from where the robot stands (on the costmap the recovery just cleared)
    #: instead of asking route A* first. Route A* cannot use the detour (it is no route
    #: yet): it would send the robot the whole way round a loop back to the block
    #: (docs/tuning/navigation.md).
    keep_detour_on_recovery: bool = True
    #: Tunables of the parts; the stack sets the robot radius, speed and hard clearance. A
    #: scenario gives them as tables (``[driver.params.follower]``): a mapping becomes the
    #: part's dataclass, an unknown key is an error that lists the known ones.
    route_memory: RouteMemoryParams = field(default_factory=RouteMemoryParams)
    costmap: CostmapParams = field(default_factory=CostmapParams)
    follower: CorridorFollowerParams = field(default_factory=CorridorFollowerParams)
    monitor: CollisionMonitorParams = field(default_factory=CollisionMonitorParams)
    recovery: RecoveryParams = field(default_factory=RecoveryParams)

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in _PART_PARAMS and isinstance(value, Mapping):
                owner = f"StackParams.{f.name}"
                fixed = sorted(set(value) & set(_SET_BY_STACK.get(f.name, ())))
                if fixed:
                    raise ValueError(
                        f"{owner}: {', '.join(fixed)} set by the stack (the cruise speed, robot "
                        "radius and safety_margin_m), not by the part's table"
                    )
                part = config_from_params(_PART_PARAMS[f.name], owner, value)
                object.__setattr__(self, f.name, part)
        for name in ("speed_mps", "route_half_width_m", "replan_period_s", "goal_tolerance_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise ValueError(f"StackParams.{name} must be finite and > 0, got {v!r}")
        if not (math.isfinite(self.loop_via_spacing_m) and self.loop_via_spacing_m >= 0.0):
            raise ValueError(
                f"StackParams.loop_via_spacing_m must be finite and >= 0, got "
                f"{self.loop_via_spacing_m!r}"
            )
        if self.cut_offsets < 1 or self.cut_offsets % 2 == 0:
            raise ValueError(
                f"StackParams.cut_offsets must be odd and >= 1, got {self.cut_offsets}"
            )


#: The parts' parameter classes by :class:`StackParams` field.
_PART_PARAMS: dict[str, type] = {
    "route_memory": RouteMemoryParams,
    "costmap": CostmapParams,
    "follower": CorridorFollowerParams,
    "monitor": CollisionMonitorParams,
    "recovery": RecoveryParams,
}

#: The fields of a part's parameters that the stack sets (from its own speed, the robot's
#: radius and the hard clearance) and so a scenario's table may not.
_SET_BY_STACK: dict[str, tuple[str, ...]] = {
    "follower": ("speed_mps", "min_clearance_m"),
    "monitor": ("robot_radius_m",),
    "recovery": ("robot_radius_m",),
}


def _params_except(params: object, *names: str) -> dict[str, Any]:
    """A params dataclass as keywords without ``names`` (set by the stack)."""
    return {k: v for k, v in asdict(params).items() if k not in names}  # type: ignore[call-overload]


def _distance_to_polyline(pts: FloatArray, poly: FloatArray) -> FloatArray:
    """Distance [m] of each point ``(N, 2)`` to the polyline ``(K, 2)``."""
    a, b = poly[:-1], poly[1:]
    d = b - a
    len2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-18)
    rel = pts[:, None, :] - a[None, :, :]
    u = np.clip(np.einsum("nki,ki->nk", rel, d) / len2, 0.0, 1.0)
    gap = rel - u[..., None] * d[None]
    return np.hypot(gap[..., 0], gap[..., 1]).min(axis=1)


class NavigationStack:
    """H&W §5-6 composed with nav2-style safety (module doc).

    ``laser``: the scanner (for the costmap, the collision monitor and the back-up check);
    ``robot_radius_m``: the robot's radius [m]; ``params``: :class:`StackParams`.

    Per experiment: :meth:`begin_run` with each run's prior, :meth:`step` every scan,
    :meth:`end_run` after it. After a run: :attr:`done`, :attr:`gave_up`, the counters
    (:attr:`replans`, :attr:`recoveries`, :attr:`stuck_s`, :attr:`monitor_stops`,
    :attr:`monitor_slowdowns`), :attr:`events`, :meth:`planned_path`, :attr:`route_memory`.
    """

    def __init__(
        self, laser: LaserSpec, robot_radius_m: float, params: StackParams | None = None
    ) -> None:
        if not (math.isfinite(robot_radius_m) and robot_radius_m > 0.0):
            raise ValueError(f"robot_radius_m must be finite and > 0, got {robot_radius_m!r}")
        self.laser = laser
        self.robot_radius_m = float(robot_radius_m)
        self.params = params or StackParams()
        p = self.params
        self.min_clearance_m = self.robot_radius_m + p.safety_margin_m
        self.planner = GridAStar(self.min_clearance_m, self.robot_radius_m + p.preferred_margin_m)
        #: the long-term route memory (None until the first :meth:`begin_run`)
        self.route_memory: RouteMemory | None = None
        #: the costmap of the run in progress (None before the first :meth:`begin_run`)
        self.costmap: Costmap | None = None
        self.goal_xy: FloatArray | None = None
        self._goal_id: int | None = None
        #: a loop's via points ``[xy, waypoint id]``, in order (kept across runs)
        self._vias: list[tuple[FloatArray, int]] = []
        #: arc length [m] of the prior route's waypoints, whose ids are 0..len-1 in order
        self._prior_cum_m = np.zeros(0)
        self._pending_grid: OccupancyGrid | None = None
        self._graph: RouteGraph | None = None
        self._new_run_state()

    # ------------------------------------------------------------------ run lifecycle
    def _new_run_state(self) -> None:
        p = self.params
        r = self.robot_radius_m
        self.follower = CorridorFollower(
            p.speed_mps,
            self.min_clearance_m,
            **_params_except(p.follower, *_SET_BY_STACK["follower"]),
        )
        self.monitor = CollisionMonitor(
            self.laser, r, **_params_except(p.monitor, *_SET_BY_STACK["monitor"])
        )
        self.recovery = Recovery(
            self.laser, r, **_params_except(p.recovery, *_SET_BY_STACK["recovery"])
        )
        #: True once the goal is reached (the stack then commands zero)
        self.done = False
        #: True once the recovery gave up (the stack then commands zero)
        self.gave_up = False
        #: global replans: paths replaced because the old one was blocked or cut (H&W §6.3)
        self.replans = 0
        #: plans computed (route A* at ``replan_period_s`` and every detour)
        self.plans = 0
        #: control steps of the run
        self.steps = 0
        #: what is being followed: :data:`ROUTE`, :data:`DETOUR` or :data:`GRID`
        self.mode = ROUTE
        self._events: list[tuple[float, str, str]] = []
        self._plan: PlannedPath | None = None  # the route plan (route mode; base of a detour)
        self._path: FloatArray | None = None  # what the follower follows
        self._rejoin_seg = 0  # detour: follower segment from which the robot is back on the path
        self._last_plan_t: float | None = None
        self._force_plan = False
        self._recovery_replan = False  # the pending forced plan is the recovery's replan
        self._armed = False
        self._via_k = 0  # via points passed in this run
        #: the route position of the last step (H&W §5.1), None off the corridors
        self._route_pos: RoutePosition | None = None
        self._day_s = 0.0
        self._costmap_t: float | None = None
        self._global: ClearanceGrid | None = None  # the costmap's clearance at the last plan
        self._local: tuple[tuple[float, float], ClearanceGrid] | None = None  # (centre, grid)
        self._last_t = 0.0

    def begin_run(self, prior: Prior) -> None:
        """Start a run: the route memory from ``prior.route`` on the first run (kept and
        learning across runs), a fresh costmap from the prior's walls (and the map given to
        :meth:`set_static_map` before this call, if any), the goal = the route's end."""
        if prior.route is None and self.route_memory is None:
            raise ValueError("the navigation stack needs prior.route (the desired route)")
        if prior.route is not None:
            route = np.asarray(prior.route, dtype=np.float64)
            if route.ndim != 2 or route.shape[1] != 2 or len(route) < 2:
                raise ValueError(f"prior.route must be (K >= 2, 2) [m], got shape {route.shape}")
            if not np.all(np.isfinite(route)):
                raise ValueError("prior.route holds non-finite coordinates")
        else:
            route = None
        self._new_run_state()
        self._day_s = float(prior.day) * DAY_S
        p = self.params
        if self.route_memory is None:
            assert route is not None
            self.route_memory = RouteMemory.from_prior(
                route, p.speed_mps, p.route_half_width_m, self._day_s, p.route_memory
            )
            prior_route = next(iter(self.route_memory.routes.values()))
            self._goal_id = int(prior_route.ids[-1])
            self.goal_xy = route[-1].copy()
            self._vias = self._loop_vias(prior_route)
            self._prior_cum_m = prior_route.cumulative_m()
        else:
            self.route_memory.reset_run()
            if route is not None and not np.allclose(route[-1], self.goal_xy):
                self.goal_xy = route[-1].copy()
                self._goal_id = None  # resolved on the graph
        costmap_params = self.params.costmap
        if costmap_params.footprint_clear_radius_m != self.robot_radius_m:
            costmap_params = replace(costmap_params, footprint_clear_radius_m=self.robot_radius_m)
        self.costmap = Costmap.for_prior(prior, costmap_params)
        if self._pending_grid is not None:
            self.costmap.set_static_grid(self._pending_grid)
            self._pending_grid = None
        self._graph = None
        self._event(0.0, "begin_run", f"day {prior.day} run {prior.run}")

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

    def _pass_vias(self, t_s: float, pose: FloatArray) -> None:
        """Count the via points passed (``via_tolerance_m``): the next one reached, or those
        behind the prior route's waypoint the robot is tracked on by at most two via spacings
        (a detour round a block rejoined after them; never the whole loop when its end is seen
        at its start)."""
        k, n = self._via_k, len(self._vias)
        if k < n:
            vx, vy = self._vias[k][0].tolist()
            if np.hypot(float(pose[0]) - vx, float(pose[1]) - vy) <= self.params.via_tolerance_m:
                k += 1
        pos = self._route_pos
        if k < n and self._armed and pos is not None and pos.inside:
            here = pos.from_id
            if here < len(self._prior_cum_m):
                cum, reach = self._prior_cum_m, 2.0 * self.params.loop_via_spacing_m
                while (
                    k < n
                    and self._vias[k][1] <= here
                    and cum[here] - cum[self._vias[k][1]] <= reach
                ):
                    k += 1
        if k > self._via_k:
            self._event(t_s, "via", f"via points {self._via_k + 1}-{k} of {n} passed")
            self._via_k = k
            self._force_plan = True

    def _target(self) -> tuple[FloatArray, int | None, bool]:
        """What the robot heads for now: ``(xy, waypoint id, is_via)``; the next via point
        of a loop, else the goal."""
        if self._via_k < len(self._vias):
            xy, wid = self._vias[self._via_k]
            return xy, wid, True
        assert self.goal_xy is not None
        return self.goal_xy, self._goal_id, False

    def _avoid_entry(self, g: RouteGraph) -> int | None:
        """While heading for a loop's via point, its end (on its start) is no entry to the
        graph: from there no route leads on, and the robot would go round to get back."""
        if not self._target()[2] or self.goal_xy is None:
            return None
        return self._node_of(g, self.goal_xy, self._goal_id)

    def _leave_target_m(self) -> float:
        """``leave_goal_m`` of the planners: a loop's start must be left before it can end the
        run (not for a via point, which lies away from the start)."""
        if self._target()[2] or self._armed:
            return 0.0
        return self.params.goal_arm_m

    def set_static_map(self, grid: OccupancyGrid) -> None:
        """The costmap's static layer := a localizer's own map (e.g. its first-run SLAM map)
        for the run in progress; called before :meth:`begin_run` it serves the next run."""
        if self.costmap is None:
            self._pending_grid = grid
            return
        self.costmap.set_static_grid(grid)

    def end_run(self) -> int:
        """The run is over: the route memory forgets what it has not used for longer than
        its ``forget_age_s`` (H&W §5.2); returns the number of segments forgotten."""
        if self.route_memory is None:
            return 0
        g = self.route_memory.graph()
        keep = []
        if g.node_ids.size:  # the goal and the via points must stay reachable
            keep = [self._node_of(g, self.goal_xy, self._goal_id)]
            keep += [self._node_of(g, xy, wid) for xy, wid in self._vias]
        n = self.route_memory.forget(self._day_s + self._last_t, keep=keep)
        if n:
            self._event(self._last_t, "forget", f"{n} route segments")
        self._graph = None
        return n

    # ------------------------------------------------------------------ results
    @property
    def recoveries(self) -> int:
        """Recovery behaviours run in this run (waits, back-ups, replans)."""
        return self.recovery.recoveries

    @property
    def stuck_s(self) -> float:
        """Time this run spent stuck or recovering [s]."""
        return self.recovery.stuck_s

    @property
    def monitor_stops(self) -> int:
        """Steps at which the collision monitor stopped the robot."""
        return self.monitor.stop_count

    @property
    def monitor_slowdowns(self) -> int:
        """Steps at which the collision monitor slowed the robot down."""
        return self.monitor.slowdown_count

    @property
    def events(self) -> list[tuple[float, str, str]]:
        """``(t_s, kind, detail)`` of the run in time order: the stack's (plans, blocks,
        detours, goal), the recovery's and the collision monitor's."""
        merged = self._events + self.recovery.events + self.monitor.events
        return sorted(merged, key=lambda e: e[0])

    def planned_path(self) -> FloatArray | None:
        """The path being followed ``(K, 2)`` [m] (a copy), None when there is none."""
        return None if self._path is None else self._path.copy()

    def counters(self) -> dict[str, float]:
        """The run's counters by name (for a results store)."""
        return {
            "done": float(self.done),
            "gave_up": float(self.gave_up),
            "replans": float(self.replans),
            "plans": float(self.plans),
            "recoveries": float(self.recoveries),
            "stuck_s": float(self.stuck_s),
            "monitor_stops": float(self.monitor_stops),
            "monitor_slowdowns": float(self.monitor_slowdowns),
        }

    # ------------------------------------------------------------------ the control step
    def step(
        self, t_s: float, odom: Odometry, scan: Scan, estimate: PoseEstimate
    ) -> NDArray[np.float32]:
        """One control step at time ``t_s`` [s] (module doc) with the odometry, the scan and
        the localizer's estimate of this scan: the command ``[v_mps, omega_radps]`` (float32),
        always filtered by the collision monitor."""
        if self.costmap is None or self.route_memory is None:
            raise RuntimeError("call begin_run(prior) before step()")
        t_s = float(t_s)
        self._last_t = t_s
        self.steps += 1
        pose = np.asarray(estimate.mean, dtype=np.float64).reshape(3)
        stop = np.zeros(2, dtype=np.float32)
        px, py, pth = pose.tolist()
        if not (math.isfinite(px) and math.isfinite(py) and math.isfinite(pth)):
            self._event(t_s, "bad_estimate", "non-finite pose estimate: stop")
            return self.monitor.filter(stop, scan, t_s)
        p = self.params
        if self._costmap_t is None or t_s - self._costmap_t >= p.costmap_period_s - 1e-9:
            self.costmap.update(pose, scan, self.laser)
            self._costmap_t = t_s
            self._local = None
        self._route_pos = self.route_memory.observe(pose, self._day_s + t_s)
        assert self.goal_xy is not None
        gx, gy = self.goal_xy.tolist()
        to_goal = float(np.hypot(px - gx, py - gy))
        if not self._armed and to_goal > self.params.goal_arm_m:
            self._armed = True
        self._pass_vias(t_s, pose)
        if (
            not self.done
            and self._armed
            and self._via_k == len(self._vias)
            and to_goal <= self.params.goal_tolerance_m
        ):
            self.done = True
            self._event(t_s, "goal", f"{to_goal:.2f} m from the goal")
        if self.done or self.gave_up:
            return self.monitor.filter(stop, scan, t_s)
        due = self._last_plan_t is None or t_s - self._last_plan_t >= p.replan_period_s
        if self._force_plan or due or self._global is None:
            self._global = self.costmap.clearance()
            self._local = None
            self._plan_step(t_s, pose, self._global, scan)
        grid = self._local_clearance(pose)
        cmd = self.follower.command(pose, grid)
        if self.follower.blocked and self._may_replan(t_s):
            self._event(t_s, "blocked", "no free offset inside the corridor")
            self._global = self.costmap.clearance()
            self._local = None
            if self._go_around(t_s, pose, self._global):
                grid = self._local_clearance(pose)
                cmd = self.follower.command(pose, grid)
        act = self.recovery.step(t_s, odom.pose, cmd, self.follower.blocked, scan)
        if act is not None:
            if act.kind == "give_up":
                self.gave_up = True
                self._event(t_s, "gave_up", act.detail)
                cmd = stop
            elif act.kind == "replan":
                if self.params.clear_costmap_on_replan:
                    self.costmap.clear_obstacles()
                self._force_plan = True
                self._recovery_replan = True
            elif act.command is not None:
                cmd = act.command
        return self.monitor.filter(cmd, scan, t_s)

    # ------------------------------------------------------------------ planning
    def _local_clearance(self, pose: FloatArray) -> ClearanceGrid:
        """The clearance for the follower: the last plan's, with a window around the robot
        recomputed from the costmap's current layers (module doc of the params)."""
        assert self.costmap is not None and self._global is not None
        p = self.params
        if self._local is not None:
            (cx, cy), grid = self._local
            if np.hypot(cx - float(pose[0]), cy - float(pose[1])) < 0.25:
                return grid
        grid = self.costmap.window_clearance(
            self._global, pose[:2], p.local_window_m, p.local_margin_m
        )
        self._local = ((float(pose[0]), float(pose[1])), grid)
        return grid

    def _may_replan(self, t_s: float) -> bool:
        return (
            self._last_plan_t is None
            or self._force_plan
            or t_s - self._last_plan_t >= self.params.replan_period_s
        )

    def _event(self, t_s: float, kind: str, detail: str = "") -> None:
        self._events.append((float(t_s), kind, detail))

    def graph(self) -> RouteGraph:
        """The route memory's graph (rebuilt at every plan)."""
        assert self.route_memory is not None
        if self._graph is None:
            self._graph = self.route_memory.graph()
        return self._graph

    def _route_plan(self, pose: FloatArray, ignore_blocks: bool = False) -> PlannedPath | None:
        """Route A* from the estimate to the target's node (the goal or a loop's next via
        point; H&W §6.2); with ``ignore_blocks`` on the graph without its blocks."""
        assert self.route_memory is not None and self.goal_xy is not None
        self._graph = None
        if ignore_blocks:
            blocked, self.route_memory.blocked = self.route_memory.blocked, set()
            try:
                g = self.route_memory.graph()
            finally:
                self.route_memory.blocked = blocked
        else:
            g = self.graph()
        if g.node_ids.size == 0:
            return None
        self.plans += 1
        target_xy = self._target()[0]
        pos = self._route_pos
        on = (pos.from_id, pos.to_id) if pos is not None and pos.inside else None
        for start_on in (on, None) if on is not None else (None,):
            # from the segment the robot is tracked on; failing that (the way on is blocked,
            # the way back is not), from wherever the graph is nearest
            plan = plan_route(
                g,
                pose[:2],
                target_xy,
                self.params.speed_mps,
                goal_id=self._goal_node(g),
                leave_goal_m=self._leave_target_m(),
                start_on=start_on,
                avoid_entry=self._avoid_entry(g),
            )
            if plan is not None:
                return plan
        return None

    @staticmethod
    def _node_of(g: RouteGraph, xy: FloatArray | None, waypoint_id: int | None) -> int:
        """A target's node on ``g``: its waypoint while the graph has it, else the node
        nearest its position."""
        if waypoint_id is not None and waypoint_id in g.index:
            return waypoint_id
        return g.nearest_node(xy)

    def _goal_node(self, g: RouteGraph) -> int:
        """The current target's node on ``g`` (:meth:`_target`): the prior route's end or a
        via point, else the node nearest it."""
        xy, waypoint_id, _ = self._target()
        return self._node_of(g, xy, waypoint_id)

    def _bridged_plan(self, pose: FloatArray, grid: ClearanceGrid) -> PlannedPath | None:
        """Route A* when the route graph cannot reach the goal (e.g. forgetting dropped the
        stretch or the join that led to it): the graph plus a **bridge** from each dead end
        (a node without a passable way on) to the goal node, grid A* on the costmap's
        clearance, costed at ``speed_mps``. So the robot drives what is left of its routes
        and crosses the gap on the costmap, and a loop's start still leaves the goal
        (``leave_goal_m`` as for any route plan). The bridges' grid paths are in the plan's
        ``xy`` (their interior points have node id :data:`BRIDGE`); None when no dead end
        has a grid path to the goal or the graph none to a dead end."""
        g = self.graph()
        if g.node_ids.size == 0:
            return None
        p = self.params
        goal = self._goal_node(g)
        goal_xy = g.position(goal)
        end = grid.nearest_free(goal_xy, self.min_clearance_m, 0.5)
        if end is None:
            return None
        legs: dict[tuple[int, int], FloatArray] = {}
        bridges = []
        for n in g.node_ids.tolist():
            if n == goal or any(math.isfinite(e.travel_time_s) for e in g.out[n]):
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
        if not bridges:
            return None
        self.plans += 1
        plan = plan_route(
            RouteGraph(g.node_ids, g.xy, g.v_max_mps, g.half_width_m, [*g.edges, *bridges]),
            pose[:2],
            goal_xy,
            p.speed_mps,
            goal_id=goal,
            leave_goal_m=self._leave_target_m(),
            avoid_entry=self._avoid_entry(g),
        )
        if plan is None or not any(e in legs for e in plan.edges):
            return plan
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

    def _plan_step(self, t_s: float, pose: FloatArray, grid: ClearanceGrid, scan: Scan) -> None:
        """The periodic planning step: unblock what is seen free, then keep, refresh or
        replace the path (module doc)."""
        forced = self._force_plan
        recovering, self._recovery_replan = self._recovery_replan, False
        self._force_plan = False
        self._last_plan_t = t_s
        self._unblock_seen_free(t_s, pose, scan, grid)
        if (
            recovering
            and self.params.keep_detour_on_recovery
            and self.mode == DETOUR
            and self.route_memory is not None
            and self.route_memory.blocked
            and self._go_around(t_s, pose, grid)
        ):
            return
        if self.mode == DETOUR and not forced and self._path is not None:
            if self.follower.segment < self._rejoin_seg and not self.follower.done:
                if self._cut_ahead(self._path, self._path_hw, grid, pose) is not None:
                    self._event(t_s, "cut", "the detour ahead is cut")
                    self._go_around(t_s, pose, grid)
                return
            self._event(t_s, "rejoined", "back on the route")
        plan = self._route_plan(pose)
        if plan is None and self.route_memory is not None and self.route_memory.blocked:
            # every route is blocked: drive the route up to the block and go around it there
            # (H&W §6.3); the blocks stay, so a detour driven now becomes a route
            plan = self._route_plan(pose, ignore_blocks=True)
            if plan is not None and self.mode != ROUTE:
                self._event(t_s, "through_block", "no unblocked route: the route up to the block")
        bridged = False
        if plan is None:
            # the route graph cannot reach the goal: bridge its dead ends on the costmap
            plan = self._bridged_plan(pose, grid)
            bridged = plan is not None
        if plan is None:
            self._grid_to_goal(t_s, pose, grid)
            return
        if self.mode != ROUTE or not self._same_plan(plan) or self.follower.done or forced:
            self._set_route_path(plan)
            if bridged:
                self._event(
                    t_s, "bridge", "no route to the goal: routes and grid A* across the gap"
                )
        if self._cut_ahead(self._path, self._path_hw, grid, pose) is not None:
            self._event(t_s, "cut", "the corridor ahead is cut on the costmap")
            self._go_around(t_s, pose, grid)

    def _same_plan(self, plan: PlannedPath) -> bool:
        """Whether ``plan`` goes on through the same nodes as the path being followed."""
        if self._plan is None:
            return False
        new = plan.node_ids[1:]
        old = self._plan.node_ids
        return 0 < len(new) <= len(old) and tuple(old[len(old) - len(new) :]) == tuple(new)

    def _set_route_path(self, plan: PlannedPath) -> None:
        self.mode = ROUTE
        self._plan = plan
        self._follow(plan.xy, plan.half_width_m)

    def _follow(self, path: FloatArray, half_widths: FloatArray) -> None:
        self._path = np.asarray(path, dtype=np.float64)
        self._path_hw = np.asarray(half_widths, dtype=np.float64)
        self.follower.set_path(self._path, self._path_hw)

    def _cut_ahead(
        self,
        path: FloatArray | None,
        hw: FloatArray,
        grid: ClearanceGrid,
        pose: FloatArray,
        seg0: int | None = None,
    ) -> FloatArray | None:
        """The first cut stretch of the corridor within ``cut_check_m`` ahead of the robot:
        its centre-line points ``(M, 2)``, None when none is cut. A station is cut when no
        lateral offset across ``[-l, l]`` keeps the hard clearance (H&W §6.3: no offset inside
        the corridor avoids the obstacle). ``seg0``: the segment the robot is on (default: the
        follower's)."""
        if path is None or len(path) < 2:
            return None
        p = self.params
        seg0 = min(self.follower.segment if seg0 is None else seg0, len(path) - 2)
        verts = path[seg0:]
        a = verts[0] + _clamped_projection(verts[0], verts[1], pose[:2])
        verts = np.concatenate([a[None], verts[1:]])
        hw_seg = np.minimum(hw[seg0:-1], hw[seg0 + 1 :])
        # only the segments that start within cut_check_m (+ 1 m, far above rounding) of the
        # path's arc length: the samples' summed steps below equal the arc length, so no
        # later sample is within cut_check_m, and the kept samples are the same
        end_m = np.cumsum(np.hypot(*np.diff(verts, axis=0).T))  # arc length at segment ends
        n_seg = int(np.searchsorted(end_m, p.cut_check_m + 1.0, side="right")) + 1
        verts = verts[: n_seg + 1]
        lin = np.linspace(-1.0, 1.0, p.cut_offsets)
        pts, cut = cut_probe(
            verts,
            hw_seg,
            float(grid.resolution_m),
            float(p.cut_check_m),
            lin,
            grid.clearance_m,
            float(grid.origin[0]),
            float(grid.origin[1]),
            float(grid.resolution_m),
            float(self.min_clearance_m),
        )
        return first_cut_stretch(pts, cut)

    def _go_around(self, t_s: float, pose: FloatArray, grid: ClearanceGrid) -> bool:
        """H&W §6.3 global replanning; True when a new path is being followed."""
        self._last_plan_t = t_s
        self._force_plan = False
        if self.mode == ROUTE and self._plan is not None:
            cut = self._cut_ahead(self._path, self._path_hw, grid, pose)
            if cut is None:  # blocked within the follower's probe, not as a whole corridor:
                cut = self._follower_block_points(pose)
            self._block_edges(t_s, cut)
            plan = self._route_plan(pose)
            if (
                plan is not None
                and not (set(plan.edges) & self._blocked_now())
                and self._cut_ahead(plan.xy, plan.half_width_m, grid, pose, seg0=0) is None
            ):
                self._set_route_path(plan)
                self.replans += 1
                self._event(t_s, "replan", f"another route, {plan.travel_time_s:.0f} s")
                return True
        base = self._plan.xy if self._plan is not None else self._path
        if base is None:
            return False
        self.plans += 1
        det = plan_around(base, pose[:2], grid, self.planner)
        if det is None:
            self._event(t_s, "replan_failed", "no way around the block on the costmap")
            return False
        off = _distance_to_polyline(det, base) > 0.01
        rejoin = int(np.flatnonzero(off)[-1]) + 1 if off.any() else 0
        base_hw = self._plan.half_width_m if self._plan is not None else self._path_hw
        near = np.argmin(np.hypot(*(det[:, None, :] - base[None, :, :]).transpose(2, 0, 1)), 1)
        hw = np.where(off, self.params.detour_half_width_m, base_hw[near])
        hw[: rejoin + 1] = np.minimum(hw[: rejoin + 1], self.params.detour_half_width_m)
        self.mode = DETOUR
        self._rejoin_seg = rejoin
        self._follow(det, hw)
        self.replans += 1
        length = float(np.sum(np.hypot(*np.diff(det[: rejoin + 1], axis=0).T)))
        self._event(t_s, "detour", f"grid A* around the block, {length:.1f} m to rejoin")
        return True

    def _follower_block_points(self, pose: FloatArray) -> FloatArray:
        """Where the follower saw its block: the path's centre line from the robot's
        projection up to its probe distance ahead."""
        assert self._path is not None
        seg0 = min(self.follower.segment, len(self._path) - 2)
        verts = self._path[seg0:]
        a = verts[0] + _clamped_projection(verts[0], verts[1], pose[:2])
        verts = np.concatenate([a[None], verts[1:]])
        pts, _ = samples_along(verts[:-1], verts[1:], 0.05, True)
        along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
        return pts[along <= self.params.follower.probe_ahead_m]

    def _blocked_now(self) -> set[tuple[int, int]]:
        assert self.route_memory is not None
        return set(self.route_memory.blocked)

    def _block_edges(self, t_s: float, cut: FloatArray) -> None:
        """Block the route edges (not joins) whose segment passes through the cut points."""
        assert self.route_memory is not None
        if cut is None or len(cut) == 0:
            return
        g = self.graph()
        segs = [e for e in g.edges if e.route_id != JOIN and math.isfinite(e.travel_time_s)]
        if not segs:
            return
        a = g.xy[[g.index[e.u] for e in segs]]
        b = g.xy[[g.index[e.v] for e in segs]]
        tol = 0.5 * (self.costmap.resolution_m if self.costmap is not None else 0.05)
        hit = []
        for k, e in enumerate(segs):
            if _distance_to_polyline(cut, np.stack([a[k], b[k]])).min() <= tol:
                hit.append((e.u, e.v))
        for edge in hit:
            self.route_memory.block(edge)
        if hit:
            self._event(t_s, "block", f"route edges {hit}")
        self._graph = None

    def _unblock_seen_free(
        self, t_s: float, pose: FloatArray, scan: Scan, grid: ClearanceGrid
    ) -> None:
        """Unblock every blocked edge whose centre line the scan sees free (module doc)."""
        assert self.route_memory is not None
        if not self.route_memory.blocked:
            return
        p = self.params
        g = self.graph()
        lp = se2.compose(pose, np.asarray(self.laser.mount_pose, dtype=np.float64))
        ranges = np.asarray(scan.ranges_m, dtype=np.float64)
        freed = []
        for u, v in sorted(self.route_memory.blocked):
            if u not in g.index or v not in g.index:
                continue
            a, b = g.position(u), g.position(v)
            pts, _ = samples_along(a[None], b[None], p.unblock_step_m, True)
            rel = pts - lp[:2]
            dist = np.hypot(*rel.T)
            if dist.max() > p.unblock_view_m:
                continue
            bearing = np.arctan2(rel[:, 1], rel[:, 0]) - lp[2]
            bearing = (bearing + math.pi) % (2.0 * math.pi) - math.pi
            beam = np.rint((bearing - self.laser.angle_min_rad) / self.laser.angle_increment_rad)
            if np.any(beam < 0) or np.any(beam >= self.laser.n_beams):
                continue
            r = ranges[beam.astype(np.int64)]
            with np.errstate(invalid="ignore"):
                seen = (r == np.inf) | (r >= dist + p.unblock_margin_m)
            if np.all(seen) and np.all(grid.clearance_at(pts) >= self.min_clearance_m):
                freed.append((u, v))
        for edge in freed:
            self.route_memory.unblock(edge)
        if freed:
            self._event(t_s, "unblock", f"seen free: {freed}")
            self._graph = None

    def _grid_to_goal(self, t_s: float, pose: FloatArray, grid: ClearanceGrid) -> None:
        """No route to the goal: grid A* on the costmap straight to it (keep the current path
        while one is followed)."""
        if self.mode in (DETOUR, GRID) and self._path is not None and not self.follower.done:
            return
        target_xy = self._target()[0]
        self.plans += 1
        start = grid.nearest_free(pose[:2], self.min_clearance_m, 0.5)
        path = None if start is None else self.planner.plan(start, target_xy, grid)
        if path is not None and self._leave_target_m() > 0.0:
            # at a loop's start the goal is here: a grid path alone has nowhere to go (route
            # A* and the bridged plan, which drive the route, found nothing)
            path = None
        if path is None and self._target()[2]:
            # a via point nothing reaches (in a block, say): on to the next one
            self._via_k += 1
            self._force_plan = True
            self._event(t_s, "via_skipped", f"via point {self._via_k} unreachable: skipped")
            return
        if path is None:
            if self.mode != GRID or self._path is not None:
                self._event(t_s, "no_path", "neither a route nor a grid path to the goal")
            self.mode = GRID
            self._plan = None
            self._path = None
            self.follower.set_path(None)
            return
        self.mode = GRID
        self._plan = None
        self._follow(path, np.full(len(path), self.params.detour_half_width_m))
        self._event(t_s, "grid_path", "no route to the goal: grid A* on the costmap")

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_graph"] = None  # caches
        state["_global"] = None
        state["_local"] = None
        return state


@compiled
def cut_probe(  # type: ignore[no-untyped-def]
    verts, hw_seg, step_m, max_along_m, lin, clearance, ox, oy, res, min_clearance_m
):
    """The cut check's stations (:meth:`NavigationStack._cut_ahead`, H&W §6.3): samples every
    ``step_m`` along the polyline ``verts (S+1, 2)`` (each segment from its
    start, end excluded) whose summed steps are within ``max_along_m``: their points
    ``(K, 2)`` and whether every lateral offset ``lin * l`` (``l = hw_seg`` of the segment,
    along its left normal) has less than ``min_clearance_m`` in the grid ``clearance``
    (cell ``(0, 0)`` centred at ``(ox, oy)``, ``res`` [m])."""
    n_seg = verts.shape[0] - 1
    counts = np.empty(n_seg, np.int64)
    lengths = np.empty(n_seg)
    total = 0
    for i in range(n_seg):
        lengths[i] = np.hypot(verts[i + 1, 0] - verts[i, 0], verts[i + 1, 1] - verts[i, 1])
        c = np.int64(np.ceil(lengths[i] / step_m))
        counts[i] = c if c > 1 else 1
        total += counts[i]
    pts = np.empty((total, 2))
    cut = np.zeros(total, np.bool_)
    h, w = clearance.shape
    k = 0
    along = 0.0
    px, py = 0.0, 0.0
    for i in range(n_seg):
        ax, ay = verts[i, 0], verts[i, 1]
        dx, dy = verts[i + 1, 0] - ax, verts[i + 1, 1] - ay
        length = lengths[i]
        nrm = length if length > 1e-12 else 1e-12
        nx, ny = -(dy / nrm), dx / nrm
        for m in range(counts[i]):
            t = m * step_m
            u = t / length if length > 0 else 0.0
            x, y = ax + u * dx, ay + u * dy
            if k > 0:
                along += np.hypot(x - px, y - py)
                if not along <= max_along_m:
                    return pts[:k], cut[:k]
            px, py = x, y
            pts[k, 0], pts[k, 1] = x, y
            all_cut = True
            for j in range(lin.shape[0]):
                off = lin[j] * hw_seg[i]
                r = np.int64(np.rint((y + off * ny - oy) / res))
                col = np.int64(np.rint((x + off * nx - ox) / res))
                r = min(max(r, 0), h - 1)
                col = min(max(col, 0), w - 1)
                if not clearance[r, col] < min_clearance_m:
                    all_cut = False
                    break
            cut[k] = all_cut
            k += 1
    return pts[:k], cut[:k]


def first_cut_stretch(pts: FloatArray, cut: NDArray[np.bool_]) -> FloatArray | None:
    """The first run of consecutive cut stations of ``pts``, None when none is cut."""
    idx = np.flatnonzero(cut)
    if idx.size == 0:
        return None
    gaps = np.flatnonzero(np.diff(idx) > 1)
    end = idx[gaps[0]] if gaps.size else idx[-1]
    return pts[idx[0] : end + 1]


def _clamped_projection(a: FloatArray, b: FloatArray, xy: ArrayLike) -> FloatArray:
    """The offset from ``a`` of the projection of ``xy`` onto segment ``a -> b``."""
    d = b - a
    u = float(np.clip(np.dot(np.asarray(xy, float)[:2] - a, d) / max(float(d @ d), 1e-18), 0, 1))
    return u * d
