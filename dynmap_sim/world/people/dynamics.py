"""The social force on each person (Helbing & Molnár 1995, Phys. Rev. E 51) and goal progress.

Cost: for the crowds of the shipped worlds (<= ~30 people) a step is bound by the number of
numpy calls, not by arithmetic, so :func:`social_force` works on complex numbers
(``x + iy`` views of the crowd arrays) and evaluates every repulsion — people, robot and the
closest points of the candidate segments from the broad phase — as one exponential over a
single ``(P, P + 1 + K)`` matrix of source-to-person vectors. The forces are those of the
formulas of :mod:`dynmap_sim.world.people`, evaluated exactly (no precomputed field).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

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

_FAR = complex(1e9, 1e9)  # stands in for an absent robot (its force underflows to 0)


@dataclass(frozen=True)
class StepConstants:
    """Per-crowd constants of a step; ``*_log_a`` fold a force's amplitude and the bodies'
    radii into the exponent (``A exp((r - d) / B) = exp(log_a - d / B)``)."""

    n: int
    radius: FloatArray
    v0: FloatArray
    robot_radius_m: float
    v0_tau: FloatArray
    vmax: FloatArray
    vmax_max: float
    """The largest speed of anyone [m/s] (bounds a step's move)."""
    rsum_masked: FloatArray
    """``r_i + r_j`` with ``-inf`` on the diagonal (a body never overlaps itself)."""
    pair_log_a: FloatArray
    """``ln A + (r_i + r_j) / B`` with ``-inf`` on the diagonal (no self-force)."""
    wall_log_a: FloatArray
    robot_log_a: FloatArray
    evade_log_a: FloatArray
    robot_need: FloatArray
    robot_goal_reach: FloatArray
    k_cols: int
    log_a: FloatArray
    """``(P, P + 1 + K)``: the ``*_log_a`` of the people, the robot and ``K`` candidate
    segments, laid out like the source points in :func:`source_vectors`."""
    inv_b: FloatArray
    """``(P, P + 1 + K)``: ``1 / B`` of the same interactions [1/m]."""

    @classmethod
    def build(
        cls, radius: FloatArray, v0: FloatArray, robot_radius_m: float, k_cols: int
    ) -> StepConstants:
        """The constants of a crowd of radii ``radius`` and desired speeds ``v0``."""
        n = len(radius)
        rsum = radius[:, None] + radius[None, :]
        diag = np.eye(n, dtype=bool)
        reach = radius + robot_radius_m + ROBOT_GAP_M
        pair_log_a = np.where(diag, -np.inf, np.log(A_PEOPLE) + rsum / B_PEOPLE)
        wall_log_a = np.log(A_WALL) + radius / B_WALL
        robot_log_a = np.log(A_ROBOT) + reach / B_ROBOT
        log_a = np.empty((n, n + 1 + k_cols))
        inv_b = np.empty((n, n + 1 + k_cols))
        log_a[:, :n], inv_b[:, :n] = pair_log_a, 1.0 / B_PEOPLE
        log_a[:, n], inv_b[:, n] = robot_log_a, 1.0 / B_ROBOT
        log_a[:, n + 1 :], inv_b[:, n + 1 :] = wall_log_a[:, None], 1.0 / B_WALL
        return cls(
            n=n,
            radius=radius,
            v0=v0,
            robot_radius_m=robot_radius_m,
            v0_tau=v0 / TAU_S,
            vmax=1.3 * v0,
            vmax_max=float((1.3 * v0).max()) if n else 0.0,
            rsum_masked=np.where(diag, -np.inf, rsum),
            pair_log_a=pair_log_a,
            wall_log_a=wall_log_a,
            robot_log_a=robot_log_a,
            evade_log_a=np.log(A_EVADE) + reach / B_EVADE,
            robot_need=reach,
            robot_goal_reach=reach + 0.1,
            k_cols=k_cols,
            log_a=log_a,
            inv_b=inv_b,
        )


def social_force(
    crowd: Crowd,
    z: NDArray[np.complex128],
    v: NDArray[np.complex128],
    goal: NDArray[np.complex128],
    rows: NDArray[np.complex128],
    rz: complex | None,
    k: StepConstants,
) -> tuple[NDArray[np.complex128], float, FloatArray, float]:
    """The force on each person at positions ``z`` with velocities ``v`` (complex), and the
    smallest gaps before the move [m]: between two bodies, per person to a segment, and
    between a body and the robot's comfort disc (``inf`` without a robot).

    ``rows`` are the candidate segments of :meth:`Obstacles.rows`, ``rz`` the robot's
    position (None: no robot).
    """
    n = crowd.n
    e, force = driving_force(z, v, goal, k)
    diff = source_vectors(z, rows, rz)
    d = np.abs(diff)
    # smallest gaps before the move [m]: between two bodies, and per person to a segment
    pair_gap = float((d[:, :n] - k.rsum_masked).min())
    wall_gap = d[:, n + 1 :].min(axis=1) - crowd.radius
    force += repulsion_terms(diff, d, k).sum(axis=1)
    if rz is None:
        return force, pair_gap, wall_gap, np.inf
    force += evasion(e, diff[:, n], d[:, n], k)
    return force, pair_gap, wall_gap, float((d[:, n] - k.robot_need).min())


def driving_force(
    z: NDArray[np.complex128],
    v: NDArray[np.complex128],
    goal: NDArray[np.complex128],
    k: StepConstants,
) -> tuple[NDArray[np.complex128], NDArray[np.complex128]]:
    """The unit vectors ``e`` toward the goals and the driving term ``v0 e / tau - v / tau``
    (H&M eq. 2) of people at ``z`` with velocities ``v``."""
    to_goal = goal - z
    e = to_goal / np.maximum(np.abs(to_goal), 1e-9)
    return e, k.v0_tau * e - v * (1.0 / TAU_S)


def source_vectors(
    z: NDArray[np.complex128], rows: NDArray[np.complex128], rz: complex | None
) -> NDArray[np.complex128]:
    """``(P, P + 1 + K)`` vectors source -> person of all sources at once: the other people,
    the robot (far away when absent), and the closest point of each candidate segment."""
    n = len(z)
    diff = np.empty((n, n + 1 + rows.shape[1]), dtype=np.complex128)
    np.subtract(z[:, None], z[None, :], out=diff[:, :n])
    np.subtract(z, _FAR if rz is None else rz, out=diff[:, n])
    segment_vectors_into(z, rows, diff[:, n + 1 :])
    return diff


def segment_vectors_into(
    z: NDArray[np.complex128], rows: NDArray[np.complex128], out: NDArray[np.complex128]
) -> None:
    """Write into ``out`` ``(P, K)`` the vector from the closest point of each candidate
    segment (``rows``, :meth:`Obstacles.rows`) to the person at ``z``."""
    a = z[:, None] - rows[..., 0]
    cd = rows[..., 1]  # conj(d)
    t = (a * cd).real
    t *= rows[..., 2].real
    np.minimum(np.maximum(t, 0.0, out=t), 1.0, out=t)
    np.subtract(a, t * cd.conjugate(), out=out)  # closest point -> person


def max_move_m(dt_s: float, vmax_max: Any) -> Any:
    """The longest move of a step [m]: ``dt * vmax`` plus rounding (a person within it of the
    robot's disc, another body or a wall is checked after the move)."""
    return dt_s * vmax_max * (1.0 + 1e-9) + 1e-9


def repulsion_terms(diff: NDArray[np.complex128], d: FloatArray, k: Any) -> NDArray[np.complex128]:
    """The exponential repulsions ``A exp((r - d) / B) n`` of all sources ``diff`` (lengths
    ``d``), one per source: people (H&M eq. 3-4; the diagonal is masked by the constants),
    the robot, and segments (H&M eq. 5; only those within ``REACH_M`` count). Their sum over
    a row is the repulsion on that person. ``k``: :class:`StepConstants` (or the batched
    constants of :mod:`.batch`: ``n`` people columns, then the robot, then segments)."""
    n = k.n
    w = np.exp(k.log_a - d * k.inv_b)
    w /= np.maximum(d, 1e-9)
    w_wall = w[:, n + 1 :]
    w_wall[d[:, n + 1 :] > REACH_M] = 0.0
    return w * diff


def evasion(
    e: NDArray[np.complex128], rd: NDArray[np.complex128], d_robot: FloatArray, k: StepConstants
) -> NDArray[np.complex128]:
    """Sideways force of a robot ahead (vectors robot -> person ``rd``, lengths ``d_robot``)
    on people heading ``e``: they step aside early, to their right when it is dead ahead, so
    a head-on meeting in a corridor does not end in a stand-off."""
    dr = np.maximum(d_robot, 1e-9)
    # conj(e) rd: real part -(robot ahead), imaginary part > 0: robot on the right
    er = e.conjugate() * rd
    mag = np.exp(k.evade_log_a - dr * (1.0 / B_EVADE)) * (er.real < 0.0)
    # step right (keep-right convention), unless the robot is clearly on the right
    return mag * np.where(er.imag > KEEP_RIGHT_M, 1j, -1j) * e


def speed_factor(v: NDArray[np.complex128], k: StepConstants) -> FloatArray:
    """The speed cap's factor ``min(1, vmax / max(|v|, 1e-9))`` (H&M eq. 8)."""
    return np.minimum(1.0, k.vmax / np.maximum(np.abs(v), 1e-9))


def goals_due(
    crowd: Crowd,
    goal: NDArray[np.complex128],
    z: NDArray[np.complex128],
    dt_s: float,
    rz: complex | None,
    k: StepConstants,
) -> NDArray[np.bool_]:
    """Update progress toward the goals; True for who needs a new goal: arrival, no progress
    for ``STUCK_S``, or the robot standing on the goal (not while pausing)."""
    gd = np.abs(goal - z)
    progress = gd < crowd.best_goal_m - PROGRESS_M
    crowd.best_goal_m = np.where(progress, gd, crowd.best_goal_m)
    crowd.stuck_s = np.where(progress, 0.0, crowd.stuck_s + dt_s)
    redo = (gd < GOAL_TOL_M) | (crowd.stuck_s > STUCK_S)
    if rz is not None:
        redo |= np.abs(goal - rz) < k.robot_goal_reach
    redo &= crowd.stuck_s >= 0.0  # negative: pausing after a failed goal search
    return redo
