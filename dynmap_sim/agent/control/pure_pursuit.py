"""``pure-pursuit``: regulated pure pursuit along a polyline (Coulter 1992).

The carrot is ``lookahead_m`` ahead of the robot's projection on the current segment and
never passes the segment's end, so corners are not cut; a heading error above
``turn_in_place_rad`` turns on the spot. The forward speed is regulated like nav2's Regulated
Pure Pursuit: by the clearance at the robot (slower within ``slow_down_m`` of the hard
clearance), by the heading error, on the approach to the path's end, and by an external
speed limit; the turn rate follows the pure-pursuit curvature ``2 sin(alpha) / L_d``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.control.controller import Controller, SpeedLimit, register_controller
from dynmap_sim.agent.params import params_dataclass
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid

FloatArray = NDArray[np.float64]


@params_dataclass("pure-pursuit")
class PurePursuitParams:
    """Tunables (SI units). The speed floors keep the robot moving where a pure product of
    the regulation factors would stall it."""

    #: cruise speed [m/s]
    speed_mps: float = 0.35
    max_omega_radps: float = 0.8
    lookahead_m: float = 0.35
    turn_in_place_rad: float = 0.6
    goal_tolerance_m: float = 0.12
    #: the hard clearance (robot radius + safety margin) [m]
    min_clearance_m: float = 0.25
    #: full speed from this far beyond the hard clearance on [m]
    slow_down_m: float = 0.35
    #: speed floor of the clearance regulation (fraction of ``speed_mps``)
    clearance_speed_floor: float = 0.35
    #: speed floor of the heading regulation (fraction)
    heading_speed_floor: float = 0.3
    #: on the last segment: at most ``approach_gain_per_s`` x distance to the carrot [m/s] ...
    approach_gain_per_s: float = 1.2
    #: ... but at least this [m/s]
    approach_min_speed_mps: float = 0.08
    #: the turn rate is ``max(v, this) * curvature`` [m/s], so slow driving still steers
    min_steering_speed_mps: float = 0.1


@register_controller("pure-pursuit")
class PurePursuit(Controller):
    """Regulated pure pursuit (module doc); ``params``: :class:`PurePursuitParams` fields."""

    def __init__(self, speed_mps: float, min_clearance_m: float, **params: float) -> None:
        super().__init__(speed_mps, min_clearance_m)
        self.params = PurePursuitParams(
            speed_mps=speed_mps, min_clearance_m=min_clearance_m, **params
        )
        self._path: FloatArray | None = None
        self._seg = 0

    def set_path(self, path: FloatArray | None) -> None:
        self._path = None if path is None else np.asarray(path, dtype=np.float64).reshape(-1, 2)
        self._seg = 0

    @property
    def segment(self) -> int:
        return self._seg

    @property
    def done(self) -> bool:
        return self._path is None or self._seg >= len(self._path) - 1

    def command(
        self, pose: FloatArray, grid: ClearanceGrid, speed_limit: SpeedLimit | None = None
    ) -> NDArray[np.float32]:
        p = self.params
        if self.done:
            return np.zeros(2, dtype=np.float32)
        assert self._path is not None
        verts = self._path
        x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
        n_seg = len(verts) - 1
        self._seg = advance_segment(verts, self._seg, x, y, p.goal_tolerance_m)
        if self.done:
            return np.zeros(2, dtype=np.float32)
        cx, cy = carrot_on_segment(verts[self._seg], verts[self._seg + 1], x, y, p.lookahead_m)
        dx, dy = cx - x, cy - y
        # the carrot in the robot frame
        c, sn = math.cos(th), math.sin(th)
        rx, ry = c * dx + sn * dy, -sn * dx + c * dy
        alpha = math.atan2(ry, rx)
        dist = math.hypot(rx, ry)
        if abs(alpha) > p.turn_in_place_rad:
            return np.array([0.0, math.copysign(p.max_omega_radps, alpha)], dtype=np.float32)
        # speed: slower near obstacles, for large heading errors, near the path's end
        clear = float(grid.clearance_at(np.array([x, y])))
        v = p.speed_mps * min(
            max((clear - p.min_clearance_m) / p.slow_down_m, p.clearance_speed_floor), 1.0
        )
        v *= min(max(1.0 - abs(alpha) / p.turn_in_place_rad, p.heading_speed_floor), 1.0)
        if self._seg == n_seg - 1:
            v = min(v, max(p.approach_min_speed_mps, p.approach_gain_per_s * dist))
        if speed_limit is not None:
            v *= speed_limit()
        if v == 0.0:
            return np.zeros(2, dtype=np.float32)
        # pure pursuit: curvature 2 sin(alpha) / L_d towards the carrot
        omega = pursuit_turn_rate(alpha, dist, max(v, p.min_steering_speed_mps), p.max_omega_radps)
        return np.array([v, omega], dtype=np.float32)


def advance_segment(
    verts: FloatArray | list[list[float]], seg: int, x: float, y: float, tolerance_m: float
) -> int:
    """The segment to follow from ``seg`` on: past every segment whose end vertex is within
    ``tolerance_m`` of ``(x, y)`` (returns ``len(verts) - 1`` when the path's end is reached).
    ``verts``: ``(K, 2)`` [m], an array or its ``tolist()``."""
    n_seg = len(verts) - 1
    while seg < n_seg and math.hypot(verts[seg + 1][0] - x, verts[seg + 1][1] - y) < tolerance_m:
        seg += 1
    return seg


def carrot_on_segment(
    a: FloatArray | list[float], b: FloatArray | list[float], x: float, y: float, lookahead_m: float
) -> tuple[float, float]:
    """The pure-pursuit carrot: ``lookahead_m`` along segment ``a -> b`` beyond the projection
    of ``(x, y)`` on it, clamped to the segment (never past ``b``: corners are not cut)."""
    ax, ay = a
    bx, by = b
    abx, aby = bx - ax, by - ay
    len_ab = math.hypot(abx, aby)
    u = min(max(((x - ax) * abx + (y - ay) * aby) / max(len_ab * len_ab, 1e-12), 0.0), 1.0)
    s = min(u * len_ab + lookahead_m, len_ab) / max(len_ab, 1e-12)
    return ax + abx * s, ay + aby * s


def pursuit_turn_rate(
    alpha_rad: float, dist_m: float, steering_speed_mps: float, max_omega_radps: float
) -> float:
    """The pure-pursuit turn rate towards a carrot at bearing ``alpha_rad`` and distance
    ``dist_m``: ``steering_speed * 2 sin(alpha) / L_d`` (Coulter 1992), clipped to
    ``+-max_omega_radps``."""
    kappa = 2.0 * math.sin(alpha_rad) / max(dist_m, 1e-3)
    return min(max(steering_speed_mps * kappa, -max_omega_radps), max_omega_radps)
