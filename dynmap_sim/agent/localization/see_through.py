"""See-through readings: negative information for the likelihood field (Fox et al. 1999).

The likelihood field (*Probabilistic Robotics* §6.4, :mod:`.likelihood_field`) scores a
reading by its end point only, so it "can see through walls" (Thrun et al. §6.4.2 name this
its main drawback): a pose whose beams cross mapped walls and end near some other obstacle
fits as well as the true pose. Fox, Burgard & Thrun 1999 (JAIR 11, §4.2; :mod:`.distance_filter`)
give the asymmetry this module uses: a reading *shorter* than the map predicts may be an
unmapped object, one *longer* than the first mapped obstacle along its beam can only be a
wrong pose (or an object that was removed).

A particle's reading **sees through** when it ends ``delta`` beyond the first occupied cell of
the map along its beam, ``delta > margin_m`` (map error and grid steps stay below the
margin). The beam model (*Probabilistic Robotics* Table 6.1) scores such a reading by its
distance to the expected range: ``p = z_hit exp(-(delta - margin)^2 / 2 sigma_hit^2) + z_rand
/ range_max`` (:func:`see_through_logp`), the likelihood field's own form with the margin
taken off, so the score equals the field's best at ``delta = margin`` and falls to the
``z_rand`` floor a few ``sigma_hit`` beyond it: no step that would split a cloud at the
margin. The filter keeps the smaller of this and the likelihood field's value
(:attr:`~.particle_filter.MCLConfig.see_through_margin_m`).

The first occupied cell is found by walking each beam from the laser by *sphere tracing* on
the map's distance field (``grid.dist_m``: distance from each cell centre to the nearest
occupied cell centre): from a sample in a cell whose centre is ``d`` from the nearest
occupied centre, no point of an occupied cell lies within ``d - sqrt(2) res`` (half a
diagonal at each end), so the walk steps ``max(d - 1.5 res, 0.5 res)`` and tests the cell of
every sample (occupied where ``d`` is 0): in open space a few steps per beam, along walls
the half-cell steps of :func:`.distance_filter.cast_rays`. A walk stops at the reading's end
less the margin (nothing beyond can make ``delta`` exceed it), or where it leaves the grid (a
ray that left a rectangle never re-enters it).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.grid import OccupancyGrid
from dynmap_sim.agent.localization import mcl_numba
from dynmap_sim.jit import kernel_backend

FloatArray = NDArray[np.float64]


def wall_depths(
    grid: OccupancyGrid,
    particles: ArrayLike,
    ranges_m: ArrayLike,
    angles_rad: ArrayLike,
    mount_pose: ArrayLike,
    margin_m: float,
    backend: str = "auto",
) -> FloatArray:
    """``(P, B)`` [m]: along particle ``i``'s beam ``j`` (``angles_rad`` [rad] in the laser
    frame, the laser at ``mount_pose`` on the robot), the distance of the first occupied
    cell of ``grid`` met before ``ranges_m[j] - margin_m``; ``inf`` for none (the reading
    does not see through). ``backend`` (:data:`dynmap_sim.jit.KERNEL_BACKENDS`):
    :mod:`.mcl_numba`'s kernel (beam by beam) or numpy (all beams in lockstep); the same
    walk, the same samples."""
    p = np.asarray(particles, dtype=np.float64).reshape(-1, 3)
    r = np.asarray(ranges_m, dtype=np.float64)
    a = np.asarray(angles_rad, dtype=np.float64)
    mx, my, myaw = (float(v) for v in mount_pose)
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    lx = p[:, 0] + c * mx - s * my
    ly = p[:, 1] + s * mx + c * my
    cb, sb = np.cos(a + myaw), np.sin(a + myaw)
    length = r - margin_m
    kernel = kernel_backend(backend)
    frame = (float(grid.origin_xy_m[0]), float(grid.origin_xy_m[1]), float(grid.resolution_m))
    terms = (lx, ly, c, s, cb, sb, length)
    if kernel:
        return mcl_numba.wall_depths(grid.dist_m, frame, terms, python=kernel == "python")
    return _wall_depths_numpy(grid.dist_m, *frame, *terms)


def see_through_logp(
    depths_m: FloatArray,
    ranges_m: ArrayLike,
    margin_m: float,
    z_hit: float,
    z_rand: float,
    sigma_hit_m: float,
    range_max_m: float,
) -> FloatArray:
    """``(P, B)`` log score of each reading by how far it ends beyond its wall
    (``delta = range - depth``): ``log(z_hit exp(-(delta - margin)^2 / 2 sigma^2) + z_rand /
    range_max)``; ``0`` where it does not see through (``depth`` inf), so that a minimum with
    the likelihood field's value leaves those readings alone.

    Only the see-through readings are scored (a few percent of a cloud's readings on a
    tracked run): numpy's ``exp`` and ``log`` give an element the same bits wherever it
    stands in an array, so the scores are those of scoring every reading."""
    r = np.asarray(ranges_m, dtype=np.float64)
    d = np.asarray(depths_m, dtype=np.float64)
    out = np.zeros(d.shape)
    k = np.flatnonzero(np.isfinite(d))  # flat (particle, reading) indices
    beyond = np.maximum(r.take(k % d.shape[-1]) - d.take(k) - margin_m, 0.0)
    p = z_hit * np.exp(beyond * beyond * (-0.5 / sigma_hit_m**2)) + z_rand / range_max_m
    out.put(k, np.log(p))
    return out


def _wall_depths_numpy(
    dist_m: NDArray[np.float32],
    ox: float,
    oy: float,
    res: float,
    lx: FloatArray,
    ly: FloatArray,
    c: FloatArray,
    s: FloatArray,
    cb: FloatArray,
    sb: FloatArray,
    length: FloatArray,
) -> FloatArray:
    """The walk of :func:`.mcl_numba._wall_depths_py` for all beams at once: each round moves
    every unfinished beam one step (the same arithmetic, so the same samples)."""
    n_p, n_b = len(c), len(cb)
    h, w = dist_m.shape
    inv_res = 1.0 / res
    out = np.full(n_p * n_b, np.inf)
    x0 = np.repeat(lx, n_b)
    y0 = np.repeat(ly, n_b)
    cx = (c[:, None] * cb[None, :] - s[:, None] * sb[None, :]).ravel()
    sy = (s[:, None] * cb[None, :] + c[:, None] * sb[None, :]).ravel()
    lim = np.tile(length, n_p)
    t = np.full(n_p * n_b, 0.5 * res)
    live = np.flatnonzero(t < lim)
    while len(live):
        tl = t[live]
        fx = np.floor((x0[live] + cx[live] * tl - ox) * inv_res)
        fy = np.floor((y0[live] + sy[live] * tl - oy) * inv_res)
        inside = (fx >= 0) & (fx < w) & (fy >= 0) & (fy < h)
        live, fx, fy, tl = live[inside], fx[inside], fy[inside], tl[inside]
        d = dist_m[fy.astype(np.intp), fx.astype(np.intp)].astype(np.float64)
        hit = d == 0.0
        out[live[hit]] = tl[hit]
        live, d, tl = live[~hit], d[~hit], tl[~hit]
        t[live] = tl + np.maximum(d - 1.5 * res, 0.5 * res)
        live = live[t[live] < lim[live]]
    return out.reshape(n_p, n_b)
