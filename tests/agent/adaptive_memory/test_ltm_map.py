"""The long-term map's kernels (:mod:`.ltm_map`) against brute-force references written from
H&W §4.3-4.4's definitions: eqs. 13-14 as matrix products, eq. 15's update cell by cell,
§4.4's test over every cell, and the classes of §4.4 point by point."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim.agent.localization.adaptive_memory.ltm_map import (
    LTMMap,
    LTMParams,
    point_covariances,
    semistatic_classes,
)


def random_map(rng: np.random.Generator, h: int, w: int, res_m: float = 0.05) -> LTMMap:
    """A grid of log-odds around ``l_occupied`` (many exactly at the clamps), a few pinned."""
    lo = rng.choice([-2.0, 0.0, 1.4, 2.5, 3.5], size=(h, w)).astype(np.float32)
    lo += (rng.random((h, w)) < 0.3) * rng.normal(0, 0.5, (h, w)).astype(np.float32)
    pinned = rng.random((h, w)) < 0.05
    lo[pinned] = 3.5
    return LTMMap(lo, rng.uniform(-2, 2, 2), res_m, pinned, rng.random((h, w)) < 0.5)


def random_points(rng: np.random.Generator, m: LTMMap, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Points over the grid and up to half a metre beyond it, with random covariances."""
    h, w = m.shape
    pts = rng.uniform(m.origin - 0.5, m.origin + np.array([w, h]) * m.resolution + 0.5, (n, 2))
    a = rng.normal(0, rng.choice([0.005, 0.02, 0.08]), (n, 2, 2))
    return pts, a @ a.transpose(0, 2, 1)


def random_params(rng: np.random.Generator) -> LTMParams:
    return LTMParams(
        free_space=bool(rng.random() < 0.8),
        l_free=float(rng.choice([-0.4, -0.3])),
        l_occupied=float(rng.choice([2.5, 1.4, 0.7])),
        l_min=float(rng.choice([-2.0, -0.7, 0.0])),
        stencil_cells=int(rng.integers(1, 4)),
        semistatic_sigma=float(rng.uniform(1, 3)),
        semistatic_max_cells=int(rng.integers(1, 6)),
    )


def centres(m: LTMMap) -> tuple[np.ndarray, np.ndarray]:
    h, w = m.shape
    return np.meshgrid(m.origin[0] + (np.arange(w) + 0.5) * m.resolution,
                       m.origin[1] + (np.arange(h) + 0.5) * m.resolution)  # fmt: skip


def explained_reference(m: LTMMap, pts, covs, p: LTMParams) -> np.ndarray:
    """Every occupied cell of the grid whose centre lies within ``rho`` of the point, ``rho``
    from the floored covariance's largest eigenvalue."""
    cx, cy = centres(m)
    occ = m.logodds >= np.float32(p.l_occupied)
    out = []
    for q, c in zip(pts, covs, strict=True):
        lam = np.linalg.eigvalsh(c + p.cov_floor_m**2 * np.eye(2)).max()
        rho = np.clip(p.semistatic_sigma * np.sqrt(lam), 1.5 * m.resolution,
                      p.semistatic_max_cells * m.resolution)  # fmt: skip
        out.append(bool(np.any(occ & (np.hypot(cx - q[0], cy - q[1]) <= rho))))
    return np.array(out)


def test_explained_is_any_occupied_cell_within_the_points_uncertainty() -> None:
    rng = np.random.default_rng(11)
    n_true = n_all = 0
    for _ in range(150):
        m = random_map(rng, *(int(v) for v in rng.integers(3, 30, 2)))
        p = random_params(rng)
        pts, covs = random_points(rng, m, int(rng.integers(1, 40)))
        got = m.explained(pts, covs, p)
        np.testing.assert_array_equal(got, explained_reference(m, pts, covs, p))
        n_true, n_all = n_true + int(got.sum()), n_all + len(got)
    assert 0.2 < n_true / n_all < 0.9  # both verdicts were tested


def update_reference(m: LTMMap, laser, pts, covs, hit, p: LTMParams) -> np.ndarray:
    """Eq. 15 cell by cell: each hit point's Gaussian (Mahalanobis distance < 3 inside its
    ``(2k+1)²`` square) as log-odds of ``0.5 + (p_hit - 0.5) exp(-m²/2)``; ``l_free`` on each
    cell one of the point's half-cell ray samples ``t < stop`` falls in, once; then the clamp
    and the pinned cells at ``l_max``."""
    lo = m.logodds.astype(np.float64)
    h, w = m.shape
    cx, cy = centres(m)
    res, k = m.resolution, p.stencil_cells
    for q, c, on in zip(pts, covs, hit, strict=True):
        if not on:
            continue
        ic = np.floor((q - m.origin) / res).astype(int)
        ix, iy = np.meshgrid(np.arange(w), np.arange(h))
        near = (np.abs(ix - ic[0]) <= k) & (np.abs(iy - ic[1]) <= k)
        inv = np.linalg.inv(c + p.cov_floor_m**2 * np.eye(2))
        d = np.stack([cx - q[0], cy - q[1]], axis=-1)
        m2 = np.einsum("...i,ij,...j->...", d, inv, d)
        pr = 0.5 + (p.p_hit - 0.5) * np.exp(-0.5 * m2)
        lo += np.where(near & (m2 < 9), np.log(pr / (1 - pr)), 0.0)
    if p.free_space:
        for q, c in zip(pts, covs, strict=True):
            d = q - laser
            r = np.hypot(*d)
            sig = np.sqrt(d @ (c + p.cov_floor_m**2 * np.eye(2)) @ d) / r
            stop = r - max(p.free_stop_sigma * sig, res)
            t = np.arange(0.0, max(stop, 0.0), 0.5 * res)
            cells = np.floor((laser + np.outer(t, d / r) - m.origin) / res).astype(int)
            inside = (cells[:, 0] >= 0) & (cells[:, 0] < w) & (cells[:, 1] >= 0) & (cells[:, 1] < h)
            for ix, iy in {tuple(v) for v in cells[inside]}:
                lo[iy, ix] += p.l_free
    lo = np.clip(lo, p.l_min, p.l_max)
    lo[m.pinned] = p.l_max
    return lo


def test_update_is_eq_15_cell_by_cell() -> None:
    rng = np.random.default_rng(12)
    for _ in range(60):
        m = random_map(rng, *(int(v) for v in rng.integers(3, 40, 2)))
        p = random_params(rng)
        np.clip(m.logodds, p.l_min, p.l_max, out=m.logodds)  # as every map starts
        m.logodds[m.pinned] = p.l_max
        pts, covs = random_points(rng, m, int(rng.integers(1, 20)))
        h, w = m.shape
        laser = m.origin + rng.uniform(-0.3, 1.1, 2) * np.array([w, h]) * m.resolution
        hit = rng.random(len(pts)) < 0.7
        ref = update_reference(m, laser, pts, covs, hit, p)
        m.update(laser, pts, covs, p, hit)
        np.testing.assert_allclose(m.logodds, ref, atol=1e-5)  # float32 cells, float64 sums


def test_one_point_at_a_cell_centre_gives_the_sensor_models_peak() -> None:
    p = LTMParams(free_space=False)
    m = LTMMap(np.zeros((9, 9), np.float32), np.zeros(2), 0.05, np.zeros((9, 9), bool),
               np.zeros((9, 9), bool))  # fmt: skip
    m.update(np.array([0.0, 0.0]), np.array([[0.225, 0.225]]), np.zeros((1, 2, 2)), p)
    assert m.logodds[4, 4] == pytest.approx(np.log(p.p_hit / (1 - p.p_hit)), rel=1e-6)
    assert m.logodds[4, 5] == m.logodds[4, 3] == m.logodds[5, 4] == m.logodds[3, 4]  # isotropic
    assert 0 < m.logodds[4, 5] < m.logodds[4, 4]


def test_point_covariances_are_eqs_12_to_14_as_matrix_products() -> None:
    rng = np.random.default_rng(14)
    for _ in range(30):
        n = int(rng.integers(1, 50))
        pose = np.array([*rng.uniform(-5, 5, 2), rng.uniform(-np.pi, np.pi)])
        a = rng.normal(0, rng.choice([1e-3, 0.05]), (3, 3))
        cov_p = a @ a.T
        mount = np.array([*rng.uniform(-0.2, 0.2, 2), rng.uniform(-0.1, 0.1)])
        ranges, angles = rng.uniform(0.02, 6.0, n), rng.uniform(-2.1, 2.1, n)
        sig_a, sig_r = 0.0018, np.maximum(0.01, 0.01 * ranges)
        pts, covs = point_covariances(pose, cov_p, mount, ranges, angles, sig_a, sig_r)
        for j in range(n):
            lx = pose[:2] + np.array([[np.cos(pose[2]), -np.sin(pose[2])],
                                      [np.sin(pose[2]), np.cos(pose[2])]]) @ mount[:2]  # fmt: skip
            b = pose[2] + mount[2] + angles[j]
            q = lx + ranges[j] * np.array([np.cos(b), np.sin(b)])
            np.testing.assert_allclose(pts[j], q, atol=1e-12)
            # state (x, y, φ, α, r): ∇F of eq. 13 (the φ column: the lever arm)
            jac = np.array([[1, 0, -(q[1] - pose[1]), -ranges[j] * np.sin(b), np.cos(b)],
                            [0, 1, q[0] - pose[0], ranges[j] * np.cos(b), np.sin(b)]])  # fmt: skip
            full = np.zeros((5, 5))
            full[:3, :3] = cov_p
            full[3:, 3:] = np.diag([sig_a**2, sig_r[j] ** 2])
            np.testing.assert_allclose(covs[j], jac @ full @ jac.T, rtol=1e-9, atol=1e-15)


def classes_reference(cls_v, lab, explained, known, n_boxes, veto, vi, n_beams):
    """§4.4 point by point: a dynamic point whose box a map explains for at least ``veto``
    of its points is static; a non-dynamic point §4.4's map does not know is semistatic."""
    out = cls_v.copy()
    for j in range(len(out)):
        b = lab[j]
        if out[j] == 1 and b >= 0:
            share = np.mean(explained[lab == b])
            if share >= veto:
                out[j] = 3
        if out[j] != 1 and not known[j]:
            out[j] = 2
    classes = np.zeros(n_beams, np.int8)
    classes[vi] = out
    return classes, np.bincount(out, minlength=4)


@pytest.mark.parametrize("veto", [0.0, 0.3, 0.5, 1.0])
def test_semistatic_classes_follow_section_4_4_point_by_point(veto: float) -> None:
    rng = np.random.default_rng(31)
    for _ in range(100):
        n_beams = int(rng.integers(1, 200))
        vi = np.sort(rng.choice(n_beams, int(rng.integers(0, n_beams + 1)), replace=False))
        n_boxes = int(rng.integers(0, 8))
        lab = rng.integers(-1, n_boxes, len(vi)) if n_boxes else np.full(len(vi), -1)
        cls_v = np.where(lab >= 0, rng.choice(np.array([1, 3], np.int8), len(vi)), 0)
        cls_v = cls_v.astype(np.int8)
        explained = rng.random(len(vi)) < rng.choice([0.1, 0.5, 0.9])
        known = explained if rng.random() < 0.3 else rng.random(len(vi)) < 0.5
        ref = classes_reference(cls_v, lab, explained, known, n_boxes, veto, vi, n_beams)
        got = semistatic_classes(cls_v.copy(), lab.astype(np.intp), explained, known, n_boxes,
                                 veto, vi.astype(np.intp), n_beams)  # fmt: skip
        np.testing.assert_array_equal(got[0], ref[0])
        np.testing.assert_array_equal(got[1], ref[1])
