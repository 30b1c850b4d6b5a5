"""Optional numba kernels of the people's geometry queries (extra ``fast``): where a body
fits (:meth:`.Obstacles.free_mask`) and what is in line of sight (:meth:`.Obstacles.visible`,
:meth:`.Obstacles.visible_many`), with numpy's answers bit for bit.

Choosing a goal (:func:`.spawning.pick_goal`) asks these for a few dozen candidate points at a
time; in numpy each ask is a few dozen calls on small arrays (about a quarter of a millisecond),
which made goal choice an eighth of a crowded room's step with the other kernels compiled.
The kernels do numpy's arithmetic operation for operation: real ``+ - * /`` and comparisons
are the same in any loop, and the complex products and ``abs`` are numpy's as
:mod:`dynmap_sim.numpy_complex` reproduces them (in the mode
:func:`~dynmap_sim.numpy_complex.numpy_complex_mode` finds: fused multiply-adds on
x86-64-v3, plain elsewhere). :func:`queries` hands them out only when that mode is known;
without it the people keep numpy's queries. The answers are booleans of comparisons of
those numbers, so they are numpy's (the tests compare them on the shipped worlds).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, pick_kernel
from dynmap_sim.jit import numba_available as numba_available  # re-exported
from dynmap_sim.numpy_complex import cabs, cmul_im, cmul_re, numpy_complex_mode
from dynmap_sim.world.people.dynamics_numba import Kernels, candidate_rows
from dynmap_sim.world.people.obstacles import Obstacles
from dynmap_sim.world.people.params import REACH_M
from dynmap_sim.world.polygons import FloatArray


def _clear_py(z, rows, r_clear, mode, out):  # type: ignore[no-untyped-def]
    """Of :meth:`.Obstacles.free_mask`: each point's distance to its candidate segments
    (rows ``p0, conj(d), 1/|d|^2``) above ``r_clear``: ``a = z - p0``, ``t = clip(Re(a
    conj(d)) / |d|^2, 0, 1)``, ``|a - t d|`` (``t`` times ``conj(conj(d))`` as numpy's
    complex product), their NaN-propagating minimum."""
    for i in range(z.shape[0]):
        zr, zi = z[i].real, z[i].imag
        best = math.inf
        for j in range(rows.shape[1]):
            p0, cd = rows[i, j, 0], rows[i, j, 1]
            ar, ai = zr - p0.real, zi - p0.imag
            t = cmul_re(ar, ai, cd.real, cd.imag, mode) * rows[i, j, 2].real
            if not (t >= 0.0 or t != t):  # np.maximum(t, 0): NaN kept
                t = 0.0
            if not (t <= 1.0 or t != t):  # np.minimum(t, 1)
                t = 1.0
            wr = cmul_re(t, 0.0, cd.real, -cd.imag, mode)
            wi = cmul_im(t, 0.0, cd.real, -cd.imag, mode)
            d = cabs(ar - wr, ai - wi, mode)
            if d != d or best != best:
                best = math.nan
            elif d < best:
                best = d
        out[i] = best > r_clear


def _inside_py(px, py, seg, cross_den, cross_dx, starts, sizes, y_lo, y_hi, x_hi, out):  # type: ignore[no-untyped-def]
    """Of :meth:`.Obstacles.inside_any`: the crossing-number parity of a ray toward +x per
    outline, only for the outlines whose bounds it can cross (the others' parity is 0,
    exactly: :meth:`.Obstacles._outline_bounds`), each pair in the numpy test's arithmetic."""
    for i in range(px.shape[0]):
        x, y = px[i], py[i]
        inside = False
        for o in range(starts.shape[0]):
            if not (y_lo[o] <= y and y < y_hi[o] and x < x_hi[o]):
                continue
            odd = False
            for k in range(starts[o], starts[o] + sizes[o]):
                y0, y1 = seg[k, 1], seg[k, 3]
                if (y0 > y) != (y1 > y):
                    t = (y - y0) / cross_den[k]
                    if seg[k, 0] + t * cross_dx[k] > x:
                        odd = not odd
            if odd:
                inside = True
                break
        out[i] = inside


def _visible_py(ax, ay, bx, by, p0, d, mode, out):  # type: ignore[no-untyped-def]
    """Of :meth:`.Obstacles.visible_many`: no segment ``p0 + s d`` properly crosses ``a``-``b``
    (the signs of numpy's four cross products; ``b - a`` with numpy's zeros' signs aside,
    which no product's sign test can see)."""
    for i in range(bx.shape[0]):
        abr, abi = bx[i] - ax, by[i] - ay
        seen = True
        for k in range(p0.shape[0]):
            w0r, w0i = p0[k].real - ax, p0[k].imag - ay
            dr, di = d[k].real, d[k].imag
            o1 = cmul_im(abr, -abi, w0r, w0i, mode)
            o2 = cmul_im(abr, -abi, w0r + dr, w0i + di, mode)
            o3 = cmul_im(dr, -di, w0r, w0i, mode)
            o4 = cmul_im(dr, -di, w0r - abr, w0i - abi, mode)
            if o1 * o2 < 0.0 and o3 * o4 < 0.0:
                seen = False
                break
        out[i] = seen


_clear = compiled(_clear_py)
_inside = compiled(_inside_py)
_visible = compiled(_visible_py)


class CompiledQueries:
    """:class:`.Obstacles`' queries that goal choice asks (``free_mask``, ``visible``,
    ``visible_many``) in the kernels, for ``obstacles`` (``python``: the plain kernels);
    the rest of the queries, and the cases the kernels do not cover (no broad phase, a
    body too wide for the grid's reach, outlines the bounds do not describe), are
    ``obstacles``' own."""

    def __init__(self, obstacles: Obstacles, mode: int, python: bool = False) -> None:
        self.obstacles = obstacles
        self.segments = obstacles.segments
        self.mode = mode
        self._kern = Kernels(python)
        what = "people backend"
        self._clear = pick_kernel(_clear_py, _clear, python, what)
        self._inside = pick_kernel(_inside_py, _inside, python, what)
        self._visible = pick_kernel(_visible_py, _visible, python, what)

    def free_mask(self, points: FloatArray, r: float) -> NDArray[np.bool_]:
        """:meth:`.Obstacles.free_mask`, the same booleans."""
        obs = self.obstacles
        box = obs._outline_box
        if (
            len(obs.segments) == 0
            or not obs.broad_phase
            or not r + 0.05 < REACH_M
            or (obs.outline_starts is not None and box is None)
        ):
            return obs.free_mask(points, r)
        pts = np.ascontiguousarray(points, dtype=np.float64)
        z = pts.view(np.complex128)[:, 0]
        clear = np.empty(len(z), dtype=bool)
        self._clear(z, candidate_rows(self._kern, obs, z), r + 0.05, self.mode, clear)
        if obs.outline_starts is None:
            return clear
        inside = np.empty(len(z), dtype=bool)
        y_lo, y_hi, x_hi, sizes = box  # type: ignore[misc]
        starts = np.ascontiguousarray(obs.outline_starts, dtype=np.int64)
        self._inside(pts[:, 0].copy(), pts[:, 1].copy(), obs.segments, obs._cross_den,
                     obs._cross_dx, starts, sizes, y_lo, y_hi, x_hi, inside)  # fmt: skip
        return clear & ~inside

    def visible_many(self, a: FloatArray, bs: FloatArray) -> NDArray[np.bool_]:
        """:meth:`.Obstacles.visible_many`, the same booleans."""
        obs = self.obstacles
        out = np.ones(len(bs), dtype=bool)
        if len(obs.segments):
            b = np.ascontiguousarray(bs, dtype=np.float64)
            self._visible(float(a[0]), float(a[1]), b[:, 0].copy(), b[:, 1].copy(),
                          obs._seg_p0, obs._seg_d, self.mode, out)  # fmt: skip
        return out

    def visible(self, a: FloatArray, b: FloatArray) -> bool:
        """:meth:`.Obstacles.visible`, the same answer."""
        return bool(self.visible_many(a, np.asarray(b, dtype=np.float64).reshape(1, 2))[0])


def queries(obstacles: Obstacles, python: bool = False) -> Obstacles | CompiledQueries:
    """The goal choice's queries of ``obstacles``: compiled where the compiled casting knows
    numpy's complex arithmetic on this install, else ``obstacles`` itself."""
    mode = numpy_complex_mode(python)
    return obstacles if mode is None else CompiledQueries(obstacles, mode, python)
