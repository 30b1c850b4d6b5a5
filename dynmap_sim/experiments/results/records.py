"""What the store is handed: a run's arrays (:class:`RunRecord`) and a :class:`Checkpoint`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.experiments.results.schema import Artifact
from dynmap_sim.metrics import NavRunSummary, PointClassTally
from dynmap_sim.types import Diagnostic


@dataclass
class LocalizerDiagnostics:
    """One localizer's diagnostics of one run: ``declared`` (its ``Localizer.diagnostics``),
    ``per_scan`` name -> ``(T, *shape)`` float64 (NaN: not reported at that scan),
    ``per_run`` name -> value of the declared shape, ``artifacts`` name -> what it handed
    over after ``end_day`` (empty but after a day's last run)."""

    declared: tuple[Diagnostic, ...] = ()
    per_scan: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    per_run: dict[str, NDArray[Any]] = field(default_factory=dict)
    artifacts: dict[str, Artifact] = field(default_factory=dict)


@dataclass
class PeopleTrack:
    """The people of one run: ``ids``, ``radius_m`` ``(n,)`` and ``xy`` ``(T, n, 2)`` [m]
    at each scan (NaN: not on the floor)."""

    ids: tuple[str, ...]
    radius_m: NDArray[np.float64]
    xy: NDArray[np.float64]


@dataclass
class RunRecord:
    """Everything one run produces, as arrays (written in bulk by ``ResultsDB.write_run``).

    ``truth`` ``(T, 3)``; ``estimates`` ``(L, T, 3)``; ``cov_diag`` ``(L, T, 3)``;
    ``diagnostics`` one :class:`LocalizerDiagnostics` per localizer (empty: none declared).
    """

    day: int
    run: int
    date: str
    start_s: float
    t_s: NDArray[np.float64]
    truth: NDArray[np.float64]
    collision: NDArray[np.bool_]
    estimates: NDArray[np.float64]
    cov_diag: NDArray[np.float64]
    confusion: NDArray[np.int64]  # (L, 4, 4)
    terminated: bool
    route_progress: float
    skipped_waypoints: int
    wall_s: float
    events: list[tuple[int, float, str, str]]  # (step, t_s, kind, detail)
    segments: NDArray[np.float64] | None = None
    segment_class: NDArray[np.int8] | None = None
    update_s: NDArray[np.float64] | None = None  # (L,) CPU time of each localizer's update()
    diagnostics: list[LocalizerDiagnostics] = field(default_factory=list)
    #: the run's navigation measures (None: not measured)
    nav: NavRunSummary | None = None
    #: what the driver handed over after the run (name -> bytes)
    driver_artifacts: dict[str, bytes] = field(default_factory=dict)
    #: per localizer, its point classes against the seen-before truth (empty: none)
    point_tallies: list[PointClassTally] = field(default_factory=list)
    #: the laser ranges ``(T, n_beams)`` [m], REP-117, kept with ``run --keep-scans``
    ranges: NDArray[np.float32] | None = None
    #: the people at each scan, kept with ``run --keep-scans`` (None: not kept)
    people: PeopleTrack | None = None

    def scan_diagnostic(self, loc: int, name: str) -> NDArray[np.float64] | None:
        """Per-scan values ``(T, ...)`` of diagnostic ``name`` of localizer ``loc`` (None
        when it did not declare it)."""
        if loc >= len(self.diagnostics):
            return None
        return self.diagnostics[loc].per_scan.get(name)


@dataclass(frozen=True)
class Checkpoint:
    """The state to resume from: the next slot index, the state dict (driver, RNG; pickled
    into the database) and the pickled localizers (one file each)."""

    next_index: int
    next_day: int
    next_run: int
    state: dict[str, Any]
    localizers: tuple[bytes, ...] = ()
