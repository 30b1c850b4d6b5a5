"""Likelihood-field range-finder model (*Probabilistic Robotics* §6.4, Table 6.3) as in AMCL.

For every particle and every selected beam the end point is projected into the map and
looked up in the precomputed distance field ``d``; the beam's likelihood is

    p = z_hit exp(-d^2 / (2 sigma_hit^2)) + z_rand / range_max.

Two ways to combine beams, as in nav2's AMCL:

* ``likelihood_field``: AMCL's heuristic ``w = 1 + sum_k p_k^3`` (a sum, not a product,
  which keeps weights well conditioned);
* ``likelihood_field_prob``: the proper product ``w = prod_k p_k`` (here in log domain),
  with optional **beam skipping**: a beam is ignored when fewer than ``beam_skip_threshold``
  of the particles see it within ``beam_skip_distance`` of an obstacle (it most likely hit
  something not in the map), unless so many beams would be skipped (at least
  ``beam_skip_error_threshold`` of them) that the filter has probably diverged, in which
  case all beams count.

Beams are subsampled like AMCL: ``max_beams`` evenly spaced; readings that are not finite or
at/over ``range_max`` are ignored. Everything is vectorized over particles x beams.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.grid import OccupancyGrid

FloatArray = NDArray[np.float64]


def select_beams(n_beams: int, max_beams: int) -> NDArray[np.intp]:
    """Indices of AMCL's evenly spaced beam subset (``step = (n-1)/(max_beams-1)``)."""
    if max_beams >= n_beams or max_beams < 2:
        return np.arange(n_beams, dtype=np.intp)
    step = (n_beams - 1) / (max_beams - 1)
    return np.unique(np.floor(np.arange(max_beams) * step).astype(np.intp))


@dataclass(frozen=True)
class LikelihoodFieldParams:
    """Parameters of the model (nav2 names): ``sigma_hit`` [m], ``z_hit``, ``z_rand``,
    ``range_max`` [m] (the ``z_rand`` density is uniform over it), beam skipping."""

    z_hit: float = 0.5
    z_rand: float = 0.5
    sigma_hit: float = 0.2
    range_max: float = 100.0
    do_beamskip: bool = False
    beam_skip_distance: float = 0.5
    beam_skip_threshold: float = 0.3
    beam_skip_error_threshold: float = 0.9


def endpoint_distances(
    particles: FloatArray,
    ranges_m: FloatArray,
    angles_rad: FloatArray,
    mount_pose: ArrayLike,
    grid: OccupancyGrid,
) -> NDArray[np.float32]:
    """Distance-field value ``(P, B)`` at each beam's end point for each particle pose."""
    mx, my, myaw = (float(v) for v in mount_pose)
    c = np.cos(particles[:, 2])[:, None]
    s = np.sin(particles[:, 2])[:, None]
    lx = particles[:, 0:1] + c * mx - s * my
    ly = particles[:, 1:2] + s * mx + c * my
    bx = (ranges_m * np.cos(angles_rad + myaw))[None, :]
    by = (ranges_m * np.sin(angles_rad + myaw))[None, :]
    inv_res = 1.0 / grid.resolution_m
    hx = (lx + c * bx - s * by - grid.origin_xy_m[0]) * inv_res
    hy = (ly + s * bx + c * by - grid.origin_xy_m[1]) * inv_res
    h, w = grid.shape
    ix = np.floor(hx).astype(np.intp)
    iy = np.floor(hy).astype(np.intp)
    inside = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
    flat = np.where(inside, iy * w + ix, 0)
    d = np.take(grid.dist_m.ravel(), flat)
    return np.where(inside, d, np.float32(grid.max_dist_m))


def beam_likelihoods(d: ArrayLike, params: LikelihoodFieldParams) -> FloatArray:
    """Per-beam likelihood ``p = z_hit exp(-d^2/2 sigma^2) + z_rand / range_max``."""
    d = np.asarray(d, dtype=np.float64)
    return params.z_hit * np.exp(d * d * (-0.5 / params.sigma_hit**2)) + (
        params.z_rand / params.range_max
    )


def valid_beams(ranges_m: ArrayLike, range_max_m: float) -> NDArray[np.bool_]:
    """Readings the model uses: finite and below ``range_max_m``."""
    r = np.asarray(ranges_m, dtype=np.float64)
    return np.isfinite(r) & (r < range_max_m) & (r > 0)


def likelihood_field_weights(d: ArrayLike, params: LikelihoodFieldParams) -> FloatArray:
    """AMCL ``likelihood_field``: ``w = 1 + sum_k p_k^3`` per particle ``(P,)``."""
    p = beam_likelihoods(d, params)
    return 1.0 + np.sum(p * p * p, axis=1)


def likelihood_field_prob_logweights(
    d: ArrayLike, params: LikelihoodFieldParams
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """AMCL ``likelihood_field_prob``: ``log w = sum_k log p_k`` over the beams kept.

    Returns the per-particle log weights ``(P,)`` and the mask ``(B,)`` of beams used.
    """
    d = np.asarray(d)
    logp = np.log(beam_likelihoods(d, params))
    n_beams = d.shape[1]
    use = np.ones(n_beams, dtype=bool)
    if params.do_beamskip and n_beams > 0:
        frac_close = np.mean(d < params.beam_skip_distance, axis=0)
        use = frac_close > params.beam_skip_threshold
        n_skipped = int(np.sum(~use))
        if n_skipped >= n_beams * params.beam_skip_error_threshold:
            use[:] = True
    return logp[:, use].sum(axis=1), use
