"""Aggregations and plots of the dynamic-map figures (B&D Figs. 10-13)."""

from __future__ import annotations

import numpy as np

from dynmap_sim.experiments.figures_dynamic import (
    daily_means,
    plot_timescale_trend,
    plot_timescale_usage,
    timescale_usage,
    timescale_usage_per_day,
)


def test_daily_means_skip_nan():
    day = np.array([1, 1, 2, 2, 3])
    v = np.array([1.0, 3.0, np.nan, 4.0, np.nan])
    days, m = daily_means(day, v)
    assert days.tolist() == [1, 2] and m.tolist() == [2.0, 4.0]


def test_timescale_usage_counts_only_valid_choices():
    ts = np.array([0, 0, 4, -1, np.nan, 2, 4, 4])
    u = timescale_usage(ts)
    assert u.tolist() == [2 / 6, 0, 1 / 6, 0, 3 / 6]
    days, per_day = timescale_usage_per_day(np.array([1, 1, 1, 1, 2, 2, 2, 2]), ts)
    assert days.tolist() == [1, 2]
    assert np.allclose(per_day.sum(axis=1), 1.0)
    assert per_day[1].tolist() == [0, 0, 1 / 3, 0, 2 / 3]


def test_plots_write_files(tmp_path):
    p1 = plot_timescale_usage("dm", np.array([0.4, 0.2, 0.1, 0.1, 0.2]), tmp_path / "a.png")
    p2 = plot_timescale_trend("dm", np.arange(1, 4), np.full((3, 5), 0.2), tmp_path / "b.png")
    assert p1.stat().st_size > 1000 and p2.stat().st_size > 1000
