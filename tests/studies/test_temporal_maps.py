"""The temporal-map study: each run's predicted map against the run's truth, on a synthetic
results store (a room whose door is open by day and shut in the evening)."""

from __future__ import annotations

import datetime as dt

import numpy as np

from dynmap_sim.studies.study import STUDIES
from dynmap_sim.studies.temporal_maps.agreement import (
    Frame,
    changing_region,
    map_agreement,
    precision_recall,
    rasterize,
)
from dynmap_sim.studies.temporal_maps.study import RISES, TemporalMaps, finding, rises
from dynmap_sim.types import BeamClass

FRAME = Frame((-0.5, -0.5), 0.05, (80, 100))
ROOM = np.array([[0, 0, 4, 0], [4, 0, 4, 3], [4, 3, 0, 3], [0, 3, 0, 0]], float)
#: The door leaf shut across a doorway (the evening) and swung against the wall (by day).
SHUT = np.array([[1.0, 1.5, 2.0, 1.5]])
OPEN = np.array([[1.0, 1.5, 1.0, 2.5]])
CLOCK_H = (9.0, 12.5, 19.5)  # the door is shut at the third run
MONDAY = dt.date(2024, 3, 25)


def _segments(day, run):
    leaf = SHUT if run == 3 else OPEN
    seg = np.concatenate([ROOM, leaf])
    cls = np.array([BeamClass.WALL] * 4 + [BeamClass.DOOR], np.int8)
    return seg, cls


def _map(day, run, learns_from_week):
    """Occupancy as a model that knows the evening door from ``learns_from_week`` on (and
    before that always predicts it open); the corner x > 3.5 never seen."""
    week = (day - 1) // 5 + 1
    seg, _ = _segments(day, run if week >= learns_from_week else 1)
    p = rasterize(seg, FRAME).astype(np.float64)
    p[:, 80:] = np.nan
    return p


class FakeDB:
    """What the study reads of a results store: runs, geometry, the temporal-map artifacts
    of the localizers ``{label: learns_from_week}``."""

    def __init__(self, localizers, days=15):
        self.locs = list(localizers.items())
        self.days = days
        # 15 working days: Monday to Friday, three weeks
        self.dates = {}
        date = MONDAY
        for day in range(1, days + 1):
            while date.weekday() >= 5:
                date += dt.timedelta(days=1)
            self.dates[day] = date
            date += dt.timedelta(days=1)

    def has_table(self, name):
        return name == "artifacts"

    def query(self, sql, params=()):
        if "FROM artifacts" in sql:
            return [(k,) for k in range(len(self.locs))]
        if "FROM localizers" in sql:
            return [(k, label) for k, (label, _) in enumerate(self.locs)]
        if "FROM runs" in sql:
            return [
                (d, r, self.dates[d].isoformat(), CLOCK_H[r - 1] * 3600.0)
                for d in range(1, self.days + 1)
                for r in (1, 2, 3)
            ]
        raise AssertionError(sql)

    def artifacts(self, loc, name):
        assert name == "temporal_map"
        learns = self.locs[loc][1]
        out = []
        for day in range(1, self.days + 1):
            runs = (2, 3) if day == 1 else (1, 2, 3)  # the first run is mapped, not predicted
            p = np.stack([_map(day, r, learns) for r in runs]).astype(np.float16)
            out.append(
                (
                    day,
                    {
                        "p_occupied": p,
                        "run": np.array(runs),
                        "t_s": np.zeros(len(runs)),
                        "origin_m": np.array(FRAME.origin_m),
                        "resolution_m": np.array(FRAME.resolution_m),
                    },
                )
            )
        return out

    def geometry(self, day, run):
        return _segments(day, run)


def test_rasterize_marks_the_cells_a_segment_crosses():
    cells = rasterize(np.array([[0.0, 0.0, 1.0, 0.0]]), FRAME)
    iy, ix = np.nonzero(cells)
    assert set(iy.tolist()) == {10} and ix.min() == 10 and ix.max() == 30
    assert cells.sum() == 21
    assert not rasterize(np.zeros((0, 4)), FRAME).any()


def test_precision_and_recall_with_and_without_tolerance():
    truth = rasterize(ROOM, FRAME)
    seen, everywhere = np.ones(FRAME.shape, bool), np.ones(FRAME.shape, bool)
    assert precision_recall(truth, truth, seen, everywhere, 0) == (1.0, 1.0)
    shifted = np.roll(truth, 1, axis=0)  # one cell off
    p0, r0 = precision_recall(shifted, truth, seen, everywhere, 0)
    assert p0 < 0.6 and r0 < 0.6  # the horizontal walls miss, the vertical ones overlap
    assert precision_recall(shifted, truth, seen, everywhere, 1) == (1.0, 1.0)
    p, r = precision_recall(np.zeros_like(truth), truth, seen, everywhere, 1)
    assert np.isnan(p) and r == 0.0
    # a truth cell never seen is not counted against the map
    assert np.isnan(precision_recall(truth, truth, np.zeros_like(seen), everywhere, 1)[1])


def test_the_changing_region_is_the_leaf_away_from_the_walls():
    shut, opened = rasterize(_segments(1, 3)[0], FRAME), rasterize(_segments(1, 1)[0], FRAME)
    region = changing_region([shut, opened, opened], 1)
    assert region.any()
    assert not (region & rasterize(ROOM, FRAME)).any()
    assert (region & (shut ^ opened)).sum() == region.sum()


def test_a_model_that_learns_the_evening_door_rises_and_a_static_one_does_not():
    db = FakeDB({"learns": 2, "static": 99})
    agreements, doors = map_agreement(db)
    by_label = {a.label: a for a in agreements}
    learns, static = by_label["learns"], by_label["static"]
    assert len(learns.day) == 15 * 3 - 1 and learns.loc == 0 and static.loc == 1
    assert learns.week.tolist()[:3] == [1, 1, 1] and learns.week.max() == 3
    # on all cells both are near perfect; on the changing cells the static one misses the
    # shut door every evening
    assert np.nanmin(learns.precision) > 0.9 and np.nanmin(static.recall) > 0.9
    evening = static.run == 3
    assert np.all(static.changing_recall[evening] < 0.5)
    assert np.all(learns.changing_recall[(learns.week >= 2)] == 1.0)
    assert rises(learns)[0] is True
    assert rises(static)[0] is False
    assert finding(agreements).holds is False  # every temporal map must rise
    assert finding([learns]).holds is True
    # the leaf's two positions: shut across the doorway at the evening runs, against the
    # wall at the others (the hinge cell, in both, is no position's)
    shut, opened = doors
    np.testing.assert_allclose(shut.centre_m, [1.5, 1.5], atol=0.06)
    np.testing.assert_allclose(opened.centre_m, [1.0, 2.0], atol=0.06)
    runs = [(d, r) for d in range(1, 16) for r in (1, 2, 3)][1:]  # day 1's first run maps
    assert shut.truth.tolist() == [1.0 if r == 3 else 0.0 for _, r in runs]
    np.testing.assert_array_equal(opened.truth, 1.0 - shut.truth)
    assert shut.day.tolist() == [d for d, _ in runs]
    late = shut.day > 5
    for door in doors:
        np.testing.assert_allclose(door.predicted["learns"][late], door.truth[late], atol=0.1)
    assert np.nanmax(shut.predicted["static"]) < 0.2 < np.nanmin(opened.predicted["static"])


def test_two_weeks_are_no_trend():
    agreements, _ = map_agreement(FakeDB({"learns": 2}, days=10))
    holds, detail = rises(agreements[0])
    assert holds is None and "fewer than 3 weeks" in detail


def test_the_study_writes_its_files_and_checks_its_finding(tmp_path):
    study = STUDIES.get("temporal-maps")()
    assert isinstance(study, TemporalMaps)
    db = FakeDB({"learns": 2})
    assert study.applies(db)
    rep = study.write(db, tmp_path)
    names = sorted(p.name for p in rep.files + rep.figures)
    assert names == [
        "temporal_map_agreement.csv",
        "temporal_map_agreement.png",
        "temporal_map_doors.png",
    ]
    rows = (tmp_path / "temporal_map_agreement.csv").read_text().splitlines()
    assert len(rows) == 1 + 44 and rows[0].startswith("localizer,day,run,week")
    assert any(RISES in line and "holds" in line for line in rep.summary_lines)
    (check,) = study.check(db, [RISES])
    assert check.holds is True and "week 3" in check.detail


def test_no_temporal_maps_no_study():
    class Empty(FakeDB):
        def query(self, sql, params=()):
            return [] if "FROM artifacts" in sql else super().query(sql, params)

    assert not TemporalMaps().applies(Empty({}))
    assert map_agreement(Empty({})) == ([], [])
