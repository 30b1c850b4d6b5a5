"""The calendar: working days, runs, and how dates map to days."""

import datetime as dt

import pytest

from dynmap_sim.world import Calendar, load_world
from dynmap_sim.world.spec import CalendarSpec


def test_lab_calendar_matches_biber_duckett():
    cal = Calendar(load_world("lab").calendar)
    assert cal.dates[0] == dt.date(2007, 10, 18)
    assert cal.dates[-1] == dt.date(2007, 11, 19)  # the last map of Fig. 7
    assert dt.date(2007, 11, 1) in cal.dates  # the middle map of Fig. 7
    assert cal.n_days == 23 and cal.runs_per_day == 3
    assert [s.start_s for s in cal.slots[:3]] == [9.5 * 3600, 13.25 * 3600, 17.5 * 3600]
    assert (cal.dates[-1] - cal.dates[0]).days < 35  # five weeks


def test_weekends_and_holidays_are_skipped_and_dates_map_forward():
    spec = CalendarSpec(
        start=dt.date(2024, 1, 5),  # a Friday
        n_days=4,
        holidays=(dt.date(2024, 1, 9),),
        runs=("10:00",),
    )
    cal = Calendar(spec)
    assert cal.dates == (
        dt.date(2024, 1, 5),
        dt.date(2024, 1, 8),
        dt.date(2024, 1, 10),
        dt.date(2024, 1, 11),
    )
    assert cal.day_of(dt.date(2024, 1, 6)) == 2  # Saturday -> Monday
    assert cal.day_of(dt.date(2024, 1, 9)) == 3  # holiday -> next working day
    assert cal.day_of(dt.date(2024, 1, 12)) is None  # after the last working day
    assert cal.day_of(dt.date(2024, 1, 4)) is None  # before the start
    assert cal.day_of(4) == 4 and cal.day_of(5) is None


def test_slot_index_checks_its_range():
    cal = Calendar(load_world("apartment").calendar)
    assert cal.slot_index(28, 1) == 27
    with pytest.raises(ValueError, match="day 29"):
        cal.slot_index(29, 1)
    with pytest.raises(ValueError, match="run 2"):
        cal.slot_index(1, 2)
