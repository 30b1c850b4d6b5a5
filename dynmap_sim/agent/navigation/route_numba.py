"""Optional numba kernels of the route memory's and the stack's per-scan work (extra ``fast``).

* :func:`locate_segment`: :meth:`~.route_memory.RouteMemory.locate`'s search (H&W §5.1) —
  the robot projected onto every segment of every route, the nearest segment, the nearest of
  the tracked route and the nearest within the continuity window — in one loop instead of
  ~25 numpy operations on arrays of a few dozen segments.
* :func:`cut_probe`: :meth:`~.stack.NavigationStack._cut_ahead`'s corridor check (H&W §6.3)
  — samples along the path ahead (:func:`~dynmap_sim.agent.planning.costmap.samples_along`'s
  arithmetic), their summed steps, and each kept sample's lateral offsets looked up in the
  clearance grid (:meth:`~dynmap_sim.agent.planning.clearance_grid.ClearanceGrid.
  clearance_at`'s ``rint`` and clip) — in one loop instead of ~30 numpy operations.

The arithmetic is the numpy code's, operation for operation (``b - a``, the two-term dot
products, the clip as numpy's ``max`` then ``min``, ``ceil`` and ``rint``, sums in order as
``cumsum``'s, and ``np.hypot``, which is the C library's in numba as in numpy, while Python's
``math.hypot`` is not), and a minimum is the first one as ``argmin``'s, so the results are
identical. Each kernel is plain Python (what the tests run against the numpy code), compiled with
:func:`dynmap_sim.jit.compiled` when numba is installed.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled
from dynmap_sim.jit import numba_available as numba_available  # re-exported

FloatArray = NDArray[np.float64]


def _locate_py(  # type: ignore[no-untyped-def]
    px,
    py,
    a,
    b,
    rid,
    s0,
    seg_len,
    prefer_route,
    prefer_along_m,
    use_prefer,
    use_along,
    window_m,
    continuity_m,
):
    """Index of the segment :meth:`RouteMemory.locate` picks, its clamped fraction ``u``,
    distance and projection ``(qx, qy)``; ``k = -1`` without segments."""
    k, k2, k3 = -1, -1, -1
    best, best2, best3 = 0.0, 0.0, 0.0
    u_k, u_k2, u_k3 = 0.0, 0.0, 0.0
    for i in range(a.shape[0]):
        ax, ay = a[i, 0], a[i, 1]
        dx, dy = b[i, 0] - ax, b[i, 1] - ay
        len2 = dx * dx + dy * dy
        t = ((px - ax) * dx + (py - ay) * dy) / (len2 if len2 > 1e-18 else 1e-18)
        u = t if t > 0.0 else 0.0  # numpy's clip: max(t, 0), then min(., 1)
        u = u if u < 1.0 else 1.0
        dist = np.hypot(px - (ax + u * dx), py - (ay + u * dy))
        if k < 0 or dist < best:
            k, best, u_k = i, dist, u
        if use_prefer and rid[i] == prefer_route:
            if k2 < 0 or dist < best2:
                k2, best2, u_k2 = i, dist, u
            if use_along and abs(s0[i] + u * seg_len[i] - prefer_along_m) <= window_m:
                if k3 < 0 or dist < best3:
                    k3, best3, u_k3 = i, dist, u
    if k2 >= 0 and best2 <= best + 1e-9:
        k, best, u_k = k2, best2, u_k2
    if k3 >= 0 and best3 <= best + continuity_m:
        k, best, u_k = k3, best3, u_k3
    if k < 0:
        return -1, 0.0, 0.0, 0.0, 0.0
    ax, ay = a[k, 0], a[k, 1]
    return k, u_k, best, ax + u_k * (b[k, 0] - ax), ay + u_k * (b[k, 1] - ay)


_locate_nb = compiled(_locate_py)


def locate_segment(
    px: float,
    py: float,
    a: FloatArray,
    b: FloatArray,
    rid: NDArray[np.int64],
    s0: FloatArray,
    seg_len: FloatArray,
    prefer_route: int | None,
    prefer_along_m: float | None,
    window_m: float,
    continuity_m: float,
    python: bool = False,
) -> tuple[int, float, float, float, float]:
    """:func:`_locate_py` compiled: ``(k, u, distance, qx, qy)`` of the segment picked
    (``python``: the uncompiled kernel)."""
    fn = _locate_py if python or _locate_nb is None else _locate_nb
    k, u, dist, qx, qy = fn(
        px,
        py,
        a,
        b,
        rid,
        s0,
        seg_len,
        -1 if prefer_route is None else prefer_route,
        0.0 if prefer_along_m is None else prefer_along_m,
        prefer_route is not None,
        prefer_along_m is not None,
        window_m,
        continuity_m,
    )
    return int(k), float(u), float(dist), float(qx), float(qy)


def _cut_probe_py(  # type: ignore[no-untyped-def]
    verts, hw_seg, step_m, max_along_m, lin, clearance, ox, oy, res, min_clearance_m
):
    """Samples every ``step_m`` along the polyline ``verts (S+1, 2)`` (each segment from its
    start, end excluded) whose summed steps are within ``max_along_m``: their points
    ``(K, 2)`` and whether every lateral offset ``lin * l`` (``l = hw_seg`` of the segment,
    along its left normal) has less than ``min_clearance_m`` in the grid ``clearance``
    (cell ``(0, 0)`` centred at ``(ox, oy)``, ``res`` [m])."""
    n_seg = verts.shape[0] - 1
    counts = np.empty(n_seg, np.int64)
    lengths = np.empty(n_seg)
    total = 0
    for i in range(n_seg):
        lengths[i] = np.hypot(verts[i + 1, 0] - verts[i, 0], verts[i + 1, 1] - verts[i, 1])
        c = np.int64(np.ceil(lengths[i] / step_m))
        counts[i] = c if c > 1 else 1
        total += counts[i]
    pts = np.empty((total, 2))
    cut = np.zeros(total, np.bool_)
    h, w = clearance.shape
    k = 0
    along = 0.0
    px, py = 0.0, 0.0
    for i in range(n_seg):
        ax, ay = verts[i, 0], verts[i, 1]
        dx, dy = verts[i + 1, 0] - ax, verts[i + 1, 1] - ay
        length = lengths[i]
        nrm = length if length > 1e-12 else 1e-12
        nx, ny = -(dy / nrm), dx / nrm
        for m in range(counts[i]):
            t = m * step_m
            u = t / length if length > 0 else 0.0
            x, y = ax + u * dx, ay + u * dy
            if k > 0:
                along += np.hypot(x - px, y - py)
                if not along <= max_along_m:
                    return pts[:k], cut[:k]
            px, py = x, y
            pts[k, 0], pts[k, 1] = x, y
            all_cut = True
            for j in range(lin.shape[0]):
                off = lin[j] * hw_seg[i]
                r = np.int64(np.rint((y + off * ny - oy) / res))
                col = np.int64(np.rint((x + off * nx - ox) / res))
                r = min(max(r, 0), h - 1)
                col = min(max(col, 0), w - 1)
                if not clearance[r, col] < min_clearance_m:
                    all_cut = False
                    break
            cut[k] = all_cut
            k += 1
    return pts[:k], cut[:k]


_cut_probe_nb = compiled(_cut_probe_py)


def cut_probe(*args: object, python: bool = False) -> tuple[FloatArray, NDArray[np.bool_]]:
    """:func:`_cut_probe_py` compiled (its arguments; ``python``: the uncompiled one)."""
    fn = _cut_probe_py if python or _cut_probe_nb is None else _cut_probe_nb
    return fn(*args)  # type: ignore[no-any-return]
