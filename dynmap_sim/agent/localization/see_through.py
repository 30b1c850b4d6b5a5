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

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.grid import OccupancyGrid
from dynmap_sim.jit import compiled

FloatArray = NDArray[np.float64]


class _Beams(NamedTuple):
    """The walks' inputs: per particle the laser ``lx, ly`` [m] and heading ``c, s``; per beam
    its direction ``cb, sb`` on the robot and the walk's ``length`` [m]."""

    lx: FloatArray
    ly: FloatArray
    c: FloatArray
    s: FloatArray
    cb: FloatArray
    sb: FloatArray
    length: FloatArray


@compiled
def _wall_depths(dist, ox, oy, res, beams, out):  # type: ignore[no-untyped-def]
    """``out[i, j]``: the first sample ``t < length_j`` [m] at which the walk from particle
    ``i``'s laser along beam ``j`` (:class:`_Beams`) is in an occupied cell, ``inf`` for none;
    samples from ``res / 2`` on, each step ``max(dist - 1.5 res, res / 2)`` with ``dist``
    [m] the distance field at the sample's cell (0 in an occupied cell); a sample off the
    grid ends the walk."""
    lx, ly, c, s, cb, sb, length = beams
    h, w = dist.shape
    inv_res = 1.0 / res
    for i in range(c.shape[0]):
        for j in range(cb.shape[0]):
            out[i, j] = np.inf
            ca = c[i] * cb[j] - s[i] * sb[j]
            sa = s[i] * cb[j] + c[i] * sb[j]
            t = 0.5 * res
            while t < length[j]:
                fx = np.floor((lx[i] + ca * t - ox) * inv_res)
                fy = np.floor((ly[i] + sa * t - oy) * inv_res)
                if not (0 <= fx < w and 0 <= fy < h):
                    break
                d = float(dist[int(fy), int(fx)])
                if d == 0.0:  # an occupied cell: its distance to the nearest is 0
                    out[i, j] = t
                    break
                t = t + max(d - 1.5 * res, 0.5 * res)


def wall_depths(
    grid: OccupancyGrid,
    particles: ArrayLike,
    ranges_m: ArrayLike,
    angles_rad: ArrayLike,
    mount_pose: ArrayLike,
    margin_m: float,
) -> FloatArray:
    """``(P, B)`` [m]: along particle ``i``'s beam ``j`` (``angles_rad`` [rad] in the laser
    frame, the laser at ``mount_pose`` on the robot), the distance of the first occupied
    cell of ``grid`` met before ``ranges_m[j] - margin_m``; ``inf`` for none (the reading
    does not see through)."""
    p = np.asarray(particles, dtype=np.float64).reshape(-1, 3)
    r = np.asarray(ranges_m, dtype=np.float64)
    a = np.asarray(angles_rad, dtype=np.float64)
    mx, my, myaw = (float(v) for v in mount_pose)
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    beams = _Beams(p[:, 0] + c * mx - s * my, p[:, 1] + s * mx + c * my, c, s,
                   np.cos(a + myaw), np.sin(a + myaw), r - margin_m)  # fmt: skip
    out = np.empty((len(p), len(a)), dtype=np.float64)
    ox, oy = (float(v) for v in grid.origin_xy_m)
    _wall_depths(grid.dist_m, ox, oy, float(grid.resolution_m), beams, out)
    return out


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

    Only the see-through readings are scored: they are a few percent of a cloud's readings
    on a tracked run."""
    r = np.asarray(ranges_m, dtype=np.float64)
    d = np.asarray(depths_m, dtype=np.float64)
    out = np.zeros(d.shape)
    k = np.flatnonzero(np.isfinite(d))  # flat (particle, reading) indices
    beyond = np.maximum(r.take(k % d.shape[-1]) - d.take(k) - margin_m, 0.0)
    p = z_hit * np.exp(beyond * beyond * (-0.5 / sigma_hit_m**2)) + z_rand / range_max_m
    out.put(k, np.log(p))
    return out
