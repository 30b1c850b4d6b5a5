"""Pose-graph optimization in SE(2) by sparse nonlinear least squares.

Graph SLAM (Thrun et al., *Probabilistic Robotics* §11; Grisetti et al. 2010, "A tutorial on
graph-based SLAM", eq. 25-30): nodes are keyframe poses, edges relative-pose measurements
``z_ij`` with information ``Omega_ij``; the error of an edge is
``e_ij = (x_i^-1 ⊕ x_j) ⊖ z_ij`` (angle wrapped) and we minimise
``sum_ij e_ij^T Omega_ij e_ij`` with ``scipy.optimize.least_squares`` on whitened residuals
``L_ij^T e_ij`` (``Omega_ij = L_ij L_ij^T``), their sparse closed-form Jacobian (each edge
touches six variables) and a robust loss against false loop closures. The first node is
anchored, so the optimized map frame is the frame of the first pose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix, identity

from dynmap_sim import se2

FloatArray = NDArray[np.float64]
#: The node or nodes an optimization holds fixed.
Anchor = int | tuple[int, ...]


@dataclass(frozen=True)
class Edge:
    """A relative-pose measurement ``z`` of node ``j`` in the frame of node ``i``."""

    i: int
    j: int
    z: FloatArray
    info: FloatArray


def edge_errors(poses: FloatArray, edges: list[Edge]) -> FloatArray:
    """Unwhitened errors ``(E, 3)`` of all edges at ``poses`` ``(K, 3)``."""
    ii = np.array([e.i for e in edges])
    jj = np.array([e.j for e in edges])
    z = np.array([e.z for e in edges], dtype=np.float64)
    rel = se2.between(poses[ii], poses[jj])
    err = rel - z
    err[:, 2] = se2.wrap_angle(err[:, 2])
    return err


def edge_jacobians(poses: FloatArray, ii: NDArray[np.intp], jj: NDArray[np.intp]):
    """Closed-form Jacobians of the edge errors ``e = (x_i^-1 ⊕ x_j) ⊖ z`` (Grisetti et al.
    2010, eq. 29-30 in SE(2)): ``(A, B)``, each ``(E, 3, 3)``, ``A = de/dx_i``, ``B = de/dx_j``.

    With ``R_i`` the rotation of ``x_i`` and ``d = t_j - t_i``: ``de_xy/dt_i = -R_i^T``,
    ``de_xy/dtheta_i = dR_i^T/dtheta d``, ``de_xy/dt_j = R_i^T``, ``de_theta/dtheta_i = -1``,
    ``de_theta/dtheta_j = 1`` (``z`` and the angle wrap do not matter).
    """
    c, s = np.cos(poses[ii, 2]), np.sin(poses[ii, 2])
    dx = poses[jj, 0] - poses[ii, 0]
    dy = poses[jj, 1] - poses[ii, 1]
    n = len(ii)
    a = np.zeros((n, 3, 3))
    b = np.zeros((n, 3, 3))
    a[:, 0, 0], a[:, 0, 1], a[:, 0, 2] = -c, -s, -s * dx + c * dy
    a[:, 1, 0], a[:, 1, 1], a[:, 1, 2] = s, -c, -c * dx - s * dy
    a[:, 2, 2] = -1.0
    b[:, 0, 0], b[:, 0, 1] = c, s
    b[:, 1, 0], b[:, 1, 1] = -s, c
    b[:, 2, 2] = 1.0
    return a, b


def _sparsity(k: int, ii: NDArray[np.intp], jj: NDArray[np.intp], anchor: Anchor) -> tuple:
    """The free nodes (all but the ``anchor`` node or nodes) and the structure of the
    whitened residuals' Jacobian: rows 3m..3m+2 of edge m touch the columns of its free
    nodes. ``(free, rows, cols, use_i, use_j, shape)``; ``use_*`` ``(E, 3, 3)`` mask the
    blocks of the edges' free ends."""
    fixed = set(np.atleast_1d(anchor).tolist())
    free = np.array([n for n in range(k) if n not in fixed], dtype=np.intp)
    col_of = -np.ones(k, dtype=np.intp)
    col_of[free] = np.arange(len(free))
    n_e = len(ii)
    rows = np.broadcast_to(
        3 * np.arange(n_e)[:, None, None] + np.arange(3)[None, :, None], (n_e, 3, 3)
    )
    cols_i = np.broadcast_to(3 * col_of[ii][:, None, None] + np.arange(3), (n_e, 3, 3))
    cols_j = np.broadcast_to(3 * col_of[jj][:, None, None] + np.arange(3), (n_e, 3, 3))
    use_i = np.broadcast_to((col_of[ii] >= 0)[:, None, None], (n_e, 3, 3))
    use_j = np.broadcast_to((col_of[jj] >= 0)[:, None, None], (n_e, 3, 3))
    jac_rows = np.concatenate([rows[use_i], rows[use_j]])
    jac_cols = np.concatenate([cols_i[use_i], cols_j[use_j]])
    return free, jac_rows, jac_cols, use_i, use_j, (3 * n_e, 3 * len(free))


def optimize_pose_graph(
    poses: ArrayLike,
    edges: list[Edge],
    anchor: Anchor = 0,
    loss: str = "huber",
    f_scale: float = 3.0,
    max_nfev: int = 100,
) -> FloatArray:
    """Optimize node ``poses`` ``(K, 3)`` under ``edges``; node(s) ``anchor`` stay fixed.

    ``loss``/``f_scale`` are passed to ``scipy.optimize.least_squares`` (on residuals
    whitened by each edge's information, so ``f_scale`` is in standard deviations). The
    sparse Jacobian of the whitened residuals is given in closed form
    (:func:`edge_jacobians`), not by finite differences.
    """
    x0 = np.asarray(poses, dtype=np.float64).reshape(-1, 3).copy()
    k = len(x0)
    if k < 2 or not edges:
        return x0
    ii = np.array([e.i for e in edges])
    jj = np.array([e.j for e in edges])
    if ii.min() < 0 or jj.min() < 0 or ii.max() >= k or jj.max() >= k:
        raise ValueError("edge refers to a node that does not exist")
    z = np.array([e.z for e in edges], dtype=np.float64)
    chol = np.array([np.linalg.cholesky(np.asarray(e.info, dtype=np.float64)) for e in edges])
    chol_t = np.ascontiguousarray(chol.transpose(0, 2, 1))  # L^T per edge
    free, jac_rows, jac_cols, use_i, use_j, shape = _sparsity(k, ii, jj, anchor)

    def unpack(v: FloatArray) -> FloatArray:
        x = x0.copy()
        x[free] = v.reshape(-1, 3)
        return x

    def residuals(v: FloatArray) -> FloatArray:
        x = unpack(v)
        err = se2.between(x[ii], x[jj]) - z
        err[:, 2] = se2.wrap_angle(err[:, 2])
        return np.einsum("eab,eb->ea", chol_t, err).ravel()  # L^T e

    def jacobian(v: FloatArray) -> csr_matrix:
        a, b = edge_jacobians(unpack(v), ii, jj)
        wa = chol_t @ a  # whitened: d(L^T e)/dx = L^T de/dx
        wb = chol_t @ b
        data = np.concatenate([wa[use_i], wb[use_j]])
        return csr_matrix((data, (jac_rows, jac_cols)), shape=shape)

    sol = least_squares(
        residuals,
        x0[free].ravel(),
        jac=jacobian,
        loss=loss,
        f_scale=f_scale,
        max_nfev=max_nfev,
        method="trf",
        x_scale="jac",
    )
    out = unpack(sol.x)
    out[:, 2] = se2.wrap_angle(out[:, 2])
    return out


def dcs_scale(chi2: FloatArray, phi: float) -> FloatArray:
    """Dynamic covariance scaling (Agarwal, Tipaldi, Spinello, Stachniss & Burgard 2013,
    "Robust map optimization using dynamic covariance scaling", eq. 15): the factor
    ``s = min(1, 2 phi / (phi + chi2))`` by which an edge's whitened residual is scaled,
    from its squared Mahalanobis error ``chi2``: 1 for an edge that fits, ~``sqrt(phi /
    chi2)`` shrinking towards 0 for one that does not, so that a false loop closure stops
    pulling on the graph instead of bending it. ``phi`` is in units of ``chi2``."""
    return np.minimum(1.0, 2.0 * phi / (phi + chi2))


def optimize_pose_graph_dcs(
    poses: ArrayLike,
    edges: list[Edge],
    robust: NDArray[np.bool_],
    phi: float = 1.0,
    anchor: Anchor = 0,
    max_iterations: int = 60,
    tol: float = 1e-6,
) -> FloatArray:
    """Optimize node ``poses`` ``(K, 3)`` by Gauss-Newton with dynamic covariance scaling
    (:func:`dcs_scale`, re-evaluated at every iteration as in Agarwal et al. 2013 §IV) on the
    ``robust`` edges ``(E,)`` (loop closures; the others, e.g. odometry, stay Gaussian); node(s)
    ``anchor`` stay fixed.

    ``phi`` is reached by graduated non-convexity (Yang, Antonante, Tzoumas & Carlone 2020):
    it starts at the largest ``chi2`` of the robust edges -- every closure counts, whatever
    drift the initial guess carries -- and halves each iteration down to ``phi``, so the
    closures that disagree with the majority lose their weight as the graph settles, while a
    true closure far from a drifted initial guess is not dropped at the first step. Stops
    when ``phi`` is reached and the largest step is below ``tol`` [m, rad]."""
    from scipy.sparse.linalg import spsolve

    x = np.asarray(poses, dtype=np.float64).reshape(-1, 3).copy()
    k = len(x)
    if k < 2 or not edges:
        return x
    ii = np.array([e.i for e in edges])
    jj = np.array([e.j for e in edges])
    z = np.array([e.z for e in edges], dtype=np.float64)
    chol_t = np.array([np.linalg.cholesky(np.asarray(e.info, dtype=np.float64)).T for e in edges])
    robust = np.asarray(robust, dtype=bool)
    free, jac_rows, jac_cols, use_i, use_j, shape = _sparsity(k, ii, jj, anchor)
    damping = 1e-9  # keeps the normal equations regular where the graph is weakly tied
    phi_k = math.inf
    for _ in range(max_iterations):
        err = se2.between(x[ii], x[jj]) - z
        err[:, 2] = se2.wrap_angle(err[:, 2])
        r = np.einsum("eab,eb->ea", chol_t, err)
        chi2 = np.einsum("ea,ea->e", r, r)
        if math.isinf(phi_k):
            phi_k = max(float(chi2[robust].max()) if robust.any() else phi, phi)
        else:
            phi_k = max(0.5 * phi_k, phi)
        s = np.where(robust, dcs_scale(chi2, phi_k), 1.0)
        a, b = edge_jacobians(x, ii, jj)
        wa = s[:, None, None] * (chol_t @ a)
        wb = s[:, None, None] * (chol_t @ b)
        jac = csr_matrix(
            (np.concatenate([wa[use_i], wb[use_j]]), (jac_rows, jac_cols)), shape=shape
        )
        rw = (s[:, None] * r).ravel()
        h = (jac.T @ jac).tocsc()
        h = h + damping * (abs(h).max() if h.nnz else 1.0) * identity(shape[1], format="csc")
        dx = spsolve(h, -(jac.T @ rw)).reshape(-1, 3)
        x[free] += dx
        x[:, 2] = se2.wrap_angle(x[:, 2])
        if phi_k <= phi and np.abs(dx).max() < tol:
            break
    return x
