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
from dynmap_sim.jit import compiled

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


@compiled
def _first_occupied(occupied, x0, y0, ca, sa, t, ox, oy, res, out):  # type: ignore[no-untyped-def]
    """``out[i]``: the first ``k`` whose sample ``(x0 + ca_i t_k, y0 + sa_i t_k)`` falls in an
    occupied cell (``occupied[iy, ix]``, cells ``floor((x - ox) / res)``), -1 for none; each
    beam stops at its first hit."""
    h, w = occupied.shape
    for i in range(ca.shape[0]):
        out[i] = -1
        for k in range(t.shape[0]):
            fx = np.floor((x0 + ca[i] * t[k] - ox) / res)
            fy = np.floor((y0 + sa[i] * t[k] - oy) / res)
            if 0 <= fx < w and 0 <= fy < h and occupied[int(fy), int(fx)]:
                out[i] = k
                break


def cast_rays(
    occupied: NDArray[np.bool_],
    origin_xy_m: FloatArray,
    resolution_m: float,
    laser_pose: ArrayLike,
    angles_rad: ArrayLike,
    range_max_m: float,
) -> tuple[FloatArray, NDArray[np.intp]]:
    """The samples ``t`` [m] along each beam (every half cell up to ``range_max_m``) and, per
    beam, the index of the first in an ``occupied`` cell of the grid (cells ``(H, W)`` from
    ``origin_xy_m``), -1 for none; off-grid samples never hit."""
    p = np.asarray(laser_pose, dtype=np.float64).reshape(3)
    a = p[2] + np.asarray(angles_rad, dtype=np.float64)
    step = 0.5 * resolution_m
    t = np.arange(1, int(np.ceil(range_max_m / step)) + 1) * step
    first = np.empty(len(a), dtype=np.intp)
    _first_occupied(occupied, float(p[0]), float(p[1]), np.cos(a), np.sin(a), t,
                    float(origin_xy_m[0]), float(origin_xy_m[1]), float(resolution_m),
                    first)  # fmt: skip
    return t, first


def short_readings(
    ranges_m: ArrayLike, expected_m: ArrayLike, margin_m: float
) -> NDArray[np.bool_]:
    """Readings that end more than ``margin_m`` before the map's expected range."""
    r = np.asarray(ranges_m, dtype=np.float64)
    return r < np.asarray(expected_m, dtype=np.float64) - margin_m
