"""Pose-graph optimization in SE(2) by sparse nonlinear least squares.

Graph SLAM (Thrun et al., *Probabilistic Robotics* §11; Grisetti et al. 2010, "A tutorial on
graph-based SLAM", eq. 25-30): nodes are keyframe poses, edges relative-pose measurements
``z_ij`` with information ``Omega_ij``; the error of an edge is
``e_ij = (x_i^-1 ⊕ x_j) ⊖ z_ij`` (angle wrapped) and we minimise
``sum_ij e_ij^T Omega_ij e_ij`` with ``scipy.optimize.least_squares`` on whitened residuals
``L_ij^T e_ij`` (``Omega_ij = L_ij L_ij^T``), a sparse Jacobian pattern (each edge touches
six variables) and a robust loss against false loop closures. The first node is anchored,
so the optimized map frame is the frame of the first pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix

from dynmap_sim import se2

FloatArray = NDArray[np.float64]


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


def optimize_pose_graph(
    poses: ArrayLike,
    edges: list[Edge],
    anchor: int = 0,
    loss: str = "huber",
    f_scale: float = 3.0,
    max_nfev: int = 100,
) -> FloatArray:
    """Optimize node ``poses`` ``(K, 3)`` under ``edges``; node ``anchor`` stays fixed.

    ``loss``/``f_scale`` are passed to ``scipy.optimize.least_squares`` (on residuals
    whitened by each edge's information, so ``f_scale`` is in standard deviations).
    """
    x0 = np.asarray(poses, dtype=np.float64).reshape(-1, 3).copy()
    k = len(x0)
    if k < 2 or not edges:
        return x0
    ii = np.array([e.i for e in edges])
    jj = np.array([e.j for e in edges])
    if ii.min() < 0 or jj.min() < 0 or ii.max() >= k or jj.max() >= k:
        raise ValueError("edge refers to a node that does not exist")
    chol = np.array([np.linalg.cholesky(np.asarray(e.info, dtype=np.float64)) for e in edges])
    free = np.array([n for n in range(k) if n != anchor])
    col_of = -np.ones(k, dtype=np.intp)
    col_of[free] = np.arange(len(free))

    def unpack(v: FloatArray) -> FloatArray:
        x = x0.copy()
        x[free] = v.reshape(-1, 3)
        return x

    def residuals(v: FloatArray) -> FloatArray:
        err = edge_errors(unpack(v), edges)
        return np.einsum("eba,eb->ea", chol, err).ravel()  # L^T e

    sparsity = lil_matrix((3 * len(edges), 3 * len(free)), dtype=np.int8)
    for m, (a, b) in enumerate(zip(ii, jj, strict=True)):
        for node in (a, b):
            c = col_of[node]
            if c >= 0:
                sparsity[3 * m : 3 * m + 3, 3 * c : 3 * c + 3] = 1
    sol = least_squares(
        residuals,
        x0[free].ravel(),
        jac_sparsity=sparsity.tocsr(),
        loss=loss,
        f_scale=f_scale,
        max_nfev=max_nfev,
        method="trf",
        x_scale="jac",
    )
    out = unpack(sol.x)
    out[:, 2] = se2.wrap_angle(out[:, 2])
    return out
