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
from scipy.spatial import cKDTree

from dynmap_sim.agent.mapping.scan_matcher_numba import (
    BucketGrid,
    icp_loop,
    icp_terms,
    knn_indices,
    numba_available,
    point_normals,
)
from dynmap_sim.se2 import wrap_angle

FloatArray = NDArray[np.float64]

#: Condition estimate above which the closed-form 3x3 solve is used (see _newton_step).
_WELL_CONDITIONED = 1e-6
#: Bounds [m] of the cell size of the bucket grid for the normals' k nearest neighbours.
_KNN_CELL_M = (0.02, 2.0)


def _extent(points: FloatArray) -> tuple[float, float]:
    """Width and height [m] of the bounding box of ``points`` ``(M, 2)``."""
    x, y = points[:, 0], points[:, 1]
    return float(x.max()) - float(x.min()), float(y.max()) - float(y.min())


def _compact_grid(
    points: FloatArray, cell_m: float, extent: tuple[float, float] | None = None
) -> BucketGrid | None:
    """A :class:`.scan_matcher_numba.BucketGrid` of the points, or ``None`` when they spread
    over too many cells (more than ``4 M + 250,000``) for one; ``extent``: the points'
    :func:`_extent` when known."""
    if cell_m <= 0:
        return None
    w, h = _extent(points) if extent is None else extent
    if (w / cell_m + 2.0) * (h / cell_m + 2.0) > 4 * len(points) + 250_000:
        return None
    return BucketGrid.build(points, cell_m)


class PointMap:
    """A target point set with a KD-tree and per-point line normals, built once.

    ``points_map`` is ``(M, 2)`` in the map frame [m]. Normals come from the smallest
    eigenvector of the covariance of the ``k_normal`` nearest neighbours; ``planarity``
    in ``[0, 1]`` is ``1 - lambda_min / lambda_max`` (1 = a clean line). With numba (extra
    ``fast``) the neighbours come from a compiled search on a bucket grid
    (:func:`.scan_matcher_numba.knn_indices`, the same neighbours as the KD-tree's, nearest
    first) and the KD-tree is only built if the numpy matcher asks for it, and the normals
    from a compiled loop (:func:`.scan_matcher_numba.point_normals`, the same values);
    ``backend`` (``"auto"``, ``"numpy"``, ``"numba"``) chooses as in :func:`match_scan`.
    """

    def __init__(self, points_map: ArrayLike, k_normal: int = 6, backend: str = "auto") -> None:
        if backend not in ("auto", "numpy", "numba"):
            raise ValueError(f'backend must be "auto", "numpy" or "numba", got {backend!r}')
        if backend == "numba" and not numba_available():
            raise RuntimeError('backend "numba" needs numba: pip install "dynmap-sim[fast]"')
        pts = np.asarray(points_map, dtype=np.float64).reshape(-1, 2)
        if len(pts) < 3:
            raise ValueError(f"PointMap needs at least 3 points, got {len(pts)}")
        self.points = pts
        self._tree: cKDTree | None = None
        k = int(min(k_normal, len(pts)))
        use_numba = backend != "numpy" and numba_available()
        grid = None
        self._extent = _extent(pts) if use_numba else None
        if self._extent is not None:  # about one point per cell (spacing of the bounding box)
            cell = math.sqrt(max(self._extent[0] * self._extent[1], 1e-6) / len(pts))
            grid = _compact_grid(pts, min(max(cell, _KNN_CELL_M[0]), _KNN_CELL_M[1]), self._extent)
        if grid is not None:  # compiled exact k-NN on a bucket grid (same neighbours)
            idx = knn_indices(grid, k)
        else:
            _, idx = self.tree.query(pts, k=k)
        self._packed: dict[float, tuple[FloatArray, NDArray[np.bool_]]] = {}
        if use_numba:  # the same numbers in one compiled loop
            self.normals, self.planarity = point_normals(pts, idx.reshape(len(pts), k))
            return
        nx = pts[:, 0][idx]  # (M, k) neighbour coordinates
        ny = pts[:, 1][idx]
        # the means as ``mean`` computes them (sum, then divide by the count), fewer calls
        dx = nx - np.add.reduce(nx, axis=1, keepdims=True) / idx.shape[1]
        dy = ny - np.add.reduce(ny, axis=1, keepdims=True) / idx.shape[1]
        sxx = np.einsum("mk,mk->m", dx, dx)
        syy = np.einsum("mk,mk->m", dy, dy)
        sxy = np.einsum("mk,mk->m", dx, dy)
        # Closed-form eigen-decomposition of the symmetric 2x2 [[sxx, sxy], [sxy, syy]].
        tr = sxx + syy
        disc = np.sqrt(np.maximum(((sxx - syy) * 0.5) ** 2 + sxy**2, 0.0))
        lam_min = tr * 0.5 - disc
        lam_max = tr * 0.5 + disc
        # Line direction angle (eigenvector of lam_max); the normal is perpendicular.
        phi = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
        self.normals = np.stack([-np.sin(phi), np.cos(phi)], axis=1)
        self.planarity = np.where(lam_max > 1e-12, 1.0 - lam_min / np.maximum(lam_max, 1e-12), 0.0)

    def packed(self, min_planarity: float) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Rows ``(M + 1, 4)`` ``[n_x, n_y, q_x, q_y]`` (normal, point) of the points at least
        ``min_planarity`` planar, zeros for the others and for the extra last row (the index
        :meth:`cKDTree.query` returns for "no neighbour"), and the ``(M + 1,)`` mask of the
        usable rows. Cached per threshold."""
        key = float(min_planarity)
        cache = self.__dict__.setdefault("_packed", {})  # (absent in pickles of older versions)
        if key not in cache:
            usable = np.zeros(len(self.points) + 1, dtype=bool)
            usable[:-1] = self.planarity >= key
            rows = np.zeros((len(self.points) + 1, 4))
            rows[:-1, :2] = self.normals
            rows[:-1, 2:] = self.points
            rows[~usable] = 0.0
            cache[key] = (rows, usable)
        return cache[key]

    @property
    def tree(self) -> cKDTree:
        """KD-tree of the points (built on first use)."""
        if self.__dict__.get("_tree") is None:
            self._tree = cKDTree(self.points)
        return self._tree

    def bucket_grid(self, cell_m: float) -> BucketGrid | None:
        """The points in a :class:`.scan_matcher_numba.BucketGrid` of ``cell_m`` cells (cached);
        ``None`` when the points spread over too many cells for a compact grid."""
        key = float(cell_m)
        cache = self.__dict__.setdefault("_grids", {})
        if key not in cache:
            cache[key] = _compact_grid(self.points, key, self.__dict__.get("_extent"))
        return cache[key]

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


def _sym3_condition(h: FloatArray) -> float:
    """``|lambda|_min / |lambda|_max`` of a symmetric 3x3 ``h`` (0 for ``h = 0``, NaN if not
    finite), from the closed-form eigenvalues: the trigonometric solution of the
    characteristic cubic (Smith 1961). Its absolute error is small against ``|lambda|_max``
    except near a double root, where it is about ``sqrt(eps) |lambda|_max``."""
    a00, a01, a02 = float(h[0, 0]), float(h[0, 1]), float(h[0, 2])
    a11, a12, a22 = float(h[1, 1]), float(h[1, 2]), float(h[2, 2])
    if not math.isfinite(a00 + a01 + a02 + a11 + a12 + a22):
        return math.nan
    p1 = a01 * a01 + a02 * a02 + a12 * a12
    q = (a00 + a11 + a22) / 3.0
    if p1 == 0.0:
        eig = (a00, a11, a22)
    else:
        b00, b11, b22 = a00 - q, a11 - q, a22 - q
        p = math.sqrt((b00 * b00 + b11 * b11 + b22 * b22 + 2.0 * p1) / 6.0)
        det_b = (
            b00 * (b11 * b22 - a12 * a12)
            - a01 * (a01 * b22 - a12 * a02)
            + a02 * (a01 * a12 - b11 * a02)
        )
        half = min(max(det_b / (2.0 * p**3), -1.0), 1.0)
        phi = math.acos(half) / 3.0
        e1 = q + 2.0 * p * math.cos(phi)
        e3 = q + 2.0 * p * math.cos(phi + 2.0 * math.pi / 3.0)
        eig = (e1, 3.0 * q - e1 - e3, e3)
    s = [abs(e) for e in eig]
    return min(s) / max(s) if max(s) > 0.0 else 0.0


def _newton_step(h: FloatArray, grad: FloatArray) -> FloatArray | None:
    """``-h^-1 grad`` for the symmetric 3x3 Gauss-Newton matrix ``h``; ``None`` when ``h`` is
    rank deficient by :func:`numpy.linalg.matrix_rank`'s criterion.

    A clearly regular ``h`` (closed-form condition estimate above ``_WELL_CONDITIONED``) is
    solved in closed form (adjugate / determinant), the rest -- rare: degenerate geometry
    without a prior -- exactly as before by ``matrix_rank`` and LU (``numpy.linalg.solve``).
    """
    if _sym3_condition(h) > _WELL_CONDITIONED:
        a00, a01, a02 = float(h[0, 0]), float(h[0, 1]), float(h[0, 2])
        a11, a12, a22 = float(h[1, 1]), float(h[1, 2]), float(h[2, 2])
        c00 = a11 * a22 - a12 * a12
        c01 = a02 * a12 - a01 * a22
        c02 = a01 * a12 - a02 * a11
        c11 = a00 * a22 - a02 * a02
        c12 = a01 * a02 - a00 * a12
        c22 = a00 * a11 - a01 * a01
        det = a00 * c00 + a01 * c01 + a02 * c02
        b0, b1, b2 = float(grad[0]), float(grad[1]), float(grad[2])
        return np.array(
            [
                -(c00 * b0 + c01 * b1 + c02 * b2) / det,
                -(c01 * b0 + c11 * b1 + c12 * b2) / det,
                -(c02 * b0 + c12 * b1 + c22 * b2) / det,
            ]
        )
    if np.linalg.matrix_rank(h) < 3:
        return None
    return -np.linalg.solve(h, grad)


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
    backend: str = "auto",
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
    nothing to the normal equations. ``backend`` ``"numpy"`` finds correspondences with the
    KD-tree; ``"numba"`` (extra ``fast``) runs each iteration as one compiled loop
    (:mod:`.scan_matcher_numba`, same result to rounding); ``"auto"`` uses numba if installed.
    """
    if backend not in ("auto", "numpy", "numba"):
        raise ValueError(f'backend must be "auto", "numpy" or "numba", got {backend!r}')
    if backend == "numba" and not numba_available():
        raise RuntimeError('backend "numba" needs numba: pip install "dynmap-sim[fast]"')
    pts = np.asarray(points_base, dtype=np.float64).reshape(-1, 2)
    px = np.ascontiguousarray(pts[:, 0])
    py = np.ascontiguousarray(pts[:, 1])
    pw = None if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    pose = np.asarray(init_pose, dtype=np.float64).copy()
    lam = None if prior_info is None else np.asarray(prior_info, dtype=np.float64)
    mu = None
    if lam is not None:
        mu = pose.copy() if prior_mean is None else np.asarray(prior_mean, dtype=np.float64)
    packed, usable = target.packed(min_planarity)
    grid = None
    if backend != "numpy" and numba_available() and len(pts):
        grid = target.bucket_grid(max_correspondence_m)
    if grid is not None:
        pw_all = np.ones(len(pts)) if pw is None else np.ascontiguousarray(pw)
        sums = np.empty(10)
    converged = False
    n_matched = 0
    rmse = float("inf")
    h_scan = np.zeros((3, 3))
    if grid is None:  # work arrays of the numpy iterations
        world = np.empty((len(pts), 2))
        jac = np.empty((len(pts), 3))
    floor2 = sigma_floor_m**2
    n_iter = max(1, int(max_iterations))
    if grid is not None:  # compiled iterations; hands over to the loop below if ill-conditioned
        status, done, n_matched, rmse, converged, h_scan = icp_loop(
            px, py, pw_all, pose, mu, lam, n_iter, max_correspondence_m, grid, packed, usable,
            huber_m, floor2, info_inflation, tol_m, tol_rad, _WELL_CONDITIONED,
        )  # fmt: skip
        n_iter = n_iter - done if status else 0
    for _ in range(n_iter):
        c, s = np.cos(pose[2]), np.sin(pose[2])
        if grid is not None:  # compiled: correspondences and sums in one loop
            n_matched = icp_terms(
                px, py, pw_all, float(c), float(s), float(pose[0]), float(pose[1]),
                float(max_correspondence_m), grid, packed, usable, float(huber_m), sums,
            )  # fmt: skip
            h_scan = np.array(
                [
                    [sums[0], sums[1], sums[2]],
                    [sums[1], sums[3], sums[4]],
                    [sums[2], sums[4], sums[5]],
                ]
            )
            g = sums[6:9].copy()
            ss = float(sums[9])
        else:
            rx = c * px - s * py
            ry = s * px + c * py
            np.add(rx, pose[0], out=world[:, 0])
            np.add(ry, pose[1], out=world[:, 1])
            _, idx = target.tree.query(world, k=1, distance_upper_bound=max_correspondence_m)
            n_matched = int(np.count_nonzero(usable[idx]))
            if n_matched >= 3:
                t = packed[idx]  # (N, 4): normal, target point; zeros where unmatched
                r = np.einsum("ij,ij->i", t[:, :2], world - t[:, 2:])
                jac[:, :2] = t[:, :2]
                np.multiply(t[:, 1], rx, out=jac[:, 2])
                jac[:, 2] -= t[:, 0] * ry
                w = np.minimum(huber_m / np.maximum(np.abs(r), 1e-12), 1.0)  # Huber weights
                if pw is not None:
                    w *= pw
                jw = jac * w[:, None]
                h_scan = jac.T @ jw
                g = jw.T @ r
                ss = float(r @ r)
        if n_matched >= 3:
            rmse = math.sqrt(ss / n_matched)
        else:
            h_scan = np.zeros((3, 3))
            g = np.zeros(3)
            rmse = float("inf")
        # Scale the scan term by the residual variance so scan and prior mix correctly.
        sigma2 = max(rmse**2 if math.isfinite(rmse) else 0.0, floor2) * info_inflation
        h = h_scan / sigma2
        grad = g / sigma2
        if lam is not None:
            e = pose - mu
            e[2] = wrap_angle(e[2])
            h = h + lam
            grad = grad + lam @ e
        delta = _newton_step(h, grad)
        if delta is None:
            break
        pose = pose + delta
        pose[2] = float(wrap_angle(pose[2]))
        if math.hypot(delta[0], delta[1]) < tol_m and abs(delta[2]) < tol_rad:
            converged = True
            break
    sigma2 = max(rmse**2 if math.isfinite(rmse) else 0.0, floor2) * info_inflation
    scan_info = h_scan / sigma2
    info = scan_info if lam is None else scan_info + lam
    try:
        cov = np.linalg.inv(info + 1e-9 * np.eye(3))
    except np.linalg.LinAlgError:
        cov = np.diag([1e6, 1e6, 1e6])
    cov = 0.5 * (cov + cov.T)
    return MatchResult(
        pose=pose,
        cov=cov,
        n_matched=n_matched,
        rmse_m=float(rmse),
        converged=converged,
        scan_info=scan_info,
    )


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
