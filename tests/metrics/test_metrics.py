"""Metrics: closed-form values and invariants."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from dynmap_sim import se2
from dynmap_sim.metrics import (
    ErrorStats,
    LostStats,
    RPEResult,
    ate,
    class_scores,
    confusion_matrix,
    error_stats,
    heading_errors,
    lost_episodes,
    lost_stats,
    position_errors,
    rpe,
    summarize,
    summarize_groups,
)
from dynmap_sim.types import BeamClass


def test_position_and_heading_errors_closed_form():
    truth = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, math.pi - 0.1]])
    est = np.array([[3.0, 4.0, 0.2], [1.0, 1.0, -math.pi + 0.1]])
    np.testing.assert_allclose(position_errors(truth, est), [5.0, 0.0])
    np.testing.assert_allclose(heading_errors(truth, est), [0.2, 0.2], atol=1e-12)


def test_no_alignment_is_applied():
    """A constant offset is fully counted (an aligning ATE would report 0)."""
    t = np.linspace(0, 10, 50)
    truth = np.stack([t, np.sin(t), np.zeros_like(t)], axis=1)
    est = truth + np.array([0.3, -0.4, 0.0])
    s = ate(truth, est)
    assert s.rmse == pytest.approx(0.5)
    assert s.mean == pytest.approx(0.5) and s.max == pytest.approx(0.5)
    assert s.std == pytest.approx(0.0, abs=1e-12)


def test_error_stats_closed_form_and_roundtrip():
    s = error_stats([1.0, 2.0, 2.0, 3.0, np.nan])
    assert s.n == 4
    assert s.mean == pytest.approx(2.0)
    assert s.median == pytest.approx(2.0)
    assert s.rmse == pytest.approx(math.sqrt(18 / 4))
    assert (s.min, s.max) == (1.0, 3.0)
    assert ErrorStats.from_dict(s.to_dict()) == s
    empty = error_stats([])
    assert empty.n == 0 and math.isnan(empty.rmse)


def test_rpe_of_a_rigidly_shifted_trajectory_is_zero():
    """RPE is invariant to a global rigid transform of the estimate; ATE is not."""
    rng = np.random.default_rng(1)
    truth = np.cumsum(rng.normal(size=(40, 3)) * [0.1, 0.1, 0.05], axis=0)
    est = se2.compose(np.array([2.0, -1.0, 0.7]), truth)
    r = rpe(truth, est, delta=3)
    assert r.translation.n == 37
    assert r.translation.max == pytest.approx(0.0, abs=1e-9)
    assert r.rotation.max == pytest.approx(0.0, abs=1e-9)
    assert ate(truth, est).rmse > 0.5
    assert RPEResult.from_dict(r.to_dict()) == r


def test_rpe_closed_form_scale_error():
    """Straight line at 1 m/step, estimate at 1.1 m/step: each delta=2 pair errs by 0.2 m."""
    n = 10
    truth = np.stack([np.arange(n, dtype=float), np.zeros(n), np.zeros(n)], axis=1)
    est = truth * [1.1, 1.0, 1.0]
    r = rpe(truth, est, delta=2)
    assert r.translation.n == n - 2
    assert r.translation.rmse == pytest.approx(0.2)
    assert rpe(truth[:2], est[:2], delta=2).translation.n == 0
    with pytest.raises(ValueError):
        rpe(truth, est, delta=0)


def test_lost_stats_closed_form():
    err = np.array([0.1, 0.6, 0.7, 0.2, 0.1, 0.9, 0.8, 0.3, 0.6])
    t = np.arange(9) * 0.5
    s = lost_stats(err, t)
    assert s.n_scans == 9
    assert s.lost_fraction == pytest.approx(5 / 9)
    assert s.n_episodes == 3  # [1,3), [5,7), [8,9)
    assert s.n_recovered == 2  # the last one never recovers
    assert s.mean_time_to_recover_s == pytest.approx(1.0)
    assert s.max_time_to_recover_s == pytest.approx(1.0)
    assert LostStats.from_dict(s.to_dict()) == s
    np.testing.assert_array_equal(lost_episodes(err > 0.5), [[1, 3], [5, 7], [8, 9]])


def test_lost_counts_nan_as_lost():
    s = lost_stats([0.1, np.nan, 0.1], [0.0, 1.0, 2.0])
    assert s.lost_fraction == pytest.approx(1 / 3)
    assert s.n_recovered == 1


@settings(max_examples=60, deadline=None)
@given(arrays(np.float64, st.integers(0, 60), elements=st.floats(0, 2)))
def test_lost_invariants(err):
    t = np.arange(err.size, dtype=float)
    s = lost_stats(err, t)
    eps = lost_episodes(err > 0.5)
    assert s.n_episodes == len(eps)
    assert s.n_episodes - 1 <= s.n_recovered <= s.n_episodes
    if err.size:
        assert s.lost_fraction == pytest.approx(np.mean(err > 0.5))
        assert int((eps[:, 1] - eps[:, 0]).sum()) == int((err > 0.5).sum())


def test_summarize_and_groups():
    e = np.array([0.1, 0.3, 0.6, 0.2])
    s = summarize(e, scan_loglik=[np.nan, -1.0, -3.0, np.nan])
    assert s.mean_error_m == pytest.approx(0.3)
    assert s.max_error_m == pytest.approx(0.6)
    assert s.rmse_m == pytest.approx(math.sqrt((0.01 + 0.09 + 0.36 + 0.04) / 4))
    assert s.lost_fraction == pytest.approx(0.25)
    assert s.mean_scan_loglik == pytest.approx(-2.0)
    assert math.isnan(s.mean_lambda_min)
    g = summarize_groups([1, 1, 2, 2], e)
    assert sorted(g) == [1, 2]
    assert g[1].mean_error_m == pytest.approx(0.2)
    assert g[2].max_error_m == pytest.approx(0.6)


def test_point_class_precision_recall():
    beams = np.array(
        [
            BeamClass.PERSON,
            BeamClass.PERSON,
            BeamClass.WALL,
            BeamClass.WALL,
            BeamClass.FURNITURE,
            BeamClass.NONE,
            BeamClass.EXHIBIT,
        ]
    )
    pred = np.array([1, 3, 3, 3, 2, 3, 0])  # last: unknown, not scored
    c = confusion_matrix(beams, pred)
    assert c.sum() == 7
    s = class_scores(c)
    # dynamic: 1 TP, predicted once -> precision 1; truth 2 -> recall 0.5
    assert s.precision[0] == pytest.approx(1.0) and s.recall[0] == pytest.approx(0.5)
    # static: predicted 3 times (one person), 2 correct -> precision 2/3; recall 1
    assert s.precision[2] == pytest.approx(2 / 3) and s.recall[2] == pytest.approx(1.0)
    # semi-static: the exhibit predicted 'unknown' is not scored, so the support is 1
    assert s.support == (2, 1, 2)
    assert s.recall[1] == pytest.approx(1.0)
