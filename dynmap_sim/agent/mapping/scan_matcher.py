"""Point-to-line ICP scan matching with an optional Gaussian pose prior.

The matcher aligns a scan (points in the robot frame) to a target point set whose local
line normals are estimated once by PCA over nearest neighbours (:class:`PointMap`). Each
Gauss-Newton step minimises the point-to-line error of Censi's PLICP (Censi 2008, eq. 6),

    E(x) = sum_i w_i (n_i . (R(theta) p_i + t - q_i))^2,

with Huber weights ``w_i`` against outliers, plus -- when given -- a Gaussian prior on the
pose, ``(x - mu)^T Lambda (x - mu)``, added to the normal equations. This is the scan
matching with an odometry prior that Biber & Duckett use (§4.2, eq. 9): the prior keeps the
solution well defined in degenerate geometry such as a corridor.

The returned covariance is the inverse of the Gauss-Newton information, with the scan term
scaled by the residual variance (``max(rmse^2, sigma_floor^2)``) plus the prior information.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.mapping.scan_matcher_kernels import (
    BucketGrid,
    IcpParams,
    ScanArrays,
    TargetRows,
    grid_build,
    icp_loop,
    knn_kernel,
    normals_kernel,
)

FloatArray = NDArray[np.float64]

#: Bounds [m] of the cell size of the bucket grid for the normals' k nearest neighbours.
_KNN_CELL_M = (0.02, 2.0)


def bucket_grid(points: FloatArray, cell_m: float) -> BucketGrid:
    """A :class:`.scan_matcher_kernels.BucketGrid` of ``points`` ``(M, 2)`` with cells of at
    least ``cell_m`` [m], larger when the points spread over more than ``4 M + 250,000``
    cells (a search is exact for any cell size; a bounded grid keeps its memory linear)."""
    w = float(points[:, 0].max() - points[:, 0].min())
    h = float(points[:, 1].max() - points[:, 1].min())
    budget = 4 * len(points) + 250_000
    cell = float(cell_m)
    while (w / cell + 2.0) * (h / cell + 2.0) > budget:
        cell *= 2.0
    px = np.ascontiguousarray(points[:, 0], dtype=np.float64)
    py = np.ascontiguousarray(points[:, 1], dtype=np.float64)
    start, order, xs, ys, x0, y0, nx, ny = grid_build(px, py, cell)
    return BucketGrid(cell, int(x0), int(y0), int(nx), int(ny), start, order, xs, ys)


def knn_indices(points: FloatArray, k: int) -> NDArray[np.int64]:
    """``(M, k)`` indices of each of ``points``' ``k`` nearest points (itself first; equal
    distances: lower index first); ``k`` at most ``M``."""
    w = float(np.ptp(points[:, 0]))
    h = float(np.ptp(points[:, 1]))
    cell = math.sqrt(max(w * h, 1e-6) / len(points))  # about one point per cell
    grid = bucket_grid(points, min(max(cell, _KNN_CELL_M[0]), _KNN_CELL_M[1]))
    out = np.empty((len(points), k), dtype=np.int64)
    knn_kernel(grid, k, out)
    return out


class PointMap:
    """A target point set with per-point line normals, built once.

    ``points_map`` is ``(M, 2)`` in the map frame [m]. Normals come from the smallest
    eigenvector of the covariance of the ``k_normal`` nearest neighbours (an exact search on
    a bucket grid, :func:`knn_indices`); ``planarity`` in ``[0, 1]`` is
    ``1 - lambda_min / lambda_max`` (1 = a clean line).
    """

    def __init__(self, points_map: ArrayLike, k_normal: int = 6) -> None:
        pts = np.asarray(points_map, dtype=np.float64).reshape(-1, 2)
        if len(pts) < 3:
            raise ValueError(f"PointMap needs at least 3 points, got {len(pts)}")
        self.points = pts
        k = int(min(k_normal, len(pts)))
        idx = knn_indices(pts, k)
        self.normals = np.empty((len(pts), 2))
        self.planarity = np.empty(len(pts))
        normals_kernel(
            np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), idx,
            self.normals, self.planarity,
        )  # fmt: skip
        self._packed: dict[float, TargetRows] = {}
        self._grids: dict[float, BucketGrid] = {}

    def packed(self, min_planarity: float) -> TargetRows:
        """Rows ``(M + 1, 4)`` ``[n_x, n_y, q_x, q_y]`` (normal, point) of the points at least
        ``min_planarity`` planar, zeros for the others and for an extra last row, and the
        ``(M + 1,)`` mask of the usable rows. Cached per threshold."""
        key = float(min_planarity)
        if key not in self._packed:
            usable = np.zeros(len(self.points) + 1, dtype=bool)
            usable[:-1] = self.planarity >= key
            rows = np.zeros((len(self.points) + 1, 4))
            rows[:-1, :2] = self.normals
            rows[:-1, 2:] = self.points
            rows[~usable] = 0.0
            self._packed[key] = TargetRows(rows, usable)
        return self._packed[key]

    def bucket_grid(self, cell_m: float) -> BucketGrid:
        """The points in a :class:`.scan_matcher_kernels.BucketGrid` of cells of at least
        ``cell_m`` [m] (:func:`bucket_grid`, cached)."""
        key = float(cell_m)
        if key not in self._grids:
            self._grids[key] = bucket_grid(self.points, key)
        return self._grids[key]

    def __len__(self) -> int:
        return len(self.points)


@dataclass(frozen=True)
class MatchResult:
    """Outcome of :func:`match_scan`: the pose of the scan's frame in the map frame.

    ``cov`` is the 3x3 pose covariance [m², rad²]; ``n_matched`` the number of points with a
    correspondence in the last iteration; ``rmse_m`` their point-to-line RMS residual;
    ``scan_info`` the scan term's share of the information (``cov``'s inverse without the
    prior) [1/m², 1/(m rad), 1/rad²]: how well the scan alone constrains each direction.
    """

    pose: FloatArray
    cov: FloatArray
    n_matched: int
    rmse_m: float
    converged: bool
    scan_info: FloatArray


def match_scan(
    points_base: ArrayLike,
    target: PointMap,
    init_pose: ArrayLike,
    prior_mean: ArrayLike | None = None,
    prior_info: ArrayLike | None = None,
    max_iterations: int = 30,
    max_correspondence_m: float = 0.5,
    huber_m: float = 0.05,
    min_planarity: float = 0.6,
    sigma_floor_m: float = 0.01,
    tol_m: float = 1e-4,
    tol_rad: float = 1e-5,
    weights: ArrayLike | None = None,
    info_inflation: float = 1.0,
) -> MatchResult:
    """Align ``points_base`` ``(N, 2)`` (robot frame) to ``target``, starting at ``init_pose``.

    ``prior_mean`` ``(3,)`` and ``prior_info`` ``(3, 3)`` (an information matrix, i.e. an
    inverse covariance) add a Gaussian prior on the pose (B&D eq. 9). ``weights`` ``(N,)``
    (optional, relative inverse variances, e.g. ``(sigma_min / sigma(range))^2``) scale each
    point's residual. ``info_inflation`` (>= 1) divides the scan's information, accounting for
    residuals that are not independent (Censi 2007: ICP's covariance is optimistic), so that
    the prior keeps its say in directions the scan constrains only weakly. Returns the pose
    of the robot frame in the map frame with its covariance (see the module docstring).

    Every iteration works on all ``N`` points at once: a point without a usable correspondence
    (none within ``max_correspondence_m``, or a target point less planar than
    ``min_planarity``) meets the zero row of :meth:`PointMap.packed` and so adds exactly
    nothing to the normal equations; the iterations run in one compiled loop
    (:func:`.scan_matcher_kernels.icp_loop`).
    """
    pts = np.asarray(points_base, dtype=np.float64).reshape(-1, 2)
    pw = np.ones(len(pts)) if weights is None else np.asarray(weights, dtype=np.float64)
    scan = ScanArrays(
        np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]),
        np.ascontiguousarray(pw.reshape(-1)),
    )  # fmt: skip
    pose = np.asarray(init_pose, dtype=np.float64).copy()
    prior = np.zeros((4, 3))
    if prior_info is not None:
        prior[0] = pose if prior_mean is None else np.asarray(prior_mean, dtype=np.float64)
        prior[1:] = np.asarray(prior_info, dtype=np.float64)
    floor2 = sigma_floor_m**2
    params = IcpParams(
        float(max_correspondence_m), float(huber_m), floor2, float(info_inflation),
        float(tol_m), float(tol_rad), max(1, int(max_iterations)),
    )  # fmt: skip
    h_scan = np.zeros((3, 3))
    state = np.zeros(4)
    state[2] = math.inf
    if len(pts):
        grid = target.bucket_grid(max_correspondence_m)
        icp_loop(scan, pose, prior, grid, target.packed(min_planarity), params, h_scan, state)
    n_matched, rmse, converged = int(state[1]), float(state[2]), bool(state[3])
    sigma2 = max(rmse**2 if math.isfinite(rmse) else 0.0, floor2) * info_inflation
    scan_info = h_scan / sigma2
    info = scan_info if prior_info is None else scan_info + prior[1:]
    try:
        cov = np.linalg.inv(info + 1e-9 * np.eye(3))
    except np.linalg.LinAlgError:
        cov = np.diag([1e6, 1e6, 1e6])
    cov = 0.5 * (cov + cov.T)
    return MatchResult(pose, cov, n_matched, rmse, converged, scan_info)


def position_information(scan_info: FloatArray) -> FloatArray:
    """The 2x2 information of the position under a scan match's information ``scan_info``
    (3x3, x y θ, symmetrized), the heading marginalized out (Schur complement)."""
    h = 0.5 * (scan_info + scan_info.T)
    htt = h[:2, :2]
    if h[2, 2] > 0.0:
        htt = htt - np.outer(h[:2, 2], h[:2, 2]) / h[2, 2]
    return htt


def worst_position_sigma(scan_info: FloatArray) -> float:
    """Standard deviation [m] of the position along its worst-constrained direction under a
    scan match's information ``scan_info`` alone (:func:`position_information`): large along
    a corridor whose walls are blank (the degeneracy measure of Zhang, Kaess & Singh 2016, as
    a length). ``inf`` if a direction is unconstrained."""
    lam = float(np.linalg.eigvalsh(position_information(scan_info))[0])
    return float(1.0 / np.sqrt(lam)) if lam > 0.0 else float("inf")
