"""Optional numba kernel of the route memory's per-scan work (extra ``fast``).

* :func:`locate_segment`: :meth:`~.route_memory.RouteMemory.locate`'s search (H&W §5.1) —
  the robot projected onto every segment of every route, the nearest segment, the nearest of
  the tracked route and the nearest within the continuity window — in one loop instead of
  ~25 numpy operations on arrays of a few dozen segments.

The arithmetic is the numpy code's, operation for operation (``b - a``, the two-term dot
products, the clip as numpy's ``max`` then ``min``, ``hypot`` from the C library as numpy's),
and a minimum is the first one as ``argmin``'s, so the results are identical. The kernel is
plain Python (what the tests run against the numpy code), compiled with
:func:`dynmap_sim.jit.compiled` when numba is installed.
"""

from __future__ import annotations

import math

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
        dist = math.hypot(px - (ax + u * dx), py - (ay + u * dy))
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
