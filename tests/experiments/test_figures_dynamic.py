"""Aggregations and plots of the dynamic-map figures (B&D Figs. 10-13)."""

from __future__ import annotations

import numpy as np

from dynmap_sim.studies.biber_duckett.figures import (
    daily_means,
    plot_timescale_trend,
    plot_timescale_usage,
    selection_counts_per_day,
)


def test_daily_means_skip_nan():
    day = np.array([1, 1, 2, 2, 3])
    v = np.array([1.0, 3.0, np.nan, 4.0, np.nan])
    days, m = daily_means(day, v)
    assert days.tolist() == [1, 2] and m.tolist() == [2.0, 4.0]


def test_timescale_usage_counts_only_valid_choices():
    ts = np.array([0, 0, 4, -1, np.nan, 2, 4, 4])
    day = np.array([1, 1, 1, 1, 2, 2, 2, 2])
    days, counts, every = selection_counts_per_day(day, ts)
    assert not every and days.tolist() == [1, 2]
    u = counts.sum(axis=0) / counts.sum()
    assert u.tolist() == [2 / 6, 0, 1 / 6, 0, 3 / 6]
    per_day = counts / counts.sum(axis=1, keepdims=True)
    assert np.allclose(per_day.sum(axis=1), 1.0)
    assert per_day[1].tolist() == [0, 0, 1 / 3, 0, 2 / 3]
    # counts of every selection, when the results have them, take precedence
    sel = (np.array([1, 2]), np.array([[3, 1, 1, 1, 1], [0, 2, 2, 2, 2]]))
    days, counts, every = selection_counts_per_day(day, ts, sel)
    assert every and counts.tolist() == sel[1].tolist()
    assert selection_counts_per_day(day, ts, (np.zeros(0), np.zeros((0, 5))))[2] is False


def test_plots_write_files(tmp_path):
    p1 = plot_timescale_usage("dm", np.array([0.4, 0.2, 0.1, 0.1, 0.2]), tmp_path / "a.png")
    p2 = plot_timescale_trend("dm", np.arange(1, 4), np.full((3, 5), 0.2), tmp_path / "b.png")
    assert p1.stat().st_size > 1000 and p2.stat().st_size > 1000


def test_local_map_snapshot_figure(tmp_path):
    from dynmap_sim.agent.maps.dynamic_map import DynamicMap
    from dynmap_sim.studies.biber_duckett.figures import plot_local_map_timescales

    rng = np.random.default_rng(0)
    dmap = DynamicMap()
    a = np.linspace(0, 2 * np.pi, 500)
    ring = np.stack([2 * np.cos(a), 2 * np.sin(a)], axis=1)
    dmap.add_local_map([0.0, 0.0], ring, rng)
    dmap.learn_offline([1, 2, 3, 4], np.zeros((3, 3)), [ring, ring, ring], rng)
    p = plot_local_map_timescales(dmap, (0.1, 0.0), tmp_path / "fig9.png", title="t")
    assert p.stat().st_size > 1000
