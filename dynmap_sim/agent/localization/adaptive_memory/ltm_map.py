"""H&W §4.3 (eqs. 12-15): long-term obstacle grids, and §4.4: the semistatic test.

One occupancy grid (Elfes [15]) of 50 mm cells per long-term slot, kept as log-odds (Elfes'
Bayesian update is an addition in log-odds). Each scan, ``u`` of the static points (a random
``u·n_stat`` of them, inspired by Biber & Duckett) enter the current slot's grid:

* eq. 12: the world point ``s' = (x + r cos(φ+α), y + r sin(φ+α))`` (plus the laser's mount);
* eqs. 13-14: its covariance ``Σ'' = ∇F blockdiag(Σ_p, Σ_s) ∇Fᵀ`` from the pose covariance
  ``Σ_p`` and the reading's ``Σ_s = diag(σ_α², σ_r²)`` (:func:`point_covariances`);
* eq. 15: the point's pdf ``N(s', Σ'')`` raises the cells around it: a cell at Mahalanobis
  distance ``m`` gets the inverse sensor model ``P(occ) = 0.5 + (p_hit - 0.5)·exp(-m²/2)``
  (a peak-normalized Gaussian; Elfes' sensor model for a return), added as log-odds.

The paper gives occupied evidence only, so furniture that moved would never leave the map.
``free_space``: the cells a sampled point's beam passed through before it (up to
``free_stop_sigma`` standard deviations before the return) get ``l_free`` each (once per beam).
Log-odds are clamped to ``[l_min, l_max]``. The prior's walls (H&W Fig. 4) are seeded in every
map at ``l_max`` and pinned: the paper's walls are the localization landmarks the robot was
given, and no evidence removes them.

§4.4's semistatic test: a point with no occupied cell (log-odds >= ``l_occupied``) of the map
within its uncertainty (Mahalanobis distance ``semistatic_sigma``, at least one cell) is
semistatic, "not yet in long-term memory".
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from dynmap_sim.agent.localization.adaptive_memory import ltm_numba
from dynmap_sim.agent.localization.distance_filter import cast_rays
from dynmap_sim.jit import KERNEL_BACKENDS, kernel_backend

FloatArray = NDArray[np.float64]
#: Values of the ``backend`` arguments (:data:`dynmap_sim.jit.KERNEL_BACKENDS`): ``numba``
#: runs :mod:`.ltm_numba`'s kernels, identical in result to ``numpy``; ``python`` the same
#: kernels uncompiled (slow: for the tests).
BACKENDS = KERNEL_BACKENDS


@lru_cache(maxsize=16)
def _stencil(k: int) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Offsets ``(ox, oy)`` of the ``(2k+1)^2`` cells around a cell, raveled row by row
    (read-only: cached)."""
    off = np.arange(-k, k + 1)
    ox, oy = (g.ravel() for g in np.meshgrid(off, off))
    ox.setflags(write=False)
    oy.setflags(write=False)
    return ox, oy


def logit(p: float) -> float:
    return float(np.log(p / (1.0 - p)))


@dataclass(frozen=True)
class LTMParams:
    """Grid update parameters (set from ``AdaptiveMemoryConfig``; see its field docs)."""

    p_hit: float = 0.7
    free_space: bool = True
    l_free: float = -0.4
    free_stop_sigma: float = 3.0
    l_min: float = -2.0
    l_max: float = 3.5
    l_occupied: float = 2.5
    stencil_cells: int = 3
    semistatic_sigma: float = 2.0
    semistatic_max_cells: int = 4
    cov_floor_m: float = 0.025


class LTMMap:
    """One long-term slot's grid: ``logodds`` ``(H, W)`` float32 (rows along y), lower-left
    corner ``origin`` [m], ``resolution`` [m], ``pinned`` the prior's wall cells."""

    def __init__(
        self,
        logodds: NDArray[np.float32],
        origin: FloatArray,
        resolution: float,
        pinned: NDArray[np.bool_],
        prior_free: NDArray[np.bool_],
    ) -> None:
        self.logodds = logodds
        self.origin = np.asarray(origin, dtype=np.float64)
        self.resolution = float(resolution)
        self.pinned = pinned
        self.prior_free = prior_free

    @classmethod
    def from_prior(cls, walls: FloatArray, seed_xy: FloatArray | None, resolution: float,
                   params: LTMParams) -> LTMMap:  # fmt: skip
        """A map of the prior's walls (H&W Fig. 4), seeded at ``l_max`` and pinned."""
        g = OccupancyGrid.from_segments(walls, resolution_m=resolution, free_seed_xy_m=seed_xy)
        pinned = g.occupancy == OCCUPIED
        lo = np.zeros(g.shape, dtype=np.float32)
        lo[pinned] = params.l_max
        return cls(lo, g.origin_xy_m, resolution, pinned, g.occupancy == FREE)

    def copy(self) -> LTMMap:
        return LTMMap(self.logodds.copy(), self.origin, self.resolution, self.pinned,
                      self.prior_free)  # fmt: skip

    @property
    def shape(self) -> tuple[int, int]:
        return self.logodds.shape  # type: ignore[return-value]

    def cells(self, xy: FloatArray) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        ix = np.floor((xy[..., 0] - self.origin[0]) / self.resolution).astype(np.intp)
        iy = np.floor((xy[..., 1] - self.origin[1]) / self.resolution).astype(np.intp)
        return ix, iy

    def occupied(self, params: LTMParams) -> NDArray[np.bool_]:
        return self.logodds >= params.l_occupied

    # -- eq. 15: Elfes' Bayesian update ------------------------------------------------
    def update(
        self,
        laser_xy: FloatArray,
        points: FloatArray,
        covs: FloatArray,
        params: LTMParams,
        occupied: NDArray[np.bool_] | None = None,
        backend: str = "auto",
    ) -> None:
        """Fuse points ``(n, 2)`` with covariances ``(n, 2, 2)`` seen from ``laser_xy``;
        ``occupied`` (default all): the points that add occupied evidence (the others add
        only the free space along their beams). The cells it changes are clamped to
        ``[l_min, l_max]`` and the pinned ones among them reset to ``l_max``; the grid's
        other cells must already be (every map starts so). ``backend``: :data:`BACKENDS`."""
        kernel = kernel_backend(backend)
        if len(points) == 0:
            return
        hit = np.ones(len(points), bool) if occupied is None else np.asarray(occupied, bool)
        if kernel:
            ltm_numba.update(self.logodds, self.pinned, laser_xy, points, covs, hit,
                             self.origin, self.resolution, params,
                             python=kernel == "python")  # fmt: skip
            return
        h, w = self.shape
        res = self.resolution
        flat_all = []
        add_all = []
        # Occupied: peak-normalized Gaussian on a (2k+1)^2 stencil around each point.
        i_xx, i_xy, i_yy, c_xx, c_xy, c_yy = floored_inverse(covs, params.cov_floor_m**2)
        ox, oy = _stencil(params.stencil_cells)
        ix, iy = self.cells(points)
        cx = ix[:, None] + ox[None, :]
        cy = iy[:, None] + oy[None, :]
        dx = self.origin[0] + (cx + 0.5) * res - points[:, 0:1]
        dy = self.origin[1] + (cy + 0.5) * res - points[:, 1:2]
        m2 = i_xx[:, None] * dx * dx + 2 * i_xy[:, None] * dx * dy
        m2 += i_yy[:, None] * dy * dy
        ok = (cx >= 0) & (cx < w) & (cy >= 0) & (cy < h) & (m2 < 9.0) & hit[:, None]
        flat, m2 = (cy * w + cx)[ok], m2[ok]
        p = 0.5 + (params.p_hit - 0.5) * np.exp(-0.5 * m2)
        flat_all.append(flat)
        add_all.append(np.log(p / (1.0 - p)))
        if params.free_space:
            d = points - laser_xy[None, :]
            r = np.hypot(d[:, 0], d[:, 1])
            d0, d1 = d[:, 0], d[:, 1]
            dd = (c_xx * d0 * d0 + 2.0 * c_xy * d0 * d1) + c_yy * d1 * d1  # dᵀ Σ d
            sig = np.sqrt(np.maximum(dd / np.maximum(r, 1e-9) ** 2, 0))
            stop = r - np.maximum(params.free_stop_sigma * sig, res)
            step = 0.5 * res
            t = np.arange(0.0, float(stop.max(initial=0.0)), step)
            if len(t):
                u = d / np.maximum(r, 1e-9)[:, None]
                fx = laser_xy[0] + u[:, 0:1] * t[None, :]
                fy = laser_xy[1] + u[:, 1:2] * t[None, :]
                fix, fiy = self.cells(np.stack([fx, fy], axis=-1))
                okf = (t[None, :] < stop[:, None]) & (fix >= 0) & (fix < w) & (fiy >= 0) & (fiy < h)
                ray = np.broadcast_to(np.arange(len(points))[:, None], fix.shape)
                key = np.unique(ray[okf] * (h * w) + (fiy * w + fix)[okf])  # once per beam
                flat_all.append(key % (h * w))
                add_all.append(np.full(len(key), params.l_free))
        lo = self.logodds.ravel()
        flat = np.concatenate(flat_all)
        add = np.concatenate(add_all)
        np.add.at(lo, flat, add.astype(np.float32))
        # Clamp and re-pin the cells this update can have changed: those between the laser
        # and the points' stencils (the others already are, as every map starts so).
        lc = self.cells(np.asarray(laser_xy, dtype=np.float64))
        k = params.stencil_cells
        x0, x1 = max(min(int(ix.min()) - k, int(lc[0])), 0), max(int(ix.max()) + k, int(lc[0])) + 1
        y0, y1 = max(min(int(iy.min()) - k, int(lc[1])), 0), max(int(iy.max()) + k, int(lc[1])) + 1
        sub = self.logodds[y0:y1, x0:x1]
        np.clip(sub, params.l_min, params.l_max, out=sub)
        sub[self.pinned[y0:y1, x0:x1]] = params.l_max

    # -- §4.4 ---------------------------------------------------------------------------
    def explained(
        self, points: FloatArray, covs: FloatArray, params: LTMParams, backend: str = "auto"
    ) -> NDArray[np.bool_]:
        """Points with an occupied cell within their uncertainty (the complement of §4.4's
        semistatic test): a cell centre within ``semistatic_sigma`` standard deviations
        along the point's widest axis (largest eigenvalue of ``Σ''``, a circle that holds
        the Mahalanobis ellipse), at least 1.5 cells, at most ``semistatic_max_cells``.
        Two stages: the 3 x 3 cells around each point decide most points (a return on a
        known wall); the rest search their whole circle. ``backend``: :data:`BACKENDS`."""
        kernel = kernel_backend(backend)
        n = len(points)
        if n == 0:
            return np.zeros(0, bool)
        h, w = self.shape
        res = self.resolution
        if kernel:
            return ltm_numba.explained(self.logodds, params.l_occupied, points, covs,
                                       self.origin, res, params.cov_floor_m**2,
                                       params.semistatic_sigma,
                                       params.semistatic_max_cells * res,
                                       python=kernel == "python")  # fmt: skip
        a = covs[:, 0, 0] + params.cov_floor_m**2
        c = covs[:, 1, 1] + params.cov_floor_m**2
        b = covs[:, 0, 1]
        lam = 0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b * b)
        rho = np.clip(params.semistatic_sigma * np.sqrt(lam), 1.5 * res,
                      params.semistatic_max_cells * res)  # fmt: skip
        ix, iy = self.cells(points)
        fx = (points[:, 0] - self.origin[0]) / res - ix - 0.5  # offset from the cell centre
        fy = (points[:, 1] - self.origin[1]) / res - iy - 0.5
        k_max = int(np.ceil(rho.max() / res))
        occ = (self.logodds >= params.l_occupied).ravel()
        out = np.zeros(n, bool)
        todo = np.arange(n)
        for k in (1, k_max) if k_max > 1 else (1,):
            if len(todo) == 0:
                break
            ox, oy = _stencil(k)
            cx = np.clip(ix[todo, None] + ox[None, :], 0, w - 1)
            cy = np.clip(iy[todo, None] + oy[None, :], 0, h - 1)
            d2 = (ox[None, :] - fx[todo, None]) ** 2 + (oy[None, :] - fy[todo, None]) ** 2
            hit = occ[cy * w + cx] & (d2 * res * res <= rho[todo, None] ** 2)
            out[todo] = hit.any(axis=1)
            todo = todo[~out[todo]]
        return out

    # -- for MCL and map selection (§6.1) ------------------------------------------------
    def ternary(self, params: LTMParams) -> NDArray[np.int8]:
        """The cells as :class:`OccupancyGrid` codes: occupied from ``l_occupied``, free where
        the prior says so or the log-odds are negative, unknown elsewhere."""
        occ = np.full(self.shape, UNKNOWN, dtype=np.int8)
        occ[self.prior_free | (self.logodds < 0)] = FREE
        occ[self.occupied(params)] = OCCUPIED
        return occ

    def occupancy_grid(
        self,
        params: LTMParams,
        max_dist_m: float = 2.0,
        ternary: NDArray[np.int8] | None = None,
    ) -> OccupancyGrid:
        """The map as a ternary :class:`OccupancyGrid` for the MCL core (``ternary``: this
        map's :meth:`ternary`, if already at hand)."""
        occ = self.ternary(params) if ternary is None else ternary
        return OccupancyGrid(occ, self.origin, self.resolution, max_dist_m)

    def expected_ranges(
        self, laser_pose: FloatArray, angles: FloatArray, range_max: float, params: LTMParams
    ) -> FloatArray:
        """Ray-cast ranges [m] on the occupied cells (half-cell steps; ``range_max`` when
        nothing is hit)."""
        t, first = cast_rays(self.occupied(params), self.origin, self.resolution, laser_pose,
                             angles, range_max)  # fmt: skip
        return np.where(first >= 0, t[first], range_max)


def floored_inverse(
    covs: FloatArray, floor2_m2: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """The inverses of ``covs + floor2_m2·I`` (``(n, 2, 2)``, symmetric) in closed form:
    ``(inv_xx, inv_xy, inv_yy)`` and the floored entries ``(xx, xy, yy)``. The floor bounds
    the smallest eigenvalue from below, so the determinant ``xx·yy - xy²`` is at least
    ``floor2_m2²`` and its relative rounding error stays below eps times the condition
    number (at most ``(σ_max / cov_floor_m)²``)."""
    a = covs[:, 0, 0] + floor2_m2
    c = covs[:, 1, 1] + floor2_m2
    b = covs[:, 0, 1]
    det = a * c - b * b
    return c / det, -b / det, a / det, a, b, c


def point_covariances(
    pose: FloatArray,
    cov_pose: FloatArray,
    mount: FloatArray,
    ranges: FloatArray,
    angles: FloatArray,
    sigma_alpha: float,
    sigma_r: FloatArray,
    backend: str = "auto",
) -> tuple[FloatArray, FloatArray]:
    """Eqs. 12-14: world points ``(n, 2)`` of readings ``(r, α)`` taken at robot ``pose``
    (laser ``mount`` in the robot frame) and their covariances ``(n, 2, 2)``
    ``Σ'' = ∇F blockdiag(Σ_p, Σ_s) ∇Fᵀ``. The pose part's ∂/∂φ is the lever arm from the
    robot's centre to the point (the paper's ``-r sin(φ+α), r cos(φ+α)`` with the mount).

    The products are written out element by element (:func:`point_covariance_terms`), each
    an IEEE operation on arrays of points (no BLAS), so a compiled kernel can repeat them
    exactly; the result is symmetric by construction. ``backend``: :data:`BACKENDS` (the
    kernel, :func:`.ltm_numba.point_covariances`, after the cosines and sines)."""
    kernel = kernel_backend(backend)
    x, y, phi = pose
    c, s = np.cos(phi), np.sin(phi)
    lx = x + c * mount[0] - s * mount[1]
    ly = y + s * mount[0] + c * mount[1]
    b = phi + mount[2] + angles
    cb, sb = np.cos(b), np.sin(b)
    if kernel:
        return ltm_numba.point_covariances(x, y, lx, ly, cov_pose, ranges, cb, sb,
                                           sigma_alpha * sigma_alpha, sigma_r,
                                           python=kernel == "python")  # fmt: skip
    px, py = lx + ranges * cb, ly + ranges * sb
    cov = np.empty((len(ranges), 2, 2))
    cxx, cxy, cyy = point_covariance_terms(
        np.asarray(cov_pose, dtype=np.float64), -(py - y), px - x, ranges, cb, sb,
        sigma_alpha * sigma_alpha, np.square(np.asarray(sigma_r, dtype=np.float64)),
    )  # fmt: skip
    cov[:, 0, 0] = cxx
    cov[:, 0, 1] = cov[:, 1, 0] = cxy
    cov[:, 1, 1] = cyy
    return np.column_stack([px, py]), cov


def point_covariance_terms(
    cov_pose: FloatArray,
    ax: FloatArray,
    ay: FloatArray,
    ranges: FloatArray,
    cb: FloatArray,
    sb: FloatArray,
    var_alpha: float,
    var_r: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The entries ``(xx, xy, yy)`` of eq. 14's ``Σ''`` with the pose Jacobian
    ``J_p = [[1, 0, ax], [0, 1, ay]]`` (``ax = -(p_y - y)``, ``ay = p_x - x``: the lever
    arm) and the reading Jacobian ``J_s = [[-r sin β, cos β], [r cos β, sin β]]`` (columns
    α, r), ``Σ_s = diag(var_alpha, var_r)``:
    ``J_p Σ_p J_pᵀ + J_s Σ_s J_sᵀ`` written out (row ``i`` of ``J_p Σ_p`` is
    ``Σ_p[i] + a_i Σ_p[2]``; the off-diagonal entry is computed once)."""
    p = cov_pose
    r0x = p[0, 0] + ax * p[2, 0]  # row x of J_p Σ_p, columns 0 and 2
    r2x = p[0, 2] + ax * p[2, 2]
    r1y = p[1, 1] + ay * p[2, 1]  # row y, columns 1 and 2
    r2y = p[1, 2] + ay * p[2, 2]
    r1x = p[0, 1] + ax * p[2, 1]  # row x, column 1
    rs, rc = ranges * sb, ranges * cb
    ta, tr = rs * var_alpha, cb * var_r  # row x of J_s Σ_s: (-r sin β σ_α², cos β σ_r²)
    xx = (r0x + ax * r2x) + (rs * ta + cb * tr)
    xy = (r1x + ay * r2x) + (sb * tr - rc * ta)
    yy = (r1y + ay * r2y) + (rc * (rc * var_alpha) + sb * (sb * var_r))
    return xx, xy, yy
