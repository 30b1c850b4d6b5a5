"""The static geometry people walk among: free space, line of sight, nearby segments."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.world.people.broad_phase import SegmentGrid
from dynmap_sim.world.people.params import REACH_M
from dynmap_sim.world.polygons import FloatArray, point_segment_distance

#: Below this many points :meth:`Obstacles.inside_any` tests each against every segment.
_FEW_POINTS = 8


class Obstacles:
    """Fixed ``segments`` ``(N, 4)`` of a run (closed outlines start at ``outline_starts``).

    With ``broad_phase`` the segments near a point come from a :class:`SegmentGrid`;
    without it every segment is a candidate (the naive reference).
    """

    def __init__(
        self,
        segments: FloatArray,
        broad_phase: bool = True,
        outline_starts: NDArray[np.int64] | None = None,
    ) -> None:
        self.segments = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
        self.broad_phase = broad_phase
        #: first segment of each closed outline in ``segments`` (for inside tests), or None
        self.outline_starts = outline_starts
        s = self.segments
        # per segment, complex: start p0, direction d and conj(d) (line-of-sight tests)
        self._seg_p0 = s[:, 0] + 1j * s[:, 1]
        self._seg_d = (s[:, 2] - s[:, 0]) + 1j * (s[:, 3] - s[:, 1])
        self._seg_dc = self._seg_d.conjugate()
        self._crossing_constants()
        self.grid = SegmentGrid(s)

    def _crossing_constants(self) -> None:
        """Per segment, for the crossing test of :meth:`inside_any` (fixed with the
        segments): ``y1 - y0`` (1 where 0) and ``x1 - x0``."""
        s = self.segments
        y0, y1 = s[:, 1], s[:, 3]
        self._cross_den = np.where(y1 == y0, 1.0, y1 - y0)
        self._cross_dx = s[:, 2] - s[:, 0]
        self._outline_box = self._outline_bounds()

    def _outline_bounds(
        self,
    ) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.int64]] | None:
        """Per outline (the segment runs of ``outline_starts``), where a crossing test can
        count at all: the lowest and highest ``y`` of its segments' ends and the largest
        crossing ``x`` [m] (``max(x0, x0 + dx)``: the rounded ``x0 + t dx`` for ``0 <= t <=
        1`` never exceeds it); a point with ``y`` below the lowest, at or above the highest,
        or ``x`` at or beyond the largest crosses none of the outline's segments, exactly.
        Also each outline's segment count. None without outlines (or with an empty one)."""
        starts = self.outline_starts
        s = self.segments
        if starts is None or len(s) == 0 or len(starts) == 0 or starts[0] != 0:
            return None
        sizes = np.diff(np.append(starts, len(s)))
        if (sizes <= 0).any():
            return None
        y_lo = np.minimum.reduceat(np.minimum(s[:, 1], s[:, 3]), starts)
        y_hi = np.maximum.reduceat(np.maximum(s[:, 1], s[:, 3]), starts)
        x_hi = np.maximum.reduceat(np.maximum(s[:, 0], s[:, 0] + self._cross_dx), starts)
        return y_lo, y_hi, x_hi, sizes

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Restore (states pickled before the crossing constants existed get them)."""
        self.__dict__.update(state)
        if "_outline_box" not in state:
            self._crossing_constants()

    def rows(self, z: NDArray[np.complex128]) -> NDArray[np.complex128]:
        """Candidate segments near each person as ``(P, K, 3)`` complex rows
        ``p0, conj(d), 1/|d|^2`` (padded with a far dummy).

        Without ``broad_phase`` every segment is a candidate (the naive reference).
        """
        if not self.broad_phase:
            return self.grid.all_rows(len(z))  # all segments and the far dummy (never empty)
        return self.grid.rows(z)

    def inside_any(self, points: FloatArray) -> NDArray[np.bool_]:
        """True where points ``(P, 2)`` lie inside a closed outline (crossing-number parity of
        a ray toward +x, counted per outline)."""
        if self.outline_starts is None or len(self.segments) == 0:
            return np.zeros(len(points), dtype=bool)
        if self._outline_box is None or len(points) < _FEW_POINTS:
            # every point against every segment (few points: cheaper than sorting out pairs)
            s = self.segments
            y0, y1 = s[:, 1], s[:, 3]
            py = points[:, 1:2]
            straddle = (y0 > py) != (y1 > py)
            t = (py - y0) / self._cross_den
            x_cross = s[:, 0] + t * self._cross_dx
            hits = straddle & (x_cross > points[:, 0:1])
            # parity of the crossings of each outline
            odd = np.logical_xor.reduceat(hits, self.outline_starts, axis=1)
            return odd.any(axis=1)
        return self._inside_near(points)

    def _inside_near(self, points: FloatArray) -> NDArray[np.bool_]:
        """:meth:`inside_any` testing each point only against the segments of the outlines
        it can cross (:meth:`_outline_bounds`; the other outlines' parities are 0), each
        (point, segment) pair with the same arithmetic as the all-pairs test."""
        y_lo, y_hi, x_hi, sizes = self._outline_box  # type: ignore[misc]
        inside = np.zeros(len(points), dtype=bool)
        px, py = points[:, 0], points[:, 1]
        pi, ki = ((y_lo <= py[:, None]) & (py[:, None] < y_hi) & (px[:, None] < x_hi)).nonzero()
        if not pi.shape[0]:
            return inside
        # the (point, segment) pairs: each (point, outline) pair's run of segments
        n_seg = sizes.take(ki)
        first = n_seg.cumsum() - n_seg
        seg = np.arange(int(first[-1] + n_seg[-1])) + (self.outline_starts.take(ki) - first).repeat(
            n_seg
        )
        at = pi.repeat(n_seg)
        s = self.segments
        y0, y1 = s[:, 1].take(seg), s[:, 3].take(seg)
        pyv = py.take(at)
        straddle = (y0 > pyv) != (y1 > pyv)
        t = (pyv - y0) / self._cross_den.take(seg)
        x_cross = s[:, 0].take(seg) + t * self._cross_dx.take(seg)
        hits = straddle & (x_cross > px.take(at))
        inside[pi[np.logical_xor.reduceat(hits, first)]] = True
        return inside

    def free_mask(self, points: FloatArray, r: float) -> NDArray[np.bool_]:
        """True where a body of radius ``r`` fits at ``points`` ``(P, 2)`` (clear of outlines
        by 5 cm and not inside any)."""
        if len(self.segments) == 0:
            return np.ones(len(points), dtype=bool)
        if self.broad_phase and r + 0.05 < REACH_M:  # the grid lists every segment that near
            pts = np.ascontiguousarray(points, dtype=np.float64)
            z = pts.view(np.complex128)[:, 0]
            rows = self.rows(z)
            a = z[:, None] - rows[..., 0]
            cd = rows[..., 1]
            t = (a * cd).real * rows[..., 2].real
            np.minimum(np.maximum(t, 0.0, out=t), 1.0, out=t)
            clear = np.abs(a - t * cd.conjugate()).min(axis=1) > r + 0.05
        else:
            clear = point_segment_distance(points, self.segments).min(axis=1) > r + 0.05
        return clear & ~self.inside_any(points)

    def free(self, xy: FloatArray, r: float) -> bool:
        """True where a body of radius ``r`` fits at the point ``xy``."""
        return bool(self.free_mask(xy[None, :], r)[0])

    def visible(self, a: FloatArray, b: FloatArray) -> bool:
        """True where no segment properly crosses the line of sight ``a``-``b``."""
        if len(self.segments) == 0:
            return True
        za, ab = complex(a[0], a[1]), complex(b[0] - a[0], b[1] - a[1])
        o1, o2, o3, o4 = self._sides(za, ab)
        return not bool(((o1 * o2 < 0.0) & (o3 * o4 < 0.0)).any())

    def visible_many(self, a: FloatArray, bs: FloatArray) -> NDArray[np.bool_]:
        """Per point of ``bs`` ``(M, 2)``: True where no segment properly crosses the line of
        sight ``a``-``b`` (one pass for all ``M``; the same tests as :meth:`visible`)."""
        if len(self.segments) == 0:
            return np.ones(len(bs), dtype=bool)
        za = complex(a[0], a[1])
        ab = ((bs[:, 0] - a[0]) + 1j * (bs[:, 1] - a[1]))[:, None]
        o1, o2, o3, o4 = self._sides(za, ab)
        return ~((o1 * o2 < 0.0) & (o3 * o4 < 0.0)).any(axis=1)

    def _sides(self, za: complex, ab: Any) -> tuple[FloatArray, ...]:
        """Proper crossings of ``a``-``b`` (``za``, ``ab = b - a``; a complex scalar, or a
        column of them) with each segment ``p0 + s d``: the endpoints of each lie on opposite
        sides of the other. The signs of 2-D cross products (``Im(conj(u) w) = u x w``) of
        ``p0, p1`` against ``a-b`` and of ``a, b`` against each segment."""
        abc = ab.conjugate()
        w0 = self._seg_p0 - za  # p0 - a
        o1 = (abc * w0).imag
        o2 = (abc * (w0 + self._seg_d)).imag
        o3 = (self._seg_dc * w0).imag  # = -(d x (a - p0))
        o4 = (self._seg_dc * (w0 - ab)).imag  # = -(d x (b - p0))
        return o1, o2, o3, o4
