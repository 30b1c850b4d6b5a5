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
   corridor is free) or the corridor is cut within ``cut_check_m`` ahead (at a replan), and
   the obstacles that cut it have stood for ``block_persist_s`` (the paper cuts corridors on
   its long-term map, which holds no dynamic points: a person passing by is left to the
   follower, the monitor and the recovery's wait), the route edges of the cut stretch are
   **blocked** in the route memory (infinite cost), route A* is asked again (another route
   may exist, e.g. the detour recorded on an earlier day), and failing that a **detour** is
   planned with grid A* on the costmap's clearance around the block back onto the path
   (:func:`~dynmap_sim.agent.planning.grid_astar.plan_around`). The robot drives it (a detour
   is planned again round whatever cuts it, as it is seen); the route memory records it as a
   new route joined to the graph; once the robot is back on the path, route planning takes
   over again. A blocked edge is **unblocked** when the scan sees its centre line free (every
   point of it in view, a beam passing beyond it, and no lasting obstacle there), or when the
   robot drives it (the route memory does that).
6. **Recovery** (:class:`~dynmap_sim.agent.control.recovery.Recovery`): stuck detection on the
   odometry pose, then wait, back up, replan (with the costmap's obstacle layer cleared, nav2's
   first recovery), and a recorded give-up (:attr:`NavigationStack.gave_up`).
7. **Collision monitor** (:class:`~dynmap_sim.agent.control.collision_monitor.
   CollisionMonitor`): every command, the recovery's included, is filtered by the raw scan in
   the robot frame, so a wrong estimate or a controller bug cannot drive into an obstacle.

A route may be driven against its direction at ``RouteMemoryParams.reverse_cost_factor``
times its travel time (a route that returns through a doorway it passed), never back over a
loop's via point already passed (the loop is closed forwards), and a block holds both ways.
When the recovery gives up, an ``unreachable`` event says why the goal was not reached
(:attr:`NavigationStack.unreachable_cause`): no way exists on the routes or the costmap, the
localizer is lost (its position std above ``lost_std_m``; ``lost`` and ``found`` events mark
when), or the robot was stuck on a way that exists.

The run ends for the stack when the estimate is within ``goal_tolerance_m`` of the goal
(:attr:`NavigationStack.done`); a route that ends where it starts (a loop) is driven through
via points (every ``loop_via_spacing_m`` of it, passed within ``via_tolerance_m`` or once
the robot is tracked beyond them) before its end counts, and the end only once the robot
has been ``goal_arm_m`` away from it.
Everything here sees only what the agent sees: estimate, scan, odometry, the prior.

Time: ``t_s`` of :meth:`NavigationStack.step` is the time within the run's day [s] (seconds
since midnight, or since the run started: anything below a day); the route memory's clock is
``prior.day * 86400 + t_s``, so its forgetting ages count in days as the calendar does.

What the stack follows is its mode (:class:`NavMode`): a route plan, a detour around a block,
a grid path when no route reaches the target, or nothing once the goal is reached or the
recovery gave up. The parts live in their own modules: route planning and the targets
(:mod:`.route_planning`), block handling (:mod:`.block_handling`), the parameters
(:mod:`.stack_params`).

The stack pickles (the experiment runner checkpoints it after every run): plain data, no
lambdas; the cached route graph is dropped.
"""

from __future__ import annotations

import enum
import math
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.control.collision_monitor import CollisionMonitor
from dynmap_sim.agent.control.corridor_follower import CorridorFollower
from dynmap_sim.agent.control.recovery import Recovery
from dynmap_sim.agent.grid import OccupancyGrid
from dynmap_sim.agent.navigation.block_handling import BlockHandling
from dynmap_sim.agent.navigation.route_memory import RouteMemory
from dynmap_sim.agent.navigation.route_planning import RoutePlanning, Targets
from dynmap_sim.agent.navigation.route_tracking import RoutePosition
from dynmap_sim.agent.navigation.stack_params import SET_BY_STACK, StackParams, params_except
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid
from dynmap_sim.agent.planning.costmap import Costmap
from dynmap_sim.agent.planning.grid_astar import GridAStar
from dynmap_sim.agent.planning.route_astar import PlannedPath
from dynmap_sim.agent.planning.route_graph import RouteGraph, both_ways
from dynmap_sim.types import LaserSpec, Odometry, PoseEstimate, Prior, Scan

__all__ = ["DAY_S", "NavMode", "NavigationStack", "PlanRequest", "StackParams"]

FloatArray = NDArray[np.float64]

#: Seconds per day: the route memory's clock is ``prior.day * DAY_S + t_s``.
DAY_S = 86_400.0

#: Why a goal was not reached (:attr:`NavigationStack.unreachable_cause`): no way exists on
#: the routes or the costmap, the localizer is lost, or the robot was stuck on a way that
#: exists (the recovery gave up).
NO_WAY, LOST, STUCK = "no_way", "lost", "stuck"


def position_std_m(cov: FloatArray) -> float:
    """The standard deviation [m] along the larger axis of a pose covariance's x-y ellipse
    (the square root of the 2 x 2 block's largest eigenvalue); inf when it is not finite."""
    a, b, c = float(cov[0, 0]), float(cov[0, 1]), float(cov[1, 1])
    top = 0.5 * (a + c) + math.hypot(0.5 * (a - c), b)
    return math.sqrt(max(top, 0.0)) if math.isfinite(top) else math.inf


class NavMode(enum.Enum):
    """What the stack follows (module doc)."""

    #: a route A* plan (H&W §6.2)
    ROUTE = "route"
    #: a grid detour around a block back onto the route plan (§6.3)
    DETOUR = "detour"
    #: a grid path to the target when the route graph has none (or nothing, when neither is)
    GRID = "grid"
    #: the goal is reached: the stack commands zero
    DONE = "done"
    #: the recovery gave up: the stack commands zero
    GAVE_UP = "gave_up"


class PlanRequest(enum.Enum):
    """Whether the next step must plan before its period is due, and why."""

    #: at the planning period only
    NONE = "none"
    #: at the next step (a via point passed or skipped)
    FORCED = "forced"
    #: at the next step, asked by the recovery (its replan behaviour)
    RECOVERY = "recovery"


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
        self.routing = RoutePlanning(p, self.min_clearance_m, self.planner)
        self.blocks = BlockHandling(p, laser, self.min_clearance_m, self.planner)
        #: the goal and a loop's via points (kept across runs)
        self.targets = Targets(p)
        #: the long-term route memory (None until the first :meth:`begin_run`)
        self.route_memory: RouteMemory | None = None
        #: the costmap of the run in progress (None before the first :meth:`begin_run`)
        self.costmap: Costmap | None = None
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
            **params_except(p.follower, *SET_BY_STACK["follower"]),
        )
        self.monitor = CollisionMonitor(
            self.laser, r, **params_except(p.monitor, *SET_BY_STACK["monitor"])
        )
        self.recovery = Recovery(
            self.laser, r, **params_except(p.recovery, *SET_BY_STACK["recovery"])
        )
        #: global replans: paths replaced because the old one was blocked or cut (H&W §6.3)
        self.replans = 0
        #: plans computed (route A* at ``replan_period_s`` and every detour)
        self.plans = 0
        #: control steps of the run
        self.steps = 0
        #: what the stack follows (:class:`NavMode`)
        self.mode = NavMode.ROUTE
        self._request = PlanRequest.NONE
        #: why the goal was not reached (:data:`NO_WAY`, :data:`LOST`, :data:`STUCK`), None
        #: while it may be
        self.unreachable_cause: str | None = None
        #: why no way to the goal exists, from the last planning failure that found none
        #: (cleared by a plan that has one)
        self._no_way: str | None = None
        self._lost_std_m: float | None = None  # the estimate's std while the localizer is lost
        self._events: list[tuple[float, str, str]] = []
        self._plan: PlannedPath | None = None  # the route plan (route mode; base of a detour)
        self._path: FloatArray | None = None  # what the follower follows
        self._path_hw = np.zeros(0)
        self._rejoin_seg = 0  # detour: follower segment from which the robot is back on the path
        self._last_plan_t: float | None = None
        self.targets.new_run()
        #: the route position of the last step (H&W §5.1), None off the corridors
        self._route_pos: RoutePosition | None = None
        self._day_s = 0.0
        self._costmap_t: float | None = None
        self._global: ClearanceGrid | None = None  # the costmap's clearance at the last plan
        #: the clearance of the lasting obstacles at the last plan (the cut check's map),
        #: computed on first use (:meth:`_lasting_grid`)
        self._lasting: ClearanceGrid | None = None
        self._local: tuple[tuple[float, float], ClearanceGrid] | None = None  # (centre, grid)
        self._last_t = 0.0

    @property
    def done(self) -> bool:
        """True once the goal is reached (the stack then commands zero)."""
        return self.mode is NavMode.DONE

    @property
    def gave_up(self) -> bool:
        """True once the recovery gave up (the stack then commands zero)."""
        return self.recovery.gave_up

    @property
    def goal_xy(self) -> FloatArray | None:
        """The run's goal [m]: the end of the prior's route."""
        return self.targets.goal_xy

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
            self.targets.set_route(next(iter(self.route_memory.routes.values())), route[-1])
        else:
            self.route_memory.reset_run()
            if route is not None:
                self.targets.move_goal(route[-1])
        costmap_params = self.params.costmap
        if costmap_params.footprint_clear_radius_m != self.robot_radius_m:
            costmap_params = replace(costmap_params, footprint_clear_radius_m=self.robot_radius_m)
        self.costmap = Costmap.for_prior(prior, costmap_params)
        if self._pending_grid is not None:
            self.costmap.set_static_grid(self._pending_grid)
            self._pending_grid = None
        self._graph = None
        self._event(0.0, "begin_run", f"day {prior.day} run {prior.run}")

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
            keep = self.targets.nodes(g)
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
        self._check_lost(t_s, estimate)
        if self._costmap_t is None or t_s - self._costmap_t >= p.costmap_period_s - 1e-9:
            self.costmap.update(pose, scan, self.laser, t_s)
            self._costmap_t = t_s
            self._local = None
        self._route_pos = self.route_memory.observe(pose, self._day_s + t_s)
        self._check_goal(t_s, pose)
        if self.mode in (NavMode.DONE, NavMode.GAVE_UP):
            return self.monitor.filter(stop, scan, t_s)
        due = self._last_plan_t is None or t_s - self._last_plan_t >= p.replan_period_s
        if self._request is not PlanRequest.NONE or due or self._global is None:
            self._refresh_grids()
            self._plan_step(t_s, pose, self._global, scan)
        grid = self._local_clearance(pose)
        cmd = self.follower.command(pose, grid)
        if self.follower.blocked and self._may_replan(t_s):
            self._event(t_s, "blocked", "no free offset inside the corridor")
            self._refresh_grids()
            if self._go_around(t_s, pose, self._global):
                grid = self._local_clearance(pose)
                cmd = self.follower.command(pose, grid)
        act = self.recovery.step(t_s, odom.pose, cmd, self.follower.blocked, scan)
        if act is not None:
            if act.kind == "give_up":
                self.mode = NavMode.GAVE_UP
                self._event(t_s, "gave_up", act.detail)
                self._unreachable(t_s, act.detail, pose)
                cmd = stop
            elif act.kind == "replan":
                if self.params.clear_costmap_on_replan:
                    self.costmap.clear_obstacles()
                self._request = PlanRequest.RECOVERY
            elif act.command is not None:
                cmd = act.command
        return self.monitor.filter(cmd, scan, t_s)

    def _check_goal(self, t_s: float, pose: FloatArray) -> None:
        """Arm the goal once the robot is ``goal_arm_m`` away from it, count the via points
        passed, and end the run's driving when the goal is reached."""
        targets = self.targets
        assert targets.goal_xy is not None
        gx, gy = targets.goal_xy.tolist()
        to_goal = float(np.hypot(float(pose[0]) - gx, float(pose[1]) - gy))
        if not targets.armed and to_goal > self.params.goal_arm_m:
            targets.armed = True
        k0 = targets.via_k
        if targets.pass_vias(pose, self._route_pos):
            n = len(targets.vias)
            self._event(t_s, "via", f"via points {k0 + 1}-{targets.via_k} of {n} passed")
            self._force()
        if (
            self.mode is not NavMode.DONE
            and targets.armed
            and targets.at_last()
            and to_goal <= self.params.goal_tolerance_m
        ):
            self.mode = NavMode.DONE
            self._event(t_s, "goal", f"{to_goal:.2f} m from the goal")

    def _check_lost(self, t_s: float, estimate: PoseEstimate) -> None:
        """Record when the localizer gets lost (its position std above ``lost_std_m``) and
        when it is found again (``lost`` / ``found`` events)."""
        cov = np.asarray(estimate.cov, dtype=np.float64)
        std = position_std_m(cov) if cov.shape == (3, 3) else 0.0
        lost = std > self.params.lost_std_m
        if lost and self._lost_std_m is None:
            self._event(t_s, "lost", f"the localizer's position std is {std:.2f} m")
        elif not lost and self._lost_std_m is not None:
            self._event(t_s, "found", f"the localizer's position std is {std:.2f} m again")
        self._lost_std_m = std if lost else None

    def _unreachable(self, t_s: float, stuck_detail: str, pose: FloatArray) -> None:
        """The run ends without the goal: an ``unreachable`` event that says why in words,
        ending with the cause in brackets (``(no_way)``, ``(lost)``, ``(stuck)``) for the
        results' summary; ``pose`` is the estimate (where a stuck robot stands)."""
        if self._lost_std_m is not None:
            self.unreachable_cause = LOST
            detail = (
                f"the localizer is lost: its position std is {self._lost_std_m:.2f} m "
                f"(> {self.params.lost_std_m:.2f} m)"
            )
        elif self._no_way is not None:
            self.unreachable_cause = NO_WAY
            detail = f"no way to the goal exists: {self._no_way}"
        else:
            self.unreachable_cause = STUCK
            detail = (
                f"stuck for {self.stuck_s:.0f} s near ({float(pose[0]):.1f}, "
                f"{float(pose[1]):.1f}) on the way to the goal: {stuck_detail}"
            )
        self._event(t_s, "unreachable", f"{detail} ({self.unreachable_cause})")

    def _force(self) -> None:
        """Plan at the next step (a recovery's pending replan stays one)."""
        if self._request is PlanRequest.NONE:
            self._request = PlanRequest.FORCED

    # ------------------------------------------------------------------ planning
    def _refresh_grids(self) -> None:
        """The costmap's clearance for planning; the clearance of its lasting obstacles is
        computed again when next needed (:meth:`_lasting_grid`)."""
        assert self.costmap is not None
        self._global = self.costmap.clearance()
        self._local = None
        self._lasting = None

    def _lasting_grid(self) -> ClearanceGrid:
        """The clearance of the lasting obstacles (``block_persist_s``) at this step, for the
        cut and unblock checks: a distance transform of its own, computed on first use after
        :meth:`_refresh_grids` (most plans never need it, see :meth:`_cut_ahead`)."""
        assert self.costmap is not None
        if self._lasting is None:
            self._lasting = self.costmap.persistent_clearance(
                self._last_t, self.params.block_persist_s
            )
        return self._lasting

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
            or self._request is not PlanRequest.NONE
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
        assert self.route_memory is not None and self.targets.goal_xy is not None
        self._graph = None
        if ignore_blocks:
            blocked, self.route_memory.blocked = self.route_memory.blocked, set()
            try:
                g = self.route_memory.graph()
            finally:
                self.route_memory.blocked = blocked
        else:
            g = self.graph()
        plan, n = self.routing.route_plan(g, pose, self._route_pos, self.targets)
        self.plans += n
        return plan

    def _plan_step(self, t_s: float, pose: FloatArray, grid: ClearanceGrid, scan: Scan) -> None:
        """The periodic planning step: unblock what is seen free, then keep, refresh or
        replace the path (module doc)."""
        request, self._request = self._request, PlanRequest.NONE
        forced = request is not PlanRequest.NONE
        self._last_plan_t = t_s
        self._unblock_seen_free(t_s, pose, scan)
        if self.mode is NavMode.DETOUR and self._keep_detour(t_s, pose, grid, request):
            return
        plan = self._route_plan(pose)
        if plan is not None:
            self._no_way = None
        if plan is None and self.route_memory is not None and self.route_memory.blocked:
            # every route is blocked: drive the route up to the block and go around it there
            # (H&W §6.3); the blocks stay, so a detour driven now becomes a route
            plan = self._route_plan(pose, ignore_blocks=True)
            if plan is not None and self.mode is not NavMode.ROUTE:
                self._event(t_s, "through_block", "no unblocked route: the route up to the block")
        bridged = False
        if plan is None:
            # the route graph cannot reach the goal: bridge its dead ends on the costmap
            plan, n = self.routing.bridged_plan(self.graph(), pose, grid, self.targets)
            self.plans += n
            bridged = plan is not None
            if bridged:
                self._no_way = None
        if plan is None:
            self._grid_to_goal(t_s, pose, grid)
            return
        if (
            self.mode is not NavMode.ROUTE
            or not self._same_plan(plan)
            or self.follower.done
            or forced
        ):
            self._set_route_path(plan)
            if bridged:
                self._event(
                    t_s, "bridge", "no route to the goal: routes and grid A* across the gap"
                )
        if self._cut_ahead(self._path, self._path_hw, pose) is not None:
            self._event(t_s, "cut", "the corridor ahead is cut on the costmap")
            self._go_around(t_s, pose, grid)

    def _keep_detour(
        self, t_s: float, pose: FloatArray, grid: ClearanceGrid, request: PlanRequest
    ) -> bool:
        """In a detour: True while it is followed on (re-planned around a block still there
        at the recovery's request, or when cut ahead); False once the robot is back on the
        route (or a forced plan replaces the detour)."""
        if (
            request is PlanRequest.RECOVERY
            and self.params.keep_detour_on_recovery
            and self.route_memory is not None
            and self.route_memory.blocked
            and self._go_around(t_s, pose, grid)
        ):
            return True
        if request is PlanRequest.NONE and self._path is not None:
            if self.follower.segment < self._rejoin_seg and not self.follower.done:
                if self._cut_ahead(self._path, self._path_hw, pose, lasting=False) is not None:
                    self._event(t_s, "cut", "the detour ahead is cut")
                    self._go_around(t_s, pose, grid)
                return True
            self._event(t_s, "rejoined", "back on the route")
        return False

    def _same_plan(self, plan: PlannedPath) -> bool:
        """Whether ``plan`` goes on through the same nodes as the path being followed."""
        if self._plan is None:
            return False
        new = plan.node_ids[1:]
        old = self._plan.node_ids
        return 0 < len(new) <= len(old) and tuple(old[len(old) - len(new) :]) == tuple(new)

    def _set_route_path(self, plan: PlannedPath) -> None:
        self.mode = NavMode.ROUTE
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
        pose: FloatArray,
        seg0: int | None = None,
        lasting: bool = True,
    ) -> FloatArray | None:
        """:meth:`.BlockHandling.cut_ahead` from segment ``seg0`` (default: the follower's)
        on the lasting obstacles (``block_persist_s``: a route's corridor, whose cut blocks
        route edges), or with ``lasting=False`` on every mark (a detour's, re-planned round
        whatever the robot sees as it drives into the unmapped)."""
        assert self._global is not None
        seg = self.follower.segment if seg0 is None else seg0
        cut = self.blocks.cut_ahead(path, hw, self._global, pose, seg)
        if cut is None or not lasting:
            return cut
        # the lasting obstacles are some of all the marks: their clearance is nowhere
        # smaller, so a corridor cut by them is cut on the whole costmap too
        return self.blocks.cut_ahead(path, hw, self._lasting_grid(), pose, seg)

    # ------------------------------------------------------------------ blocks (H&W §6.3)
    def _go_around(self, t_s: float, pose: FloatArray, grid: ClearanceGrid) -> bool:
        """H&W §6.3 global replanning; True when a new path is being followed: the route
        edges of the block are blocked and route A* asked for another route; failing that, a
        grid detour around the block back onto the path."""
        self._last_plan_t = t_s
        self._request = PlanRequest.NONE
        if self.mode is NavMode.ROUTE and self._plan is not None:
            cut = self._cut_ahead(self._path, self._path_hw, pose)
            if cut is None:  # blocked within the follower's probe, not as a whole corridor:
                assert self._path is not None
                cut = self.blocks.follower_block_points(self._path, self.follower.segment, pose)
                if np.all(self._lasting_grid().clearance_at(cut) >= self.min_clearance_m):
                    cut = None  # by obstacles passing by: a grid detour, no route edge blocked
            self._block_edges(t_s, cut)
            plan = self._route_plan(pose)
            assert self.route_memory is not None
            if (
                plan is not None
                and not (set(plan.edges) & both_ways(self.route_memory.blocked))
                and self._cut_ahead(plan.xy, plan.half_width_m, pose, seg0=0) is None
            ):
                self._set_route_path(plan)
                self._no_way = None
                self.replans += 1
                self._event(t_s, "replan", f"another route, {plan.travel_time_s:.0f} s")
                return True
        base = self._plan.xy if self._plan is not None else self._path
        if base is None:
            return False
        self.plans += 1
        base_hw = self._plan.half_width_m if self._plan is not None else self._path_hw
        found = self.blocks.detour(base, base_hw, pose, grid)
        if found is None:
            self._event(t_s, "replan_failed", "no way around the block on the costmap")
            if self._cut_ahead(self._path, self._path_hw, pose) is not None:
                # a lasting block and no way round it (a person in the way is no such block)
                self._no_way = "no way around the block on the costmap"
            return False
        self._no_way = None
        det, hw, rejoin, length = found
        self.mode = NavMode.DETOUR
        self._rejoin_seg = rejoin
        self._follow(det, hw)
        self.replans += 1
        self._event(t_s, "detour", f"grid A* around the block, {length:.1f} m to rejoin")
        return True

    def _block_edges(self, t_s: float, cut: FloatArray | None) -> None:
        """Block the route edges (not joins) whose segment passes through the cut points."""
        assert self.route_memory is not None
        if cut is None or len(cut) == 0:
            return
        tol = 0.5 * (self.costmap.resolution_m if self.costmap is not None else 0.05)
        hit = self.blocks.edges_through(self.graph(), cut, tol)
        if hit is None:
            return
        for edge in hit:
            self.route_memory.block(edge)
        if hit:
            self._event(t_s, "block", f"route edges {hit}")
        self._graph = None

    def _unblock_seen_free(self, t_s: float, pose: FloatArray, scan: Scan) -> None:
        """Unblock every blocked edge whose centre line the scan sees free
        (:meth:`.BlockHandling.seen_free`, on the lasting obstacles)."""
        assert self.route_memory is not None
        if not self.route_memory.blocked:
            return
        freed = self.blocks.seen_free(
            self.graph(), self.route_memory.blocked, pose, scan, self._lasting_grid()
        )
        for edge in freed:
            self.route_memory.unblock(edge)
        if freed:
            self._event(t_s, "unblock", f"seen free: {freed}")
            self._graph = None

    def _grid_to_goal(self, t_s: float, pose: FloatArray, grid: ClearanceGrid) -> None:
        """No route to the goal: grid A* on the costmap straight to it (keep the current path
        while one is followed)."""
        if (
            self.mode in (NavMode.DETOUR, NavMode.GRID)
            and self._path is not None
            and not self.follower.done
        ):
            return
        target_xy, _, is_via = self.targets.target()
        self.plans += 1
        start = grid.nearest_free(pose[:2], self.min_clearance_m, 0.5)
        path = None if start is None else self.planner.plan(start, target_xy, grid)
        if path is not None and self.targets.leave_target_m() > 0.0:
            # at a loop's start the goal is here: a grid path alone has nowhere to go (route
            # A* and the bridged plan, which drive the route, found nothing)
            path = None
        if path is None and is_via:
            # a via point nothing reaches (in a block, say): on to the next one
            self.targets.via_k += 1
            self._force()
            self._event(t_s, "via_skipped", f"via point {self.targets.via_k} unreachable: skipped")
            return
        if path is None:
            if self.mode is not NavMode.GRID or self._path is not None:
                self._event(t_s, "no_path", "neither a route nor a grid path to the goal")
            self._no_way = "neither a route nor a grid path on the costmap leads there"
            self.mode = NavMode.GRID
            self._plan = None
            self._path = None
            self.follower.set_path(None)
            return
        self.mode = NavMode.GRID
        self._plan = None
        self._no_way = None
        self._follow(path, np.full(len(path), self.params.detour_half_width_m))
        self._event(t_s, "grid_path", "no route to the goal: grid A* on the costmap")

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_graph"] = None  # caches
        state["_global"] = None
        state["_lasting"] = None
        state["_local"] = None
        return state
