"""Point-to-line ICP: a transformed scan matches back; the prior rules in degenerate geometry."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dynmap_sim import se2
from dynmap_sim.agent.mapping.scan_matcher import PointMap, match_scan


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
