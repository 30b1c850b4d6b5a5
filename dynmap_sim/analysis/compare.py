"""Compare two results folders of the same scenario: before and after a change.

The unit of comparison is the **run**: both folders hold the same runs (day, run) of the same
scenario, so each measure gives one paired difference ``B - A`` per run and localizer. The
verdict on a measure is the Student t interval of those differences
(:func:`dynmap_sim.metrics.intervals.paired_difference`): a change *moved* a measure when the
interval excludes zero. Runs of one experiment are not independent (a map learned on day 3
serves day 4), so the interval is a screening tool, not a test at its nominal level: a
verdict over fewer than :data:`MIN_RUNS` runs is not given at all. Folders run with the same
seed share the world, the people and the sensor noise, which makes the pairing tight; with
different seeds the comparison still holds but the noise is larger (said in a note).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dynmap_sim.errors import InputError
from dynmap_sim.experiments.results import DB_NAME, ResultsDB
from dynmap_sim.metrics.intervals import MeanInterval, paired_difference

#: A verdict needs at least this many paired runs: the t interval of two differences has one
#: degree of freedom and spans almost anything.
MIN_RUNS = 3

#: The localization measures compared, per run and localizer (``run_summaries`` columns),
#: with their units.
LOCALIZER_MEASURES = {
    "mean_error_m": "m",
    "max_error_m": "m",
    "lost_fraction": "share",
    "update_ms_per_scan": "ms",
}
#: The navigation measures compared, per run (``nav_runs`` columns), with their units.
NAV_MEASURES = {
    "goal_reached": "runs",
    "collisions": "count",
    "near_misses": "count",
    "time_s": "s",
    "stuck_s": "s",
}
#: Measures whose difference is machine noise rather than a result: reported, never judged.
TIMING_MEASURES = ("update_ms_per_scan",)


@dataclass(frozen=True)
class MeasureChange:
    """One measure of one localizer (or the navigation, ``localizer=None``) in A and B."""

    localizer: str | None
    measure: str
    unit: str
    mean_a: float
    mean_b: float
    difference: MeanInterval
    per_day: dict[int, float]  # day -> mean of B - A over that day's runs
    verdict: str


@dataclass(frozen=True)
class Comparison:
    """The result of :func:`compare_results`."""

    dir_a: Path
    dir_b: Path
    scenario: str
    n_runs: int
    changes: list[MeasureChange]
    notes: list[str] = field(default_factory=list)

    @property
    def moved(self) -> list[MeasureChange]:
        """The measures whose paired interval excludes zero."""
        return [c for c in self.changes if c.verdict in ("higher in B", "lower in B")]


def _verdict(m: MeanInterval, diffs: np.ndarray, measure: str) -> str:
    if diffs.size and np.all(diffs == 0):
        return "identical"
    if measure in TIMING_MEASURES:
        return "timing (not judged)"
    if m.n < MIN_RUNS or math.isnan(m.low):
        return f"too few runs (< {MIN_RUNS})"
    if m.low > 0:
        return "higher in B"
    if m.high < 0:
        return "lower in B"
    return "within noise"


def _open(folder: Path) -> ResultsDB:
    if not (folder / DB_NAME).is_file():
        raise InputError(f"{folder}: not a results folder (no {DB_NAME})")
    return ResultsDB.open(folder)


def _per_run(db: ResultsDB, table: str, columns: list[str], loc: int | None) -> dict:
    where = "" if loc is None else f" WHERE loc = {int(loc)}"
    rows = db.query(f"SELECT day, run, {', '.join(columns)} FROM {table}{where}")
    return {
        (int(r[0]), int(r[1])): [np.nan if v is None else float(v) for v in r[2:]] for r in rows
    }


def _comparable(meta_a: dict[str, Any], meta_b: dict[str, Any], a: Path, b: Path) -> list[str]:
    """Refuse folders of different scenarios or worlds; notes on what else differs."""
    for key, what in (("scenario_name", "scenario"), ("world", "world")):
        if meta_a.get(key) != meta_b.get(key):
            raise InputError(
                f"not comparable: {a} holds {what} {meta_a.get(key)!r}, {b} holds "
                f"{meta_b.get(key)!r}; compare two runs of the same scenario"
            )
    notes = []
    if meta_a.get("seed") != meta_b.get("seed"):
        notes.append(
            f"seeds differ ({meta_a.get('seed')} and {meta_b.get('seed')}): the runs are paired "
            "by day and run but not by world draw, so the intervals are wider"
        )
    if not meta_a.get("complete") or not meta_b.get("complete"):
        notes.append("one folder is not complete: only the runs both hold are compared")
    return notes


def _change(
    loc: str | None, measure: str, unit: str, a: dict, b: dict, col: int, keys: list
) -> MeasureChange:
    va = np.array([a[k][col] for k in keys])
    vb = np.array([b[k][col] for k in keys])
    ok = np.isfinite(va) & np.isfinite(vb)
    diffs = (vb - va)[ok]
    m = paired_difference(vb[ok], va[ok])
    days = np.array([k[0] for k in keys])[ok]
    per_day = {int(d): float(diffs[days == d].mean()) for d in np.unique(days)}
    mean_a = float(va[ok].mean()) if ok.any() else math.nan
    mean_b = float(vb[ok].mean()) if ok.any() else math.nan
    return MeasureChange(
        loc, measure, unit, mean_a, mean_b, m, per_day, _verdict(m, diffs, measure)
    )


def compare_results(dir_a: str | Path, dir_b: str | Path) -> Comparison:
    """Paired per-run differences ``B - A`` of the error and navigation measures of two
    results folders of one scenario; :class:`InputError` when they are not comparable."""
    a, b = Path(dir_a), Path(dir_b)
    with _open(a) as db_a, _open(b) as db_b:
        meta_a, meta_b = db_a.meta(), db_b.meta()
        notes = _comparable(meta_a, meta_b, a, b)
        labels_a, labels_b = db_a.labels(), db_b.labels()
        common = [lb for lb in labels_a if lb in labels_b]
        if not common:
            raise InputError(
                f"not comparable: no localizer label in both folders ({', '.join(labels_a)} "
                f"against {', '.join(labels_b)})"
            )
        only = sorted(set(labels_a) ^ set(labels_b))
        if only:
            notes.append(f"compared only the localizers in both: not {', '.join(only)}")
        cols = list(LOCALIZER_MEASURES)
        changes: list[MeasureChange] = []
        keys: list[tuple[int, int]] = []
        for label in common:
            ra = _per_run(db_a, "run_summaries", cols, labels_a.index(label))
            rb = _per_run(db_b, "run_summaries", cols, labels_b.index(label))
            keys = sorted(set(ra) & set(rb))
            if not keys:
                raise InputError(f"not comparable: {a} and {b} share no finished run")
            for j, (measure, unit) in enumerate(LOCALIZER_MEASURES.items()):
                changes.append(_change(label, measure, unit, ra, rb, j, keys))
        na = _per_run(db_a, "nav_runs", list(NAV_MEASURES), None)
        nb = _per_run(db_b, "nav_runs", list(NAV_MEASURES), None)
        nav_keys = sorted(set(na) & set(nb))
        if nav_keys:
            for j, (measure, unit) in enumerate(NAV_MEASURES.items()):
                changes.append(_change(None, measure, unit, na, nb, j, nav_keys))
    scenario = str(meta_a.get("scenario_name"))
    return Comparison(a, b, scenario, len(keys), changes, notes)


def _num(v: float) -> str:
    return "—" if math.isnan(v) else f"{v:.4g}"


def comparison_table(cmp: Comparison) -> str:
    """A markdown table of :func:`compare_results`, one row per localizer and measure, with
    the verdicts, and a closing line naming what moved."""
    lines = [
        f"{cmp.scenario}: B = {cmp.dir_b} against A = {cmp.dir_a}, {cmp.n_runs} paired runs",
        "",
        "| localizer | measure | A | B | B − A (95 % CI) | verdict |",
        "|---|---|---|---|---|---|",
    ]
    for c in cmp.changes:
        d = c.difference
        ci = _num(d.mean) + ("" if math.isnan(d.low) else f" [{_num(d.low)}, {_num(d.high)}]")
        who = c.localizer if c.localizer is not None else "navigation"
        lines.append(
            f"| {who} | {c.measure} [{c.unit}] | {_num(c.mean_a)} | {_num(c.mean_b)} | {ci} | "
            f"{c.verdict} |"
        )
    lines.append("")
    moved = cmp.moved
    if moved:
        names = ", ".join(f"{c.localizer or 'navigation'} {c.measure} ({c.verdict})" for c in moved)
        lines.append(f"moved beyond noise: {names}")
    else:
        lines.append("nothing moved beyond noise")
    lines += [f"note: {n}" for n in cmp.notes]
    return "\n".join(lines) + "\n"


def write_comparison_csv(cmp: Comparison, path: Path) -> Path:
    """Per localizer, measure and day: the mean paired difference ``B - A`` of that day."""
    import csv

    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["localizer", "measure", "day", "difference", "verdict"])
        for c in cmp.changes:
            for day, diff in c.per_day.items():
                w.writerow([c.localizer or "navigation", c.measure, day, f"{diff:.6g}", c.verdict])
    return path
