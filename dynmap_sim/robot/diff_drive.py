"""A differential-drive robot body in the world's pymunk space (docs/architecture.md §4).

The chain from command to motion is the one a real robot has:

1. the commanded twist ``(v, omega)`` is clipped to the speed limits and rate-limited by the
   acceleration limits (per control step);
2. the motor controller turns it into wheel rotation rates with the *nominal* geometry
   (:func:`~dynmap_sim.sensors.odometry.wheel_rates_for_twist`);
3. the wheels move the body with the *actual* geometry (UMBmark errors ``E_d``, ``E_b``,
   :func:`~dynmap_sim.sensors.odometry.body_twist_from_wheels`), reduced by a random
   **slip** drawn per control step: ``v_body = v_wheels (1 - s_v)``,
   ``omega_body = omega_wheels (1 - s_w)``, ``s ~ N(slip_mean, slip_sigma)`` clipped to
   ``[-0.5, 0.5]``;
4. the body is a circle moved by *swept-circle collision* against the world's pymunk space:
   each substep casts the disc along its displacement (``Shape.segment_query`` with the
   robot's radius, which is exactly the swept disc), stops at the first contact and slides the
   rest of the way along the obstacle's surface. A person who walks into the robot is handled
   by a nearest-point query: the robot may only move away from it. The body stays a kinematic
   pymunk shape in the space, so other queries see it. Substeps are at most
   ``max_substep_m`` long, and the sweep is continuous anyway, so the robot never tunnels.

Any contact during a step is a **bumper event** (``StepResult.collision``). The wheels keep
turning against an obstacle, so the encoders (and thus the odometry) run on while the body
is stopped, as on a real robot that pushes against a wall.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import pymunk
from numpy.typing import NDArray

from dynmap_sim.sensors.odometry import (
    WheelGeometry,
    body_twist_from_wheels,
    wheel_rates_for_twist,
)

FloatArray = NDArray[np.float64]

#: pymunk collision type and shape-filter category of the robot.
COLLISION_ROBOT = 7
CATEGORY_ROBOT = 0b1000
#: Gap [m] kept between the robot and an obstacle it stops at.
_SKIN_M = 1e-4
_SET_POSITION = pymunk.Body.position.fset
_SET_ANGLE = pymunk.Body.angle.fset
_SET_VELOCITY = pymunk.Body.velocity.fset
_SET_ANGULAR_VELOCITY = pymunk.Body.angular_velocity.fset


#: Sensible ranges of the robot's parameters: (name, smallest, largest).
_PARAM_RANGES = (
    ("radius_m", 0.01, 5.0),
    ("max_v_mps", 1e-3, 20.0),
    ("max_omega_radps", 1e-3, 50.0),
    ("max_accel_mps2", 1e-3, 1000.0),
    ("max_alpha_radps2", 1e-3, 1000.0),
    ("max_substep_m", 1e-3, 1.0),
)


@dataclass(frozen=True)
class RobotParams:
    """Body, limits and wheel parameters of the robot (SI units; each within
    :data:`_PARAM_RANGES`: a 1e-9 m substep would simulate for ever)."""

    radius_m: float = 0.2
    max_v_mps: float = 1.0
    max_omega_radps: float = 1.5
    max_accel_mps2: float = 1.0
    max_alpha_radps2: float = 3.0
    wheels: WheelGeometry = field(default_factory=WheelGeometry)
    slip_mean: float = 0.0
    slip_sigma: float = 0.01
    max_substep_m: float = 0.05

    def __post_init__(self) -> None:
        for name, low, high in _PARAM_RANGES:
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0.0):
                raise ValueError(f"RobotParams.{name} must be finite and > 0, got {v!r}")
            if not low <= v <= high:
                raise ValueError(f"RobotParams.{name} must be in {low:g}..{high:g}, got {v!r}")
        if not (math.isfinite(self.slip_sigma) and self.slip_sigma >= 0.0):
            raise ValueError(f"RobotParams.slip_sigma must be >= 0, got {self.slip_sigma!r}")
        if not (math.isfinite(self.slip_mean) and abs(self.slip_mean) < 0.5):
            raise ValueError(f"RobotParams.slip_mean must be in (-0.5, 0.5), got {self.slip_mean}")


class StepResult(NamedTuple):
    """Outcome of one control step: wheel rotations [rad] and the bumper state (a named
    tuple: immutable and cheap to build every step)."""

    dphi_left_rad: float
    dphi_right_rad: float
    collision: bool
    v_mps: float
    omega_radps: float


def _sweep(
    shapes: list[pymunk.Shape], x: float, y: float, dx: float, dy: float, r: float
) -> pymunk.SegmentQueryInfo | None:
    """First contact among ``shapes`` of a disc of radius ``r`` swept by ``(dx, dy)``.

    ``Space.segment_query_first`` is not used on purpose: its broad phase tests the *thin*
    segment against shapes' bounding boxes, ignoring the radius, so it misses an obstacle
    the disc grazes sideways. The candidates come from a bounding-box query around the
    whole step instead (:meth:`DiffDriveRobot.step`); each is queried exactly here.
    """
    best = None
    for shape in shapes:
        q = shape.segment_query((x, y), (x + dx, y + dy), r)
        if q is not None and (best is None or q.alpha < best.alpha):
            best = q
    return best


class DiffDriveRobot:
    """The robot's body in a pymunk ``space`` (it queries the space, it never steps it)."""

    def __init__(
        self,
        space: pymunk.Space,
        params: RobotParams | None = None,
        pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        self.params = params if params is not None else RobotParams()
        p = self.params
        self.body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        self.shape = pymunk.Circle(self.body, p.radius_m)
        self.shape.collision_type = COLLISION_ROBOT
        self.shape.filter = pymunk.ShapeFilter(categories=CATEGORY_ROBOT)
        # our own queries see everything but the robot itself
        self._filter = pymunk.ShapeFilter(mask=pymunk.ShapeFilter.ALL_MASKS() ^ CATEGORY_ROBOT)
        self.space: pymunk.Space | None = None
        self.attach(space)
        self.set_pose(pose)

    # -- space ----------------------------------------------------------------------------
    def attach(self, space: pymunk.Space) -> None:
        """Put the body into ``space`` (leaving the previous one, if any)."""
        if self.space is space:
            return
        if self.space is not None:
            self.space.remove(self.body, self.shape)
        self.space = space
        space.add(self.body, self.shape)

    # -- state ----------------------------------------------------------------------------
    def set_pose(self, pose: tuple[float, float, float] | FloatArray) -> None:
        """Place the body at ``pose`` (map frame) at rest."""
        self._x, self._y, self._th = float(pose[0]), float(pose[1]), float(pose[2])
        self.body.position = (self._x, self._y)
        self.body.angle = self._th
        self._v = 0.0
        self._w = 0.0
        if self.space is not None:
            self.space.reindex_shapes_for_body(self.body)

    @property
    def pose(self) -> FloatArray:
        """True pose ``(x_m, y_m, theta_rad)`` in the map frame (a fresh array)."""
        return np.array([self._x, self._y, math.remainder(self._th, 2.0 * math.pi)])

    @property
    def twist(self) -> tuple[float, float]:
        """The current commanded (rate-limited) twist ``(v_mps, omega_radps)``."""
        return self._v, self._w

    # -- motion ---------------------------------------------------------------------------
    def limit(self, v_mps: float, omega_radps: float, dt_s: float) -> tuple[float, float]:
        """Apply speed and acceleration limits to a commanded twist."""
        p = self.params
        v = min(max(v_mps, -p.max_v_mps), p.max_v_mps)
        w = min(max(omega_radps, -p.max_omega_radps), p.max_omega_radps)
        dv = p.max_accel_mps2 * dt_s
        dw = p.max_alpha_radps2 * dt_s
        v = min(max(v, self._v - dv), self._v + dv)
        w = min(max(w, self._w - dw), self._w + dw)
        return v, w

    def step(
        self, v_mps: float, omega_radps: float, dt_s: float, rng: np.random.Generator | None
    ) -> StepResult:
        """Drive for ``dt_s`` seconds with a commanded twist (clipped and rate-limited)."""
        if not (math.isfinite(v_mps) and math.isfinite(omega_radps)):
            raise ValueError(f"robot command must be finite, got ({v_mps}, {omega_radps})")
        p = self.params
        v, w = self.limit(v_mps, omega_radps, dt_s)
        self._v, self._w = v, w
        wl, wr = wheel_rates_for_twist(p.wheels, v, w)
        vb, wb = body_twist_from_wheels(p.wheels, wl, wr)
        if rng is not None and p.slip_sigma > 0.0:
            s = rng.normal(p.slip_mean, p.slip_sigma, 2)
            vb *= 1.0 - min(max(float(s[0]), -0.5), 0.5)
            wb *= 1.0 - min(max(float(s[1]), -0.5), 0.5)
        elif p.slip_mean != 0.0:
            vb *= 1.0 - p.slip_mean
            wb *= 1.0 - p.slip_mean
        n_sub = max(1, math.ceil(abs(vb) * dt_s / p.max_substep_m - 1e-9))
        h = dt_s / n_sub
        # broad phase once per step: every shape the disc could touch during the step
        assert self.space is not None
        reach = abs(vb) * dt_s + p.radius_m + 2.0 * _SKIN_M
        x, y = self._x, self._y
        bb = pymunk.BB(x - reach, y - reach, x + reach, y + reach)
        shapes = [s for s in self.space.bb_query(bb, self._filter) if not s.sensor]
        contact = False
        th = self._th
        for _ in range(n_sub):
            a = th + 0.5 * wb * h  # midpoint heading over the substep
            dx, dy = vb * h * math.cos(a), vb * h * math.sin(a)
            if shapes:
                contact |= self._move(shapes, dx, dy)
            else:
                self._x += dx
                self._y += dy
            th += wb * h
        self._th = math.remainder(th, 2.0 * math.pi)
        body = self.body
        # the property setters themselves, without pymunk's per-attribute __setattr__ wrapper
        _SET_POSITION(body, (self._x, self._y))
        _SET_ANGLE(body, self._th)
        _SET_VELOCITY(body, (vb * math.cos(th), vb * math.sin(th)))
        _SET_ANGULAR_VELOCITY(body, wb)
        self.space.reindex_shapes_for_body(body)
        return StepResult(wl * dt_s, wr * dt_s, contact, vb, wb)

    def _move(self, shapes: list[pymunk.Shape], dx: float, dy: float) -> bool:
        """Sweep the disc by ``(dx, dy)`` [m] among ``shapes``, sliding; True on contact."""
        r = self.params.radius_m
        x, y = self._x, self._y
        free = []
        for shape in shapes:
            q = shape.point_query((x, y))
            if q.distance < r - _SKIN_M:
                # overlapping (a person stepped into us): only moves away from it are allowed
                gx, gy = q.gradient  # points out of the shape, inside or outside it
                into = dx * gx + dy * gy
                if into < 0.0:
                    dx -= into * gx
                    dy -= into * gy
            else:
                free.append(shape)
        overlap = len(free) < len(shapes)
        shapes = free
        contact = overlap
        for _ in range(3):
            length = math.hypot(dx, dy)
            if length < 1e-12:
                break
            hit = _sweep(shapes, x, y, dx, dy, r)
            if hit is None:
                x += dx
                y += dy
                break
            contact = True
            travel = max(hit.alpha * length - _SKIN_M, 0.0)
            x += dx * travel / length
            y += dy * travel / length
            rest = 1.0 - travel / length
            dx *= rest
            dy *= rest
            nx, ny = hit.normal
            into = dx * nx + dy * ny
            if into < 0.0:  # slide: drop the component into the surface
                dx -= into * nx
                dy -= into * ny
        self._x, self._y = x, y
        return contact
