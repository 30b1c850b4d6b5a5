"""The experiment calendar: working days and the runs of each day (docs/architecture.md §2).

Days and runs are 1-based. A run's *slot index* ``(day - 1) * runs_per_day + (run - 1)``
orders all runs of the experiment; the schedule is evaluated on slot indices.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass

from dynmap_sim.world.spec import WEEKDAYS, CalendarSpec


@dataclass(frozen=True)
class RunSlot:
    """One run: working ``day`` and ``run`` (1-based), its ``date`` and clock ``start_s``."""

    day: int
    run: int
    date: dt.date
    start_s: float


class Calendar:
    """Working days from ``spec.start`` on the allowed weekdays, minus holidays."""

    def __init__(self, spec: CalendarSpec) -> None:
        self.spec = spec
        allowed = {WEEKDAYS.index(w) for w in spec.weekdays}
        holidays = set(spec.holidays)
        dates: list[dt.date] = []
        d = spec.start
        while len(dates) < spec.n_days:
            if d.weekday() in allowed and d not in holidays:
                dates.append(d)
            d += dt.timedelta(days=1)
        self.dates: tuple[dt.date, ...] = tuple(dates)
        starts = []
        for t in spec.runs:
            h, m = t.split(":")
            starts.append(3600.0 * int(h) + 60.0 * int(m))
        self.run_starts_s: tuple[float, ...] = tuple(starts)
        self.slots: tuple[RunSlot, ...] = tuple(
            RunSlot(day=i + 1, run=j + 1, date=date, start_s=s)
            for i, date in enumerate(self.dates)
            for j, s in enumerate(starts)
        )

    @property
    def n_days(self) -> int:
        """Number of working days."""
        return len(self.dates)

    @property
    def runs_per_day(self) -> int:
        """Runs on each working day."""
        return len(self.run_starts_s)

    @property
    def n_slots(self) -> int:
        """Total number of runs of the experiment."""
        return len(self.slots)

    def slot_index(self, day: int, run: int) -> int:
        """0-based index of run ``run`` of working day ``day``; ``ValueError`` if out of range."""
        if not (1 <= day <= self.n_days):
            raise ValueError(f"day {day} outside the calendar (1..{self.n_days})")
        if not (1 <= run <= self.runs_per_day):
            raise ValueError(f"run {run} outside 1..{self.runs_per_day}")
        return (day - 1) * self.runs_per_day + (run - 1)

    def slot(self, day: int, run: int) -> RunSlot:
        """The :class:`RunSlot` of ``(day, run)``."""
        return self.slots[self.slot_index(day, run)]

    def day_of(self, when: int | dt.date) -> int | None:
        """Working day of a calendar moment: a day number as is, a date to the first working
        day on or after it; ``None`` if outside the calendar."""
        if isinstance(when, dt.date):
            if when < self.spec.start or when > self.dates[-1]:
                return None
            for i, d in enumerate(self.dates):
                if d >= when:
                    return i + 1
            return None
        return when if 1 <= when <= self.n_days else None
