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
semistatic, "not yet in long-term memory". The test, the update and the covariances are
compiled kernels (:func:`_explained`, :func:`_update`, :func:`_point_covariances`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from dynmap_sim.agent.localization.distance_filter import cast_rays
from dynmap_sim.jit import compiled, jitable

FloatArray = NDArray[np.float64]


def logit(p: float) -> float:
    return float(np.log(p / (1.0 - p)))


class LTMParams(NamedTuple):
    """Grid update parameters (set from ``AdaptiveMemoryConfig``; see its field docs); a
    NamedTuple, so the kernels take it as one argument."""

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

    def typed(self) -> LTMParams:
        """The same values with the field types the kernels are compiled for."""
        return LTMParams(
            float(self.p_hit), bool(self.free_space), float(self.l_free),
            float(self.free_stop_sigma), float(self.l_min), float(self.l_max),
            float(self.l_occupied), int(self.stencil_cells), float(self.semistatic_sigma),
            int(self.semistatic_max_cells), float(self.cov_floor_m),
        )  # fmt: skip


class GridGeom(NamedTuple):
    """Where a grid lies: lower-left corner [m] and cell size [m]."""

    origin_x: float
    origin_y: float
    res: float


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

    @property
    def geom(self) -> GridGeom:
        return GridGeom(float(self.origin[0]), float(self.origin[1]), self.resolution)

    def cells(self, xy: FloatArray) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        ix = np.floor((xy[..., 0] - self.origin[0]) / self.resolution).astype(np.intp)
        iy = np.floor((xy[..., 1] - self.origin[1]) / self.resolution).astype(np.intp)
        return ix, iy

    def occupied(self, params: LTMParams) -> NDArray[np.bool_]:
        return self.logodds >= np.float32(params.l_occupied)

    def update(
        self,
        laser_xy: FloatArray,
        points: FloatArray,
        covs: FloatArray,
        params: LTMParams,
        occupied: NDArray[np.bool_] | None = None,
    ) -> None:
        """Eq. 15: fuse points ``(n, 2)`` [m] with covariances ``(n, 2, 2)`` [m²] seen from
        ``laser_xy``; ``occupied`` (default all): the points that add occupied evidence (the
        others add only the free space along their beams). The cells it changes are clamped
        to ``[l_min, l_max]`` and the pinned ones reset to ``l_max``; the grid's other cells
        must already be (every map starts so)."""
        if len(points) == 0:
            return
        hit = np.ones(len(points), bool) if occupied is None else np.asarray(occupied, bool)
        _update(self.logodds, self.pinned, np.asarray(laser_xy, dtype=np.float64)[:2],
                np.ascontiguousarray(points, dtype=np.float64),
                np.ascontiguousarray(covs, dtype=np.float64), hit, self.geom,
                params.typed())  # fmt: skip

    def explained(
        self, points: FloatArray, covs: FloatArray, params: LTMParams
    ) -> NDArray[np.bool_]:
        """Points with an occupied cell within their uncertainty (the complement of §4.4's
        semistatic test): a cell centre within ``semistatic_sigma`` standard deviations
        along the point's widest axis (largest eigenvalue of ``Σ''`` plus the floor, a
        circle that holds the Mahalanobis ellipse), at least 1.5 cells, at most
        ``semistatic_max_cells``. Cells outside the grid hold no obstacle."""
        if len(points) == 0:
            return np.zeros(0, bool)
        return _explained(self.logodds, np.ascontiguousarray(points, dtype=np.float64),
                          np.ascontiguousarray(covs, dtype=np.float64), self.geom,
                          params.typed())  # fmt: skip

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


def point_covariances(
    pose: FloatArray,
    cov_pose: FloatArray,
    mount: FloatArray,
    ranges: FloatArray,
    angles: FloatArray,
    sigma_alpha: float,
    sigma_r: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Eqs. 12-14: world points ``(n, 2)`` [m] of readings ``(r, α)`` taken at robot ``pose``
    (laser ``mount`` in the robot frame) and their covariances ``(n, 2, 2)`` [m²]
    ``Σ'' = ∇F blockdiag(Σ_p, Σ_s) ∇Fᵀ``, ``Σ_s = diag(σ_α², σ_r²)``. The pose part's ∂/∂φ
    is the lever arm from the robot's centre to the point (the paper's
    ``-r sin(φ+α), r cos(φ+α)`` with the mount)."""
    f64 = np.float64
    return _point_covariances(
        np.asarray(pose, dtype=f64), np.ascontiguousarray(cov_pose, dtype=f64),
        np.asarray(mount, dtype=f64), np.ascontiguousarray(ranges, dtype=f64),
        np.ascontiguousarray(angles, dtype=f64), float(sigma_alpha) ** 2,
        np.ascontiguousarray(sigma_r, dtype=f64),
    )  # fmt: skip


def semistatic_classes(
    cls_v: NDArray[np.int8], lab_v: NDArray[np.intp], explained: NDArray[np.bool_],
    known: NDArray[np.bool_], n_boxes: int, veto_share: float, vi: NDArray[np.intp], n_beams: int,
) -> tuple[NDArray[np.int8], NDArray[np.int64]]:  # fmt: skip
    """§4.4 on the valid returns' tracker classes ``cls_v`` (boxes ``lab_v``, -1 none; in
    place): a dynamic point of a box at least ``veto_share`` of whose points a map
    ``explained`` becomes static (``ltm_veto_dynamic``), then every non-dynamic point that
    is not ``known`` (explained by §4.4's map) semistatic. Returns the classes of all
    ``n_beams`` beams (unknown where not valid; ``vi``: the valid returns' beams) and the
    count of each class."""
    return _semistatic_classes(cls_v, lab_v, np.asarray(explained, dtype=np.bool_),
                               np.asarray(known, dtype=np.bool_), int(n_boxes),
                               float(veto_share), vi, int(n_beams))  # fmt: skip


# -- kernels ------------------------------------------------------------------------------
@jitable
def _floored(covs, j, floor2):  # type: ignore[no-untyped-def]
    """Entries ``(xx, xy, yy)`` of ``covs[j] + floor2·I``: the floor bounds the smallest
    eigenvalue, so the inverse stays well conditioned."""
    return covs[j, 0, 0] + floor2, covs[j, 0, 1], covs[j, 1, 1] + floor2


@compiled
def _explained(logodds, points, covs, geom, params):  # type: ignore[no-untyped-def]
    """:meth:`LTMMap.explained`: per point its search radius ``rho`` [m], then the 3 x 3
    cells around it (a return on a mapped wall), then the rest of its square, stopping at
    the first occupied cell whose centre lies within ``rho``."""
    h, w = logodds.shape
    l_occ = np.float32(params.l_occupied)
    res = geom.res
    floor2 = params.cov_floor_m * params.cov_floor_m
    rho_max = params.semistatic_max_cells * res
    n = points.shape[0]
    out = np.zeros(n, dtype=np.bool_)
    for j in range(n):
        a, b, c = _floored(covs, j, floor2)
        d = a - c
        lam = 0.5 * (a + c) + math.sqrt(0.25 * d * d + b * b)
        rho = min(max(params.semistatic_sigma * math.sqrt(lam), 1.5 * res), rho_max) / res
        gx = (points[j, 0] - geom.origin_x) / res
        gy = (points[j, 1] - geom.origin_y) / res
        ix, iy = int(math.floor(gx)), int(math.floor(gy))
        fx, fy = gx - ix - 0.5, gy - iy - 0.5  # offset from the cell's centre [cells]
        k_all = int(math.ceil(rho))
        for ring in range(2):
            k = 1 if ring == 0 else k_all
            for oy in range(-k, k + 1):
                cy = iy + oy
                if cy < 0 or cy >= h:
                    continue
                for ox in range(-k, k + 1):
                    if ring == 1 and -1 <= ox <= 1 and -1 <= oy <= 1:
                        continue
                    cx = ix + ox
                    if 0 <= cx < w and logodds[cy, cx] >= l_occ:
                        if (ox - fx) ** 2 + (oy - fy) ** 2 <= rho * rho:
                            out[j] = True
                            break
                if out[j]:
                    break
            if out[j] or k_all <= 1:
                break
    return out


@compiled
def _update(logodds, pinned, laser_xy, points, covs, hit, geom, params):  # type: ignore[no-untyped-def]
    """:meth:`LTMMap.update` in place on ``logodds`` (C-contiguous): the stencils' occupied
    log-odds (cells within Mahalanobis distance 3 on a ``(2k+1)²`` square), then
    ``l_free`` once per cell along each beam (samples every half cell up to where the free
    space stops), then the clamp and re-pin of the rectangle between the laser and the
    stencils (every other cell is within the clamps already)."""
    h, w = logodds.shape
    res, ox0, oy0 = geom.res, geom.origin_x, geom.origin_y
    k = params.stencil_cells
    floor2 = params.cov_floor_m * params.cov_floor_m
    lx, ly = laser_xy[0], laser_xy[1]
    x0 = x1 = int(math.floor((lx - ox0) / res))
    y0 = y1 = int(math.floor((ly - oy0) / res))
    for j in range(points.shape[0]):
        px, py = points[j, 0], points[j, 1]
        ix = int(math.floor((px - ox0) / res))
        iy = int(math.floor((py - oy0) / res))
        x0, x1, y0, y1 = min(x0, ix - k), max(x1, ix + k), min(y0, iy - k), max(y1, iy + k)
        if not hit[j]:
            continue
        a, b, c = _floored(covs, j, floor2)
        det = a * c - b * b
        i_xx, i_xy, i_yy = c / det, -b / det, a / det
        for cy in range(max(iy - k, 0), min(iy + k + 1, h)):
            dy = oy0 + (cy + 0.5) * res - py
            for cx in range(max(ix - k, 0), min(ix + k + 1, w)):
                dx = ox0 + (cx + 0.5) * res - px
                m2 = i_xx * dx * dx + 2.0 * i_xy * dx * dy + i_yy * dy * dy
                if m2 < 9.0:
                    p = 0.5 + (params.p_hit - 0.5) * math.exp(-0.5 * m2)
                    logodds[cy, cx] += np.float32(math.log(p / (1.0 - p)))
    if params.free_space:
        l_free = np.float32(params.l_free)
        step = 0.5 * res
        for j in range(points.shape[0]):
            a, b, c = _floored(covs, j, floor2)
            d0, d1 = points[j, 0] - lx, points[j, 1] - ly
            r = max(math.hypot(d0, d1), 1e-9)
            sig = math.sqrt(max((a * d0 * d0 + 2.0 * b * d0 * d1 + c * d1 * d1) / (r * r), 0.0))
            stop = r - max(params.free_stop_sigma * sig, res)
            ux, uy = d0 / r, d1 / r
            prev_x = prev_y = -1
            i = 0
            while i * step < stop:
                t = i * step
                cx = int(math.floor((lx + ux * t - ox0) / res))
                cy = int(math.floor((ly + uy * t - oy0) / res))
                i += 1
                if (cx != prev_x or cy != prev_y) and 0 <= cx < w and 0 <= cy < h:
                    logodds[cy, cx] += l_free  # a ray's cells are monotone: once per beam
                prev_x, prev_y = cx, cy
    l_min, l_max = np.float32(params.l_min), np.float32(params.l_max)
    for cy in range(max(y0, 0), min(y1 + 1, h)):
        for cx in range(max(x0, 0), min(x1 + 1, w)):
            if pinned[cy, cx]:
                logodds[cy, cx] = l_max
            else:
                logodds[cy, cx] = min(max(logodds[cy, cx], l_min), l_max)


@compiled
def _point_covariances(pose, cov_pose, mount, ranges, angles, var_alpha, sigma_r):  # type: ignore[no-untyped-def]
    """:func:`point_covariances`: ``J_p Σ_p J_pᵀ + J_s Σ_s J_sᵀ`` written out, with
    ``J_p = [[1, 0, ax], [0, 1, ay]]`` (the lever arm ``ax = -(p_y - y)``, ``ay = p_x - x``)
    and ``J_s = [[-r sin β, cos β], [r cos β, sin β]]`` (columns α, r)."""
    x, y, phi = pose[0], pose[1], pose[2]
    c0, s0 = math.cos(phi), math.sin(phi)
    lx = x + c0 * mount[0] - s0 * mount[1]
    ly = y + s0 * mount[0] + c0 * mount[1]
    p = cov_pose
    n = ranges.shape[0]
    points = np.empty((n, 2))
    covs = np.empty((n, 2, 2))
    for j in range(n):
        r = ranges[j]
        beta = phi + mount[2] + angles[j]
        cb, sb = math.cos(beta), math.sin(beta)
        px, py = lx + r * cb, ly + r * sb
        points[j, 0], points[j, 1] = px, py
        ax, ay = -(py - y), px - x
        var_r = sigma_r[j] * sigma_r[j]
        pxx = p[0, 0] + ax * (p[2, 0] + p[0, 2]) + ax * ax * p[2, 2]
        pxy = p[0, 1] + ax * p[2, 1] + ay * p[0, 2] + ax * ay * p[2, 2]
        pyy = p[1, 1] + ay * (p[2, 1] + p[1, 2]) + ay * ay * p[2, 2]
        rs, rc = r * sb, r * cb
        covs[j, 0, 0] = pxx + rs * rs * var_alpha + cb * cb * var_r
        cxy = pxy - rc * rs * var_alpha + cb * sb * var_r
        covs[j, 0, 1] = cxy
        covs[j, 1, 0] = cxy
        covs[j, 1, 1] = pyy + rc * rc * var_alpha + sb * sb * var_r
    return points, covs


@compiled
def _semistatic_classes(cls_v, lab_v, explained, known, n_boxes, veto_share, vi, n_beams):  # type: ignore[no-untyped-def]
    """:func:`semistatic_classes` (class codes as :mod:`.object_tracker`'s: 0 unknown,
    1 dynamic, 2 semistatic, 3 static)."""
    n_pts = np.zeros(n_boxes, dtype=np.int64)
    n_expl = np.zeros(n_boxes, dtype=np.int64)
    for j in range(cls_v.shape[0]):
        b = lab_v[j]
        if b >= 0:
            n_pts[b] += 1
            n_expl[b] += explained[j]
    classes = np.zeros(n_beams, dtype=np.int8)
    counts = np.zeros(4, dtype=np.int64)
    for j in range(cls_v.shape[0]):
        b = lab_v[j]
        if cls_v[j] == 1 and b >= 0 and n_expl[b] >= veto_share * max(n_pts[b], 1):
            cls_v[j] = 3
        if cls_v[j] != 1 and not known[j]:
            cls_v[j] = 2
        classes[vi[j]] = cls_v[j]
        counts[cls_v[j]] += 1
    return classes, counts
