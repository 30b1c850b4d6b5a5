"""Position correction after the explicit Euler move: bodies out of the robot's comfort disc,
each other, then walls (walls win), so no person is ever shown inside a wall."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled
from dynmap_sim.world.people.dynamics import RADIUS, ROBOT_NEED, StepConstants
from dynmap_sim.world.polygons import FloatArray


def correct(
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

    ``z``, ``v`` are complex views of positions and velocities (updated in place), ``rows``
    the candidate segments. Distances are 1-Lipschitz in position, so a body that moved less
    than its gap before the move (``gaps``: between bodies, per body to a segment, to the
    robot's disc [m]; ``moved_max_m`` bounds the move) cannot overlap: those checks are
    skipped.
    """
    pair_gap, wall_gap, robot_gap = gaps
    disp = np.empty(len(z))
    robot = rz is not None
    limits = np.array([pair_gap, robot_gap if robot else math.inf, moved_max_m])
    _correct(z, v, rows, complex(rz) if robot else 0j, k.per, k.pair, old, wall_gap, limits, disp)
    return disp


@compiled
def _correct(z, v, rows, rz, per, pair, old, wall_gap, limits, disp):  # type: ignore[no-untyped-def]
    """The correction in place (see :func:`correct`); ``limits = (pair_gap, robot_gap,
    moved_max)``, ``disp`` receives ``|z - old|``."""
    n = z.shape[0]
    pair_gap, robot_gap, moved_max = limits[0], limits[1], limits[2]
    if robot_gap <= moved_max:  # radially out to robot_need from the robot
        for i in range(n):
            rd = z[i] - rz
            dr = max(abs(rd), 1e-9)
            if per[i, ROBOT_NEED] > dr:
                z[i] += (per[i, ROBOT_NEED] - dr) / dr * rd
    dmax = 0.0
    for i in range(n):
        disp[i] = abs(z[i] - old[i])
        dmax = max(dmax, disp[i])
    if n > 1 and 2.0 * dmax >= pair_gap:  # each overlapping pair apart, half the overlap each
        push = np.zeros(n, dtype=np.complex128)
        for i in range(n):
            for j in range(n):
                if j != i:
                    dv = z[i] - z[j]
                    d = abs(dv)
                    if pair[0, i, j] > d:
                        push[i] += 0.5 * (pair[0, i, j] - d) / max(d, 1e-9) * dv
        for i in range(n):
            z[i] += push[i]
            disp[i] = abs(z[i] - old[i])
    into_wall = False
    for i in range(n):
        into_wall = into_wall or disp[i] >= wall_gap[i]
    if not into_wall:
        return
    for _ in range(2):  # out of the deepest candidate segment, velocity into it removed
        anyone = False
        for i in range(n):
            depth = -math.inf
            q = 0j
            dist = 0.0
            for c in range(rows.shape[1]):
                a = z[i] - rows[i, c, 0]
                cd = rows[i, c, 1]
                t = min(max((a * cd).real * rows[i, c, 2].real, 0.0), 1.0)
                qc = a - t * cd.conjugate()
                dc = abs(qc)
                if per[i, RADIUS] - dc > depth:
                    depth, q, dist = per[i, RADIUS] - dc, qc, dc
            if depth > 0.0:
                anyone = True
                nv = q / max(dist, 1e-9)
                z[i] += depth * nv
                vn = (v[i] * nv.conjugate()).real
                if vn < 0.0:
                    v[i] -= vn * nv
        if not anyone:
            break
    for i in range(n):
        disp[i] = abs(z[i] - old[i])
