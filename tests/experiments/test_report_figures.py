"""The report's figures: legends beside the data, not on it; whole days on day axes; and the
summary's note on the mapping run of day 1."""

from __future__ import annotations

import json

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from dynmap_sim.analysis import report  # noqa: E402
from dynmap_sim.studies.biber_duckett import figures  # noqa: E402
from dynmap_sim.studies.biber_duckett.map_structure import (  # noqa: E402
    MapStructure,
    plot_map_structure,
)

ROOM = np.array([[0, 0, 6, 0], [6, 0, 6, 4], [6, 4, 0, 4], [0, 4, 0, 0]], float)


class FakeDB:
    """What the figures and the note read of a :class:`ResultsDB`: three days of one run."""

    def __init__(self, localizers, meta=None):
        self.locs = localizers  # (label, registry name, params)
        self._meta = meta or {}

    def labels(self):
        return [label for label, _, _ in self.locs]

    def meta(self):
        return self._meta

    def query(self, sql, params=()):
        if "SELECT idx, name FROM localizers" in sql:
            return [(k, name) for k, (_, name, _) in enumerate(self.locs)]
        if "FROM localizers" in sql:
            return [(lb, name, json.dumps(p)) for lb, name, p in self.locs]
        if "FROM run_summaries" in sql:  # (loc, day, run, max error): odometry worst last
            return [(0, d, 1, 1.0 * d) for d in (1, 2, 3)] + [(1, 2, 1, 0.4), (1, 3, 1, 0.1)]
        return [(d, 1) for d in (1, 2, 3)]

    def geometry(self, day, run):
        return ROOM, np.zeros(len(ROOM), dtype=np.int8)

    def driver_artifacts(self, name):
        return []

    def per_scan(self, k, day=None, run=None):
        t = np.linspace(0, 20, 50)
        truth = np.column_stack([1 + 4 * t / 20, 2 + np.sin(t / 3), t * 0])
        est = truth + 0.05 * (k + 1)
        return {"t_s": t, "truth": truth, "estimate": est, "err_m": np.full(len(t), 0.05)}


@pytest.fixture
def kept_figures(monkeypatch):
    """The figures the plotting functions made since the last call, kept open (they close
    them when saved)."""
    close = plt.close
    close("all")
    monkeypatch.setattr(plt, "close", lambda *a, **k: None)
    seen: set[int] = set()

    def new_figures():
        nums = [n for n in plt.get_fignums() if n not in seen]
        seen.update(nums)
        return [plt.figure(n) for n in nums]

    yield new_figures
    close("all")


def assert_whole_days(ax):
    lo, hi = ax.get_xlim()
    ticks = [t for t in ax.get_xticks() if lo <= t <= hi]
    assert ticks and all(float(t).is_integer() for t in ticks), ticks


def assert_legend_beside_the_data(fig):
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    assert len(fig.legends) == 1
    box = fig.legends[0].get_window_extent(renderer)
    for ax in fig.axes:
        assert ax.get_legend() is None
        assert not box.overlaps(ax.get_window_extent(renderer)), (box, ax.get_window_extent())


LOCS = [
    ("odometry", "odometry", {}),
    ("mcl-tuned", "static-mcl", {"config": "tuned"}),
    ("mcl-walls", "static-mcl", {"map_source": "prior-walls"}),
    ("dynamic-map", "dynamic-map", {}),
]


def test_error_per_day_and_trajectories_keep_their_legends_off_the_data(
    tmp_path, monkeypatch, kept_figures
):
    rows = [
        {"day": d, "localizer": lb, "mean_error_m": 0.1 * d, "max_error_m": 0.3 * d}
        for d in (1, 2) for lb, _, _ in LOCS
    ]  # fmt: skip
    monkeypatch.setattr(report, "per_day_rows", lambda db: rows)
    db = FakeDB(LOCS, {"route": [[1, 2], [5, 2]]})
    report._fig_error_per_day(db, tmp_path / "e.png")
    (fig,) = kept_figures()
    assert_legend_beside_the_data(fig)
    assert_whole_days(fig.axes[0])  # two days: no 1.25, 1.5 ...
    report._fig_trajectories(db, tmp_path / "t.png")
    (fig,) = kept_figures()
    assert len(fig.axes) == 3  # first, worst, last run
    assert [ax.get_title() for ax in fig.axes] == [
        "first run: day 1, run 1",
        "worst run: day 2, run 1",
        "last run: day 3, run 1",
    ]  # fmt: skip  (the odometry reference, worst on the last day, does not count)
    assert_legend_beside_the_data(fig)
    assert [t.get_text() for t in fig.legends[0].get_texts()] == [
        "route", "truth", "odometry", "mcl-tuned", "mcl-walls", "dynamic-map"
    ]  # fmt: skip


def test_a_localizer_has_one_colour_in_every_figure(tmp_path, monkeypatch, kept_figures):
    rows = [
        {"day": d, "localizer": lb, "mean_error_m": 0.1, "max_error_m": 0.3}
        for d in (1, 2) for lb, _, _ in LOCS
    ]  # fmt: skip
    monkeypatch.setattr(report, "per_day_rows", lambda db: rows)
    db = FakeDB(LOCS, {"route": [[1, 2], [5, 2]]})
    report._fig_error_per_day(db, tmp_path / "e.png")
    report._fig_trajectories(db, tmp_path / "t.png")
    report._fig_error_over_time(db, tmp_path / "o.png")
    colours: dict[str, set] = {}
    for fig in kept_figures():
        for ax in fig.axes:
            for line in ax.get_lines():
                if line.get_label() in db.labels():
                    colours.setdefault(line.get_label(), set()).add(line.get_color())
            for bar in ax.patches:
                label = bar.get_label().removesuffix(" (mean)")
                if label in db.labels():
                    colours.setdefault(label, set()).add(matplotlib.colors.to_hex(bar.get_fc()))
    for k, label in enumerate(db.labels()):
        want = matplotlib.colors.to_hex(f"C{k}")
        assert {matplotlib.colors.to_hex(c) for c in colours[label]} == {want}, label


def test_every_per_day_figure_has_whole_days(tmp_path, kept_figures):
    days, means = np.array([1, 2]), np.array([0.5, 0.7])
    figures._plot_per_day([("dyn", "C0", days, means)], "y", "t", tmp_path / "a.png")
    figures.plot_timescale_trend("dyn", days, np.full((2, 5), 0.2), tmp_path / "b.png")
    ms = MapStructure(
        days=(1, 2),
        levels=(1, 4),
        n_points=np.full((2, 2), 10),
        on_walls=np.full((2, 2), 0.5),
        on_world=np.full((2, 2), 0.6),
        median_dist_m=np.full((2, 2), 0.01),
        tol_m=0.05,
    )
    plot_map_structure(ms, tmp_path / "c.png")
    axes = [ax for fig in kept_figures() for ax in fig.axes]
    assert len(axes) == 4
    for ax in axes:
        assert_whole_days(ax)


def test_the_day_1_note_names_the_localizers_that_map_their_first_run():
    assert report._mapping_run_labels(FakeDB(LOCS)) == ["`mcl-tuned`", "`dynamic-map`"]
    assert report._mapping_run_labels(FakeDB(LOCS[:1] + LOCS[2:3])) == []
    # a replay that handed the log's map to static-mcl: no mapping run for it
    replay = FakeDB(LOCS[:2], {"map_from_log_poses": True})
    assert report._mapping_run_labels(replay) == []
