"""``tour``: a scripted operator who steers the robot along the world's route.

The papers' robots were driven along a fixed route by a human operator (B&D §5; H&W §7). This
driver plays that operator. It sees the truth — the robot's true pose, the people, and the
current geometry of the world — which is fine because it is part of the *simulation*, not of
the agent; the localizers never see any of it.

* Planning: at the start of a run (and after a kidnapping) it plans a collision-free polyline
  through the route's waypoints on a clearance grid of the current snapshot
  (:mod:`.grid_planner`). A leg whose straight line is blocked by the schedule becomes a
  *detour*; a waypoint that is inside an obstacle or unreachable is *skipped*. Both are
  recorded as events.
* Following: pure pursuit (Coulter 1992) with a carrot on the current segment that never
  passes the segment's end, so corners are not cut; large heading errors turn on the spot.
* Speed: cruise speed (~0.35 m/s) reduced near obstacles; it stops and waits while a person
  stands in its way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim import se2
from dynmap_sim.agent.planning.grid_astar import GridPlanner, build_clearance_grid
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


@dataclass
class TourParams:
    """Tunables of the operator (SI units)."""

    speed_mps: float = 0.35
    max_omega_radps: float = 0.8
    lookahead_m: float = 0.35
    turn_in_place_rad: float = 0.6
    goal_tolerance_m: float = 0.12
    robot_radius_m: float = 0.2
    safety_margin_m: float = 0.05
    clearance_m: float = 0.12
    slow_down_m: float = 0.35
    wait_for_people: bool = True
    person_stop_m: float = 0.9
    person_slow_m: float = 1.8
    person_cone_rad: float = 1.0
    snap_waypoint_m: float = 0.4
    grid_resolution_m: float = 0.05
    backoff_s: float = 1.0
    backoff_mps: float = 0.1
    dt_s: float = 0.1


@dataclass
class _Plan:
    vertices: FloatArray  # (K, 2) path polyline
    waypoint_of_vertex: NDArray[np.int64]  # route waypoint index each vertex leads towards


@dataclass
class TourDriver:
    """The scripted operator. Call :meth:`begin_run`, then :meth:`act` every step."""

    route: FloatArray
    params: TourParams = field(default_factory=TourParams)
    events: list[tuple[int, float, str, str]] = field(default_factory=list)
    skipped_waypoints: int = 0
    _planner: GridPlanner | None = None
    _plan: _Plan | None = None
    _seg: int = 0
    _waiting: bool = False
    _step: int = 0
    _backoff: int = 0

    # ----------------------------------------------------------------- planning
    def begin_run(self, geometry: Any, start_pose: FloatArray) -> None:
        """Plan the run on the current world ``geometry`` (a GeometryView) from the start."""
        self.events = []
        self.skipped_waypoints = 0
        self._step = 0
        self._waiting = False
        self._backoff = 0
        p = self.params
        seg = np.asarray(geometry.segments, dtype=np.float64).reshape(-1, 4)
        circles = np.asarray(geometry.circles, dtype=np.float64).reshape(-1, 3)
        circle_class = np.asarray(geometry.circle_class).ravel()
        static_circles = circles[circle_class != BeamClass.PERSON]
        grid = build_clearance_grid(seg, static_circles, resolution_m=p.grid_resolution_m)
        hard = p.robot_radius_m + p.safety_margin_m
        self._planner = GridPlanner(grid, hard, p.robot_radius_m + p.clearance_m)
        self._replan(np.asarray(start_pose, dtype=np.float64), 0, t_s=0.0)

    def _replan(self, pose: FloatArray, first_wp: int, t_s: float) -> None:
        assert self._planner is not None
        planner = self._planner
        here = planner.nearest_free(pose[:2], 1.0)
        if here is None:
            here = pose[:2].copy()
        verts = [here]
        owner = [first_wp]
        for k in range(first_wp, len(self.route)):
            wp = self.route[k]
            goal = planner.nearest_free(wp, self.params.snap_waypoint_m)
            if goal is None:
                self._skip(k, t_s, "waypoint inside an obstacle")
                continue
            leg = planner.plan(verts[-1], goal)
            if leg is None:
                self._skip(k, t_s, "waypoint unreachable")
                continue
            if len(leg) > 2:
                self.events.append(
                    (self._step, t_s, "detour", f"waypoint {k}: {len(leg) - 2} extra vertices")
                )
            verts.extend(leg[1:])
            owner.extend([k] * (len(leg) - 1))
        self._plan = _Plan(np.array(verts).reshape(-1, 2), np.array(owner, dtype=np.int64))
        self._seg = 0

    def _skip(self, k: int, t_s: float, why: str) -> None:
        self.skipped_waypoints += 1
        self.events.append((self._step, t_s, "skip_waypoint", f"waypoint {k}: {why}"))

    def free_place_near(self, xy: FloatArray, max_dist_m: float = 1.0) -> FloatArray | None:
        """The nearest place to ``xy`` where the robot fits (this run's grid), or None."""
        if self._planner is None:
            return None
        return self._planner.nearest_free(np.asarray(xy, dtype=np.float64), max_dist_m)

    def end_run(self) -> None:
        """Drop the run's grid and plan (they are rebuilt next run; keeps checkpoints small)."""
        self._planner = None
        self._plan = None

    def notify_teleport(self, pose: FloatArray, t_s: float) -> None:
        """The true robot was moved (kidnapping): replan from there to the rest of the route."""
        assert self._plan is not None
        nxt = int(self._plan.waypoint_of_vertex[min(self._seg + 1, len(self._plan.vertices) - 1)])
        self._replan(np.asarray(pose, dtype=np.float64), nxt, t_s)

    # ----------------------------------------------------------------- driving
    @property
    def done(self) -> bool:
        return self._plan is None or self._seg >= len(self._plan.vertices) - 1

    def act(
        self, pose: FloatArray, people: FloatArray, t_s: float, bumped: bool = False
    ) -> NDArray[np.float32]:
        """The command ``[v_mps, omega_radps]`` for the true ``pose`` and people ``(P, >=2)``.

        ``bumped``: the bumper was pressed in the last step; the operator backs off for
        ``backoff_s`` before going on (a person walked into the robot, say).
        """
        self._step += 1
        p = self.params
        if self.done:
            return np.zeros(2, dtype=np.float32)
        if bumped and self._backoff == 0:
            self._backoff = max(1, int(round(p.backoff_s / p.dt_s)))
            self.events.append((self._step, t_s, "bump", "bumper pressed; backing off"))
        if self._backoff > 0:
            self._backoff -= 1
            return np.array([-p.backoff_mps, 0.0], dtype=np.float32)
        assert self._plan is not None and self._planner is not None
        verts = self._plan.vertices
        x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
        # advance past reached vertices
        n_seg = len(verts) - 1
        while (
            self._seg < n_seg
            and math.hypot(verts[self._seg + 1, 0] - x, verts[self._seg + 1, 1] - y)
            < p.goal_tolerance_m
        ):
            self._seg += 1
        if self.done:
            return np.zeros(2, dtype=np.float32)
        ax, ay = verts[self._seg]
        bx, by = verts[self._seg + 1]
        abx, aby = bx - ax, by - ay
        len_ab = math.hypot(abx, aby)
        u = min(max(((x - ax) * abx + (y - ay) * aby) / max(len_ab * len_ab, 1e-12), 0.0), 1.0)
        s = min(u * len_ab + p.lookahead_m, len_ab) / max(len_ab, 1e-12)
        dx, dy = ax + abx * s - x, ay + aby * s - y
        # the carrot in the robot frame
        c, sn = math.cos(th), math.sin(th)
        rx, ry = c * dx + sn * dy, -sn * dx + c * dy
        alpha = math.atan2(ry, rx)
        dist = math.hypot(rx, ry)
        if abs(alpha) > p.turn_in_place_rad:
            return np.array([0.0, math.copysign(p.max_omega_radps, alpha)], dtype=np.float32)
        # speed: slower near obstacles, near the final goal, and for people ahead
        clear = float(self._planner.grid.clearance_at(np.array([x, y])))
        hard = self._planner.min_clearance_m
        v = p.speed_mps * min(max((clear - hard) / p.slow_down_m, 0.35), 1.0)
        v *= min(max(1.0 - abs(alpha) / p.turn_in_place_rad, 0.3), 1.0)
        v = min(v, max(0.08, 1.2 * dist)) if self._seg == n_seg - 1 else v
        if len(people):
            v *= self._people_factor(pose, people, t_s)
        elif self._waiting:
            self._waiting = False
        if v == 0.0:
            return np.zeros(2, dtype=np.float32)
        # pure pursuit: curvature 2 sin(alpha) / L_d towards the carrot
        kappa = 2.0 * math.sin(alpha) / max(dist, 1e-3)
        w_max = p.max_omega_radps
        omega = min(max(max(v, 0.1) * kappa, -w_max), w_max)
        return np.array([v, omega], dtype=np.float32)

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
