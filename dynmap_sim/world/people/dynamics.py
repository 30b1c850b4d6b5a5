"""The social force on each person (Helbing & Molnár 1995, Phys. Rev. E 51), the explicit
Euler move and goal progress: compiled kernels over the crowd's complex positions ``x + iy``.

The forces are those of the formulas of :mod:`dynmap_sim.world.people`, evaluated exactly
(no precomputed field); the exponentials fold their prefactors in
(``A exp((r - d) / B) = exp(ln A + r / B - d / B)``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled
from dynmap_sim.world.people.crowd import Crowd
from dynmap_sim.world.people.params import (
    A_EVADE,
    A_PEOPLE,
    A_ROBOT,
    A_WALL,
    B_EVADE,
    B_PEOPLE,
    B_ROBOT,
    B_WALL,
    GOAL_TOL_M,
    KEEP_RIGHT_M,
    PROGRESS_M,
    REACH_M,
    ROBOT_GAP_M,
    STUCK_S,
    TAU_S,
)
from dynmap_sim.world.polygons import FloatArray

ComplexArray = NDArray[np.complex128]

_INV_TAU = 1.0 / TAU_S
_INV_B_PEOPLE = 1.0 / B_PEOPLE
_INV_B_ROBOT = 1.0 / B_ROBOT
_INV_B_WALL = 1.0 / B_WALL
_INV_B_EVADE = 1.0 / B_EVADE


#: Columns of :attr:`StepConstants.per` (per-person constants of the kernels):
#: desired speed over the relaxation time [m/s^2], the ``ln A + r / B`` of the walls', the
#: robot's and the evasion's forces, the distance the robot is kept at (body radius + robot
#: radius + ``ROBOT_GAP_M``) [m] and the body radius [m].
V0_TAU, WALL_LOG_A, ROBOT_LOG_A, EVADE_LOG_A, ROBOT_NEED, RADIUS = range(6)


@dataclass(frozen=True)
class StepConstants:
    """Per-crowd constants of a step (rebuilt when the crowd or the robot's radius changes)."""

    n: int
    radius: FloatArray
    v0: FloatArray
    robot_radius_m: float
    vmax: FloatArray
    """Speed cap ``1.3 v0`` [m/s] (H&M eq. 8)."""
    vmax_max: float
    """The largest speed of anyone [m/s] (bounds a step's move)."""
    robot_goal_reach: FloatArray
    """How near the robot may come to a goal before it is given up [m]."""
    per: FloatArray
    """``(P, 6)``: per-person constants, columns :data:`V0_TAU` ... :data:`RADIUS`."""
    pair: FloatArray
    """``(2, P, P)``: ``r_i + r_j`` [m] and ``ln A + (r_i + r_j) / B`` of the repulsion
    between two people."""

    @classmethod
    def build(cls, radius: FloatArray, v0: FloatArray, robot_radius_m: float) -> StepConstants:
        """The constants of a crowd of radii ``radius`` [m] and desired speeds ``v0`` [m/s]."""
        n = len(radius)
        rsum = radius[:, None] + radius[None, :]
        reach = radius + robot_radius_m + ROBOT_GAP_M
        per = np.empty((n, 6))
        per[:, V0_TAU] = v0 / TAU_S
        per[:, WALL_LOG_A] = np.log(A_WALL) + radius / B_WALL
        per[:, ROBOT_LOG_A] = np.log(A_ROBOT) + reach / B_ROBOT
        per[:, EVADE_LOG_A] = np.log(A_EVADE) + reach / B_EVADE
        per[:, ROBOT_NEED] = reach
        per[:, RADIUS] = radius
        return cls(
            n=n,
            radius=radius,
            v0=v0,
            robot_radius_m=robot_radius_m,
            vmax=1.3 * v0,
            vmax_max=float((1.3 * v0).max()) if n else 0.0,
            robot_goal_reach=reach + 0.1,
            per=per,
            pair=np.stack([rsum, np.log(A_PEOPLE) + rsum / B_PEOPLE]),
        )


@compiled
def _force(z, v, goal, rows, rz, robot, per, pair, force, wall_gap):  # type: ignore[no-untyped-def]
    """The force on each person into ``force``: driving term (H&M eq. 2), repulsion by the
    other people (eq. 3-4), by the robot and by the closest point of each candidate segment
    within ``REACH_M`` (eq. 5), and the evasion of a robot ahead. Writes each person's gap to
    its nearest segment (``wall_gap``); returns the smallest gap between two bodies and to
    the robot's comfort disc (inf without a robot) [m]."""
    n = z.shape[0]
    pair_gap = math.inf
    robot_gap = math.inf
    for i in range(n):
        zi = z[i]
        to_goal = goal[i] - zi
        e = to_goal / max(abs(to_goal), 1e-9)
        f = per[i, V0_TAU] * e - v[i] * _INV_TAU
        for j in range(n):
            if j != i:
                dv = zi - z[j]
                d = abs(dv)
                pair_gap = min(pair_gap, d - pair[0, i, j])
                f += math.exp(pair[1, i, j] - d * _INV_B_PEOPLE) / max(d, 1e-9) * dv
        if robot:
            dv = zi - rz
            d = abs(dv)
            robot_gap = min(robot_gap, d - per[i, ROBOT_NEED])
            f += math.exp(per[i, ROBOT_LOG_A] - d * _INV_B_ROBOT) / max(d, 1e-9) * dv
            # evasion: conj(e) (z - robot) has real part < 0 when the robot is ahead, and
            # imaginary part > 0 when it is on the right: step right unless clearly so
            er = e.conjugate() * dv
            if er.real < 0.0:
                mag = math.exp(per[i, EVADE_LOG_A] - max(d, 1e-9) * _INV_B_EVADE)
                f += (1j * mag if er.imag > KEEP_RIGHT_M else -1j * mag) * e
        wall = math.inf
        for c in range(rows.shape[1]):
            a = zi - rows[i, c, 0]
            cd = rows[i, c, 1]  # conj(d)
            t = min(max((a * cd).real * rows[i, c, 2].real, 0.0), 1.0)
            dv = a - t * cd.conjugate()  # closest point -> person
            d = abs(dv)
            wall = min(wall, d)
            if d <= REACH_M:
                f += math.exp(per[i, WALL_LOG_A] - d * _INV_B_WALL) / max(d, 1e-9) * dv
        wall_gap[i] = wall - per[i, RADIUS]
        force[i] = f
    return pair_gap, robot_gap


def social_force(
    z: ComplexArray,
    v: ComplexArray,
    goal: ComplexArray,
    rows: ComplexArray,
    rz: complex | None,
    k: StepConstants,
) -> tuple[ComplexArray, float, FloatArray, float]:
    """The force on each person at positions ``z`` with velocities ``v`` heading for
    ``goal`` (complex), and the smallest gaps before the move [m]: between two bodies, per
    person to a segment, and between a body and the robot's comfort disc (``inf`` without a
    robot). ``rows``: the candidate segments (:meth:`.Obstacles.rows`); ``rz``: the robot's
    position (None: no robot)."""
    n = len(z)
    force = np.empty(n, dtype=np.complex128)
    wall_gap = np.empty(n)
    robot = rz is not None
    pair_gap, robot_gap = _force(
        z, v, goal, rows, complex(rz) if robot else 0j, robot, k.per, k.pair, force, wall_gap
    )
    return force, pair_gap, wall_gap, robot_gap


@compiled
def _move(z, v, force, dt, vmax, old):  # type: ignore[no-untyped-def]
    """Explicit Euler step in place: ``v += dt force``, capped at ``vmax`` (H&M eq. 8), then
    ``z += dt v``; the positions before the move into ``old``."""
    for i in range(z.shape[0]):
        old[i] = z[i]
        vi = v[i] + dt * force[i]
        cap = vmax[i] / max(abs(vi), 1e-9)
        if cap < 1.0:
            vi = vi * cap
        v[i] = vi
        z[i] = z[i] + dt * vi


def move(
    z: ComplexArray, v: ComplexArray, force: ComplexArray, dt_s: float, k: StepConstants
) -> ComplexArray:
    """Move the people ``z`` (velocities ``v``, updated in place) by ``dt_s`` under
    ``force``; returns the positions before the move."""
    old = np.empty_like(z)
    _move(z, v, force, float(dt_s), k.vmax, old)
    return old


def max_move_m(dt_s: float, vmax_max: Any) -> Any:
    """The longest move of a step [m]: ``dt * vmax`` plus rounding (a person within it of the
    robot's disc, another body or a wall is checked after the move)."""
    return dt_s * vmax_max * (1.0 + 1e-9) + 1e-9


@compiled
def _goals(z, goal, rz, robot, reach, best, stuck, dt, redo):  # type: ignore[no-untyped-def]
    """Goal progress in place (``best``: the closest approach to the goal, ``stuck``: time
    without ``PROGRESS_M`` of it) and who needs a new goal into ``redo``: arrival, stuck for
    ``STUCK_S``, or the robot within ``reach`` of the goal (not while pausing, ``stuck <
    0``). Returns whether anyone does."""
    anyone = False
    for i in range(z.shape[0]):
        g = abs(goal[i] - z[i])
        if g < best[i] - PROGRESS_M:
            best[i] = g
            stuck[i] = 0.0
        else:
            stuck[i] += dt
        due = g < GOAL_TOL_M or stuck[i] > STUCK_S
        if robot and abs(goal[i] - rz) < reach[i]:
            due = True
        due = due and stuck[i] >= 0.0
        redo[i] = due
        anyone = anyone or due
    return anyone


def goals_due(
    crowd: Crowd,
    goal: ComplexArray,
    z: ComplexArray,
    dt_s: float,
    rz: complex | None,
    k: StepConstants,
) -> NDArray[np.bool_] | None:
    """Update ``crowd``'s progress toward the goals (``best_goal_m``, ``stuck_s`` in place);
    who needs a new goal, or None when nobody does."""
    redo = np.empty(crowd.n, dtype=bool)
    robot = rz is not None
    due = _goals(
        z, goal, complex(rz) if robot else 0j, robot, k.robot_goal_reach,
        crowd.best_goal_m, crowd.stuck_s, float(dt_s), redo,
    )  # fmt: skip
    return redo if due else None
