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

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from dynmap_sim.se2 import wrap_angle

FloatArray = NDArray[np.float64]


class PointMap:
    """A target point set with a KD-tree and per-point line normals, built once.

    ``points_map`` is ``(M, 2)`` in the map frame [m]. Normals come from the smallest
    eigenvector of the covariance of the ``k_normal`` nearest neighbours; ``planarity``
    in ``[0, 1]`` is ``1 - lambda_min / lambda_max`` (1 = a clean line).
    """

    def __init__(self, points_map: ArrayLike, k_normal: int = 6) -> None:
        pts = np.asarray(points_map, dtype=np.float64).reshape(-1, 2)
        if len(pts) < 3:
            raise ValueError(f"PointMap needs at least 3 points, got {len(pts)}")
        self.points = pts
        self.tree = cKDTree(pts)
        k = int(min(k_normal, len(pts)))
        _, idx = self.tree.query(pts, k=k)
        nb = pts[idx]  # (M, k, 2)
        d = nb - nb.mean(axis=1, keepdims=True)
        sxx = np.einsum("mk,mk->m", d[..., 0], d[..., 0])
        syy = np.einsum("mk,mk->m", d[..., 1], d[..., 1])
        sxy = np.einsum("mk,mk->m", d[..., 0], d[..., 1])
        # Closed-form eigen-decomposition of the symmetric 2x2 [[sxx, sxy], [sxy, syy]].
        tr = sxx + syy
        disc = np.sqrt(np.maximum(((sxx - syy) * 0.5) ** 2 + sxy**2, 0.0))
        lam_min = tr * 0.5 - disc
        lam_max = tr * 0.5 + disc
        # Line direction angle (eigenvector of lam_max); the normal is perpendicular.
        phi = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)
        self.normals = np.stack([-np.sin(phi), np.cos(phi)], axis=1)
        self.planarity = np.where(lam_max > 1e-12, 1.0 - lam_min / np.maximum(lam_max, 1e-12), 0.0)

    def __len__(self) -> int:
        return len(self.points)


@dataclass(frozen=True)
class MatchResult:
    """Outcome of :func:`match_scan`: the pose of the scan's frame in the map frame.

    ``cov`` is the 3x3 pose covariance [m², rad²]; ``n_matched`` the number of points with a
    correspondence in the last iteration; ``rmse_m`` their point-to-line RMS residual.
    """

    pose: FloatArray
    cov: FloatArray
    n_matched: int
    rmse_m: float
    converged: bool


def _rotation_terms(theta: float, pts: FloatArray) -> tuple[FloatArray, FloatArray]:
    c, s = np.cos(theta), np.sin(theta)
    rp = np.stack([c * pts[:, 0] - s * pts[:, 1], s * pts[:, 0] + c * pts[:, 1]], axis=1)
    drp = np.stack([-rp[:, 1], rp[:, 0]], axis=1)  # d(R p)/d theta
    return rp, drp


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
    """
    pts = np.asarray(points_base, dtype=np.float64).reshape(-1, 2)
    pw = None if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    pose = np.asarray(init_pose, dtype=np.float64).copy()
    lam = None if prior_info is None else np.asarray(prior_info, dtype=np.float64)
    mu = None
    if lam is not None:
        mu = pose.copy() if prior_mean is None else np.asarray(prior_mean, dtype=np.float64)
    converged = False
    n_matched = 0
    rmse = float("inf")
    h_scan = np.zeros((3, 3))
    for _ in range(max(1, int(max_iterations))):
        rp, drp = _rotation_terms(pose[2], pts)
        world = rp + pose[:2]
        dist, idx = target.tree.query(world, k=1, distance_upper_bound=max_correspondence_m)
        ok = np.isfinite(dist)
        if np.any(ok):
            ok[ok] &= target.planarity[idx[ok]] >= min_planarity
        n_matched = int(ok.sum())
        h_scan = np.zeros((3, 3))
        g = np.zeros(3)
        if n_matched >= 3:
            n = target.normals[idx[ok]]
            q = target.points[idx[ok]]
            r = np.einsum("ij,ij->i", n, world[ok] - q)
            jac = np.column_stack([n[:, 0], n[:, 1], np.einsum("ij,ij->i", n, drp[ok])])
            a = np.abs(r)
            w = np.where(a <= huber_m, 1.0, huber_m / np.maximum(a, 1e-12))
            if pw is not None:
                w = w * pw[ok]
            h_scan = jac.T @ (jac * w[:, None])
            g = jac.T @ (w * r)
            rmse = float(np.sqrt(np.mean(r * r)))
        else:
            rmse = float("inf")
        # Scale the scan term by the residual variance so scan and prior mix correctly.
        sigma2 = max(rmse**2 if np.isfinite(rmse) else 0.0, sigma_floor_m**2) * info_inflation
        h = h_scan / sigma2
        grad = g / sigma2
        if lam is not None:
            e = pose - mu
            e[2] = wrap_angle(e[2])
            h = h + lam
            grad = grad + lam @ e
        if np.linalg.matrix_rank(h) < 3:
            break
        delta = -np.linalg.solve(h, grad)
        pose = pose + delta
        pose[2] = float(wrap_angle(pose[2]))
        if np.hypot(delta[0], delta[1]) < tol_m and abs(delta[2]) < tol_rad:
            converged = True
            break
    sigma2 = max(rmse**2 if np.isfinite(rmse) else 0.0, sigma_floor_m**2) * info_inflation
    info = h_scan / sigma2
    if lam is not None:
        info = info + lam
    try:
        cov = np.linalg.inv(info + 1e-9 * np.eye(3))
    except np.linalg.LinAlgError:
        cov = np.diag([1e6, 1e6, 1e6])
    cov = 0.5 * (cov + cov.T)
    return MatchResult(
        pose=pose, cov=cov, n_matched=n_matched, rmse_m=float(rmse), converged=converged
    )
