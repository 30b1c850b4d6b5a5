"""Optional numba backend of :func:`dynmap_sim.sensors.raycast.cast_scan` (extra ``fast``).

The same algorithm as the numpy caster — bounding-box range cull, angular-interval broad
phase per shape, exact segment and circle intersections — written as one compiled loop, so
it returns the same ranges (to rounding, far below 1e-6 m). Install with
``pip install "dynmap-sim[fast]"``; :func:`numba_available` says whether it can be used.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, require_numba
from dynmap_sim.jit import numba_available as numba_available  # re-exported
from dynmap_sim.sensors.raycast import SegmentCache

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def _kernel_py(
    ox: float,
    oy: float,
    heading: float,
    amin: float,
    inc: float,
    cos_l: FloatArray,
    sin_l: FloatArray,
    r_max: float,
    data: FloatArray,
    bbox: FloatArray,
    circles: FloatArray,
    ranges: FloatArray,
    hit: IntArray,
) -> None:
    """The casting loop (compiled by numba; see the numpy module for the geometry)."""
    two_pi = 2.0 * math.pi
    n = cos_l.shape[0]
    ch = math.cos(heading)
    sh = math.sin(heading)
    for b in range(n):
        ranges[b] = math.inf
        hit[b] = -1
    n_seg = data.shape[1]
    for k in range(n_seg):
        if (
            bbox[0, k] > ox + r_max
            or bbox[2, k] < ox - r_max
            or bbox[1, k] > oy + r_max
            or bbox[3, k] < oy - r_max
        ):
            continue
        wx = data[0, k] - ox
        wy = data[1, k] - oy
        ax = ch * wx + sh * wy
        ay = ch * wy - sh * wx
        dx = ch * data[2, k] + sh * data[3, k]
        dy = ch * data[3, k] - sh * data[2, k]
        bx = ax + dx
        by = ay + dy
        cr = ax * by - ay * bx
        span = math.atan2(abs(cr), ax * bx + ay * by)
        start = math.atan2(ay, ax) if cr >= 0.0 else math.atan2(by, bx)
        rel = (start - amin) % two_pi
        for shift in (0.0, two_pi):
            s0 = (rel - shift) / inc
            lo = max(int(math.ceil(s0)) - 1, 0)
            hi = min(int(math.floor(s0 + span / inc)) + 1, n - 1)
            for b in range(lo, hi + 1):
                ux = cos_l[b]
                uy = sin_l[b]
                den = ux * dy - uy * dx
                if den == 0.0:
                    continue
                inv = 1.0 / den
                t = (ax * dy - ay * dx) * inv
                s = (ax * uy - ay * ux) * inv
                if t >= 0.0 and s >= 0.0 and s <= 1.0 and t < ranges[b]:
                    ranges[b] = t
                    hit[b] = k
    for j in range(circles.shape[0]):
        wx = circles[j, 0] - ox
        wy = circles[j, 1] - oy
        r = circles[j, 2]
        d2 = wx * wx + wy * wy
        if d2 > (r_max + r) * (r_max + r):
            continue
        cx = ch * wx + sh * wy
        cy = ch * wy - sh * wx
        c0 = d2 - r * r
        half = math.pi if c0 <= 0.0 else math.asin(min(r / math.sqrt(d2), 1.0))
        rel = (math.atan2(cy, cx) - half - amin) % two_pi
        for shift in (0.0, two_pi):
            s0 = (rel - shift) / inc
            lo = max(int(math.ceil(s0)) - 1, 0)
            hi = min(int(math.floor(s0 + 2.0 * half / inc)) + 1, n - 1)
            for b in range(lo, hi + 1):
                bb = cos_l[b] * cx + sin_l[b] * cy
                disc = bb * bb - c0
                if disc < 0.0:
                    continue
                if c0 <= 0.0:
                    t = 0.0
                elif bb < 0.0:
                    continue
                else:
                    t = bb - math.sqrt(disc)
                if t < ranges[b]:
                    ranges[b] = t
                    hit[b] = n_seg + j
    for b in range(n):
        if ranges[b] > r_max:
            ranges[b] = math.inf
            hit[b] = -1


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
) -> tuple[FloatArray, IntArray]:
    """Same contract as :func:`dynmap_sim.sensors.raycast.cast_scan`, compiled with numba.

    ``u_l`` (the numpy caster's complex beam directions) is accepted and ignored.
    """
    require_numba("backend")
    n = cos_l.shape[0]
    ranges = np.empty(n)
    hit = np.empty(n, dtype=np.int64)
    circ = np.zeros((0, 3)) if circles is None else np.ascontiguousarray(circles, dtype=np.float64)
    _kernel(
        float(pose[0]),
        float(pose[1]),
        float(pose[2]),
        float(angle_min_rad),
        float(angle_increment_rad),
        cos_l,
        sin_l,
        float(max_range_m),
        segments.data,
        segments.bbox,
        circ,
        ranges,
        hit,
    )
    return ranges, hit
