"""Optional numba backend of :func:`dynmap_sim.sensors.raycast.cast_scan` (extra ``fast``),
with numpy's ranges and hit indices bit for bit.

The numpy caster's pair arithmetic is written as one compiled loop, operation for operation
and operand for operand, its complex products and ``abs`` as :mod:`dynmap_sim.numpy_complex`
reproduces numpy's on this install (fused multiply-adds on x86-64-v3, plain on older CPUs;
:func:`~dynmap_sim.numpy_complex.numpy_complex_mode` probes which). The broad phase (the beams
each shape's bearing interval covers, widened by one beam) uses ``atan2``/``asin``, whose
last bits differ between numpy and libm, but a one-beam margin only adds pairs that miss;
the bounding-box range cull likewise keeps every segment within range. Where two shapes are
hit at the same range the later one in numpy's pair order wins, as in numpy's scatter
(segments before their copies shifted by a turn, then circles, then theirs).

So, with the mode numpy matches, the ranges and hit indices are numpy's (tests compare the
bytes); with another mode they agree to rounding (~1e-15 m). Install with
``pip install "dynmap-sim[fast]"``; :func:`numba_available` says whether it can be used.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, jitable, pick_kernel
from dynmap_sim.jit import numba_available as numba_available  # re-exported
from dynmap_sim.numpy_complex import FUSED, cabs, cmul_im, cmul_re, numpy_complex_mode
from dynmap_sim.sensors.raycast import SegmentCache

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@jitable
def _beam_run(start: float, span: float, amin: float, inv_inc: float, shift: float, n: int):  # type: ignore[no-untyped-def]
    """First and last beam of the numpy caster's run for a bearing interval (``shift``: 0,
    or one turn for the copy of an interval that wraps), widened by one beam."""
    s_b = ((start - amin) % (2.0 * math.pi) - shift) * inv_inc
    return max(int(s_b) - 1, 0), min(int(s_b + span * inv_inc) + 1, n - 1)


def _kernel_py(  # type: ignore[no-untyped-def]
    ox, oy, rr, ri, amin, inc, cos_l, sin_l, r_max, data, bbox, circles, mode, ranges, hit
):
    """The casting loop (see the module doc): the sensor at ``(ox, oy)``, ``rr + i ri`` the
    rotation map -> sensor; ``ranges`` / ``hit`` receive the result."""
    n = cos_l.shape[0]
    inv_inc = 1.0 / inc
    two_pi = 2.0 * math.pi
    for b in range(n):
        ranges[b] = math.inf
        hit[b] = -1
    n_seg = data.shape[1]
    # per segment in range: a, d (sensor frame), a x d, and its bearing interval
    seg = np.empty((n_seg, 7))
    near = np.empty(n_seg, np.int64)
    m = 0
    for k in range(n_seg):
        if (
            bbox[0, k] > ox + r_max
            or bbox[2, k] < ox - r_max
            or bbox[1, k] > oy + r_max
            or bbox[3, k] < oy - r_max
        ):
            continue
        wr, wi = data[0, k] - ox, data[1, k] - oy
        ar, ai = cmul_re(wr, wi, rr, ri, mode), cmul_im(wr, wi, rr, ri, mode)
        d0r, d0i = data[2, k], data[3, k]
        dr, di = cmul_re(d0r, d0i, rr, ri, mode), cmul_im(d0r, d0i, rr, ri, mode)
        br, bi = ar + dr, ai + di
        a_x_d = cmul_im(ar, -ai, br, bi, mode)  # conj(a) b: imag a x b, real a . b
        span = abs(math.atan2(a_x_d, cmul_re(ar, -ai, br, bi, mode)))
        start = math.atan2(ai, ar) if a_x_d >= 0.0 else math.atan2(bi, br)
        seg[m, 0], seg[m, 1], seg[m, 2], seg[m, 3] = ar, ai, dr, di
        seg[m, 4], seg[m, 5], seg[m, 6] = a_x_d, start, span
        near[m] = k
        m += 1
    for shift in (0.0, two_pi):
        for q in range(m):
            ar, ai, dr, di, a_x_d = seg[q, 0], seg[q, 1], seg[q, 2], seg[q, 3], seg[q, 4]
            lo, hi = _beam_run(seg[q, 5], seg[q, 6], amin, inv_inc, shift, n)
            for b in range(lo, hi + 1):
                ucr, uci = cos_l[b], -sin_l[b]  # conj(u)
                den = cmul_im(ucr, uci, dr, di, mode)  # u x d
                if den == 0.0:  # numpy: t is +-inf or NaN, never a hit
                    continue
                inv = 1.0 / den
                t = a_x_d * inv
                s_neg = cmul_im(ar, ai, ucr, uci, mode) * inv
                if t >= 0.0 and t <= r_max and s_neg <= 0.0 and s_neg >= -1.0 and t <= ranges[b]:
                    ranges[b] = t
                    hit[b] = near[q]
    # circles within range: centre c (sensor frame), |c|^2 - r^2, inside, bearing interval
    n_circ = circles.shape[0]
    circ = np.empty((n_circ, 6))
    cnear = np.empty(n_circ, np.int64)
    m = 0
    for j in range(n_circ):
        wr, wi = circles[j, 0] - ox, circles[j, 1] - oy
        r = circles[j, 2]
        dist = cabs(wr, wi, mode)
        if not dist <= r_max + r:
            continue
        cr, ci = cmul_re(wr, wi, rr, ri, mode), cmul_im(wr, wi, rr, ri, mode)
        c0 = (dist - r) * (dist + r)
        half = math.pi if c0 <= 0.0 else math.asin(r / max(dist, r))
        circ[m, 0], circ[m, 1], circ[m, 2] = cr, ci, c0
        circ[m, 3], circ[m, 4] = math.atan2(ci, cr) - half, 2.0 * half
        cnear[m] = j
        m += 1
    for shift in (0.0, two_pi):
        for q in range(m):
            cr, ci, c0 = circ[q, 0], circ[q, 1], circ[q, 2]
            lo, hi = _beam_run(circ[q, 3], circ[q, 4], amin, inv_inc, shift, n)
            for b in range(lo, hi + 1):
                if c0 <= 0.0:  # the sensor inside the circle
                    t = 0.0
                else:
                    bdot = cmul_re(cos_l[b], -sin_l[b], cr, ci, mode)  # u . c
                    disc = bdot * bdot - c0
                    if not disc >= 0.0:
                        continue
                    t = bdot - math.sqrt(disc)
                if t >= 0.0 and t <= r_max and t <= ranges[b]:
                    ranges[b] = t
                    hit[b] = n_seg + cnear[q]


_kernel = compiled(_kernel_py)


def cast_scan_numba(
    pose: tuple[float, float, float],
    angle_min_rad: float,
    angle_increment_rad: float,
    cos_l: FloatArray,
    sin_l: FloatArray,
    max_range_m: float,
    segments: SegmentCache,
    circles: FloatArray | None = None,
    u_l: NDArray[np.complex128] | None = None,
    python: bool = False,
) -> tuple[FloatArray, IntArray]:
    """Same contract and numbers as :func:`dynmap_sim.sensors.raycast.cast_scan`, compiled
    with numba (``python``: the same kernel uncompiled, for the tests).

    The complex arithmetic follows :func:`numpy_complex_mode` (:data:`FUSED` when it is
    None: the ranges then agree with numpy's to rounding). ``u_l`` (the numpy caster's
    complex beam directions) is accepted and ignored.
    """
    kernel = pick_kernel(_kernel_py, _kernel, python, "ray casting")
    mode = numpy_complex_mode(python)
    n = cos_l.shape[0]
    ranges = np.empty(n)
    hit = np.empty(n, dtype=np.int64)
    circ = np.zeros((0, 3)) if circles is None else np.ascontiguousarray(circles, dtype=np.float64)
    heading = float(pose[2])
    kernel(
        float(pose[0]),
        float(pose[1]),
        math.cos(heading),  # the numpy caster's rotation map -> sensor, cos - i sin
        -math.sin(heading),
        float(angle_min_rad),
        float(angle_increment_rad),
        cos_l,
        sin_l,
        float(max_range_m),
        segments.data,
        segments.bbox,
        circ,
        FUSED if mode is None else mode,
        ranges,
        hit,
    )
    return ranges, hit
