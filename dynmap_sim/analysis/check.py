"""Regression checks: run a scenario and test its ``[expectations]`` (docs/architecture.md §6).

``dynmap-sim check SCENARIO`` prints the table of :meth:`CheckResult.table` and exits 1 when
any expectation fails; :func:`dynmap_sim.testing.run_scenario` does the same for pytest.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from dynmap_sim.analysis.report import overall_of
from dynmap_sim.analysis.scenarios import load_scenario
from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.experiments.runner import run_experiment
from dynmap_sim.experiments.scenario import (
    Expectations,
    LocalizerExpectation,
    NavigationExpectation,
    Scenario,
)
from dynmap_sim.studies.study import Study, study_of_finding


@dataclass(frozen=True)
class CheckRow:
    """One checked expectation."""

    seed: int
    subject: str  # a localizer label or "robot"
    criterion: str
    limit: float
    measured: float
    passed: bool
    where: str = ""  # e.g. the failing day
    at_least: bool = False  # the limit is a minimum (else a maximum)


@dataclass
class CheckResult:
    """All checked expectations of one scenario; ``passed`` when every row passed."""

    scenario: str
    rows: list[CheckRow] = field(default_factory=list)
    out_dirs: list[Path] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return all(r.passed for r in self.rows)

    def table(self) -> str:
        """A plain-text pass/fail table."""
        head = ("seed", "subject", "criterion", "limit", "measured", "where", "result")
        body = [
            (
                str(r.seed),
                r.subject,
                r.criterion,
                f"{'>=' if r.at_least else '<='} {r.limit:g}",
                "nan" if math.isnan(r.measured) else f"{r.measured:.4g}",
                r.where,
                "PASS" if r.passed else "FAIL",
            )
            for r in self.rows
        ]
        widths = [max(len(x) for x in col) for col in zip(head, *body, strict=True)]
        line = "  ".join("{:<" + str(w) + "}" for w in widths)
        out = [f"scenario {self.scenario}: " + ("PASSED" if self.passed else "FAILED")]
        out.append(line.format(*head))
        out.append("  ".join("-" * w for w in widths))
        out += [line.format(*row) for row in body]
        if not self.rows:
            out.append("(no expectations in this scenario)")
        return "\n".join(out)


def _le(measured: float, limit: float) -> bool:
    return not math.isnan(measured) and measured <= limit


def evaluate(scenario: Scenario, out_dir: Path, seed: int) -> list[CheckRow]:
    """Check a finished experiment in ``out_dir`` against the scenario's expectations."""
    exp = scenario.expectations
    rows: list[CheckRow] = []
    with ResultsDB.open(out_dir) as db:
        labels = db.labels()
        rows += _robot_rows(db, exp, seed)
        if exp.findings:
            rows += _finding_rows(db, exp.findings, seed)
        if exp.navigation is not None:
            rows += _navigation_rows(db, exp.navigation, seed)
        for label, e in exp.localizers.items():
            rows += _localizer_rows(db, labels.index(label), label, e, seed)
    return rows


def _robot_rows(db: ResultsDB, exp: Expectations, seed: int) -> list[CheckRow]:
    """Rows for the robot's expectations over every stored run: no collisions, at most so
    many skipped waypoints."""
    rows = []
    if exp.no_collisions:
        n = db.query("SELECT coalesce(sum(collisions), 0) FROM runs")[0][0]
        rows.append(CheckRow(seed, "robot", "collisions", 0, float(n), n == 0))
    if exp.max_skipped_waypoints is not None:
        n = db.query("SELECT coalesce(sum(skipped_waypoints), 0) FROM runs")[0][0]
        lim = exp.max_skipped_waypoints
        rows.append(CheckRow(seed, "robot", "skipped waypoints", lim, float(n), n <= lim))
    return rows


def _localizer_rows(
    db: ResultsDB, k: int, label: str, e: LocalizerExpectation, seed: int
) -> list[CheckRow]:
    """Rows for the expectations of localizer ``k`` (``label``): the worst day's mean
    error, RMSE and heading error, and over every scan the largest error, the longest
    recovery and the lost fraction."""
    rows: list[CheckRow] = []
    overall = overall_of(db, k) if _needs_scans(e) else None
    days = db.query(
        "SELECT day, mean_error_m, rmse_m, mean_heading_error_rad FROM day_summaries "
        "WHERE loc=? ORDER BY day",
        (k,),
    )

    def worst(col: int) -> tuple[float, str]:
        vals = [(math.nan if r[col] is None else r[col], r[0]) for r in days]
        if not vals:
            return math.nan, ""
        v, d = max(vals, key=lambda x: math.inf if math.isnan(x[0]) else x[0])
        return v, f"day {d}"

    if e.mean_error_m is not None:
        v, w = worst(1)
        rows.append(
            CheckRow(
                seed,
                label,
                "mean error per day [m]",
                e.mean_error_m,
                v,
                _le(v, e.mean_error_m),
                w,
            )
        )
    if e.rmse_m is not None:
        v, w = worst(2)
        rows.append(CheckRow(seed, label, "RMSE per day [m]", e.rmse_m, v, _le(v, e.rmse_m), w))
    if e.mean_heading_error_rad is not None:
        v, w = worst(3)
        lim = e.mean_heading_error_rad
        rows.append(
            CheckRow(seed, label, "mean heading error per day [rad]", lim, v, _le(v, lim), w)
        )
    if e.max_error_m is not None and overall is not None:
        v = overall.worst_error_m
        rows.append(CheckRow(seed, label, "max error [m]", e.max_error_m, v, _le(v, e.max_error_m)))
    if e.max_time_to_recover_s is not None and overall is not None:
        v = overall.worst_time_to_recover_s
        w = (
            "day {} run {}".format(*overall.worst_recovery_run)
            if overall.worst_recovery_run
            else ""
        )
        lim = e.max_time_to_recover_s
        rows.append(CheckRow(seed, label, "time to recover [s]", lim, v, _le(v, lim), w))
    if e.lost_fraction is not None and overall is not None:
        v = overall.lost_fraction
        rows.append(
            CheckRow(seed, label, "lost fraction", e.lost_fraction, v, _le(v, e.lost_fraction))
        )
    return rows


def _navigation_rows(db: ResultsDB, e: NavigationExpectation, seed: int) -> list[CheckRow]:
    """Rows for the navigation expectations, over every stored run (measured against the
    truth by :func:`dynmap_sim.metrics.nav_run_summary`)."""
    runs = db.nav_runs()
    if not runs:
        return [CheckRow(seed, "robot", "navigation measures", 0, math.nan, False, "none stored")]
    nav = [s for _, _, s in runs]
    rows = []
    if e.goal_reached_fraction is not None:
        v = sum(s.goal_reached for s in nav) / len(nav)
        lim = e.goal_reached_fraction
        missed = [f"day {d} run {r}" for d, r, s in runs if not s.goal_reached]
        rows.append(
            CheckRow(
                seed,
                "robot",
                "goal reached (share of runs)",
                lim,
                v,
                v >= lim,
                ", ".join(missed[:3]),
                at_least=True,
            )
        )
    for key, field_name, name in (
        ("max_collisions", "collisions", "collisions (navigation)"),
        ("max_near_misses", "near_misses", "near misses with people"),
        ("max_gave_up", "gave_up", "runs given up"),
    ):
        lim = getattr(e, key)
        if lim is not None:
            v = float(sum(getattr(s, field_name) for s in nav))
            rows.append(CheckRow(seed, "robot", name, lim, v, v <= lim))
    if e.min_clearance_m is not None:
        d, r, worst = min(runs, key=lambda x: x[2].min_clearance_m)
        v = worst.min_clearance_m
        rows.append(
            CheckRow(
                seed,
                "robot",
                "smallest clearance [m]",
                e.min_clearance_m,
                v,
                v >= e.min_clearance_m,
                f"day {d} run {r}",
                at_least=True,
            )
        )
    return rows


def _finding_rows(db: ResultsDB, keys: list[str], seed: int) -> list[CheckRow]:
    """One row per required finding, asked of the study that defines it: measured 0 when it
    holds, 1 when it does not or cannot be measured (limit 0)."""
    by_study: dict[str, tuple[Study, list[str]]] = {}
    for key in keys:
        study = study_of_finding(key)
        if study is None:  # validated when the scenario was loaded
            raise ValueError(f"no study defines the finding {key!r}")
        by_study.setdefault(study.name, (study, []))[1].append(key)
    checks = {}
    for study, mine in by_study.values():
        checks.update({c.key: (study.name, c) for c in study.check(db, mine)})
    rows = []
    for key in keys:
        name, c = checks[key]
        holds = c.holds is True
        where = "" if c.holds is not None else "not measurable"
        rows.append(
            CheckRow(seed, name, f"finding {key} fails", 0, 0.0 if holds else 1.0, holds, where)
        )
    return rows


def _needs_scans(e: object) -> bool:
    """Whether a localizer's expectations need its whole-experiment summary (per-scan data)."""
    keys = ("max_error_m", "max_time_to_recover_s", "lost_fraction")
    return any(getattr(e, key) is not None for key in keys)


def check_scenario(
    path: str | Path | Scenario, out_dir: str | Path | None = None, progress: bool = True
) -> CheckResult:
    """Run a scenario (every seed in its ``seeds``) and check its expectations.

    Results go to ``out_dir`` (``seed-<n>`` subfolders when there are several seeds), or to a
    temporary folder that is removed afterwards; earlier results there are replaced.
    """
    scenario = path if isinstance(path, Scenario) else load_scenario(path)
    result = CheckResult(scenario.name)
    tmp = tempfile.TemporaryDirectory(prefix="dynmap-check-") if out_dir is None else None
    base = Path(tmp.name if tmp is not None else out_dir)  # type: ignore[arg-type]
    try:
        for seed in scenario.seeds:
            out = base if len(scenario.seeds) == 1 else base / f"seed-{seed}"
            run_experiment(scenario, out_dir=out, seed=seed, progress=progress, overwrite=True)
            result.rows += evaluate(scenario, out, seed)
            if tmp is None:
                result.out_dirs.append(out)
    finally:
        if tmp is not None:
            tmp.cleanup()
    return result
