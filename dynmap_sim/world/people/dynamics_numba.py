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

Where those are known to be reproduced too — numpy's complex products and ``abs`` in the
mode :func:`~dynmap_sim.numpy_complex.numpy_complex_mode` finds, its ``exp`` equal to
libm's (:func:`exp_matches_numpy`, probed once per process) — the whole social force is one
kernel (:func:`_force_py`): the driving force, the sources, the gaps, the repulsions and
their row sums in numpy's pairwise order (:func:`_row_sum`), the evasion. The room of
``benchmarks/bench_peers.py`` with 10 people: the force 36 -> 10 µs, the env step 13 %
faster (median of 12 alternating rounds in one process).

Each kernel is plain Python (what the tests also run), compiled with
:func:`dynmap_sim.jit.compiled` when numba is installed.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, jitable, pick_kernel
from dynmap_sim.jit import numba_available as numba_available  # re-exported
from dynmap_sim.numpy_complex import cabs, cmul_im, cmul_re, numpy_complex_mode
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
    TAU_S,
)
from dynmap_sim.world.polygons import FloatArray


@jitable
def _nan_min(a, b):  # type: ignore[no-untyped-def]
    """One step of numpy's ``min``: ``b`` where it is smaller than ``a`` or NaN (a NaN, once
    taken, stays)."""
    return b if (b < a or b != b) else a


@jitable
def _at_least_1e9(d):  # type: ignore[no-untyped-def]
    """numpy's ``np.maximum(d, 1e-9)`` (NaN stays)."""
    return 1e-9 if d < 1e-9 else d


@jitable
def _clip01(v):  # type: ignore[no-untyped-def]
    """numpy's ``np.minimum(np.maximum(v, 0), 1)`` (the first operand when equal, NaN kept)."""
    if not (v >= 0.0 or v != v):
        v = 0.0
    if not (v <= 1.0 or v != v):
        v = 1.0
    return v


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
            pair_gap = _nan_min(pair_gap, d[i, j] - rsum_masked[i, j])
        w = d[i, n + 1]
        for j in range(n + 2, m):
            w = _nan_min(w, d[i, j])
        wall_gap[i] = w - radius[i]
        if robot:
            dr = d[i, n]
            robot_gap = _nan_min(robot_gap, dr - robot_need[i])
            earg[i] = evade_log_a[i] - _at_least_1e9(dr) * inv_b_evade
    return pair_gap, robot_gap


def _weights_py(w, d, n, reach):  # type: ignore[no-untyped-def]
    """The repulsions' weights in place: ``w / max(d, 1e-9)``, 0 for segments beyond
    ``reach``."""
    p, m = d.shape
    for i in range(p):
        for j in range(m):
            dj = d[i, j]
            w[i, j] = w[i, j] / _at_least_1e9(dj)
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
        f = vmax[i] / _at_least_1e9(s)
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
            out[i, j] = o / _at_least_1e9(dj)
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
            t[i, j] = _clip01(prod[i, j].real * inv[i, j])


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


#: The longest row (people + robot + candidate segments) :func:`_force_py` sums: numpy's
#: pairwise sum splits a row of more than 64 complex numbers once, up to 121 into halves of
#: at most 64 (longer rows keep numpy's sums).
FORCE_MAX_COLS = 121


@jitable
def _pairwise_block(x, lo, m):  # type: ignore[no-untyped-def]
    """numpy's pairwise sum of ``x[lo : lo + m]`` (one part of ``m <= 64`` complex numbers,
    numpy's ``pairwise_sum`` of ``2 m <= 128`` floats): under 4 numbers in order, else four
    accumulators over every fourth number, joined ``(r0 + r1) + (r2 + r3)``, then the rest."""
    if m < 4:
        s = -0.0
        for i in range(lo, lo + m):
            s += x[i]
        return s
    r0 = x[lo]
    r1 = x[lo + 1]
    r2 = x[lo + 2]
    r3 = x[lo + 3]
    i = 4
    end = m - m % 4
    while i < end:
        r0 += x[lo + i]
        r1 += x[lo + i + 1]
        r2 += x[lo + i + 2]
        r3 += x[lo + i + 3]
        i += 4
    s = (r0 + r1) + (r2 + r3)
    while i < m:
        s += x[lo + i]
        i += 1
    return s


@jitable
def _row_sum(x, m):  # type: ignore[no-untyped-def]
    """``x[:m].sum()`` of one part of a complex row as numpy's reduction gives it: ``0 +``
    the pairwise sum, which splits ``m > 64`` numbers at ``(m - m % 8) / 2`` (``m <=``
    :data:`FORCE_MAX_COLS`)."""
    if m <= 64:
        return 0.0 + _pairwise_block(x, 0, m)
    c2 = (m - m % 8) // 2
    return 0.0 + (_pairwise_block(x, 0, c2) + _pairwise_block(x, c2, m - c2))


def _force_py(  # type: ignore[no-untyped-def]
    z,
    v,
    goal,
    rows,
    rz,
    robot,
    v0_tau,
    inv_tau,
    log_a,
    inv_b,
    rsum_masked,
    radius,
    robot_need,
    evade_log_a,
    inv_b_evade,
    reach,
    keep,
    mode,
    force,
    wall_gap,
    sre,
    sim,
):
    """:func:`social_force` in one loop: numpy's operations one by one, in its order, with
    numpy's complex products, quotients by reals and ``abs`` (``mode``,
    :mod:`dynmap_sim.numpy_complex`), libm's ``exp`` (which numpy's gives here:
    :func:`exp_matches_numpy`) and its pairwise row sums (:func:`_row_sum`). Writes the
    forces and the gaps to the walls; returns the smallest gaps between two bodies and to
    the robot's disc (inf without a robot). ``sre``, ``sim``: scratch rows of the summed terms."""
    n = z.shape[0]
    m = n + 1 + rows.shape[1]
    pair_gap = math.inf
    robot_gap = math.inf
    for i in range(n):
        zr = z[i].real
        zi = z[i].imag
        # driving force: e = (goal - z) / max(|goal - z|, 1e-9), v0/tau e - v (1/tau)
        tr = goal[i].real - zr
        ti = goal[i].imag - zi
        ab = cabs(tr, ti, mode)
        den = ab if (ab >= 1e-9 or ab != ab) else 1e-9
        rat = 0.0 / den  # numpy's complex quotient by (den + 0j), Smith's form
        scl = 1.0 / (den + 0.0 * rat)
        er_ = (tr + ti * rat) * scl
        ei_ = (ti - tr * rat) * scl
        vr = v[i].real
        vi = v[i].imag
        fr = cmul_re(v0_tau[i], 0.0, er_, ei_, mode) - cmul_re(vr, vi, inv_tau, 0.0, mode)
        fi = cmul_im(v0_tau[i], 0.0, er_, ei_, mode) - cmul_im(vr, vi, inv_tau, 0.0, mode)
        # sources -> person: people, the robot, the closest point of each segment
        wall = math.inf
        dn_r = 0.0
        dn_i = 0.0
        earg = 0.0
        for j in range(m):
            if j < n:
                dr_ = zr - z[j].real
                di_ = zi - z[j].imag
            elif j == n:
                dr_ = zr - rz.real
                di_ = zi - rz.imag
                dn_r = dr_
                dn_i = di_
            else:
                c = j - n - 1
                ar = zr - rows[i, c, 0].real
                ai = zi - rows[i, c, 0].imag
                cdr = rows[i, c, 1].real
                cdi = rows[i, c, 1].imag
                t = _clip01(cmul_re(ar, ai, cdr, cdi, mode) * rows[i, c, 2].real)
                dr_ = ar - cmul_re(t, 0.0, cdr, -cdi, mode)
                di_ = ai - cmul_im(t, 0.0, cdr, -cdi, mode)
            d = cabs(dr_, di_, mode)
            arg = log_a[i, j] - d * inv_b[i, j]
            if j < n:
                pair_gap = _nan_min(pair_gap, d - rsum_masked[i, j])
            elif j == n:
                if robot:
                    robot_gap = _nan_min(robot_gap, d - robot_need[i])
                    earg = evade_log_a[i] - _at_least_1e9(d) * inv_b_evade
            elif j == n + 1:
                wall = d
            else:
                wall = _nan_min(wall, d)
            w = math.exp(arg) / _at_least_1e9(d)
            if j > n and d > reach:
                w = 0.0
            sre[j] = cmul_re(w, 0.0, dr_, di_, mode)
            sim[j] = cmul_im(w, 0.0, dr_, di_, mode)
        wall_gap[i] = wall - radius[i]
        fr = fr + _row_sum(sre, m)
        fi = fi + _row_sum(sim, m)
        if robot:
            # the evasion: conj(e) (z - robot), sideways (+-1j) times e
            cr = cmul_re(er_, -ei_, dn_r, dn_i, mode)
            ci = cmul_im(er_, -ei_, dn_r, dn_i, mode)
            mag = math.exp(earg) * (1.0 if cr < 0.0 else 0.0)
            side = (mag if ci > keep else -mag) + 0.0
            fr = fr + cmul_re(0.0, side, er_, ei_, mode)
            fi = fi + cmul_im(0.0, side, er_, ei_, mode)
        force[i] = complex(fr, fi)
    return pair_gap, robot_gap


def _exp_probe_py(x, out):  # type: ignore[no-untyped-def]
    for i in range(x.shape[0]):
        out[i] = math.exp(x[i])


_exp_probe = compiled(_exp_probe_py)


@functools.cache
def exp_matches_numpy(python: bool = False) -> bool:
    """Whether the kernels' ``exp`` (libm's) gives numpy's float64 ``exp`` bits on this
    install: numpy runs its own SIMD loops (x86-64-v3, AVX-512), which nothing promises to
    round as libm does. Probed once per process on 3,000 values over the exponents the
    social force meets and beyond (measured 2026-11-28 on this project's x86-64-v3 machine:
    0 of 3,000,000 differ). ``python``: the plain-Python kernel (``math.exp``)."""
    probe = pick_kernel(_exp_probe_py, _exp_probe, python, "kernels")
    rng = np.random.default_rng(20261128)
    x = np.concatenate([rng.uniform(-60.0, 5.0, 2000), rng.uniform(-745.0, 709.0, 1000)])
    out = np.empty_like(x)
    probe(x, out)
    return out.tobytes() == np.exp(x).tobytes()


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
_force = compiled(_force_py)

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
        # the whole force in one kernel where its complex arithmetic and exp are numpy's
        mode = numpy_complex_mode(python)
        self.force = _force_py if python else _force
        self.force_mode = mode if mode is not None and exp_matches_numpy(python) else None


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
    """:func:`.dynamics.social_force`, with the kernels: the same force and gaps (in one
    kernel, :func:`_force_py`, where numpy's complex arithmetic and ``exp`` are known to be
    reproduced here; else its parts between numpy's calls)."""
    n = crowd.n
    m = n + 1 + rows.shape[1]
    if kern.force_mode is not None and m <= FORCE_MAX_COLS:
        force = np.empty(n, dtype=np.complex128)
        wall_gap = np.empty(n)
        pair_gap, robot_gap = kern.force(
            z, v, goal, rows, _FAR if rz is None else rz, rz is not None, k.v0_tau,
            1.0 / TAU_S, k.log_a, k.inv_b, k.rsum_masked, k.radius, k.robot_need,
            k.evade_log_a, _INV_B_EVADE, REACH_M, KEEP_RIGHT_M, kern.force_mode, force,
            wall_gap, np.empty(m), np.empty(m),
        )  # fmt: skip
        return force, pair_gap, wall_gap, robot_gap  # inf without a robot
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
