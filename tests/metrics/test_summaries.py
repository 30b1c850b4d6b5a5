"""Summaries per run, day and experiment, and the RPE's delta units, on closed-form cases."""

import json
import math

import numpy as np
import pytest

from dynmap_sim.metrics import (
    LOST_THRESHOLD_M,
    RUN_RPE_DELTA,
    RUN_RPE_UNIT,
    DaySummary,
    ErrorStats,
    LostStats,
    OverallSummary,
    RPEResult,
    RunSummary,
    class_scores,
    day_summary,
    lost_fraction,
    mean_per_scan,
    n_onsets,
    overall_summary,
    rpe,
    rpe_pairs,
    run_summary,
)
from dynmap_sim.metrics.point_classes import ClassScores


def line(n, hz, v=0.5):
    """A straight drive along x at ``v`` m/s sampled at ``hz``: stamps and poses."""
    t = 1000.0 + np.arange(n) / hz
    return t, np.stack([v * (t - t[0]), np.zeros(n), np.zeros(n)], axis=1)


def test_rpe_in_seconds_and_metres_with_a_known_scale_drift():
    """The estimate runs 10 % long: over 1 s at 0.5 m/s it errs by 0.05 m, over 2 m by 0.2 m."""
    t, truth = line(101, hz=10.0)
    est = truth * [1.1, 1.0, 1.0]
    per_s = rpe(truth, est, delta=1.0, unit="s", stamps_s=t)
    assert per_s.translation.n == 91  # every pose with one at least 1 s later
    assert per_s.translation.rmse == pytest.approx(0.05)
    assert per_s.translation.max == pytest.approx(0.05)
    assert per_s.rotation.max == pytest.approx(0.0, abs=1e-12)
    per_m = rpe(truth, est, delta=2.0, unit="m")
    assert per_m.translation.n == 61  # 2 m = 4 s = 40 poses on
    assert per_m.translation.rmse == pytest.approx(0.2)
    assert (per_s.label, per_m.label) == ("RPE 1 s", "RPE 2 m")


def test_rpe_in_seconds_with_a_known_heading_drift():
    """Turning on the spot at 0.2 rad/s, the estimate turns 5 % faster: 0.01 rad per second."""
    t = np.arange(60) / 5.0  # the LMS200's 5 Hz
    truth = np.stack([np.zeros(60), np.zeros(60), 0.2 * t], axis=1)
    est = truth * [1.0, 1.0, 1.05]
    r = rpe(truth, est, delta=1.0, unit="s", stamps_s=t)
    assert r.translation.max == pytest.approx(0.0, abs=1e-12)
    assert r.rotation.rmse == pytest.approx(0.01)
    assert r.rotation.n == 55


def test_frames_and_seconds_agree_at_the_sampling_rate():
    """10 frames are 1 s at 10 Hz (stamps that sum to 0.9999999 s still count) and 2 s at 5 Hz."""
    rng = np.random.default_rng(3)
    for hz, seconds in ((10.0, 1.0), (5.0, 2.0)):
        t, truth = line(80, hz)
        est = truth + rng.normal(scale=0.02, size=truth.shape)
        frames = rpe(truth, est, delta=10)
        timed = rpe(truth, est, delta=seconds, unit="s", stamps_s=t)
        assert frames.unit == "frames" and frames.label == "RPE 10 frames"
        assert timed.translation == frames.translation and timed.rotation == frames.rotation
    i, j = rpe_pairs(5, 2)
    assert i.tolist() == [0, 1, 2] and j.tolist() == [2, 3, 4]


def test_rpe_delta_checks():
    t, truth = line(10, 10.0)
    with pytest.raises(ValueError, match="whole number"):
        rpe(truth, truth, delta=1.5)
    with pytest.raises(ValueError, match="stamps_s"):
        rpe(truth, truth, delta=1.0, unit="s")
    with pytest.raises(ValueError, match="unit"):
        rpe(truth, truth, delta=1.0, unit="min")
    with pytest.raises(ValueError, match="decrease"):
        rpe(truth, truth, delta=0.1, unit="s", stamps_s=t[::-1])
    assert rpe(truth, truth, delta=5.0, unit="s", stamps_s=t).translation.n == 0


def test_results_save_to_json_and_load_back_equal():
    t, truth = line(50, 10.0)
    est = truth + [0.1, 0.0, 0.0]
    results = [
        run_summary(truth, est, t, update_s=0.01),  # NaN likelihoods
        overall_summary(truth, est, t, np.ones(50)),
        rpe(truth, est, delta=1.0, unit="s", stamps_s=t),
        day_summary([0.1, np.nan], [0.0, 0.0]),
        class_scores(np.eye(4, dtype=int)),
        LostStats(3, 0.5, 1, 0, math.nan, math.nan),
        OverallSummary.from_dict(
            overall_summary(truth, est * [1, 1, 0], t, np.ones(50)).to_dict()
            | {"worst_time_to_recover_s": math.inf, "worst_recovery_run": (2, 1)}
        ),
    ]
    for r in results:
        text = r.to_json()
        json.loads(text)  # plain JSON: no NaN or Infinity tokens
        assert "NaN" not in text and "Infinity" not in text
        back = type(r).from_json(text)
        assert back == r and type(back) is type(r)
        assert type(r).from_dict(r.to_dict()) == r
    assert isinstance(results[3], DaySummary) and isinstance(results[4], ClassScores)
    assert ErrorStats.from_json(results[2].translation.to_json()) == results[2].translation
    assert RPEResult.from_dict({**results[2].to_dict(), "unit": "frames", "delta": 10}).delta == 10


def test_run_summary_closed_form():
    """Two episodes (one recovers after 0.2 s), a constant scan log-likelihood, 10 ms total."""
    n = 20
    t, truth = line(n, 10.0)
    off = np.zeros(n)
    off[[3, 4]] = 1.0  # lost at scans 3-4, found at 5
    off[-2:] = 2.0  # lost at the end
    est = truth + np.column_stack([off, np.zeros(n), np.zeros(n)])
    s = run_summary(truth, est, t, scan_loglik=np.full(n, -2.0), update_s=0.01)
    assert isinstance(s, RunSummary)
    assert s.n_scans == n and s.lost_fraction == pytest.approx(4 / n)
    assert s.max_error_m == pytest.approx(2.0) and s.mean_error_m == pytest.approx(6.0 / n)
    assert (s.n_lost_episodes, s.n_recovered) == (2, 1)
    assert s.mean_time_to_recover_s == pytest.approx(0.2)
    assert s.mean_scan_loglik == -2.0 and math.isnan(s.mean_lambda_min)
    assert s.update_ms_per_scan == pytest.approx(0.5)
    ref = rpe(truth, est, delta=RUN_RPE_DELTA, unit=RUN_RPE_UNIT).translation.rmse
    assert s.rpe_m == ref
    assert math.isnan(run_summary(truth[:0], est[:0], t[:0]).mean_error_m)


def test_overall_summary_evaluates_run_by_run():
    """Two runs: RPE pairs and lost episodes never span them; a scan without an estimate
    makes the worst error infinite and its run never recovers."""
    t1, tr1 = line(30, 10.0)
    t2, tr2 = line(30, 10.0)
    e1 = tr1 * [1.1, 1.0, 1.0]  # RPE 0.05 m over 10 frames
    e2 = tr2.copy()
    e2[5:8, 0] += 1.0  # lost for 0.3 s
    runs = np.array([[1, 1]] * 30 + [[1, 2]] * 30)
    s = overall_summary(np.vstack([tr1, tr2]), np.vstack([e1, e2]), np.r_[t1, t2], runs)
    assert s.n_scans == 60
    # 20 pairs per run; in run 2 the pairs that start in the lost stretch err by 1 m
    assert s.rpe_rmse_m == pytest.approx(math.sqrt((20 * 0.05**2 + 3 * 1.0**2) / 40))
    assert (s.lost_episodes, s.recovered) == (1, 1)
    assert s.mean_time_to_recover_s == pytest.approx(0.3)
    assert s.worst_time_to_recover_s == pytest.approx(0.3) and s.worst_recovery_run == (1, 2)
    assert s.lost_fraction == pytest.approx(3 / 60) and s.worst_error_m == s.max_error_m
    assert s.rpe_label == "RPE 10 frames"
    e2[-1] = np.nan  # no estimate at the last scan: lost to the end
    s = overall_summary(np.vstack([tr1, tr2]), np.vstack([e1, e2]), np.r_[t1, t2], runs)
    assert s.worst_error_m == math.inf and s.worst_time_to_recover_s == math.inf
    assert (s.lost_episodes, s.recovered) == (2, 1)
    empty = overall_summary(np.zeros((0, 3)), np.zeros((0, 3)), [], np.zeros((0, 2)))
    assert empty.n_scans == 0 and math.isnan(empty.lost_fraction) and empty.worst_recovery_run == ()


def test_small_helpers():
    assert lost_fraction([0.1, LOST_THRESHOLD_M, 0.6, np.nan]) == 0.5
    assert math.isnan(lost_fraction([]))
    assert n_onsets([True, True, False, True, False]) == 2 and n_onsets([]) == 0
    assert mean_per_scan([1.0, 3.0, np.nan], [1, 3, 5]) == 2.5
    assert math.isnan(mean_per_scan([np.nan], [2]))
