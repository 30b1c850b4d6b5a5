"""The static geometry people walk among: free space, line of sight, nearby segments.

Choosing a goal (:func:`.spawning.pick_goal`) asks these queries for a few dozen candidate
points at a time, so they are compiled loops.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled
from dynmap_sim.world.people.broad_phase import SegmentGrid
from dynmap_sim.world.people.params import REACH_M
from dynmap_sim.world.polygons import FloatArray

#: How far a body's edge keeps clear of outlines where it is placed [m].
CLEARANCE_M = 0.05


class Obstacles:
    """Fixed ``segments`` ``(N, 4)`` of a run; closed outlines are the runs of segments
    starting at ``outline_starts`` (None: no outlines, nothing is inside).

    With ``broad_phase`` the segments near a point come from a :class:`SegmentGrid`;
    without it every segment is a candidate (the naive reference).
    """

    def __init__(
        self,
        segments: FloatArray,
        broad_phase: bool = True,
        outline_starts: NDArray[np.int64] | None = None,
    ) -> None:
        self.segments = np.ascontiguousarray(segments, dtype=np.float64).reshape(-1, 4)
        self.broad_phase = broad_phase
        self.outline_starts = outline_starts
        self.grid = SegmentGrid(self.segments)
        self._outlines = _outline_bounds(self.segments, outline_starts)

    def rows(self, z: NDArray[np.complex128]) -> NDArray[np.complex128]:
        """Candidate segments near each person as ``(P, K, 3)`` complex rows
        ``p0, conj(d), 1/|d|^2`` (padded with a far dummy); without ``broad_phase``, all."""
        if not self.broad_phase:
            return self.grid.all_rows(len(z))  # all segments and the far dummy (never empty)
        return self.grid.rows(z)

    def inside_any(self, points: FloatArray) -> NDArray[np.bool_]:
        """True where points ``(P, 2)`` lie inside a closed outline (crossing-number parity of
        a ray toward +x, counted per outline)."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        out = np.zeros(len(pts), dtype=bool)
        if self._outlines is not None:
            _inside(pts, self.segments, *self._outlines, out)
        return out

    def free_mask(self, points: FloatArray, r: float) -> NDArray[np.bool_]:
        """True where a body of radius ``r`` [m] fits at ``points`` ``(P, 2)`` (clear of
        outlines by ``CLEARANCE_M`` and not inside any)."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        if len(self.segments) == 0:
            return np.ones(len(pts), dtype=bool)
        z = pts.view(np.complex128)[:, 0]
        need = r + CLEARANCE_M
        # the grid lists every segment within REACH_M: enough for a body that narrow
        rows = self.rows(z) if need < REACH_M else self.grid.all_rows(len(z))
        clear = np.empty(len(z), dtype=bool)
        _clear(z, rows, need, clear)
        return clear & ~self.inside_any(pts)

    def free(self, xy: FloatArray, r: float) -> bool:
        """True where a body of radius ``r`` fits at the point ``xy``."""
        return bool(self.free_mask(np.asarray(xy, dtype=np.float64).reshape(1, 2), r)[0])

    def visible(self, a: FloatArray, b: FloatArray) -> bool:
        """True where no segment properly crosses the line of sight ``a``-``b``."""
        return bool(self.visible_many(a, np.asarray(b, dtype=np.float64).reshape(1, 2))[0])

    def visible_many(self, a: FloatArray, bs: FloatArray) -> NDArray[np.bool_]:
        """Per point of ``bs`` ``(M, 2)``: True where no segment properly crosses the line of
        sight ``a``-``b`` (the endpoints of each lie strictly on opposite sides of the other)."""
        b = np.ascontiguousarray(bs, dtype=np.float64).reshape(-1, 2)
        out = np.ones(len(b), dtype=bool)
        _visible(float(a[0]), float(a[1]), b, self.segments, out)
        return out


def _outline_bounds(
    s: FloatArray, starts: NDArray[np.int64] | None
) -> tuple[NDArray[np.int64], NDArray[np.int64], FloatArray] | None:
    """The closed outlines of segments ``s`` starting at ``starts`` (None: none): each one's
    first segment, its number of segments, and ``(3, Q)`` rows ``y_lo``, ``y_hi``, ``x_hi``
    of where a crossing test can count at all (a point with ``y`` below ``y_lo``, at or above
    ``y_hi``, or ``x`` at or beyond ``x_hi`` crosses none of its segments). ValueError unless
    the outlines start at 0, ascend and none is empty."""
    if starts is None or len(s) == 0:
        return None
    first = np.asarray(starts, dtype=np.int64).ravel()
    size = np.diff(np.append(first, len(s)))
    if len(first) == 0 or first[0] != 0 or (size <= 0).any():
        raise ValueError(f"outline_starts must ascend from 0 over {len(s)} segments: {starts!r}")
    box = np.stack(
        [
            np.minimum.reduceat(np.minimum(s[:, 1], s[:, 3]), first),
            np.maximum.reduceat(np.maximum(s[:, 1], s[:, 3]), first),
            np.maximum.reduceat(np.maximum(s[:, 0], s[:, 2]), first),
        ]
    )
    return first, size, box


@compiled
def _inside(pts, seg, first, size, box, out):  # type: ignore[no-untyped-def]
    """``out[i]``: point ``i`` has odd crossing parity for some outline (its ray toward +x
    crosses the outline's segments an odd number of times)."""
    for i in range(pts.shape[0]):
        x, y = pts[i, 0], pts[i, 1]
        for q in range(first.shape[0]):
            if not (box[0, q] <= y < box[1, q] and x < box[2, q]):
                continue
            odd = False
            for k in range(first[q], first[q] + size[q]):
                y0, y1 = seg[k, 1], seg[k, 3]
                if (y0 > y) != (y1 > y):
                    x_cross = seg[k, 0] + (y - y0) / (y1 - y0) * (seg[k, 2] - seg[k, 0])
                    if x_cross > x:
                        odd = not odd
            if odd:
                out[i] = True
                break


@compiled
def _clear(z, rows, need, out):  # type: ignore[no-untyped-def]
    """``out[i]``: point ``z[i]`` is farther than ``need`` from each of its candidate
    segments (rows ``p0, conj(d), 1/|d|^2``)."""
    for i in range(z.shape[0]):
        best = math.inf
        for j in range(rows.shape[1]):
            a = z[i] - rows[i, j, 0]
            cd = rows[i, j, 1]
            t = min(max((a * cd).real * rows[i, j, 2].real, 0.0), 1.0)
            best = min(best, abs(a - t * cd.conjugate()))
        out[i] = best > need


@compiled
def _visible(ax, ay, bs, seg, out):  # type: ignore[no-untyped-def]
    """``out[i]``: no segment properly crosses ``a``-``bs[i]`` (the signs of the four cross
    products of each segment's ends against the sight line and of its ends against it)."""
    for i in range(bs.shape[0]):
        ux, uy = bs[i, 0] - ax, bs[i, 1] - ay
        for k in range(seg.shape[0]):
            w0x, w0y = seg[k, 0] - ax, seg[k, 1] - ay
            w1x, w1y = seg[k, 2] - ax, seg[k, 3] - ay
            dx, dy = w1x - w0x, w1y - w0y
            o1 = ux * w0y - uy * w0x  # u x (p0 - a)
            o2 = ux * w1y - uy * w1x  # u x (p1 - a)
            o3 = dx * w0y - dy * w0x  # d x (p0 - a) = (a - p0) x d
            o4 = dx * (w0y - uy) - dy * (w0x - ux)  # d x (p0 - b)
            if o1 * o2 < 0.0 and o3 * o4 < 0.0:
                out[i] = False
                break
