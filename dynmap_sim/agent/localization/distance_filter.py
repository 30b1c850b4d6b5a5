"""Distance filter: readings much shorter than the map predicts (Fox, Burgard & Thrun 1999).

D. Fox, W. Burgard and S. Thrun, "Markov Localization for Mobile Robots in Dynamic
Environments", JAIR 11, 1999, §4.2: in a populated environment a reading that is *shorter*
than the distance to the nearest mapped obstacle along the beam is most likely caused by an
unmodelled object (a person, a moved chair), while a reading that is *longer* than the map
allows cannot be explained by anything but a wrong pose (or a removed object). Their filter
drops readings whose probability of being "short" exceeds 0.99; this is its deterministic
form at a single pose: a reading is short when it ends more than ``margin_m`` before the
first occupied cell along the beam in the map.

``static-mcl`` (``tuned``) uses it only for its recovery signal (``w_slow``/``w_fast``): a
crowd in front of the robot lowers the likelihood of the scan but not of the readings that
pass it, so it no longer looks like a kidnapping.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.grid import OCCUPIED, OccupancyGrid
from dynmap_sim.agent.localization import mcl_numba
from dynmap_sim.jit import kernel_backend

FloatArray = NDArray[np.float64]


def expected_ranges(
    grid: OccupancyGrid,
    laser_pose: ArrayLike,
    angles_rad: ArrayLike,
    range_max_m: float,
    occupied: NDArray[np.bool_] | None = None,
) -> FloatArray:
    """Distance [m] from ``laser_pose`` (x, y, theta) to the first occupied cell along each
    beam at ``angles_rad`` (laser frame), stepping half a cell; ``inf`` when there is none
    within ``range_max_m`` (unknown and off-grid cells do not stop a beam). ``occupied``:
    ``grid.occupancy == OCCUPIED``, for a caller that casts from many poses on one grid
    (made here when not given)."""
    if occupied is None:
        occupied = grid.occupancy == OCCUPIED
    t, first = cast_rays(occupied, grid.origin_xy_m, grid.resolution_m, laser_pose, angles_rad,
                         range_max_m)  # fmt: skip
    return np.where(first >= 0, t[first], np.inf)


def cast_rays(
    occupied: NDArray[np.bool_],
    origin_xy_m: FloatArray,
    resolution_m: float,
    laser_pose: ArrayLike,
    angles_rad: ArrayLike,
    range_max_m: float,
    backend: str = "auto",
) -> tuple[FloatArray, NDArray[np.intp]]:
    """The samples ``t`` [m] along each beam (every half cell up to ``range_max_m``) and, per
    beam, the index of the first in an ``occupied`` cell of the grid (cells ``(H, W)`` from
    ``origin_xy_m``), -1 for none; off-grid samples never hit. ``backend``
    (:data:`dynmap_sim.jit.KERNEL_BACKENDS`): :mod:`.mcl_numba`'s kernel, which stops each
    beam at its first hit (the same indices), or numpy."""
    kernel = kernel_backend(backend)
    p = np.asarray(laser_pose, dtype=np.float64).reshape(3)
    a = p[2] + np.asarray(angles_rad, dtype=np.float64)
    step = 0.5 * resolution_m
    t = np.arange(1, int(np.ceil(range_max_m / step)) + 1) * step
    if kernel:
        first = mcl_numba.first_occupied(occupied, origin_xy_m, resolution_m, p[:2],
                                         (np.cos(a), np.sin(a)), t,
                                         python=kernel == "python")  # fmt: skip
        return t, first
    xs = p[0] + np.cos(a)[:, None] * t[None, :]
    ys = p[1] + np.sin(a)[:, None] * t[None, :]
    ix = np.floor((xs - origin_xy_m[0]) / resolution_m).astype(np.intp)
    iy = np.floor((ys - origin_xy_m[1]) / resolution_m).astype(np.intp)
    h, w = occupied.shape
    inside = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
    occ = np.zeros(xs.shape, dtype=bool)
    occ[inside] = occupied[iy[inside], ix[inside]]
    return t, np.where(occ.any(axis=1), np.argmax(occ, axis=1), -1)


def short_readings(
    ranges_m: ArrayLike, expected_m: ArrayLike, margin_m: float
) -> NDArray[np.bool_]:
    """Readings that end more than ``margin_m`` before the map's expected range."""
    r = np.asarray(ranges_m, dtype=np.float64)
    return r < np.asarray(expected_m, dtype=np.float64) - margin_m
