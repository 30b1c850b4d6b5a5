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

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class SegmentCache:
    """Contiguous per-column copies of a ``(N, 4)`` segment array (built once per geometry)."""

    x0: FloatArray
    y0: FloatArray
    dx: FloatArray
    dy: FloatArray
    dd: FloatArray  # squared length [m^2]; 0 for degenerate segments
    n: int

    @classmethod
    def build(cls, segments: FloatArray) -> SegmentCache:
        """Split ``segments`` rows ``x0, y0, x1, y1`` [m] into contiguous columns."""
        seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
        x0 = np.ascontiguousarray(seg[:, 0])
        y0 = np.ascontiguousarray(seg[:, 1])
        dx = seg[:, 2] - seg[:, 0]
        dy = seg[:, 3] - seg[:, 1]
        return cls(x0=x0, y0=y0, dx=dx, dy=dy, dd=dx * dx + dy * dy, n=seg.shape[0])


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
    s = np.concatenate([start_rad, start_rad - _TWO_PI]) / inc_rad
    e = s + np.concatenate([span_rad, span_rad]) / inc_rad
    lo = np.maximum(np.ceil(s).astype(np.int64) - 1, 0)
    hi = np.minimum(np.floor(e).astype(np.int64) + 1, n_beams - 1)
    return lo, np.maximum(hi - lo + 1, 0)


def _expand(lo: IntArray, count: IntArray) -> tuple[IntArray, IntArray]:
    """``(run index, beam index)`` of every pair in the runs ``lo[k] .. lo[k] + count[k] - 1``."""
    total = int(count.sum())
    run = np.repeat(np.arange(count.shape[0]), count)
    first = np.cumsum(count) - count
    beam = np.arange(total) + np.repeat(lo - first, count)
    return run, beam


def cast_scan(
    origin_xy: tuple[float, float],
    bearings_rad: FloatArray,
    cos_b: FloatArray,
    sin_b: FloatArray,
    max_range_m: float,
    segments: SegmentCache,
    circles: FloatArray | None = None,
) -> tuple[FloatArray, IntArray]:
    """Cast all beams of one scan; return the true range [m] and the hit shape of each beam.

    ``bearings_rad`` are the world-frame beam directions, evenly spaced and increasing
    (``bearings_rad[i] = bearings_rad[0] + i * inc``), with ``cos_b``/``sin_b`` their cosines
    and sines. ``circles`` rows are ``x, y, r`` [m]. The hit index is a row of the segments
    (``0 .. N-1``), ``N + j`` for circle ``j``, or ``-1`` (no hit within ``max_range_m``,
    range ``+inf``). Ranges are distances from ``origin_xy`` along the beam.
    """
    ox, oy = float(origin_xy[0]), float(origin_xy[1])
    n_beams = bearings_rad.shape[0]
    inc = float(bearings_rad[1] - bearings_rad[0]) if n_beams > 1 else 1.0
    base = float(bearings_rad[0])
    r_max = float(max_range_m)

    # --- segments: range cull + bearing interval -------------------------------------
    ax = segments.x0 - ox
    ay = segments.y0 - oy
    dx, dy, dd = segments.dx, segments.dy, segments.dd
    with np.errstate(invalid="ignore", divide="ignore"):
        tproj = np.clip(-(ax * dx + ay * dy) / dd, 0.0, 1.0)
    px = ax + tproj * dx
    py = ay + tproj * dy
    near = (px * px + py * py <= r_max * r_max) & (dd > 0.0)
    sidx = np.flatnonzero(near)
    ax = ax[sidx]
    ay = ay[sidx]
    dx = dx[sidx]
    dy = dy[sidx]
    bx = ax + dx
    by = ay + dy
    cross_ab = ax * by - ay * bx
    span = np.arctan2(np.abs(cross_ab), ax * bx + ay * by)
    th_a = np.arctan2(ay, ax)
    th_b = np.arctan2(by, bx)
    start = np.where(cross_ab >= 0.0, th_a, th_b)
    start = (start - base) % _TWO_PI

    # --- circles ------------------------------------------------------------------------
    n_seg = segments.n
    if circles is not None and circles.shape[0] > 0:
        cx = circles[:, 0] - ox
        cy = circles[:, 1] - oy
        cr = circles[:, 2]
        cd = np.hypot(cx, cy)
        cnear = np.flatnonzero(cd - cr <= r_max)
        cx = cx[cnear]
        cy = cy[cnear]
        cr = cr[cnear]
        cd = cd[cnear]
        inside = cd <= cr
        with np.errstate(invalid="ignore", divide="ignore"):
            half = np.where(inside, np.pi, np.arcsin(np.minimum(cr / cd, 1.0)))
        cstart = (np.arctan2(cy, cx) - half - base) % _TWO_PI
        cspan = 2.0 * half
    else:
        cnear = np.empty(0, dtype=np.int64)
        cx = cy = cr = cstart = cspan = np.empty(0)

    n_s = sidx.shape[0]
    n_c = cnear.shape[0]
    lo, count = _beam_runs(
        np.concatenate([start, cstart]), np.concatenate([span, cspan]), inc, n_beams
    )
    run, beam = _expand(lo, count)
    shape_k = np.where(run >= n_s + n_c, run - (n_s + n_c), run)  # undo the wrap copy

    ranges = np.full(n_beams, np.inf)
    hit = np.full(n_beams, -1, dtype=np.int64)
    ux = cos_b[beam]
    uy = sin_b[beam]

    is_seg = shape_k < n_s
    # segment pairs
    ks = shape_k[is_seg]
    bs = beam[is_seg]
    uxs = ux[is_seg]
    uys = uy[is_seg]
    sdx = dx[ks]
    sdy = dy[ks]
    sax = ax[ks]
    say = ay[ks]
    denom = uxs * sdy - uys * sdx
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (sax * sdy - say * sdx) / denom
        s = (sax * uys - say * uxs) / denom
    ok = (t >= 0.0) & (s >= 0.0) & (s <= 1.0)
    t_all = [t[ok]]
    b_all = [bs[ok]]
    id_all = [sidx[ks[ok]]]

    if n_c:
        kc = shape_k[~is_seg] - n_s
        bc = beam[~is_seg]
        ccx = cx[kc]
        ccy = cy[kc]
        ccr = cr[kc]
        b = ux[~is_seg] * ccx + uy[~is_seg] * ccy
        c = ccx * ccx + ccy * ccy - ccr * ccr
        disc = b * b - c
        okc = disc >= 0.0
        tc = b[okc] - np.sqrt(disc[okc])
        tc = np.where(c[okc] <= 0.0, 0.0, tc)  # origin inside the circle
        keep = tc >= 0.0
        t_all.append(tc[keep])
        b_all.append(bc[okc][keep])
        id_all.append(n_seg + cnear[kc[okc][keep]])

    t_hit = np.concatenate(t_all) if n_c else t_all[0]
    b_hit = np.concatenate(b_all) if n_c else b_all[0]
    id_hit = np.concatenate(id_all) if n_c else id_all[0]
    np.minimum.at(ranges, b_hit, t_hit)
    win = t_hit == ranges[b_hit]
    hit[b_hit[win]] = id_hit[win]
    far = ranges > r_max
    ranges[far] = np.inf
    hit[far] = -1
    return ranges, hit


def scan_bearings(
    heading_rad: float, angle_min_rad: float, angle_increment_rad: float, n_beams: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """World-frame bearings of a scan and their cosines and sines."""
    b = heading_rad + angle_min_rad + angle_increment_rad * np.arange(n_beams, dtype=np.float64)
    return b, np.cos(b), np.sin(b)
