"""Optional numba kernels of the people's step (extra ``fast``): the real-valued arithmetic
between numpy's calls, fused, with numpy's numbers bit for bit.

A step of :class:`~dynmap_sim.world.people.SocialForce` is about ninety numpy calls on
arrays of a few hundred entries (:mod:`.dynamics`), so its cost is call overhead. Every
operation whose result is one correctly rounded IEEE double or a comparison — ``+``, ``-``,
``*``, ``/`` on reals, ``min``/``max`` (NaN-propagating, as numpy's), comparisons, picking —
has the same result in a compiled loop as in numpy, whatever numpy's SIMD path. These
kernels take over those operations: the smallest gaps, the exponents of the repulsions, the
weights' division and reach cut, the evasion's sideways factor, the speed cap's factor, the
pair separation's weights, the goal bookkeeping and the legs' heading and swing. What stays
numpy's, called on the same operands: complex products and quotients (numpy may fuse a
multiply and an add there, depending on the CPU), ``abs`` of complex numbers, ``exp`` and
the sums. So the people's trajectories are numpy's, bit for bit (the tests compare both
steps); the step is a few dozen calls fewer.

Each kernel is plain Python (what the tests also run), compiled with
:func:`dynmap_sim.jit.compiled` when numba is installed.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled
from dynmap_sim.jit import numba_available as numba_available  # re-exported
from dynmap_sim.world.people.crowd import Crowd
from dynmap_sim.world.people.dynamics import _FAR, StepConstants, driving_force
from dynmap_sim.world.people.obstacles import Obstacles
from dynmap_sim.world.people.params import (
    B_EVADE,
    CELL_M,
    GOAL_TOL_M,
    KEEP_RIGHT_M,
    PROGRESS_M,
    REACH_M,
    STUCK_S,
)
from dynmap_sim.world.polygons import FloatArray


def _gaps_py(  # type: ignore[no-untyped-def]
    d,
    n,
    log_a,
    inv_b,
    rsum_masked,
    radius,
    robot,
    robot_need,
    evade_log_a,
    inv_b_evade,
    arg,
    earg,
    wall_gap,
):
    """From the distances ``d`` ``(P, P + 1 + K)`` of :func:`.source_vectors`: the
    repulsions' exponents ``arg = log_a - d inv_b``, the smallest gap between two bodies
    (returned), per person to a segment (``wall_gap``), and with a ``robot`` the smallest
    gap to its disc (returned, else inf) and the evasion's exponents ``earg``."""
    p, m = d.shape
    pair_gap = math.inf
    robot_gap = math.inf
    for i in range(p):
        for j in range(m):
            arg[i, j] = log_a[i, j] - d[i, j] * inv_b[i, j]
        for j in range(n):
            g = d[i, j] - rsum_masked[i, j]
            if g < pair_gap or g != g:  # numpy's min propagates NaN
                pair_gap = g
        w = d[i, n + 1]
        for j in range(n + 2, m):
            v = d[i, j]
            if v < w or v != v:
                w = v
        wall_gap[i] = w - radius[i]
        if robot:
            dr = d[i, n]
            g = dr - robot_need[i]
            if g < robot_gap or g != g:
                robot_gap = g
            if dr < 1e-9:  # np.maximum(d, 1e-9) (NaN stays)
                dr = 1e-9
            earg[i] = evade_log_a[i] - dr * inv_b_evade
    return pair_gap, robot_gap


def _weights_py(w, d, n, reach):  # type: ignore[no-untyped-def]
    """The repulsions' weights in place: ``w / max(d, 1e-9)``, 0 for segments beyond
    ``reach``."""
    p, m = d.shape
    for i in range(p):
        for j in range(m):
            dj = d[i, j]
            w[i, j] = w[i, j] / (1e-9 if dj < 1e-9 else dj)
            if j > n and dj > reach:
                w[i, j] = 0.0


def _evasion_factor_py(ex, er, keep, out):  # type: ignore[no-untyped-def]
    """``out = (ex (er.real < 0)) * (1j if er.imag > keep else -1j)``: numpy's complex
    product of a real and ``+-1j`` is ``(+0, +-mag + 0)`` exactly, with or without a fused
    multiply-add."""
    for i in range(ex.shape[0]):
        z = er[i]
        mag = ex[i] * (1.0 if z.real < 0.0 else 0.0)
        out[i] = complex(0.0, (mag if z.imag > keep else -mag) + 0.0)


def _speed_factor_py(sp, vmax, out):  # type: ignore[no-untyped-def]
    """``out = min(1, vmax / max(sp, 1e-9))`` (H&M eq. 8), NaN-propagating as numpy."""
    for i in range(sp.shape[0]):
        s = sp[i]
        f = vmax[i] / (1e-9 if s < 1e-9 else s)
        out[i] = 1.0 if f > 1.0 else f


def _pair_push_py(d, rsum_masked, out):  # type: ignore[no-untyped-def]
    """The pair separation's weights ``out = max(rsum - d, 0) / max(d, 1e-9)`` (numpy's
    ``np.maximum``: the first operand when equal, NaN kept); True if any is nonzero."""
    anyone = False
    p, m = d.shape
    for i in range(p):
        for j in range(m):
            dj = d[i, j]
            o = rsum_masked[i, j] - dj
            if not (o >= 0.0 or o != o):
                o = 0.0
            if o != 0.0:
                anyone = True
            out[i, j] = o / (1e-9 if dj < 1e-9 else dj)
    return anyone


def _legs_py(  # type: ignore[no-untyped-def]
    sp, q, swing, gain, cap, spread_re, spread_im, h, side
):
    """The legs' heading ``h = q`` where the speed ``sp > 1e-3`` (else 1) and their offset
    factor ``side = swing min(sp gain, cap) + 1j spread`` (numpy's ``swing + 1j spread``:
    ``(swing + spread_re, 0 + spread_im)``)."""
    for i in range(sp.shape[0]):
        s = sp[i]
        h[i] = q[i] if s > 1e-3 else complex(1.0, 0.0)
        g = s * gain
        if not (g <= cap or g != g):  # np.minimum(g, cap)
            g = cap
        side[i] = complex(swing[i] * g + spread_re, 0.0 + spread_im)


def _rows_py(  # type: ignore[no-untyped-def]
    z, origin_re, origin_im, inv_cell, nx, ny, cells, segrows, rows
):
    """The broad phase's candidate rows of :meth:`.SegmentGrid.rows` into ``rows``
    ``(P, K, 3)``: the cell of each point (numpy's ``(z - origin) * inv_cell``, truncated,
    clipped to the grid) and its listed segments' rows."""
    k_cols = cells.shape[1]
    for i in range(z.shape[0]):
        ci = int((z[i].real - origin_re) * inv_cell)
        cj = int((z[i].imag - origin_im) * inv_cell)
        ci = min(max(ci, 0), nx - 1)
        cj = min(max(cj, 0), ny - 1)
        cell = ci * ny + cj
        for j in range(k_cols):
            seg = cells[cell, j]
            for c in range(3):
                rows[i, j, c] = segrows[seg, c]


def _sources_py(z, rz, p0, diff, a):  # type: ignore[no-untyped-def]
    """Of :func:`.source_vectors`: the vectors person -> person and robot -> person into
    ``diff[:, :P + 1]`` and the vectors from the candidate segments' starts ``a = z - p0``
    (complex differences: two exact real subtractions each)."""
    p = z.shape[0]
    for i in range(p):
        zi = z[i]
        for j in range(p):
            diff[i, j] = zi - z[j]
        diff[i, p] = zi - rz
        for j in range(p0.shape[1]):
            a[i, j] = zi - p0[i, j]


def _clamp_py(prod, inv, t):  # type: ignore[no-untyped-def]
    """``t = clip(prod.real * inv, 0, 1)`` (numpy's ``np.maximum`` then ``np.minimum``: the
    first operand when equal, NaN kept)."""
    p, m = inv.shape
    for i in range(p):
        for j in range(m):
            v = prod[i, j].real * inv[i, j]
            if not (v >= 0.0 or v != v):
                v = 0.0
            if not (v <= 1.0 or v != v):
                v = 1.0
            t[i, j] = v


def _goals_py(  # type: ignore[no-untyped-def]
    gd, best, stuck, dt, robot, gr, reach, redo
):
    """:func:`.goals_due`'s bookkeeping in place (``best``, ``stuck``) from the distances to
    the goals ``gd`` and between goals and robot ``gr``; ``redo`` and whether any is due."""
    anyone = False
    for i in range(gd.shape[0]):
        g = gd[i]
        progress = g < best[i] - PROGRESS_M
        if progress:
            best[i] = g
            stuck[i] = 0.0
        else:
            stuck[i] = stuck[i] + dt
        s = stuck[i]
        due = g < GOAL_TOL_M or s > STUCK_S
        if robot and gr[i] < reach[i]:
            due = True
        due = due and s >= 0.0
        redo[i] = due
        anyone = anyone or due
    return anyone


_gaps = compiled(_gaps_py)
_weights = compiled(_weights_py)
_evasion_factor = compiled(_evasion_factor_py)
_speed_factor = compiled(_speed_factor_py)
_goals = compiled(_goals_py)
_pair_push = compiled(_pair_push_py)
_legs = compiled(_legs_py)
_rows = compiled(_rows_py)
_sources = compiled(_sources_py)
_clamp = compiled(_clamp_py)

_INV_B_EVADE = 1.0 / B_EVADE


class Kernels:
    """The compiled kernels (``python=True``: the plain-Python ones)."""

    def __init__(self, python: bool = False) -> None:
        fns = (
            (_gaps_py, _weights_py, _evasion_factor_py, _speed_factor_py, _goals_py)
            + (_pair_push_py, _legs_py, _rows_py, _sources_py, _clamp_py)
            if python
            else (_gaps, _weights, _evasion_factor, _speed_factor, _goals)
            + (_pair_push, _legs, _rows, _sources, _clamp)
        )
        self.gaps, self.weights, self.evasion_factor, self.speed_factor, self.goals = fns[:5]
        self.pair_push, self.legs, self.rows, self.sources, self.clamp = fns[5:]


def candidate_rows(
    kern: Kernels, obstacles: Obstacles, z: NDArray[np.complex128]
) -> NDArray[np.complex128]:
    """:meth:`.Obstacles.rows` with the kernel (the same rows)."""
    if not obstacles.broad_phase:
        return obstacles.rows(z)
    g = obstacles.grid
    rows = np.empty((len(z), g.cells.shape[1], 3), dtype=np.complex128)
    nx, ny = g.shape
    kern.rows(z, g.origin_c.real, g.origin_c.imag, 1.0 / CELL_M, nx, ny, g.cells, g.segrows, rows)
    return rows


def source_vectors(
    kern: Kernels,
    z: NDArray[np.complex128],
    rows: NDArray[np.complex128],
    rz: complex | None,
) -> NDArray[np.complex128]:
    """:func:`.dynamics.source_vectors` with the kernels (the same vectors)."""
    n = len(z)
    k_cols = rows.shape[1]
    diff = np.empty((n, n + 1 + k_cols), dtype=np.complex128)
    a = np.empty((n, k_cols), dtype=np.complex128)
    kern.sources(z, _FAR if rz is None else rz, rows[..., 0], diff, a)
    cd = rows[..., 1]  # conj(d)
    t = np.empty((n, k_cols))
    kern.clamp(a * cd, rows[..., 2].real, t)
    np.subtract(a, t * cd.conjugate(), out=diff[:, n + 1 :])  # closest point -> person
    return diff


def social_force(
    kern: Kernels,
    crowd: Crowd,
    z: NDArray[np.complex128],
    v: NDArray[np.complex128],
    goal: NDArray[np.complex128],
    rows: NDArray[np.complex128],
    rz: complex | None,
    k: StepConstants,
) -> tuple[NDArray[np.complex128], float, FloatArray, float]:
    """:func:`.dynamics.social_force`, with the kernels: the same force and gaps."""
    n = crowd.n
    e, force = driving_force(z, v, goal, k)
    diff = source_vectors(kern, z, rows, rz)
    d = np.abs(diff)
    arg = np.empty_like(d)
    earg = np.empty(n)
    wall_gap = np.empty(n)
    robot = rz is not None
    pair_gap, robot_gap = kern.gaps(
        d, n, k.log_a, k.inv_b, k.rsum_masked, k.radius, robot, k.robot_need,
        k.evade_log_a, _INV_B_EVADE, arg, earg, wall_gap,
    )  # fmt: skip
    w = np.exp(arg)
    kern.weights(w, d, n, REACH_M)
    force += (w * diff).sum(axis=1)
    if not robot:
        return force, pair_gap, wall_gap, np.inf
    er = e.conjugate() * diff[:, n]
    side = np.empty(n, dtype=np.complex128)
    kern.evasion_factor(np.exp(earg), er, KEEP_RIGHT_M, side)
    force += side * e
    return force, pair_gap, wall_gap, robot_gap


def speed_factor(kern: Kernels, v: NDArray[np.complex128], k: StepConstants) -> FloatArray:
    """The speed cap's factor ``min(1, vmax / max(|v|, 1e-9))`` (H&M eq. 8)."""
    out = np.empty(len(v))
    kern.speed_factor(np.abs(v), k.vmax, out)
    return out


def goals_due(
    kern: Kernels,
    crowd: Crowd,
    goal: NDArray[np.complex128],
    z: NDArray[np.complex128],
    dt_s: float,
    rz: complex | None,
    k: StepConstants,
) -> NDArray[np.bool_] | None:
    """:func:`.dynamics.goals_due` with the kernel (``best_goal_m`` and ``stuck_s`` updated
    in place): who needs a new goal, or None when nobody does."""
    for name in ("best_goal_m", "stuck_s"):
        a = getattr(crowd, name)
        if not (a.flags.writeable and a.flags.c_contiguous and a.dtype == np.float64):
            setattr(crowd, name, np.array(a, dtype=np.float64))
    gd = np.abs(goal - z)
    gr = gd if rz is None else np.abs(goal - rz)
    redo = np.empty(crowd.n, dtype=bool)
    due = kern.goals(
        gd, crowd.best_goal_m, crowd.stuck_s, float(dt_s), rz is not None, gr,
        k.robot_goal_reach, redo,
    )  # fmt: skip
    return redo if due else None
