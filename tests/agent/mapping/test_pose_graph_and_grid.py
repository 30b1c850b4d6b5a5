"""Pose graph (closed-form loop) and occupancy grid / likelihood field (closed-form distances)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import least_squares
from synthetic_scans import LASER, raycast, room_segments

from dynmap_sim import se2
from dynmap_sim.agent.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from dynmap_sim.agent.mapping.pose_graph import (
    Edge,
    dcs_scale,
    edge_errors,
    edge_jacobians,
    optimize_pose_graph,
    optimize_pose_graph_dcs,
)


def test_loop_closure_spreads_the_error_and_keeps_the_anchor():
    truth = np.array([[0, 0, 0], [1, 0, np.pi / 2], [1, 1, np.pi], [0, 1, -np.pi / 2]], float)
    info = np.diag([1e4, 1e4, 1e4])
    # Odometry edges with a heading bias, and an exact loop-closure edge 3 -> 0.
    edges = []
    drifted = [truth[0]]
    for k in range(3):
        z = se2.between(truth[k], truth[k + 1]) + np.array([0.0, 0.0, 0.05])
        edges.append(Edge(k, k + 1, z, info))
        drifted.append(se2.compose(drifted[-1], z))
    edges.append(Edge(3, 0, se2.between(truth[3], truth[0]), info))
    drifted = np.array(drifted)
    opt = optimize_pose_graph(drifted, edges, anchor=0)
    assert np.allclose(opt[0], truth[0])
    before = np.abs(edge_errors(drifted, edges)).sum()
    after = np.abs(edge_errors(opt, edges)).sum()
    assert after < 0.5 * before
    err = np.hypot(*(opt[:, :2] - truth[:, :2]).T)
    assert err.max() < np.hypot(*(drifted[:, :2] - truth[:, :2]).T).max()


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_edge_jacobians_match_finite_differences(seed):
    rng = np.random.default_rng(seed)
    poses = np.column_stack([rng.uniform(-5, 5, (6, 2)), rng.uniform(-np.pi, np.pi, 6)])
    ii, jj = np.array([0, 1, 2, 5, 3]), np.array([1, 2, 4, 0, 1])
    edges = [Edge(i, j, rng.normal(0, 0.5, 3), np.eye(3)) for i, j in zip(ii, jj, strict=True)]
    a, b = edge_jacobians(poses, ii, jj)
    h = 1e-6
    for node, jac, ends in ((ii, a, ii), (jj, b, jj)):
        for c in range(3):
            step = np.zeros_like(poses)
            num = np.zeros((len(edges), 3))
            for m in range(len(edges)):
                step[:] = 0.0
                step[ends[m], c] = h
                up = edge_errors(poses + step, edges)[m]
                down = edge_errors(poses - step, edges)[m]
                d = up - down
                d[2] = se2.wrap_angle(d[2])
                num[m] = d / (2 * h)
            assert np.allclose(jac[:, :, c], num, atol=1e-6), (node, c)


def test_closed_form_jacobian_gives_the_finite_difference_optimum():
    rng = np.random.default_rng(5)
    truth = np.array([[np.cos(t) * 3, np.sin(t) * 3, t + np.pi / 2] for t in np.linspace(0, 5, 12)])
    edges = []
    for k in range(11):
        z = se2.between(truth[k], truth[k + 1]) + rng.normal(0, [0.02, 0.02, 0.01])
        edges.append(Edge(k, k + 1, z, np.diag([1e3, 1e3, 4e3])))
    for i, j in ((0, 6), (3, 11), (2, 9)):
        edges.append(Edge(i, j, se2.between(truth[i], truth[j]), np.diag([1e4, 1e4, 1e4])))
    start = truth + rng.normal(0, [0.1, 0.1, 0.05], truth.shape)
    start[0] = truth[0]
    opt = optimize_pose_graph(start, edges, anchor=0, loss="linear")

    def whitened(v):
        x = start.copy()
        x[1:] = v.reshape(-1, 3)
        err = edge_errors(x, edges)
        return np.concatenate(
            [np.linalg.cholesky(e.info).T @ r for e, r in zip(edges, err, strict=True)]
        )

    ref = least_squares(whitened, start[1:].ravel(), method="trf", x_scale="jac").x
    diff = opt[1:] - ref.reshape(-1, 3)
    diff[:, 2] = se2.wrap_angle(diff[:, 2])
    assert np.abs(diff).max() < 1e-6
    assert np.array_equal(opt[0], start[0])


def test_pose_graph_rejects_bad_edges():
    with pytest.raises(ValueError):
        optimize_pose_graph(np.zeros((2, 3)), [Edge(0, 5, np.zeros(3), np.eye(3))])


def test_grid_from_one_wall_distance_field_closed_form():
    g = OccupancyGrid.from_segments(np.array([[0.0, 0.0, 4.0, 0.0]]), resolution_m=0.05)
    assert g.distance_at(2.0, 0.0) == 0.0
    assert g.distance_at(2.0, 0.8) == pytest.approx(0.8, abs=0.06)
    assert g.distance_at(2.0, -0.5) == pytest.approx(0.5, abs=0.06)
    assert g.distance_at(100.0, 100.0) == g.max_dist_m == 2.0
    assert (g.occupancy == OCCUPIED).sum() == pytest.approx(80, abs=2)


def test_grid_free_seed_marks_inside_free_and_outside_unknown():
    sq = np.array([[0, 0, 2, 0], [2, 0, 2, 2], [2, 2, 0, 2], [0, 2, 0, 0]], float)
    g = OccupancyGrid.from_segments(sq, free_seed_xy_m=(1.0, 1.0))
    ix, iy = g.cell_of(np.array([[1.0, 1.0], [-0.5, -0.5]]))
    assert g.occupancy[iy[0], ix[0]] == FREE
    assert g.occupancy[iy[1], ix[1]] == UNKNOWN
    free = g.free_points()
    assert free[:, 0].min() > 0 and free[:, 0].max() < 2


def _reference_from_scans(poses, ranges, laser, res=0.05, margin=1.0, reach=4.0, hit_max=None):
    """Thrun et al. §9.2 beam tracing written plainly, one scan and one beam at a time: the
    vectorized :meth:`OccupancyGrid.from_scans` must give exactly this grid."""
    hit_max = laser.range_max_m if hit_max is None else hit_max
    angles = laser.angles()
    lp = se2.compose(poses, np.broadcast_to(np.asarray(laser.mount_pose, float), poses.shape))
    pts = [lp[:, :2]]
    for k in range(len(poses)):
        r = ranges[k]
        ok = np.isfinite(r) & (r >= laser.range_min_m) & (r < min(laser.range_max_m, hit_max))
        th = lp[k, 2] + angles[ok]
        pts.append(lp[k, :2] + r[ok, None] * np.column_stack([np.cos(th), np.sin(th)]))
    allpts = np.concatenate(pts)
    bounds = (*(allpts.min(axis=0) - reach), *(allpts.max(axis=0) + reach))
    origin, h, w = OccupancyGrid._empty(bounds, res, margin)
    hits, passes = np.zeros((h, w)), np.zeros((h, w))
    for k in range(len(poses)):
        for b, r in enumerate(ranges[k]):
            th = lp[k, 2] + angles[b]
            c, s = np.cos(th), np.sin(th)
            valid = np.isfinite(r) and laser.range_min_m <= r < laser.range_max_m
            if valid and r < hit_max:
                clear = r - res
                ix = int(np.floor((lp[k, 0] + c * r - origin[0]) / res))
                iy = int(np.floor((lp[k, 1] + s * r - origin[1]) / res))
                hits[iy, ix] += 1
            else:
                clear = hit_max if valid else (reach if r == np.inf else 0.0)
            t = np.arange(int(np.ceil(max(clear, 0.0) / (0.5 * res)))) * (0.5 * res)
            t = t[t < clear]
            ix = np.floor((lp[k, 0] + c * t - origin[0]) / res).astype(int)
            iy = np.floor((lp[k, 1] + s * t - origin[1]) / res).astype(int)
            for cell in set(zip(iy.tolist(), ix.tolist(), strict=True)):
                passes[cell] += 1
    logodds = 0.9 * hits - 0.4 * passes
    grid = np.full((h, w), UNKNOWN)
    seen = hits + passes > 0
    grid[seen & (logodds < 0)] = FREE
    grid[seen & (logodds >= 0) & (hits > 0)] = OCCUPIED
    grid[seen & (logodds >= 0) & (hits == 0)] = FREE
    return grid, origin


@pytest.mark.parametrize("hit_max", [None, 3.0])
def test_from_scans_equals_the_plain_beam_tracer(hit_max):
    rng = np.random.default_rng(4)
    segs = room_segments()
    poses = np.column_stack(
        [rng.uniform(1.0, 4.0, 5), rng.uniform(0.8, 3.5, 5), rng.uniform(-np.pi, np.pi, 5)]
    )
    ranges = np.array([raycast(p, LASER.angles(), segs, LASER.range_max_m) for p in poses])
    ranges += rng.normal(0, 0.01, ranges.shape)
    ranges[0, :40] = np.inf  # no return: clears 4 m
    ranges[1, 50:60] = np.nan
    ranges[2, 70:75] = 0.01  # below the minimum range
    g = OccupancyGrid.from_scans(poses, ranges, LASER, max_hit_range_m=hit_max)
    ref, origin = _reference_from_scans(poses, ranges, LASER, hit_max=hit_max)
    assert np.array_equal(g.origin_xy_m, origin)
    assert np.array_equal(g.occupancy, ref)
    assert (g.occupancy == OCCUPIED).sum() > 100


def test_dcs_scale_closed_form():
    chi2 = np.array([0.0, 1.0, 3.0, 99.0])
    assert np.allclose(dcs_scale(chi2, 1.0), [1.0, 1.0, 0.5, 0.02])


def _ring(n=24, radius=3.0):
    t = 2 * np.pi * np.arange(n) / n
    return np.column_stack([radius * np.cos(t), radius * np.sin(t), t + np.pi / 2])


@pytest.mark.parametrize("n_false", [0, 1, 3])
def test_dcs_keeps_true_closures_and_ignores_false_ones(n_false):
    """A ring of odometry edges with a heading bias, true closures between neighbours of the
    ring's ends, and ``n_false`` false closures (poses off by metres): DCS ends within a few
    cm of the truth; plain least squares is bent by the false ones."""
    truth = _ring()
    n = len(truth)
    odo_info = np.diag([1e4, 1e4, 1e4])
    loop_info = np.diag([1e4, 1e4, 1e4])
    edges, drifted = [], [truth[0]]
    for k in range(n - 1):
        z = se2.between(truth[k], truth[k + 1]) + [0.0, 0.0, 0.01]
        edges.append(Edge(k, k + 1, z, odo_info))
        drifted.append(se2.compose(drifted[-1], z))
    n_seq = len(edges)
    for i, j in [(0, n - 1), (1, n - 1), (0, n - 2)]:
        edges.append(Edge(i, j, se2.between(truth[i], truth[j]), loop_info))
    rng = np.random.default_rng(1)
    for i, j in [(2, 14), (5, 20), (8, 17)][:n_false]:
        edges.append(Edge(i, j, se2.between(truth[i], truth[j]) + [2.0, -1.5, 0.8], loop_info))
    robust = np.arange(len(edges)) >= n_seq
    init = np.array(drifted) + rng.normal(0, 0.01, (n, 3)) * [1, 1, 0]
    init[0] = truth[0]
    opt = optimize_pose_graph_dcs(init, edges, robust, phi=1.0)
    err = np.hypot(*(opt[:, :2] - truth[:, :2]).T)
    assert np.allclose(opt[0], truth[0]) and err.max() < 0.05
    if n_false:
        plain = optimize_pose_graph(init, edges, anchor=0, loss="linear")
        assert np.hypot(*(plain[:, :2] - truth[:, :2]).T).max() > 0.3


def test_grid_from_scans_holds_far_readings_cleared_beyond_no_return_reach():
    """A hit range above ``no_return_free_m``: readings beyond it clear free space up to the
    hit range, and the grid is large enough to hold it (no out-of-bounds cells)."""
    from dynmap_sim.types import LaserSpec

    laser = LaserSpec("far", 11, -0.5, 0.1, 0.1, 80.0, 0.1, 0.0)
    ranges = np.full((1, 11), 30.0)  # far readings only: beyond the 10 m hit range
    grid = OccupancyGrid.from_scans(
        np.zeros((1, 3)), ranges, laser, resolution_m=0.1, max_hit_range_m=10.0
    )
    ix, iy = grid.cell_of(np.array([[5.0, 0.0], [9.5, 0.0], [10.5, 0.0]]))
    assert list(grid.occupancy[iy, ix]) == [FREE, FREE, UNKNOWN]
