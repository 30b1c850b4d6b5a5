"""Exact 2-D ray casting of one scan against line segments and circles (a compiled kernel).

All beams of a scan start at the sensor, so each shape within range, moved into the sensor
frame, covers one interval of bearings and hence one contiguous run of beam indices (widened
by one beam, so that rounding in ``atan2`` never loses a hit). Only those (beam, shape) pairs
are intersected, in closed form:

* segment ``a + s d`` (``0 <= s <= 1``) and ray ``t u``: ``t = (a x d) / (u x d)``,
  ``s = (a x u) / (u x d)`` (2-D cross products);
* circle ``|p - c| = r``: ``t = b - sqrt(b^2 - (|c|^2 - r^2))`` with ``b = u . c`` (0 from
  inside the circle).

Segments whose bounding box lies farther than the range on either axis are skipped first.
Where two shapes are hit at the same range either may be reported. The ranges agree with
pymunk's ``segment_query_first`` to floating-point precision (``tests/sensors/test_raycast.py``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, jitable

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_TWO_PI = 2.0 * math.pi


@jitable
def _beam_run(start: float, span: float, amin: float, inv_inc: float, shift: float, n: int):  # type: ignore[no-untyped-def]
    """First and last beam of the run covering the bearings ``[start, start + span]``
    (``shift``: 0, or one turn for the copy of an interval that wraps past the last beam),
    widened by one beam (truncation toward zero only widens it further)."""
    s_b = ((start - amin) % _TWO_PI - shift) * inv_inc
    return max(int(s_b) - 1, 0), min(int(s_b + span * inv_inc) + 1, n - 1)


@compiled
def _cast(sensor, beams, cos_l, sin_l, segments, circles, ranges, hit):  # type: ignore[no-untyped-def]
    """The casting loop: ``sensor = (x, y, cos, sin)`` of the sensor's pose in the map frame,
    ``beams = (angle_min, increment, range_max)``; writes ``ranges`` and ``hit``."""
    ox, oy, c, s = sensor[0], sensor[1], sensor[2], sensor[3]
    amin, inc, r_max = beams[0], beams[1], beams[2]
    n = cos_l.shape[0]
    inv_inc = 1.0 / inc
    for b in range(n):
        ranges[b] = math.inf
        hit[b] = -1
    n_seg = segments.shape[0]
    for k in range(n_seg):
        x0, y0, x1, y1 = segments[k, 0], segments[k, 1], segments[k, 2], segments[k, 3]
        if (
            min(x0, x1) > ox + r_max
            or max(x0, x1) < ox - r_max
            or min(y0, y1) > oy + r_max
            or max(y0, y1) < oy - r_max
        ):
            continue
        # into the sensor frame (rotation by -heading): first endpoint a, direction d
        wx, wy = x0 - ox, y0 - oy
        ax, ay = c * wx + s * wy, c * wy - s * wx
        ex, ey = x1 - x0, y1 - y0
        dx, dy = c * ex + s * ey, c * ey - s * ex
        bx, by = ax + dx, ay + dy
        a_x_d = ax * dy - ay * dx  # = a x b (> 0: b is counter-clockwise of a)
        span = abs(math.atan2(a_x_d, ax * bx + ay * by))
        start = math.atan2(ay, ax) if a_x_d >= 0.0 else math.atan2(by, bx)
        for shift in (0.0, _TWO_PI):
            lo, hi = _beam_run(start, span, amin, inv_inc, shift, n)
            for b in range(lo, hi + 1):
                ux, uy = cos_l[b], sin_l[b]
                den = ux * dy - uy * dx  # u x d
                if den == 0.0:  # parallel
                    continue
                t = a_x_d / den
                along = (ax * uy - ay * ux) / den
                if 0.0 <= t <= r_max and 0.0 <= along <= 1.0 and t < ranges[b]:
                    ranges[b] = t
                    hit[b] = k
    for j in range(circles.shape[0]):
        wx, wy, r = circles[j, 0] - ox, circles[j, 1] - oy, circles[j, 2]
        dist = math.hypot(wx, wy)
        if not dist <= r_max + r:
            continue
        cx, cy = c * wx + s * wy, c * wy - s * wx
        c0 = (dist - r) * (dist + r)  # |c|^2 - r^2 (<= 0: the sensor is inside)
        half = math.pi if c0 <= 0.0 else math.asin(r / max(dist, r))
        start = math.atan2(cy, cx) - half
        for shift in (0.0, _TWO_PI):
            lo, hi = _beam_run(start, 2.0 * half, amin, inv_inc, shift, n)
            for b in range(lo, hi + 1):
                if c0 <= 0.0:
                    t = 0.0
                else:
                    bdot = cos_l[b] * cx + sin_l[b] * cy  # u . c
                    disc = bdot * bdot - c0
                    if not disc >= 0.0:
                        continue
                    t = bdot - math.sqrt(disc)
                if 0.0 <= t <= r_max and t < ranges[b]:
                    ranges[b] = t
                    hit[b] = n_seg + j


_NO_CIRCLES = np.zeros((0, 3))


def cast_scan(
    pose: tuple[float, float, float],
    angle_min_rad: float,
    angle_increment_rad: float,
    cos_l: FloatArray,
    sin_l: FloatArray,
    max_range_m: float,
    segments: FloatArray,
    circles: FloatArray | None = None,
) -> tuple[FloatArray, IntArray]:
    """Cast all beams of one scan; return the true range [m] and the hit shape of each beam.

    The sensor is at ``pose = (x, y, heading)`` in the map frame; beam ``i`` points at
    ``angle_min_rad + i * angle_increment_rad`` in the sensor frame, and ``cos_l``/``sin_l``
    are the cosines and sines of those angles (:func:`beam_directions`). ``segments`` rows
    are ``x0, y0, x1, y1``, ``circles`` rows ``x, y, r`` [m]. The hit index is a row of the
    segments (``0 .. N-1``), ``N + j`` for circle ``j``, or ``-1`` (no hit within
    ``max_range_m``: range ``+inf``).
    """
    n = cos_l.shape[0]
    ranges = np.empty(n)
    hit = np.empty(n, dtype=np.int64)
    heading = float(pose[2])
    sensor = np.array([pose[0], pose[1], math.cos(heading), math.sin(heading)], dtype=np.float64)
    beams = np.array([angle_min_rad, angle_increment_rad, max_range_m], dtype=np.float64)
    seg = np.ascontiguousarray(segments, dtype=np.float64).reshape(-1, 4)
    circ = _NO_CIRCLES if circles is None else np.ascontiguousarray(circles, dtype=np.float64)
    _cast(sensor, beams, cos_l, sin_l, seg, circ, ranges, hit)
    return ranges, hit


def beam_directions(
    angle_min_rad: float, angle_increment_rad: float, n_beams: int
) -> tuple[FloatArray, FloatArray]:
    """Cosines and sines of the sensor-frame beam angles."""
    a = angle_min_rad + angle_increment_rad * np.arange(n_beams, dtype=np.float64)
    return np.cos(a), np.sin(a)
