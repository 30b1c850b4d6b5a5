"""Optional numba backend of :meth:`.local_map.LocalMap.log_likelihoods` (extra ``fast``).

The perceptual model of Biber & Duckett eq. 6–8 for the readings of one scan under several
timescales of one local map: each reading is projected to the map's centre (bearing, distance,
§4.1), goes to the closest ray of each sub-map and gets ``log p(d)`` from that ray's row of
the model table (:meth:`.sample_set.SampleSets.model_table`) -- the numpy code's operations
in one compiled loop (``libm``'s ``atan2``/``exp``/``log`` instead of numpy's, so values agree
to rounding). :func:`numba_available` says whether it can be used.

:func:`polar_rays` is the projection alone for learning (:meth:`.local_map.LocalMap.
learn_levels`): each point's millimetre range and its ray in sub-maps of a few numbers of
rays, for the points within the maximum range -- ``libm``'s ``atan2`` and ``hypot``, which
numpy's ``arctan2`` and ``hypot`` call, then the numpy code's operations: the same values.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, require_numba
from dynmap_sim.jit import numba_available as numba_available  # re-exported

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


def _scan_loglik_py(
    px: FloatArray,
    py: FloatArray,
    cx: float,
    cy: float,
    table: FloatArray,
    offsets: IntArray,
    n_rays: IntArray,
    max_range_m: float,
    out: FloatArray,
) -> None:
    """``out[b, i] = log p`` of reading ``i`` under the level whose table rows start at
    ``offsets[b]`` (``n_rays[b]`` rays)."""
    two_pi = 2.0 * math.pi
    for i in range(px.shape[0]):
        dx = px[i] - cx
        dy = py[i] - cy
        ang = math.atan2(dy, dx) % two_pi
        dist = math.hypot(dx, dy)
        inside = dist >= 0.0 and dist <= max_range_m
        for b in range(offsets.shape[0]):
            nr = n_rays[b]
            ray = np.int64(np.rint(ang * (nr / two_pi))) % nr
            row = offsets[b] + ray
            z = dist - table[row, 0]
            p = math.exp(table[row, 2] - z * z * table[row, 1])
            if inside:
                p += table[row, 3]
            out[b, i] = math.log(p) if p > 0.0 else -math.inf


_scan_loglik = compiled(_scan_loglik_py)


def _polar_rays_py(
    px: FloatArray,
    py: FloatArray,
    cx: float,
    cy: float,
    max_range_m: float,
    n_rays: IntArray,
    mm: NDArray[np.uint16],
    rays: IntArray,
) -> int:
    """The points within ``max_range_m`` of ``(cx, cy)``, in order: their ranges rounded
    to millimetres (clipped to ``[0, 65535]``) in ``mm`` and their closest rays in
    ``rays[b]`` for sub-maps of ``n_rays[b]`` rays; returns how many."""
    two_pi = 2.0 * math.pi
    k = 0
    for i in range(px.shape[0]):
        dx = px[i] - cx
        dy = py[i] - cy
        dist = math.hypot(dx, dy)
        if not dist <= max_range_m:
            continue
        ang = math.atan2(dy, dx) % two_pi
        mm[k] = np.uint16(min(max(np.rint(dist * 1000.0), 0.0), 65535.0))
        for b in range(n_rays.shape[0]):
            nr = n_rays[b]
            rays[b, k] = np.int64(np.rint(ang * (nr / two_pi))) % nr
        k += 1
    return k


_polar_rays = compiled(_polar_rays_py)


def polar_rays(
    points_map: FloatArray,
    centre: FloatArray,
    max_range_m: float,
    n_rays: IntArray,
    python: bool = False,
) -> tuple[NDArray[np.uint16], IntArray]:
    """Millimetre ranges ``(K,)`` and rays ``(len(n_rays), K)`` of the ``K`` map-frame points
    ``(N, 2)`` within ``max_range_m`` of ``centre`` (compiled; ``python``: the plain kernel)."""
    if not python:
        require_numba("backend")
    n = len(points_map)
    mm = np.empty(n, dtype=np.uint16)
    rays = np.empty((len(n_rays), n), dtype=np.int64)
    k = (_polar_rays_py if python else _polar_rays)(
        np.ascontiguousarray(points_map[:, 0]),
        np.ascontiguousarray(points_map[:, 1]),
        float(centre[0]),
        float(centre[1]),
        float(max_range_m),
        n_rays,
        mm,
        rays,
    )
    return mm[:k], rays[:, :k]


def scan_log_likelihoods(
    points_map: FloatArray,
    centre: FloatArray,
    table: FloatArray,
    offsets: IntArray,
    n_rays: IntArray,
    max_range_m: float,
    out: FloatArray | None = None,
    columns: tuple[FloatArray, FloatArray] | None = None,
) -> FloatArray:
    """``(len(offsets), N)`` log-likelihoods of map-frame points (compiled; needs numba),
    written into ``out`` (C-contiguous) when given; ``columns``: the points' x and y as
    contiguous arrays, when the caller has them (``points_map`` is then not read)."""
    require_numba("backend")
    if columns is None:
        columns = (np.ascontiguousarray(points_map[:, 0]), np.ascontiguousarray(points_map[:, 1]))
    if out is None:
        out = np.empty((len(offsets), len(columns[0])))
    _scan_loglik(
        columns[0],
        columns[1],
        float(centre[0]),
        float(centre[1]),
        table,
        offsets,
        n_rays,
        float(max_range_m),
        out,
    )
    return out
