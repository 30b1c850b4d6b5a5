"""Planar convex-polygon geometry used by the world: poses, boxes, overlap and distance tests.

Polygons are ``(K, 2)`` float64 arrays of vertices in counter-clockwise order, in metres.
Overlap tests use the separating axis theorem (SAT) on convex polygons; a segment is treated
as a degenerate two-vertex polygon.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def box_vertices(width_m: float, depth_m: float) -> FloatArray:
    """Corners of a ``width_m`` x ``depth_m`` box centred at the origin (local x along width)."""
    hx, hy = 0.5 * width_m, 0.5 * depth_m
    return np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]], dtype=np.float64)


def circle_vertices(radius_m: float, n: int = 16) -> FloatArray:
    """A regular ``n``-gon circumscribing a circle of ``radius_m`` (conservative for overlap)."""
    a = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    r = radius_m / np.cos(np.pi / n)
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def transform(local_xy: FloatArray, pose: tuple[float, float, float], scale: float = 1.0):
    """Map local vertices through ``scale``, then rotation by ``pose[2]`` [rad] and translation."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    rot = np.array([[c, -s], [s, c]])
    return (scale * np.asarray(local_xy, dtype=np.float64)) @ rot.T + np.array(pose[:2])


def ccw(poly: FloatArray) -> FloatArray:
    """Return ``poly`` with counter-clockwise vertex order."""
    x, y = poly[:, 0], poly[:, 1]
    area2 = float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    return poly if area2 >= 0 else poly[::-1].copy()


def is_convex(poly: FloatArray, tol: float = 1e-9) -> bool:
    """True if the simple polygon ``poly`` is convex (collinear vertices allowed)."""
    p = np.asarray(poly, dtype=np.float64)
    if len(p) < 3:
        return False
    e = np.roll(p, -1, axis=0) - p
    cross = e[:, 0] * np.roll(e, -1, axis=0)[:, 1] - e[:, 1] * np.roll(e, -1, axis=0)[:, 0]
    return bool(np.all(cross >= -tol) or np.all(cross <= tol)) and bool(np.any(np.abs(cross) > tol))


def thick_segment(p0, p1, thickness_m: float) -> FloatArray:
    """Rectangle around segment ``p0-p1`` of width ``thickness_m``, capped by half the width.

    The square caps make consecutive pieces of a polyline overlap at the joints, so the
    outline is closed at corners and rays hit the faces.
    """
    p0 = np.asarray(p0, dtype=np.float64)
    p1 = np.asarray(p1, dtype=np.float64)
    d = p1 - p0
    length = float(np.hypot(*d))
    u = d / length
    n = np.array([-u[1], u[0]])
    h = 0.5 * thickness_m
    a, b = p0 - h * u, p1 + h * u
    return np.array([a - h * n, b - h * n, b + h * n, a + h * n])


def edge_normals(poly: FloatArray) -> FloatArray:
    """Unit outward-or-inward edge normals ``(K, 2)`` of a polygon (one for a segment)."""
    e = np.empty_like(poly)
    e[:-1] = poly[1:] - poly[:-1]
    e[-1] = poly[0] - poly[-1]
    if len(poly) == 2:
        e = e[:1]
    n = np.empty_like(e)
    n[:, 0] = -e[:, 1]
    n[:, 1] = e[:, 0]
    norm = np.hypot(n[:, 0], n[:, 1])
    ok = norm > 0
    return n[ok] / norm[ok, None]


def sat_separation(
    a: FloatArray, b: FloatArray, a_axes: FloatArray | None = None, b_axes: FloatArray | None = None
) -> float:
    """Largest gap [m] between the projections of convex ``a`` and ``b`` over SAT axes.

    Positive: the shapes are separated by at least that much (a lower bound on their distance).
    Negative: they overlap; ``-value`` is the penetration depth along the best axis.
    ``a_axes``/``b_axes`` are the polygons' :func:`edge_normals` when already known.
    """
    axes = np.concatenate(
        [
            edge_normals(a) if a_axes is None else a_axes,
            edge_normals(b) if b_axes is None else b_axes,
        ]
    ).T
    pa = a @ axes
    pb = b @ axes
    gap = np.maximum(pb.min(axis=0) - pa.max(axis=0), pa.min(axis=0) - pb.max(axis=0))
    return float(gap.max())


def point_segment_distance(points: FloatArray, segments: FloatArray) -> FloatArray:
    """Distances ``(P, N)`` [m] from points ``(P, 2)`` to segments ``(N, 4)``."""
    p = points[:, None, :]
    a = segments[None, :, 0:2]
    d = segments[None, :, 2:4] - a
    dd = np.maximum(np.sum(d * d, axis=-1), 1e-18)
    t = np.clip(np.sum((p - a) * d, axis=-1) / dd, 0.0, 1.0)
    c = a + t[..., None] * d
    return np.hypot(p[..., 0] - c[..., 0], p[..., 1] - c[..., 1])


def polygon_edges(poly: FloatArray) -> FloatArray:
    """Closed outline of ``poly`` as segments ``(K, 4)`` rows ``x0, y0, x1, y1``."""
    out = np.empty((len(poly), 4))
    out[:, :2] = poly
    out[:-1, 2:] = poly[1:]
    out[-1, 2:] = poly[0]
    return out


def points_in_convex(points: FloatArray, poly: FloatArray) -> NDArray[np.bool_]:
    """True where points ``(P, 2)`` lie strictly inside the CCW convex polygon ``poly``."""
    e = np.roll(poly, -1, axis=0) - poly
    rel = points[:, None, :] - poly[None, :, :]
    cross = e[None, :, 0] * rel[..., 1] - e[None, :, 1] * rel[..., 0]
    return np.all(cross > 0, axis=1)


def segment_pair_distances(a: FloatArray, b: FloatArray) -> FloatArray:
    """Distances ``(A, B)`` [m] between every segment of ``a`` ``(A, 4)`` and ``b`` ``(B, 4)``."""

    def pt_seg(p: FloatArray, s: FloatArray) -> FloatArray:  # p (A,1,2) or (1,B,2); s likewise
        s0 = s[..., 0:2]
        d = s[..., 2:4] - s0
        dd = np.maximum(np.sum(d * d, axis=-1), 1e-18)
        t = np.clip(np.sum((p - s0) * d, axis=-1) / dd, 0.0, 1.0)
        q = p - (s0 + t[..., None] * d)
        return np.hypot(q[..., 0], q[..., 1])

    A, B = a[:, None, :], b[None, :, :]
    dist = np.minimum.reduce(
        [
            pt_seg(A[..., 0:2], B),
            pt_seg(A[..., 2:4], B),
            pt_seg(B[..., 0:2], A),
            pt_seg(B[..., 2:4], A),
        ]
    )

    def orient(p, q, r):
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (
            r[..., 0] - p[..., 0]
        )

    o1 = orient(A[..., 0:2], A[..., 2:4], B[..., 0:2])
    o2 = orient(A[..., 0:2], A[..., 2:4], B[..., 2:4])
    o3 = orient(B[..., 0:2], B[..., 2:4], A[..., 0:2])
    o4 = orient(B[..., 0:2], B[..., 2:4], A[..., 2:4])
    return np.where((o1 * o2 < 0) & (o3 * o4 < 0), 0.0, dist)


def polyline_clearance(route: FloatArray, polygons: list[FloatArray]) -> FloatArray:
    """Clearance [m] of a route polyline ``(K, 2)`` from each convex polygon (0 if it enters)."""
    route = np.asarray(route, dtype=np.float64)
    if not polygons:
        return np.zeros(0)
    legs = np.concatenate([route[:-1], route[1:]], axis=1)
    edges = [polygon_edges(p) for p in polygons]
    starts = np.cumsum([0] + [len(e) for e in edges[:-1]])
    d = segment_pair_distances(legs, np.concatenate(edges)).min(axis=0)
    out = np.minimum.reduceat(d, starts)
    for k, poly in enumerate(polygons):  # a route wholly inside a polygon crosses no edge
        if out[k] > 0 and points_in_convex(route[:1], ccw(poly)).any():
            out[k] = 0.0
    return out
