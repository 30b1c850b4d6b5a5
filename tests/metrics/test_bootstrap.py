"""Percentile bootstrap intervals over worlds (properties and closed forms)."""

import math

import numpy as np
import pytest

from dynmap_sim.metrics.intervals import bootstrap_interval


def test_constant_samples_give_a_point_interval() -> None:
    b = bootstrap_interval([0.2] * 7, "median")
    assert (b.value, b.low, b.high, b.n) == (0.2, 0.2, 0.2, 7)


@pytest.mark.parametrize("stat", ["median", "mean", "p90", "share"])
def test_the_interval_holds_the_statistic_and_is_reproducible(stat: str) -> None:
    x = np.random.default_rng(3).exponential(0.1, 40)
    if stat == "share":
        x = (x < 0.1).astype(float)
    a, b = bootstrap_interval(x, stat), bootstrap_interval(x, stat)
    assert a.low <= a.value <= a.high
    assert (a.low, a.high) == (b.low, b.high)  # the same seed, the same resamples
    assert a.n_boot > 0


def test_the_mean_interval_is_close_to_the_normal_one_for_many_samples() -> None:
    x = np.random.default_rng(0).normal(1.0, 2.0, 400)
    b = bootstrap_interval(x, "mean")
    half = 1.96 * x.std(ddof=1) / math.sqrt(len(x))
    assert b.high - b.low == pytest.approx(2 * half, rel=0.15)


def test_few_samples_and_bad_arguments() -> None:
    assert math.isnan(bootstrap_interval([], "mean").value)
    one = bootstrap_interval([np.nan, 0.3], "mean")
    assert one.n == 1 and one.value == 0.3 and math.isnan(one.low)
    with pytest.raises(ValueError, match="statistic must be one of"):
        bootstrap_interval([1.0, 2.0], "mode")
    with pytest.raises(ValueError, match="level"):
        bootstrap_interval([1.0, 2.0], level=1.5)
