"""Means over seeds with Student-t intervals and paired differences, on closed-form data."""

import math

import numpy as np
import pytest

from dynmap_sim.metrics import (
    CI_LEVEL,
    MeanInterval,
    mean_interval,
    paired_difference,
    t_quantile,
)


def test_t_quantiles_are_the_tables():
    """t(0.975, n-1) from any statistics table; it tends to the normal 1.96."""
    assert t_quantile(2) == pytest.approx(12.7062, abs=1e-4)
    assert t_quantile(4) == pytest.approx(3.1824, abs=1e-4)
    assert t_quantile(5) == pytest.approx(2.7764, abs=1e-4)
    assert t_quantile(10_000) == pytest.approx(1.96, abs=1e-3)
    assert t_quantile(4, level=0.90) == pytest.approx(2.3534, abs=1e-4)
    assert math.isnan(t_quantile(1)) and math.isnan(t_quantile(0))


def test_mean_interval_of_one_to_five():
    """1..5: mean 3, sd sqrt(2.5), half width t(0.975, 4) * sqrt(2.5) / sqrt(5)."""
    m = mean_interval([1.0, 2.0, 3.0, 4.0, 5.0])
    half = 2.7764451 * math.sqrt(2.5) / math.sqrt(5.0)
    assert (m.n, m.mean, m.level) == (5, 3.0, CI_LEVEL)
    assert m.sd == pytest.approx(math.sqrt(2.5))
    assert m.half_width == pytest.approx(half, rel=1e-6)
    assert (m.low, m.high) == (pytest.approx(3.0 - half), pytest.approx(3.0 + half))
    assert m.contains(3.0) and not m.contains(5.0)


def test_equal_values_have_a_zero_width_interval():
    m = mean_interval([0.25] * 4)
    assert (m.mean, m.sd, m.low, m.high) == (0.25, 0.0, 0.25, 0.25)


def test_nan_values_are_skipped_and_few_values_have_no_interval():
    assert mean_interval([1.0, math.nan, 3.0]) == mean_interval([1.0, 3.0])
    one = mean_interval([2.0, math.nan])
    assert one.n == 1 and one.mean == 2.0
    assert math.isnan(one.low) and math.isnan(one.high) and not one.contains(2.0)
    none = mean_interval([])
    assert none.n == 0 and math.isnan(none.mean)


def test_paired_difference_cancels_what_both_share():
    """b = a + 0.1 exactly, seeds spread widely: the paired difference is exactly -0.1 with a
    zero-width interval, while each side's own interval is wide."""
    a = np.array([0.1, 0.5, 0.2, 0.9])
    d = paired_difference(a, a + 0.1)
    assert d.n == 4
    assert d.mean == pytest.approx(-0.1)
    assert d.half_width == pytest.approx(0.0, abs=1e-12)
    assert mean_interval(a).half_width > 0.5


def test_paired_difference_of_known_differences():
    """Differences 1, 2, 3: mean 2, sd 1, half width t(0.975, 2) / sqrt(3)."""
    d = paired_difference([2.0, 4.0, 6.0], [1.0, 2.0, 3.0])
    assert d.mean == pytest.approx(2.0) and d.sd == pytest.approx(1.0)
    assert d.half_width == pytest.approx(4.3026527 / math.sqrt(3.0), rel=1e-6)


def test_paired_difference_drops_incomplete_pairs_and_needs_equal_lengths():
    d = paired_difference([1.0, math.nan, 3.0], [0.0, 1.0, 1.0])
    assert d.n == 2 and d.mean == pytest.approx(1.5)
    with pytest.raises(ValueError, match="same length"):
        paired_difference([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="level"):
        mean_interval([1.0, 2.0], level=1.0)


def test_the_t_interval_holds_the_mean_95_percent_of_the_time_with_four_seeds():
    """Why Student t: with 4 samples it covers the true mean ~95 % of the time; the normal
    quantile 1.96 would cover only ~86 %."""
    rng = np.random.default_rng(12)
    x = rng.normal(0.3, 0.05, size=(20_000, 4))
    mean, sd = x.mean(axis=1), x.std(axis=1, ddof=1)
    t_cover = np.mean(np.abs(mean - 0.3) <= t_quantile(4) * sd / 2.0)
    z_cover = np.mean(np.abs(mean - 0.3) <= 1.96 * sd / 2.0)
    assert t_cover == pytest.approx(0.95, abs=0.01)
    assert z_cover == pytest.approx(0.86, abs=0.015)
    m = mean_interval(x[0])
    assert m.half_width == pytest.approx(t_quantile(4) * sd[0] / 2.0)


def test_an_interval_saves_to_json_and_loads_back_equal():
    for m in (mean_interval([0.1, 0.2, 0.4]), mean_interval([1.0]), mean_interval([])):
        assert MeanInterval.from_json(m.to_json()) == m
