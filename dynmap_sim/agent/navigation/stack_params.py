"""The navigation stack's parameters (:class:`StackParams`), with the reason for each default."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, field
from typing import Any

from pydantic import ValidationInfo, field_validator

from dynmap_sim.agent.control.collision_monitor import CollisionMonitorParams
from dynmap_sim.agent.control.corridor_follower import CorridorFollowerParams
from dynmap_sim.agent.control.recovery import RecoveryParams
from dynmap_sim.agent.navigation.routes import RouteMemoryParams
from dynmap_sim.agent.params import Int, NonNegative, ParamError, Positive, build, params_dataclass
from dynmap_sim.agent.planning.costmap import CostmapParams

#: The parts' parameter classes by :class:`StackParams` field.
PART_PARAMS: dict[str, type] = {
    "route_memory": RouteMemoryParams,
    "costmap": CostmapParams,
    "follower": CorridorFollowerParams,
    "monitor": CollisionMonitorParams,
    "recovery": RecoveryParams,
}


@params_dataclass("StackParams")
class StackParams:
    """Every choice of :class:`NavigationStack`, with the reason for its default (SI units)."""

    #: Cruise speed [m/s]: the corridor follower's and the prior route's ``v_max``. 0.35 m/s is
    #: the follower's (and the tour operator's) pace; H&W's Roomba drove ≈ 0.2-0.3 m/s.
    speed_mps: Positive = 0.35
    #: Corridor half-width ``l`` of the prior's route [m]: the route memory's width for
    #: recorded routes (a ≈ 1.2 m doorway minus a 0.4 m robot leaves ± 0.35 m).
    route_half_width_m: Positive = 0.35
    #: Hard clearance = robot radius + this [m], for the follower and grid A*: 5 cm covers
    #: the costmap's cell size, so no plan or offset touches an inflated obstacle cell.
    safety_margin_m: float = 0.05
    #: Grid A* prefers clearance robot radius + this [m] (the tour's 0.12 m plus a little):
    #: detours keep off furniture where there is room.
    preferred_margin_m: float = 0.15
    #: Planning period [s] (nav2's behaviour tree replans at 1 Hz): route A*, the cut check,
    #: the unblock check. Also the least time between two global replans on ``blocked``.
    replan_period_s: Positive = 1.0
    #: The goal is reached when the estimate is this close [m]: above the follower's vertex
    #: tolerance (0.12 m) so its stop at the path's end counts, below the env's 0.3 m so the
    #: true pose is within the env's tolerance with a 0.1 m localization error.
    goal_tolerance_m: Positive = 0.2
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
    loop_via_spacing_m: NonNegative = 5.0
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
    #: An obstacle mark cuts the corridor (blocks route edges, H&W §6.3) only once it has
    #: stood this long [s]: the paper cuts corridors on its long-term map, which has no
    #: dynamic points, so a person walking or pausing in a doorway is left to the reactive
    #: layer (slow down, stop, the recovery's wait). 3 s: a person crossing the corridor
    #: (0.7 m plus the inflation) at 0.55 m/s or faster is gone before, and a block first
    #: marked at the costmap's 2.5 m obstacle range lasts before a robot at 0.35 m/s is within
    #: the follower's 1.35 m reach (docs/tuning/navigation.md). 0: every mark cuts at once.
    block_persist_s: NonNegative = 3.0
    #: Lateral samples across the corridor of the cut check (odd: the centre line is one).
    cut_offsets: Int = 9
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
    #: The localizer counts as lost while the standard deviation of its position estimate
    #: (the larger axis of the covariance's x-y ellipse) exceeds this [m]: a robot uncertain
    #: by more than a doorway's width (≈ 1 m) cannot tell which doorway it stands in, so a
    #: goal it fails to reach then is put down to the localizer (the ``lost`` and
    #: ``unreachable`` events).
    lost_std_m: Positive = 1.0
    #: Tunables of the parts; the stack sets the robot radius, speed and hard clearance. A
    #: scenario gives them as tables (``[driver.params.follower]``): a mapping becomes the
    #: part's dataclass, an unknown key is an error that lists the known ones.
    route_memory: RouteMemoryParams = field(default_factory=RouteMemoryParams)
    costmap: CostmapParams = field(default_factory=CostmapParams)
    follower: CorridorFollowerParams = field(default_factory=CorridorFollowerParams)
    monitor: CollisionMonitorParams = field(default_factory=CollisionMonitorParams)
    recovery: RecoveryParams = field(default_factory=RecoveryParams)

    @field_validator(*PART_PARAMS, mode="before")
    @classmethod
    def _part(cls, value: Any, info: ValidationInfo) -> Any:
        """A part's table (a mapping) as the part's dataclass; its errors name the table."""
        if not isinstance(value, Mapping):
            return value
        owner = f"StackParams.{info.field_name}"
        fixed = sorted(set(value) & set(SET_BY_STACK.get(str(info.field_name), ())))
        if fixed:
            raise ParamError(
                f"{owner}: {', '.join(fixed)} set by the stack (the cruise speed, robot "
                "radius and safety_margin_m), not by the part's table"
            )
        return build(PART_PARAMS[str(info.field_name)], value, owner)

    def __post_init__(self) -> None:
        if self.cut_offsets < 1 or self.cut_offsets % 2 == 0:
            raise ValueError(f"cut_offsets must be odd and >= 1, got {self.cut_offsets}")


#: The fields of a part's parameters that the stack sets (from its own speed, the robot's
#: radius and the hard clearance) and so a scenario's table may not.
SET_BY_STACK: dict[str, tuple[str, ...]] = {
    "follower": ("speed_mps", "min_clearance_m"),
    "monitor": ("robot_radius_m",),
    "recovery": ("robot_radius_m",),
}


def params_except(params: object, *names: str) -> dict[str, Any]:
    """A params dataclass as keywords without ``names`` (set by the stack)."""
    return {k: v for k, v in asdict(params).items() if k not in names}  # type: ignore[call-overload]
