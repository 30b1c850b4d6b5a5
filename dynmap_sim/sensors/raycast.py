"""Batched, exact 2-D ray casting against line segments and circles (pure geometry).

All beams of one scan start at the same origin, so the broad phase is *angular-interval
culling*: every segment (circle) seen from the origin covers one interval of bearings, hence
one contiguous run of beam indices. Only those (beam, shape) pairs are tested, with the exact
closed-form intersection:

* segment ``a + s d`` (``0 <= s <= 1``) and ray ``o + t u``:
  ``t = (a - o) x d / (u x d)``, ``s = (a - o) x u / (u x d)`` (2-D cross products);
* circle ``|p - c| = r``: ``t = b - sqrt(b^2 - (|c - o|^2 - r^2))`` with ``b = u . (c - o)``.

Shapes farther than the maximum range are culled first. The nearest hit per beam is a
``numpy.minimum.at`` scatter. The result agrees with pymunk's ``segment_query_first`` (radius-0
segments and circles) to floating-point precision; see ``tests/sensors/test_raycast.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class SegmentCache:
    """Per-geometry precomputation for :func:`cast_scan` (built once per static version).

    Points are complex numbers ``x + iy``: ``p0`` the segments' first endpoints, ``d`` their
    direction vectors ``p1 - p0``; ``bbox`` rows are ``xmin, ymin, xmax, ymax`` of each
    segment (range cull). ``data`` rows ``x0, y0, dx, dy`` serve the numba backend.
    """

    p0: NDArray[np.complex128]
    d: NDArray[np.complex128]
    data: FloatArray
    bbox: FloatArray
    n: int

    @classmethod
    def build(cls, segments: FloatArray) -> SegmentCache:
        """Precompute from ``segments`` rows ``x0, y0, x1, y1`` [m]."""
        seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
        dx = seg[:, 2] - seg[:, 0]
        dy = seg[:, 3] - seg[:, 1]
        data = np.ascontiguousarray(np.stack([seg[:, 0], seg[:, 1], dx, dy]))
        bbox = np.ascontiguousarray(
            np.stack(
                [
                    np.minimum(seg[:, 0], seg[:, 2]),
                    np.minimum(seg[:, 1], seg[:, 3]),
                    np.maximum(seg[:, 0], seg[:, 2]),
                    np.maximum(seg[:, 1], seg[:, 3]),
                ]
            )
        )
        return cls(
            p0=seg[:, 0] + 1j * seg[:, 1], d=dx + 1j * dy, data=data, bbox=bbox, n=seg.shape[0]
        )


def _beam_runs(
    start_rad: FloatArray, span_rad: FloatArray, inc_rad: float, n_beams: int
) -> tuple[IntArray, IntArray]:
    """Beam index runs ``[lo, hi]`` covered by bearing intervals ``[start, start + span]``.

    Bearings are relative to the first beam and ``start`` lies in ``[0, 2 pi)``. Each interval
    yields two candidate runs (as is, and shifted by ``-2 pi`` for intervals that wrap), each
    widened by one beam for safety: the narrow phase is exact, the broad phase only needs to
    be conservative. Returns ``lo`` and ``count`` (``count = 0`` for an empty run), shape
    ``(2 K,)``.
    """
    s = start_rad * (1.0 / inc_rad)
    s = np.concatenate([s, s - _TWO_PI / inc_rad])
    e = s + np.concatenate([span_rad, span_rad]) * (1.0 / inc_rad)
    lo = np.maximum(np.ceil(s).astype(np.int64) - 1, 0)
    hi = np.minimum(np.floor(e).astype(np.int64) + 1, n_beams - 1)
    return lo, np.maximum(hi - lo + 1, 0)


def _expand(lo: IntArray, count: IntArray) -> tuple[IntArray, IntArray]:
    """``(run index, beam index)`` of every pair in the runs ``lo[k] .. lo[k] + count[k] - 1``."""
    run = np.repeat(np.arange(count.shape[0]), count)
    first = np.cumsum(count) - count
    beam = np.arange(run.shape[0]) + (lo - first)[run]
    return run, beam


def cast_scan(
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
    """Cast all beams of one scan; return the true range [m] and the hit shape of each beam.

    The sensor is at ``pose = (x, y, heading)`` in the map frame; beam ``i`` points at
    ``angle_min_rad + i * angle_increment_rad`` in the sensor frame, and ``cos_l``/``sin_l``
    are the cosines and sines of those sensor-frame angles (``u_l = cos_l + i sin_l`` may be
    passed precomputed). The shapes within range are moved into the sensor frame; points are
    complex numbers, so a rotation is one multiplication and ``conj(p) q`` holds both the dot
    (real part) and the cross product (imaginary part) of ``p`` and ``q``. ``circles`` rows
    are ``x, y, r`` [m]. The hit index is a row of the segments (``0 .. N-1``), ``N + j`` for
    circle ``j``, or ``-1`` (no hit within ``max_range_m``, range ``+inf``).
    """
    ox, oy, heading = float(pose[0]), float(pose[1]), float(pose[2])
    n_beams = cos_l.shape[0]
    if u_l is None:
        u_l = cos_l + 1j * sin_l
    inc = float(angle_increment_rad)
    r_max = float(max_range_m)
    rot = complex(math.cos(heading), -math.sin(heading))  # map -> sensor frame

    # --- segments: range cull (bounding boxes), into the sensor frame, bearing interval ----
    bb = segments.bbox
    near = (bb[0] <= ox + r_max) & (bb[2] >= ox - r_max) & (bb[1] <= oy + r_max)
    near &= bb[3] >= oy - r_max
    sidx = np.flatnonzero(near)
    a = (segments.p0[sidx] - complex(ox, oy)) * rot  # first endpoint
    d = segments.d[sidx] * rot
    b = a + d  # second endpoint
    ab = a.conjugate() * b  # imag: a x b (> 0: b is counter-clockwise of a)
    span = np.abs(np.angle(ab))
    start = np.angle(np.where(ab.imag >= 0.0, a, b))
    n_s = sidx.shape[0]

    # --- circles ------------------------------------------------------------------------
    n_seg = segments.n
    if circles is not None and circles.shape[0] > 0:
        wx = circles[:, 0] - ox
        wy = circles[:, 1] - oy
        cr = circles[:, 2]
        cd2 = wx * wx + wy * wy
        rr = r_max + cr
        cnear = np.flatnonzero(cd2 <= rr * rr)
        c = (wx[cnear] + 1j * wy[cnear]) * rot
        cr = cr[cnear]
        cd2 = cd2[cnear]
        c0 = cd2 - cr * cr  # < 0: the sensor is inside the circle
        with np.errstate(invalid="ignore", divide="ignore"):
            half = np.where(c0 <= 0.0, np.pi, np.arcsin(np.minimum(cr / np.sqrt(cd2), 1.0)))
        start = np.concatenate([start, np.angle(c) - half])
        span = np.concatenate([span, 2.0 * half])
        n_c = cnear.shape[0]
    else:
        n_c = 0

    lo, count = _beam_runs((start - angle_min_rad) % _TWO_PI, span, inc, n_beams)
    run, beam = _expand(lo, count)
    n_sc = n_s + n_c
    shape_k = run - n_sc * (run >= n_sc)  # undo the wrap copy
    u = u_l[beam]

    ranges = np.full(n_beams, np.inf)
    hit = np.full(n_beams, -1, dtype=np.int64)
    if n_c:
        is_seg = shape_k < n_s
        ks = shape_k[is_seg]
        bs = beam[is_seg]
        us = u[is_seg]
    else:
        ks, bs, us = shape_k, beam, u
    pac = a[ks].conjugate()
    pd = d[ks]
    with np.errstate(invalid="ignore", divide="ignore"):
        inv = 1.0 / (us.conjugate() * pd).imag  # 1 / (u x d)
        t = (pac * pd).imag * inv  # (a x d) / (u x d)
        s = (pac * us).imag * inv  # (a x u) / (u x d)
    ok = (t >= 0.0) & (t <= r_max) & (s >= 0.0) & (s <= 1.0)
    t_hit = t[ok]
    b_hit = bs[ok]
    id_hit = sidx[ks[ok]]

    if n_c:
        notseg = ~is_seg
        kc = shape_k[notseg] - n_s
        bc = beam[notseg]
        cc0 = c0[kc]
        bdot = (u[notseg].conjugate() * c[kc]).real  # u . c
        disc = bdot * bdot - cc0
        okc = (disc >= 0.0) & ((bdot >= 0.0) | (cc0 <= 0.0))
        tc = np.where(cc0[okc] <= 0.0, 0.0, bdot[okc] - np.sqrt(disc[okc]))
        near_c = tc <= r_max
        t_hit = np.concatenate([t_hit, tc[near_c]])
        b_hit = np.concatenate([b_hit, bc[okc][near_c]])
        id_hit = np.concatenate([id_hit, n_seg + cnear[kc[okc][near_c]]])

    np.minimum.at(ranges, b_hit, t_hit)
    win = t_hit == ranges[b_hit]
    hit[b_hit[win]] = id_hit[win]
    return ranges, hit


def beam_directions(
    angle_min_rad: float, angle_increment_rad: float, n_beams: int
) -> tuple[FloatArray, FloatArray]:
    """Cosines and sines of the sensor-frame beam angles."""
    a = angle_min_rad + angle_increment_rad * np.arange(n_beams, dtype=np.float64)
    return np.cos(a), np.sin(a)
