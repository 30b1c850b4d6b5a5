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
at/over ``range_max`` are ignored. The end points are projected and looked up in one compiled
loop over particles x beams (:func:`endpoint_values`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.grid import OccupancyGrid
from dynmap_sim.jit import compiled

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


def _endpoint_terms(
    particles: FloatArray,
    ranges_m: FloatArray,
    angles_rad: FloatArray,
    mount_pose: ArrayLike,
    grid: OccupancyGrid,
) -> tuple[NDArray[np.float32], ...]:
    """The per-particle and per-beam float32 terms of the end points [cells]: laser origins
    ``lx, ly`` relative to the grid origin, ``cos, sin`` of the headings, beam offsets
    ``bx, by`` in the laser frame (:func:`_endpoint_values`)."""
    mx, my, myaw = (float(v) for v in mount_pose)
    th = particles[:, 2]
    c64, s64 = np.cos(th), np.sin(th)
    inv_res = 1.0 / grid.resolution_m
    ox, oy = float(grid.origin_xy_m[0]), float(grid.origin_xy_m[1])
    if len(particles) == 1:  # one pose (a diagnostic, every scan): the same operations in floats
        x, y = float(particles[0, 0]), float(particles[0, 1])
        c1, s1 = float(c64[0]), float(s64[0])
        lx = np.array([(x + c1 * mx - s1 * my - ox) * inv_res], dtype=np.float32)
        ly = np.array([(y + s1 * mx + c1 * my - oy) * inv_res], dtype=np.float32)
    else:
        lx = ((particles[:, 0] + c64 * mx - s64 * my - ox) * inv_res).astype(np.float32)
        ly = ((particles[:, 1] + s64 * mx + c64 * my - oy) * inv_res).astype(np.float32)
    bx = (ranges_m * np.cos(angles_rad + myaw) * inv_res).astype(np.float32)
    by = (ranges_m * np.sin(angles_rad + myaw) * inv_res).astype(np.float32)
    return lx, ly, c64.astype(np.float32), s64.astype(np.float32), bx, by


@compiled
def _endpoint_values(lx, ly, c, s, bx, by, values, h, w, out):  # type: ignore[no-untyped-def]
    """``out[i, j]``: ``values[iy * w + ix]`` at the cell of particle ``i``'s beam ``j``, whose
    end point is ``(c_i bx_j - s_i by_j + lx_i, s_i bx_j + c_i by_j + ly_i)`` [cells] (all
    float32), or ``values[h * w]`` outside the grid (*Probabilistic Robotics* Table 6.3,
    line 5)."""
    outside = values[h * w]
    for i in range(lx.shape[0]):
        ci, si, lxi, lyi = c[i], s[i], lx[i], ly[i]
        for j in range(bx.shape[0]):
            fx = np.floor(ci * bx[j] - si * by[j] + lxi)
            fy = np.floor(si * bx[j] + ci * by[j] + lyi)
            if 0 <= fx < w and 0 <= fy < h:
                out[i, j] = values[int(fy) * w + int(fx)]
            else:
                out[i, j] = outside


def endpoint_values(
    values: NDArray[np.generic],
    particles: FloatArray,
    ranges_m: FloatArray,
    angles_rad: FloatArray,
    mount_pose: ArrayLike,
    grid: OccupancyGrid,
) -> NDArray[np.generic]:
    """``values`` ``(H * W + 1,)`` (a :class:`LikelihoodTable`'s, the last entry for outside
    the grid) at each beam's end point ``(P, B)``, in ``values``' dtype; the end points are
    computed in float32 for speed."""
    terms = _endpoint_terms(particles, ranges_m, angles_rad, mount_pose, grid)
    h, w = grid.shape
    out = np.empty((len(particles), len(ranges_m)), dtype=values.dtype)
    _endpoint_values(*terms, values, int(h), int(w), out)
    return out


class LikelihoodTable:
    """Per-cell beam likelihood tables for one grid and one parameter set (AMCL precomputes
    the distance map; we also precompute ``p`` and ``log p`` so the hot loop is a gather).
    The last entry is the value outside the grid (distance ``max_dist_m``): ``dist`` [m]
    float32, read by :func:`endpoint_values`."""

    def __init__(
        self,
        grid: OccupancyGrid,
        params: LikelihoodFieldParams,
        previous: LikelihoodTable | None = None,
    ) -> None:
        """``previous``: the table of an earlier grid of the same shape and ``params`` (e.g.
        the same map a few scans before): only the cells whose distance changed are
        computed anew, the others copied from it (the values are elementwise functions of
        the distance: the same table either way)."""
        self.params = params
        self.dist = np.append(grid.dist_m.ravel(), np.float32(grid.max_dist_m))
        if (
            previous is not None
            and getattr(previous, "params", None) == params
            and previous.dist.shape == self.dist.shape
        ):
            changed = np.flatnonzero(self.dist != previous.dist)
            p = beam_likelihoods(self.dist[changed], params)
            self.p = previous.p.copy()
            self.p[changed] = p.astype(np.float32)
            self.logp = previous.logp.copy()
            self.logp[changed] = np.log(p).astype(np.float32)
            self.logp_skip = previous.logp_skip
            return
        p = beam_likelihoods(self.dist, params)
        self.p = p.astype(np.float32)
        self.logp = np.log(p).astype(np.float32)
        self.logp_skip = float(
            np.log(beam_likelihoods(np.array([params.beam_skip_distance]), params)[0])
        )


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


def likelihood_field_weights_beams(p: NDArray[np.float32]) -> FloatArray:
    """AMCL ``likelihood_field``: ``w = 1 + sum_k p_k^3`` per particle ``(P,)`` from the
    per-beam ``p`` ``(P, B)`` of the end points (:func:`endpoint_values` of ``table.p``)."""
    return 1.0 + np.sum((p * p * p).astype(np.float64), axis=1)


def likelihood_field_prob_beams(
    logp: NDArray[np.float32],
    table: LikelihoodTable,
    params: LikelihoodFieldParams,
    scored: NDArray[np.float32] | None = None,
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """AMCL ``likelihood_field_prob``: ``log w = sum_k log p_k`` per particle ``(P,)`` over
    the beams kept, and the mask ``(B,)`` of those beams, from the per-beam ``log p``
    ``(P, B)`` of the end points (:func:`endpoint_values` of ``table.logp``). ``scored``: the
    ``(P, B)`` values to sum instead (e.g. see-through readings rescored,
    :mod:`.see_through`); beam skipping still decides on ``logp``.

    ``d < beam_skip_distance`` is ``log p > log p(beam_skip_distance)`` (p falls with d).
    """
    n_beams = logp.shape[1]
    use = np.ones(n_beams, dtype=bool)
    if params.do_beamskip and n_beams > 0:
        frac_close = np.mean(logp > table.logp_skip, axis=0)
        use = frac_close > params.beam_skip_threshold
        if int(np.sum(~use)) >= n_beams * params.beam_skip_error_threshold:
            use[:] = True
    values = logp if scored is None else scored
    kept = values if use.all() else values[:, use]
    return kept.sum(axis=1, dtype=np.float64), use
