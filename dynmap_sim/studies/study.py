"""The Study role: one paper's findings and figures, checked on an experiment's results.

A study says which scenarios it can judge (:meth:`Study.scenario_errors`: the findings a
scenario may require and what they need), whether it applies to a results folder, and writes
its own files into the report; ``dynmap-sim check`` asks it whether required findings hold.
Built-in studies register by name; the report and the check ask every registered study
instead of naming one.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from dynmap_sim.registry import Registry

if TYPE_CHECKING:
    from dynmap_sim.experiments.results import ResultsDB
    from dynmap_sim.experiments.scenario import Scenario


@dataclass
class StudyReport:
    """What a study added to a report: ``files`` written, ``figures`` among them (linked
    from ``summary.md``), and ``summary_lines`` (a markdown section for ``summary.md``)."""

    files: list[Path] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)
    summary_lines: list[str] = field(default_factory=list)


@dataclass(frozen=True)
class FindingCheck:
    """A required finding on a results folder: ``key``, ``holds`` (None: not measurable) and
    the measured ``detail``."""

    key: str
    holds: bool | None
    detail: str


class Study(ABC):
    """A paper's study (module doc)."""

    #: Registry name (set by :func:`register_study`).
    name: str = "study"
    #: The findings a scenario may require (``[expectations] findings``), in report order.
    finding_keys: tuple[str, ...] = ()

    def scenario_errors(self, scenario: Scenario, required: list[str]) -> list[tuple[str, str]]:
        """Problems with the findings of this study that ``scenario`` requires (``required``:
        those of its keys that are this study's), as ``(dotted field, message)``."""
        return []

    @abstractmethod
    def applies(self, db: ResultsDB) -> bool:
        """True when the results hold what this study measures."""

    @abstractmethod
    def write(self, db: ResultsDB, out: Path) -> StudyReport:
        """Measure and write this study's files into ``out``."""

    @abstractmethod
    def check(self, db: ResultsDB, keys: list[str]) -> list[FindingCheck]:
        """Whether each required finding ``keys`` holds on these results."""


#: The study registry.
STUDIES: Registry[Study] = Registry(
    "study",
    Study,
    builtin_modules=(
        "dynmap_sim.studies.biber_duckett.study",
        "dynmap_sim.studies.hentschel_wagner.study",
        "dynmap_sim.studies.temporal_maps.study",
    ),
)

#: Class decorator: make a :class:`Study` available under a name.
register_study = STUDIES.register


def all_studies() -> list[Study]:
    """One instance of every registered study, by name."""
    return [STUDIES.get(name)() for name in STUDIES.names()]


def study_of_finding(key: str) -> Study | None:
    """The study that defines finding ``key`` (None: none does)."""
    return next((s for s in all_studies() if key in s.finding_keys), None)
