"""Point-to-line ICP: a transformed scan matches back; the prior rules in degenerate geometry."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree
from synthetic_scans import LASER, raycast, room_segments

from dynmap_sim import se2
from dynmap_sim.agent.mapping.scan_matcher import (
    PointMap,
    bucket_grid,
    knn_indices,
    match_scan,
    worst_position_sigma,
)
from dynmap_sim.agent.mapping.scan_matcher_kernels import (
    IcpParams,
    ScanArrays,
    _condition3,
    icp_terms,
    solve3,
)


def _dense_points(segs: np.ndarray, step_m: float = 0.02) -> np.ndarray:
    out = []
    for x0, y0, x1, y1 in segs:
        n = max(2, int(np.hypot(x1 - x0, y1 - y0) / step_m) + 1)
        t = np.linspace(0.0, 1.0, n)
        out.append(np.stack([x0 + t * (x1 - x0), y0 + t * (y1 - y0)], axis=1))
    return np.concatenate(out)


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    dx=st.floats(-0.25, 0.25),
    dy=st.floats(-0.25, 0.25),
    dth=st.floats(-0.15, 0.15),
    x=st.floats(1.0, 4.0),
    y=st.floats(0.8, 1.6),
)
def test_transformed_scan_matches_back(segments, laser, cast, dx, dy, dth, x, y):
    target = PointMap(_dense_points(segments))
    truth = np.array([x, y, 0.3])
    r = cast(truth, laser.angles(), segments, laser.range_max_m)
    pts = se2.scan_to_points(r, laser.angles())
    init = truth + np.array([dx, dy, dth])
    res = match_scan(pts, target, init)
    assert res.converged
    assert np.hypot(*(res.pose[:2] - truth[:2])) < 0.01
    assert abs(se2.wrap_angle(res.pose[2] - truth[2])) < 0.005
    assert res.rmse_m < 0.01
    assert res.n_matched > 0.8 * len(pts)
    # A well-constrained scan gives a small, symmetric positive-definite covariance.
    assert np.allclose(res.cov, res.cov.T)
    assert np.all(np.linalg.eigvalsh(res.cov) > 0)
    assert np.sqrt(res.cov[0, 0]) < 0.01


def test_noisy_scan_covariance_is_consistent(segments, laser, cast):
    rng = np.random.default_rng(3)
    target = PointMap(_dense_points(segments))
    truth = np.array([3.0, 1.2, -0.4])
    r = cast(truth, laser.angles(), segments, laser.range_max_m)
    r = r + rng.normal(0.0, 0.01, r.shape)
    res = match_scan(se2.scan_to_points(r, laser.angles()), target, truth + [0.1, -0.1, 0.05])
    err = res.pose - truth
    assert np.hypot(err[0], err[1]) < 0.01
    assert 0.005 < res.rmse_m < 0.02
    assert np.sqrt(res.cov[0, 0]) < 0.01


def test_prior_pulls_along_a_corridor(laser, cast):
    # Two long parallel walls: the scan fixes y and theta but not x.
    corridor = np.array([[-50.0, -1.0, 50.0, -1.0], [-50.0, 1.0, 50.0, 1.0]])
    target = PointMap(_dense_points(corridor, 0.05))
    truth = np.array([0.0, 0.1, 0.0])
    r = cast(truth, laser.angles(), corridor, laser.range_max_m)
    pts = se2.scan_to_points(r, laser.angles())
    prior_mean = np.array([0.3, 0.0, 0.02])
    prior_info = np.diag([1.0 / 0.05**2, 1.0 / 0.05**2, 1.0 / 0.02**2])
    res = match_scan(pts, target, prior_mean, prior_mean=prior_mean, prior_info=prior_info)
    # Along the corridor only the prior speaks: x stays at the prior mean.
    assert res.pose[0] == pytest.approx(0.3, abs=1e-3)
    # Across it the scan wins.
    assert res.pose[1] == pytest.approx(0.1, abs=0.01)
    assert abs(res.pose[2]) < 0.005
    # The covariance says so: large along x (the prior's 5 cm), tiny across.
    assert np.sqrt(res.cov[0, 0]) == pytest.approx(0.05, rel=0.05)
    assert np.sqrt(res.cov[1, 1]) < 0.005


def test_scan_info_tells_the_corridor_from_a_room(laser, cast, segments):
    # The scan term's information is the covariance's inverse without the prior ...
    corridor = np.array([[-50.0, -1.0, 50.0, -1.0], [-50.0, 1.0, 50.0, 1.0]])
    truth = np.array([0.0, 0.1, 0.0])
    r = cast(truth, laser.angles(), corridor, laser.range_max_m)
    pts = se2.scan_to_points(r, laser.angles())
    prior_info = np.diag([1.0 / 0.05**2, 1.0 / 0.05**2, 1.0 / 0.02**2])
    res = match_scan(
        pts, PointMap(_dense_points(corridor, 0.05)), truth, prior_mean=truth, prior_info=prior_info
    )
    np.testing.assert_allclose(
        np.linalg.inv(res.cov), res.scan_info + prior_info, rtol=1e-6, atol=1e-3
    )
    # ... and says that two parallel walls do not fix the position along them (metres) ...
    assert worst_position_sigma(res.scan_info) > 1.0
    # ... while a room does.
    room = np.array([2.5, 1.2, 0.3])
    r = cast(room, laser.angles(), segments, laser.range_max_m)
    res = match_scan(se2.scan_to_points(r, laser.angles()), PointMap(_dense_points(segments)), room)
    assert worst_position_sigma(res.scan_info) < 0.01


def test_worst_position_sigma_closed_form():
    # Uncoupled: the weaker of the two translation directions, as a standard deviation.
    assert worst_position_sigma(np.diag([100.0, 10_000.0, 5.0])) == pytest.approx(0.1)
    # A direction with no information at all.
    assert worst_position_sigma(np.diag([0.0, 10_000.0, 5.0])) == np.inf
    # Heading coupled to x: marginalizing it out leaves x with 100 - 40^2/20 = 20.
    h = np.array([[100.0, 0.0, 40.0], [0.0, 1e4, 0.0], [40.0, 0.0, 20.0]])
    assert worst_position_sigma(h) == pytest.approx(1.0 / np.sqrt(20.0))


def test_too_few_points_is_not_converged(segments):
    target = PointMap(_dense_points(segments))
    res = match_scan(np.array([[100.0, 100.0]]), target, np.zeros(3))
    assert not res.converged
    assert res.n_matched == 0


def test_info_inflation_scales_scan_covariance(laser, cast):
    corridor = np.array([[-50.0, -1.0, 50.0, -1.0], [-50.0, 1.0, 50.0, 1.0]])
    target = PointMap(_dense_points(corridor, 0.05))
    truth = np.array([0.0, 0.1, 0.0])
    pts = se2.scan_to_points(cast(truth, laser.angles(), corridor, 5.6), laser.angles())
    prior = np.diag([1 / 0.05**2, 1 / 0.05**2, 1 / 0.02**2])
    a = match_scan(pts, target, truth, prior_mean=truth, prior_info=prior)
    b = match_scan(pts, target, truth, prior_mean=truth, prior_info=prior, info_inflation=100.0)
    # Across the corridor the scan rules: the sd grows by sqrt(100) = 10.
    assert np.sqrt(b.cov[1, 1] / a.cov[1, 1]) == pytest.approx(10.0, rel=0.05)


def _reference_match(
    pts,
    target,
    init,
    prior_mean=None,
    prior_info=None,
    max_iterations=30,
    max_correspondence_m=0.5,
    huber_m=0.05,
    min_planarity=0.6,
):
    """The Gauss-Newton loop of the module docstring written plainly with a KD-tree: matched
    points only, LU solves and ``matrix_rank`` -- the reference the compiled matcher must
    reproduce."""
    tree = cKDTree(target.points)
    pose = np.asarray(init, dtype=np.float64).copy()
    for _ in range(max_iterations):
        c, s = np.cos(pose[2]), np.sin(pose[2])
        rp = np.column_stack([c * pts[:, 0] - s * pts[:, 1], s * pts[:, 0] + c * pts[:, 1]])
        world = rp + pose[:2]
        dist, idx = tree.query(world, k=1, distance_upper_bound=max_correspondence_m)
        ok = np.isfinite(dist)
        ok[ok] &= target.planarity[idx[ok]] >= min_planarity
        h, g, rmse = np.zeros((3, 3)), np.zeros(3), np.inf
        if ok.sum() >= 3:
            n, q = target.normals[idx[ok]], target.points[idx[ok]]
            r = np.sum(n * (world[ok] - q), axis=1)
            jac = np.column_stack([n, n[:, 0] * -rp[ok, 1] + n[:, 1] * rp[ok, 0]])
            w = np.where(np.abs(r) <= huber_m, 1.0, huber_m / np.abs(r))
            h, g, rmse = jac.T @ (jac * w[:, None]), jac.T @ (w * r), np.sqrt(np.mean(r * r))
        sigma2 = max(rmse**2 if np.isfinite(rmse) else 0.0, 0.01**2)
        h, g = h / sigma2, g / sigma2
        if prior_info is not None:
            e = pose - prior_mean
            e[2] = se2.wrap_angle(e[2])
            h, g = h + prior_info, g + prior_info @ e
        if np.linalg.matrix_rank(h) < 3:
            break
        delta = -np.linalg.solve(h, g)
        pose = pose + delta
        pose[2] = se2.wrap_angle(pose[2])
        if np.hypot(delta[0], delta[1]) < 1e-4 and abs(delta[2]) < 1e-5:
            break
    return pose


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), with_prior=st.booleans())
def test_matcher_reproduces_the_plain_reference(seed, with_prior):
    """Same algorithm as the plain loop (up to round-off): points without a usable
    correspondence add nothing, the closed-form 3x3 solve equals LU."""
    rng = np.random.default_rng(seed)
    segs = room_segments()
    target = PointMap(_dense_points(segs, 0.03) + rng.normal(0, 0.003, (1, 2)))
    truth = np.array([rng.uniform(1.2, 3.8), rng.uniform(1.0, 1.6), rng.uniform(-np.pi, np.pi)])
    r = raycast(truth, LASER.angles(), segs, LASER.range_max_m)
    r = r + rng.normal(0.0, 0.01, r.shape)
    pts = se2.scan_to_points(r, LASER.angles())
    init = truth + rng.normal(0, [0.1, 0.1, 0.05])
    kw = {}
    if with_prior:
        kw = {"prior_mean": init, "prior_info": np.diag([400.0, 400.0, 2500.0])}
    res = match_scan(pts, target, init, **kw)
    ref = _reference_match(pts, target, init, **kw)
    assert np.allclose(res.pose, ref, atol=1e-9)


@numba.njit
def _solve3_compiled(h, g):
    return solve3(h, g), _condition3(h)


def test_gauss_newton_step_closed_form_and_rank_test():
    rng = np.random.default_rng(0)
    for _ in range(200):
        a = rng.normal(size=(3, 3)) * rng.uniform(0.01, 1e4, 3)
        h = a @ a.T
        g = rng.normal(size=3)
        step = g.copy()
        ok, cond = _solve3_compiled(h, step)
        assert ok
        assert np.allclose(step, -np.linalg.solve(h, g), rtol=1e-7, atol=0)
        ev = np.linalg.eigvalsh(h)
        assert cond == pytest.approx(ev[0] / ev[-1], rel=1e-6, abs=1e-12)
    # Rank deficient (all normals alike, no prior): no step, as matrix_rank says.
    j = np.column_stack([np.full(9, 0.6), np.full(9, 0.8), rng.normal(size=9)])
    assert np.linalg.matrix_rank(j.T @ j) < 3
    assert not _solve3_compiled(j.T @ j, np.ones(3))[0]
    assert not _solve3_compiled(np.zeros((3, 3)), np.ones(3))[0]
    assert _solve3_compiled(np.diag([4.0, 2.0, 1.0]), np.ones(3))[1] == 0.25


def test_packed_rows_are_zero_for_unusable_points():
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [3.0, 0.0], [0.0, 5.0], [0.5, 5.4]])
    pm = PointMap(pts, k_normal=3)
    rows, usable = pm.packed(0.6)
    assert rows.shape == (7, 4) and usable.shape == (7,)
    assert not usable[-1] and np.all(rows[-1] == 0.0)
    assert np.array_equal(usable[:-1], pm.planarity >= 0.6)
    assert np.all(rows[~usable] == 0.0)
    assert np.array_equal(rows[:-1][usable[:-1], 2:], pts[usable[:-1]])
    assert pm.packed(0.6)[0] is rows  # cached


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), radius=st.sampled_from([0.05, 0.15, 0.3, 0.5]))
def test_icp_terms_find_the_kd_tree_neighbour_and_sums(seed, radius):
    """The compiled loop's correspondences are a KD-tree's, and its sums the normal
    equations written with numpy."""
    rng = np.random.default_rng(seed)
    target = PointMap(
        np.concatenate([_dense_points(room_segments(), 0.03), rng.uniform(0, 5, (40, 2))])
    )
    pts = rng.uniform(-1.0, 6.0, (60, 2))
    pw = rng.uniform(0.5, 1.0, 60)
    rows = target.packed(0.6)
    packed, usable = rows
    out = np.empty(10)
    c, s, tx, ty = np.cos(0.3), np.sin(0.3), 0.2, -0.1
    scan = ScanArrays(pts[:, 0].copy(), pts[:, 1].copy(), pw)
    params = IcpParams(radius, 0.02, 1e-4, 1.0, 1e-4, 1e-5, 30)
    n = icp_terms(scan, c, s, tx, ty, target.bucket_grid(radius), rows, params, out)
    world = pts @ np.array([[c, s], [-s, c]]) + [tx, ty]
    _, idx = cKDTree(target.points).query(world, k=1, distance_upper_bound=radius)
    ok = usable[idx]
    assert n == ok.sum()
    t = packed[idx[ok]]
    r = np.sum(t[:, :2] * (world[ok] - t[:, 2:]), axis=1)
    rp = world[ok] - [tx, ty]
    jac = np.column_stack([t[:, :2], t[:, 1] * rp[:, 0] - t[:, 0] * rp[:, 1]])
    w = np.minimum(0.02 / np.maximum(np.abs(r), 1e-12), 1.0) * pw[ok]
    h = jac.T @ (jac * w[:, None])
    assert np.allclose(out[[0, 1, 2, 3, 4, 5]], h[np.triu_indices(3)], rtol=1e-9, atol=1e-12)
    assert np.allclose(out[6:9], jac.T @ (w * r), rtol=1e-9, atol=1e-12)
    assert out[9] == pytest.approx(float(r @ r), rel=1e-9, abs=1e-15)


def test_spread_out_target_gets_coarser_cells():
    """Points 140 km apart would need billions of 0.3 m cells: the grid's cells grow, and
    the search stays exact."""
    pts = np.array([[0.0, 0.0], [0.01, 0.0], [0.02, 0.0], [1e5, 1e5], [1e5, 1e5 + 0.01]])
    target = PointMap(pts, k_normal=2)
    grid = target.bucket_grid(0.3)
    assert grid.cell_m > 0.3 and grid.nx * grid.ny <= 4 * len(pts) + 250_000
    res = match_scan(pts[:3] + [0.001, 0.0], target, np.zeros(3), max_iterations=2)
    assert res.n_matched == 3


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), n=st.sampled_from([3, 7, 60, 400]))
def test_grid_knn_finds_the_brute_force_neighbours(seed, n):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-3, 8, (n, 2)) * 10.0 ** rng.integers(-2, 2)
    k = min(6, n)
    idx = knn_indices(pts, k)
    d2 = np.sum((pts[:, None, :] - pts[None, :, :]) ** 2, axis=2)
    ref = np.argsort(d2, axis=1, kind="stable")[:, :k]  # ties: lower index first
    assert np.array_equal(idx, ref)


def test_rank_deficient_problem_stops_like_the_reference():
    """One straight wall, no prior: x is unconstrained, ``matrix_rank`` < 3 at once; the
    compiled loop stops without a step as the reference does."""
    wall = np.column_stack([np.linspace(-3, 3, 301), np.full(301, 1.0)])
    target = PointMap(wall)
    pts = np.column_stack([np.linspace(-1, 1, 41), np.full(41, 0.97)])
    res = match_scan(pts, target, np.zeros(3))
    ref = _reference_match(pts, target, np.zeros(3))
    assert np.allclose(res.pose, ref, atol=1e-12)
    assert not res.converged and res.n_matched == 41


@pytest.mark.parametrize("seed", range(12))
def test_bucket_grid_holds_each_point_in_its_cell(seed):
    """Each cell's slice holds exactly the points whose ``floor(p / cell)`` is that cell, in
    index order: negative coordinates, points on cell borders, duplicates, a single point."""
    rng = np.random.default_rng(seed)
    m = 1 if seed == 0 else int(rng.integers(2, 3000))
    cell = float(rng.choice([0.03, 0.05, 0.3, 1.0]))
    pts = rng.uniform(-7.0, 9.0, (m, 2))
    pts[: m // 5] = np.round(pts[: m // 5] / cell) * cell  # on the borders
    pts[m // 5 : m // 4] = pts[: m // 4 - m // 5]  # duplicates
    g = bucket_grid(pts, cell)
    assert g.cell_m >= cell  # coarser only to bound the number of cells
    cell = g.cell_m
    keys = np.floor(pts / cell).astype(np.int64) - [g.x0, g.y0]
    flat = keys[:, 0] * g.ny + keys[:, 1]
    assert keys.min() == 0 and keys[:, 0].max() == g.nx - 1 and keys[:, 1].max() == g.ny - 1
    for k in np.unique(flat):
        sl = slice(g.start[k], g.start[k + 1])
        assert np.array_equal(g.order[sl], np.flatnonzero(flat == k))
        assert np.array_equal(g.xs[sl], pts[g.order[sl], 0])
        assert np.array_equal(g.ys[sl], pts[g.order[sl], 1])
    assert g.start[-1] == m


@pytest.mark.parametrize("seed", range(16))
def test_normals_are_the_neighbours_least_principal_axis(seed):
    """PointMap's normals and planarity against numpy's eigen-decomposition of each point's
    neighbour covariance: 3 to 6 neighbours, lines, duplicates, scattered points."""
    rng = np.random.default_rng(seed)
    m = int(rng.choice([3, 4, 5, 6, 7, 50, 400]))
    scale = 10.0 ** rng.integers(-2, 2)
    pts = rng.uniform(-7.0, 9.0, (m, 2)) * scale
    pts[: m // 3, 1] = 1.5 * scale  # a line
    pm = PointMap(pts)
    _, idx = cKDTree(pts).query(pts, k=min(6, m))
    for i in range(m):
        q = pts[idx[i]] - pts[idx[i]].mean(axis=0)
        lam, vec = np.linalg.eigh(q.T @ q)
        tol = 1e-9 * max(lam[1], 1e-300)
        assert pm.planarity[i] == pytest.approx(
            1.0 - lam[0] / lam[1] if lam[1] > 1e-12 else 0.0, abs=1e-6
        )
        if lam[1] - lam[0] > 1e-6 * lam[1] and lam[1] > tol:  # a defined normal
            assert abs(abs(pm.normals[i] @ vec[:, 0]) - 1.0) < 1e-6
