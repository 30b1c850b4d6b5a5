"""Batched, exact 2-D ray casting against line segments and circles (pure geometry).

All beams of one scan start at the same origin, so the broad phase is *angular-interval
culling*: every segment (circle) seen from the origin covers one interval of bearings, hence
one contiguous run of beam indices. Only those (beam, shape) pairs are tested, with the exact
closed-form intersection:

* segment ``a + s d`` (``0 <= s <= 1``) and ray ``o + t u``:
  ``t = (a - o) x d / (u x d)``, ``s = (a - o) x u / (u x d)`` (2-D cross products);
* circle ``|p - c| = r``: ``t = b - sqrt(b^2 - (|c - o|^2 - r^2))`` with ``b = u . (c - o)``.

Segments out of range are culled first, with a candidate list memoized per 0.25 m cell of
the sensor position (:meth:`SegmentCache.near`, a superset of the segments in range). The
nearest hit per beam is a ``numpy.fmin.at`` scatter (misses are NaN and never win). Where two
shapes are hit at the same range (collinear faces, shared corners) either may be reported.
The result agrees with pymunk's ``segment_query_first`` (radius-0 segments and circles) to
floating-point precision; see ``tests/sensors/test_raycast.py``.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
ComplexArray = NDArray[np.complex128]

_TWO_PI = 2.0 * np.pi


#: Side [m] of the square cells for which :meth:`SegmentCache.near` keeps its candidates.
NEAR_CELL_M = 0.25
#: At most this many cells' candidate lists are kept per cache (then it starts over).
NEAR_CELLS_MAX = 4096


@dataclass(frozen=True)
class SegmentCache:
    """Per-geometry precomputation for :func:`cast_scan` (built once per static version).

    Points are complex numbers ``x + iy``: ``p0`` the segments' first endpoints, ``d`` their
    direction vectors ``p1 - p0``; ``bbox`` rows are ``xmin, ymin, xmax, ymax`` of each
    segment (range cull). ``data`` rows ``x0, y0, dx, dy`` serve the numba backend.
    ``near_cells`` memoizes :meth:`near` per sensor cell.
    """

    p0: NDArray[np.complex128]
    d: NDArray[np.complex128]
    data: FloatArray
    bbox: FloatArray
    n: int
    near_cells: dict[tuple[int, int, float], tuple[IntArray, ComplexArray, ComplexArray]] = field(
        default_factory=dict, compare=False, repr=False
    )

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

    def near(
        self, x_m: float, y_m: float, r_max_m: float
    ) -> tuple[IntArray, ComplexArray, ComplexArray]:
        """Rows, ``p0`` and ``d`` of the segments whose bounding box comes within
        ``r_max_m`` (per axis) of the ``NEAR_CELL_M`` cell holding ``(x_m, y_m)``: a superset
        of those within range of any sensor in that cell (memoized per cell)."""
        key = (math.floor(x_m / NEAR_CELL_M), math.floor(y_m / NEAR_CELL_M), r_max_m)
        got = self.near_cells.get(key)
        if got is None:
            x0, y0 = key[0] * NEAR_CELL_M, key[1] * NEAR_CELL_M
            bb = self.bbox
            lo_x, hi_x = x0 - r_max_m - 1e-9, x0 + NEAR_CELL_M + r_max_m + 1e-9
            lo_y, hi_y = y0 - r_max_m - 1e-9, y0 + NEAR_CELL_M + r_max_m + 1e-9
            m = (bb[0] <= hi_x) & (bb[2] >= lo_x) & (bb[1] <= hi_y) & (bb[3] >= lo_y)
            idx = np.flatnonzero(m)
            got = (idx, self.p0[idx], self.d[idx])
            if len(self.near_cells) >= NEAR_CELLS_MAX:
                self.near_cells.clear()
            self.near_cells[key] = got
        return got


def cast_scan(
    pose: tuple[float, float, float],
    angle_min_rad: float,
    angle_increment_rad: float,
    cos_l: FloatArray,
    sin_l: FloatArray,
    max_range_m: float,
    segments: SegmentCache,
    circles: FloatArray | None = None,
    u_l: ComplexArray | None = None,
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

    The work is a fixed number of numpy calls on arrays of (beam, shape) pairs: for scans of
    a few hundred beams the call overhead, not the arithmetic, sets the cost.
    """
    if u_l is None:
        u_l = cos_l + 1j * sin_l
    shapes = _scan_shapes([pose], float(max_range_m), [segments], [circles])
    ranges, hit = _cast_shapes(
        shapes, angle_min_rad, angle_increment_rad, u_l, float(max_range_m), cos_l.shape[0]
    )
    return ranges[0], hit[0]


def cast_scans(
    poses: list[tuple[float, float, float]],
    angle_min_rad: float,
    angle_increment_rad: float,
    cos_l: FloatArray,
    sin_l: FloatArray,
    max_range_m: float,
    segments: list[SegmentCache],
    circles: list[FloatArray | None],
    u_l: ComplexArray | None = None,
) -> tuple[FloatArray, IntArray]:
    """:func:`cast_scan` of ``S`` scans at once, each from its own pose among its own shapes
    (``segments[i]``, ``circles[i]``; the same laser): ranges and hit indices ``(S, n_beams)``.

    The shapes of all scans are moved into their sensor frames in one pass (each with its
    scan's origin and rotation), and the broad phase and the intersections of all scans'
    (beam, shape) pairs are one pass too, so the numpy call overhead is paid once for all
    scans. Every number is the one
    :func:`cast_scan` gives for that scan alone.
    """
    if u_l is None:
        u_l = cos_l + 1j * sin_l
    r_max = float(max_range_m)
    shapes = _scan_shapes(poses, r_max, segments, circles)
    return _cast_shapes(shapes, angle_min_rad, angle_increment_rad, u_l, r_max, cos_l.shape[0])


class _Shapes(NamedTuple):
    """The shapes within range of the scans, each in its scan's sensor frame, scan after
    scan: segments (first endpoint ``a``, direction ``d``, ``a x d``, bearing interval
    ``start``, ``span``, rows ``ids``) and circles (centre ``c``, ``|c|^2 - r^2`` ``c0``,
    ``inside``, bearing interval ``cstart``, ``cspan``, hit indices ``cids``); ``lens``: the
    number of segments of each scan, then the number of circles of each."""

    a: ComplexArray
    d: ComplexArray
    a_x_d: FloatArray
    start: FloatArray
    span: FloatArray
    ids: IntArray
    c: ComplexArray
    c0: FloatArray
    inside: NDArray[np.bool_]
    cstart: FloatArray
    cspan: FloatArray
    cids: IntArray
    lens: list[int]


def _no_circles(n_scans: int) -> tuple[Any, ...]:
    """The circle fields of :class:`_Shapes` for scans with no circle in range (empty)."""
    f, c = np.zeros(0), np.zeros(0, np.complex128)
    return c, f, np.zeros(0, bool), f, f, np.zeros(0, np.int64), [0] * n_scans


def _per_shape(values: list[Any], counts: list[int]) -> Any:
    """``values[i]`` for each of the ``counts[i]`` shapes of scan ``i`` (the value itself
    for a single scan: numpy's arithmetic is the same with a scalar)."""
    if len(values) == 1:
        return values[0]
    return np.array(values).repeat(counts)


def _scan_shapes(
    poses: list[tuple[float, float, float]],
    r_max: float,
    segments: list[SegmentCache],
    circles: list[FloatArray | None],
) -> _Shapes:
    """The segments near each sensor's cell (memoized) and the circles within range, moved
    into the frame of the sensor at ``poses[i]`` (scan ``i`` among ``segments[i]`` and
    ``circles[i]``), all scans in one pass."""
    xs = [float(p[0]) for p in poses]
    ys = [float(p[1]) for p in poses]
    rots = [complex(math.cos(float(p[2])), -math.sin(float(p[2]))) for p in poses]  # map->sensor
    origins = [complex(x, y) for x, y in zip(xs, ys, strict=True)]
    near = [seg.near(x, y, r_max) for seg, x, y in zip(segments, xs, ys, strict=True)]
    if len(near) == 1:
        sidx, p0, d0 = near[0]
    else:
        sidx, p0, d0 = (np.concatenate(f) for f in zip(*near, strict=True))
    counts = [len(n[0]) for n in near]
    o, rot = _per_shape(origins, counts), _per_shape(rots, counts)
    a = np.multiply(p0 - o, rot)  # first endpoint
    d = d0 * rot
    b = a + d  # second endpoint
    ab = np.multiply(a.conjugate(), b)  # imag: a x b = a x d (> 0: b is counter-clockwise of a)
    a_x_d = ab.imag
    span = np.abs(np.arctan2(a_x_d, ab.real))  # bearing interval of each segment [rad]
    first = np.where(a_x_d >= 0.0, a, b)
    start = np.arctan2(first.imag, first.real)
    circ = _circle_shapes(origins, rots, r_max, segments, circles)
    return _Shapes(a, d, a_x_d, start, span, sidx, *circ[:-1], counts + circ[-1])


def _circle_shapes(
    origins: list[complex],
    rots: list[complex],
    r_max: float,
    segments: list[SegmentCache],
    circles: list[FloatArray | None],
) -> tuple[Any, ...]:
    """The circle fields of :class:`_Shapes` (and the number of circles of each scan)."""
    n_scans = len(origins)
    circ_counts = [0 if c is None else c.shape[0] for c in circles]
    if not sum(circ_counts):
        return _no_circles(n_scans)
    if n_scans == 1:
        all_c: FloatArray = circles[0]  # type: ignore[assignment]
    else:
        all_c = np.concatenate([c for c in circles if c is not None and c.shape[0]])
    o = _per_shape(origins, circ_counts)
    if all_c.flags.c_contiguous and all_c.dtype == np.float64:
        cw = all_c[:, :2].view(np.complex128)[:, 0] - o  # centres, sensor at 0
    else:
        cw = all_c[:, 0] + 1j * all_c[:, 1] - o
    cr = all_c[:, 2]
    dist = np.abs(cw)
    cnear = (dist <= r_max + cr).nonzero()[0]
    if not cnear.shape[0]:
        return _no_circles(n_scans)
    rot = _per_shape(rots, circ_counts)
    c = np.multiply(cw.take(cnear), rot if n_scans == 1 else rot.take(cnear))
    cr = cr.take(cnear)
    dist = dist.take(cnear)
    c0 = (dist - cr) * (dist + cr)  # |c|^2 - r^2 (<= 0: the sensor is inside it)
    inside = c0 <= 0.0
    half = np.arcsin(cr / np.maximum(dist, cr))  # half the angle the circle subtends
    half[inside] = np.pi
    cstart = np.arctan2(c.imag, c.real) - half
    if n_scans == 1:
        return c, c0, inside, cstart, 2.0 * half, segments[0].n + cnear, [cnear.shape[0]]
    # hit index of each circle: its scan's segment count plus its index among its circles
    scan = np.arange(n_scans).repeat(circ_counts).take(cnear)
    firsts = itertools.accumulate(circ_counts[:-1], initial=0)
    base = np.array([s.n - f for s, f in zip(segments, firsts, strict=True)])
    counts = np.bincount(scan, minlength=n_scans).tolist()
    return c, c0, inside, cstart, 2.0 * half, base.take(scan) + cnear, counts


def _cast_shapes(
    shapes: _Shapes,
    angle_min_rad: float,
    angle_increment_rad: float,
    u_l: ComplexArray,
    r_max: float,
    n_beams: int,
) -> tuple[FloatArray, IntArray]:
    """Broad phase and intersections of the (beam, shape) pairs of all scans' ``shapes``;
    ranges and hit indices ``(S, n_beams)``. Shapes are laid out as: every scan's segments,
    their wrap copies, every scan's circles, their wrap copies."""
    inc = float(angle_increment_rad)
    a, d, a_x_d, start, span, ids, c, c0, inside, cstart, cspan, cids, lens = shapes
    n_scans = len(lens) // 2
    n_s = a.shape[0]
    n_c = c.shape[0]
    # runs in the order: segments, their wrap copies, circles, their wrap copies
    if n_c:
        sb = np.concatenate([start, start, cstart, cstart])
        sp = np.concatenate([span, span, cspan, cspan])
    else:
        sb = np.concatenate([start, start])
        sp = np.concatenate([span, span])

    # --- broad phase: the beam indices each bearing interval covers, widened by one beam ----
    # (bearing from the first beam in [0, 2 pi), the copies shifted back by one turn for
    # intervals that wrap; truncation toward zero only widens a run)
    s_b = (sb - angle_min_rad) % _TWO_PI
    s_b[n_s : 2 * n_s] -= _TWO_PI
    s_b[2 * n_s + n_c :] -= _TWO_PI
    s_b *= 1.0 / inc
    lo = np.maximum(s_b.astype(np.int64) - 1, 0)
    hi = np.minimum((s_b + sp * (1.0 / inc)).astype(np.int64) + 1, n_beams - 1)
    count = np.maximum(hi - lo + 1, 0)
    ends = count.cumsum()
    # the shape of each (beam, shape) pair: segment k, or circle n_s + j
    shape = np.arange(n_s + n_c)
    if n_c:
        shape = np.concatenate([shape[:n_s], shape[:n_s], shape[n_s:], shape[n_s:]])
    else:
        shape = np.concatenate([shape, shape])
    key = shape.repeat(count)
    # the beam of each pair in the scans' beams laid end to end (scan i's beam j at
    # i n_beams + j): each run starts at its beam lo plus its scan's first beam
    first_beam = ends - count - lo
    uc_l = u_l.conjugate()
    if n_scans > 1:
        per_scan = np.arange(n_scans) * n_beams
        first_beam -= np.concatenate([per_scan, per_scan]).repeat(lens).take(shape)
        uc_l = np.concatenate([uc_l] * n_scans)
    beam = np.arange(key.shape[0]) - first_beam.repeat(count)
    uc = uc_l.take(beam)  # conj(u) of each pair's beam
    m = int(ends[2 * n_s - 1]) if n_s else 0  # pairs [0, m) are segment pairs

    # (complex products by np.multiply, not *: numpy may reuse a temporary operand of
    # >= 256 KB in place and then swap the operands, and a complex product's last bits
    # depend on their order; many scans at once would not get one scan's numbers)
    t_all = np.empty(key.shape[0])  # the range of each pair (NaN: no hit)
    with np.errstate(invalid="ignore", divide="ignore"):
        # segments: t = (a x d) / (u x d), s = (a x u) / (u x d); here s_neg = -s
        ks = key[:m]
        ucs = uc[:m]
        inv = 1.0 / np.multiply(ucs, d.take(ks)).imag
        np.multiply(a_x_d.take(ks), inv, out=t_all[:m])
        s_neg = np.multiply(a.take(ks), ucs).imag * inv
        if n_c:
            # circles: t = b - sqrt(b^2 - c0) with b = u . c (0 from inside the circle)
            kc = key[m:] - n_s
            bdot = np.multiply(uc[m:], c.take(kc)).real
            tc = np.subtract(bdot, np.sqrt(bdot * bdot - c0.take(kc)), out=t_all[m:])
            if inside.any():
                tc[inside.take(kc)] = 0.0
        # a hit: 0 <= t <= r_max, and 0 <= s <= 1 on a segment
        ok = t_all >= 0.0
        ok &= t_all <= r_max
        ok_s = ok[:m]
        ok_s &= s_neg <= 0.0
        ok_s &= s_neg >= -1.0
        t_all = np.where(ok, t_all, np.nan)

    ranges = np.empty(n_scans * n_beams)
    ranges.fill(np.inf)
    np.fmin.at(ranges, beam, t_all)  # NaN (no hit) never wins
    win = t_all == ranges.take(beam)
    hit_key = np.empty(n_scans * n_beams, dtype=np.int64)
    hit_key.fill(-1)
    hit_key[beam[win]] = key[win]
    # hit index of each shape (segment row or N + circle), and -1 (nothing) at the end
    if n_c:
        shape_id = np.concatenate([ids, cids, [-1]])
    else:
        shape_id = np.concatenate([ids, [-1]])
    return ranges.reshape(n_scans, n_beams), shape_id.take(hit_key).reshape(n_scans, n_beams)


def beam_directions(
    angle_min_rad: float, angle_increment_rad: float, n_beams: int
) -> tuple[FloatArray, FloatArray]:
    """Cosines and sines of the sensor-frame beam angles."""
    a = angle_min_rad + angle_increment_rad * np.arange(n_beams, dtype=np.float64)
    return np.cos(a), np.sin(a)
