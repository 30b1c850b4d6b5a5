"""The temporal maps (FreMEn, Krajník et al. T-RO 2017 and ECMR 2015; the Markov-chain grid,
Saarinen et al. IROS 2012) as a :class:`~dynmap_sim.studies.study.Study`: each run's
time-specific map against that run's truth (:mod:`.agreement`), per run
(``temporal_map_agreement.csv``), per week (``summary.md``) and in two figures; and the
finding that the agreement on the changing cells rises over the weeks, as a model that
learns when things change should show."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.experiments.scenario import Scenario
from dynmap_sim.studies.study import FindingCheck, Study, StudyReport, register_study
from dynmap_sim.studies.temporal_maps.agreement import (
    MapAgreement,
    map_agreement,
    temporal_localizers,
)
from dynmap_sim.studies.temporal_maps.figures import plot_agreement, plot_doors

#: The localizers that hand over time-specific maps.
TEMPORAL_LOCALIZERS = ("fremen", "markov-grid")
#: The finding: the changing cells' F1 rises from the first week to the last.
RISES = "temporal_map_agreement_rises"
#: Weeks the trend needs (two points make no trend).
MIN_WEEKS = 3


def changing_f1(a: MapAgreement) -> tuple[np.ndarray, np.ndarray]:
    """``(weeks, F1 per week)`` on the changing cells: the harmonic mean of the week's mean
    precision and mean recall."""
    weeks, p = a.weekly(a.changing_precision)
    _, r = a.weekly(a.changing_recall)
    with np.errstate(invalid="ignore", divide="ignore"):
        return weeks, 2 * p * r / (p + r)


def rises(a: MapAgreement) -> tuple[bool | None, str]:
    """Whether ``a``'s changing-cell F1 rises over the weeks: the fitted line's slope is
    positive and the last week is above the first (None: fewer than :data:`MIN_WEEKS`
    weeks with a value); and the measured numbers."""
    weeks, f1 = changing_f1(a)
    ok = np.isfinite(f1)
    numbers = ", ".join(f"week {w} {v:.3f}" for w, v in zip(weeks[ok], f1[ok], strict=True))
    if ok.sum() < MIN_WEEKS:
        return None, f"{a.label}: {numbers or 'no week'} (fewer than {MIN_WEEKS} weeks)"
    slope = float(np.polyfit(weeks[ok], f1[ok], 1)[0])
    holds = bool(slope > 0 and f1[ok][-1] > f1[ok][0])
    return holds, f"{a.label}: {numbers}; slope {slope:+.4f}/week"


def finding(agreements: list[MapAgreement]) -> FindingCheck:
    """:data:`RISES` over every temporal-map localizer: holds when it holds for each."""
    if not agreements:
        return FindingCheck(RISES, None, "no temporal maps")
    verdicts = [rises(a) for a in agreements]
    values = [v for v, _ in verdicts]
    holds = None if any(v is None for v in values) else all(values)
    return FindingCheck(RISES, holds, "; ".join(d for _, d in verdicts))


def write_agreement_csv(agreements: list[MapAgreement], path: Path) -> Path:
    """One row per predicted map: localizer, day, run, week, clock, the four shares."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(
            ["localizer", "day", "run", "week", "clock_h", "precision", "recall",
             "changing_precision", "changing_recall", "n_changing_cells"]
        )  # fmt: skip
        for a in agreements:
            for k in range(len(a.day)):
                values = (a.precision[k], a.recall[k], a.changing_precision[k],
                          a.changing_recall[k])  # fmt: skip
                w.writerow(
                    [a.label, int(a.day[k]), int(a.run[k]), int(a.week[k]),
                     f"{a.clock_h[k]:.2f}", *(f"{v:.4f}" for v in values),
                     int(a.n_changing[k])]
                )  # fmt: skip
    return path


def summary_lines(agreements: list[MapAgreement], check: FindingCheck) -> list[str]:
    """The per-week table and the finding, for ``summary.md``."""
    lines = [
        "## Temporal maps against the truth (temporal_map_agreement.csv)",
        "",
        "Each run's predicted map (made before the run) against the run's true static world; "
        "precision / recall of the occupied cells, one cell of tolerance.",
        "",
        "| localizer | week | maps | all: P / R | changing: P / R | changing F1 |",
        "|---|---|---|---|---|---|",
    ]
    for a in agreements:
        weeks, f1 = changing_f1(a)
        cols = [a.weekly(v)[1] for v in (a.precision, a.recall, a.changing_precision,
                                          a.changing_recall)]  # fmt: skip
        for i, w in enumerate(weeks):
            n = int(np.sum(a.week == w))
            lines.append(
                f"| {a.label} | {w} | {n} | {cols[0][i]:.3f} / {cols[1][i]:.3f} | "
                f"{cols[2][i]:.3f} / {cols[3][i]:.3f} | {f1[i]:.3f} |"
            )
    verdict = {True: "holds", False: "does not hold", None: "not measurable"}[check.holds]
    lines += ["", f"`{RISES}` {verdict}: {check.detail}", ""]
    return lines


@register_study("temporal-maps")
class TemporalMaps(Study):
    """The time-specific maps against the truth (module doc). Applies when a localizer handed
    over ``temporal_map`` artifacts."""

    finding_keys = (RISES,)

    def scenario_errors(self, scenario: Scenario, required: list[str]) -> list[tuple[str, str]]:
        if any(loc.name in TEMPORAL_LOCALIZERS for loc in scenario.localizers):
            return []
        return [("expectations.findings", f"{RISES} needs a localizer of {TEMPORAL_LOCALIZERS}")]

    def applies(self, db: ResultsDB) -> bool:
        return bool(temporal_localizers(db))

    def write(self, db: ResultsDB, out: Path) -> StudyReport:
        rep = StudyReport()
        agreements, doors = map_agreement(db)
        if not agreements:
            return rep
        rep.files.append(write_agreement_csv(agreements, out / "temporal_map_agreement.csv"))
        rep.figures.append(plot_agreement(agreements, out / "temporal_map_agreement.png"))
        if doors:
            rep.figures.append(plot_doors(doors, out / "temporal_map_doors.png"))
        rep.summary_lines = summary_lines(agreements, finding(agreements))
        return rep

    def check(self, db: ResultsDB, keys: list[str]) -> list[FindingCheck]:
        result = finding(map_agreement(db)[0])
        return [result if key == RISES else FindingCheck(key, None, "") for key in keys]
