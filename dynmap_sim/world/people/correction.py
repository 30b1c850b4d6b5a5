"""Position correction after the explicit Euler move: bodies out of the robot's comfort disc,
each other, then walls (walls win), so no person is ever shown inside a wall."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.world.people.crowd import Crowd
from dynmap_sim.world.people.dynamics import StepConstants
from dynmap_sim.world.polygons import FloatArray


def correct(
    crowd: Crowd,
    z: NDArray[np.complex128],
    v: NDArray[np.complex128],
    rows: NDArray[np.complex128],
    rz: complex | None,
    k: StepConstants,
    old: NDArray[np.complex128],
    gaps: tuple[float, FloatArray, float],
    moved_max_m: float,
) -> FloatArray:
    """Push bodies out of the robot's comfort disc, each other, then walls (walls win);
    return how far each body moved in the step, ``|z - old|`` [m].

    ``z``, ``v`` are complex views of positions and velocities (updated in place).
    Distances are 1-Lipschitz in position, so a body that moved less than its gap before
    the move (``gaps``: between bodies, per body to a segment, to the robot's disc [m];
    ``moved_max_m`` bounds the move) cannot overlap: those checks are skipped.
    """
    pair_gap, wall_gap, robot_gap = gaps
    if rz is not None and robot_gap <= moved_max_m:
        _clear_robot(z, rz, k)
    disp = np.abs(z - old)
    if crowd.n > 1 and 2.0 * disp.max() >= pair_gap:
        _separate_pairs(z, k)
        disp = np.abs(z - old)
    if not bool((disp >= wall_gap).any()):
        return disp
    _push_out_of_walls(crowd, z, v, rows)
    return np.abs(z - old)


def _clear_robot(z: NDArray[np.complex128], rz: complex, k: StepConstants) -> None:
    """Move bodies radially out to ``robot_need`` from the robot at ``rz``."""
    rd = z - rz
    dr = np.maximum(np.abs(rd), 1e-9)
    push = k.robot_need - dr
    if push.max() > 0.0:
        np.maximum(push, 0.0, out=push)
        z += push / dr * rd


def _separate_pairs(z: NDArray[np.complex128], k: StepConstants) -> None:
    """Move each overlapping pair of bodies apart, half the overlap each."""
    diff = z[:, None] - z[None, :]
    d = np.abs(diff)
    over = np.maximum(k.rsum_masked - d, 0.0)
    if over.any():
        z += 0.5 * (over / np.maximum(d, 1e-9) * diff).sum(axis=1)


def _push_out_of_walls(
    crowd: Crowd,
    z: NDArray[np.complex128],
    v: NDArray[np.complex128],
    rows: NDArray[np.complex128],
) -> None:
    """Two passes: push each body out of its deepest candidate segment and remove the
    velocity component into it."""
    p0 = rows[..., 0]
    cd = rows[..., 1]
    inv = rows[..., 2].real
    idx = np.arange(crowd.n)
    for _ in range(2):
        a = z[:, None] - p0
        t = (a * cd).real * inv
        np.minimum(np.maximum(t, 0.0, out=t), 1.0, out=t)
        q = a - t * cd.conjugate()
        dist = np.abs(q)
        over = crowd.radius[:, None] - dist
        j = np.argmax(over, axis=1)
        depth = over[idx, j]
        if not (depth > 0.0).any():
            break
        np.maximum(depth, 0.0, out=depth)
        nv = q[idx, j] / np.maximum(dist[idx, j], 1e-9)
        z += depth * nv
        # remove the velocity component into the obstacle
        vn = (v * nv.conjugate()).real
        hit = (depth > 0) & (vn < 0)
        v -= np.where(hit, vn, 0.0) * nv
