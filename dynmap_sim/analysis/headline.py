"""The headline of a results folder: the few lines ``run`` and ``replay`` print when done.

Per localizer the ATE RMSE, the mean and max position error [m] and the lost fraction, as an
aligned text table for the terminal; the full report is :mod:`.report`.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from dynmap_sim.analysis.navigation import goals_reached_line, missed_goal_lines
from dynmap_sim.analysis.report import NO_GROUND_TRUTH, has_ground_truth, overall_stats
from dynmap_sim.experiments.results import ResultsDB


def text_table(rows: list[tuple[str, ...]]) -> list[str]:
    """``rows`` (the first one the header) as aligned lines: the first column left-aligned,
    the others right-aligned, two spaces apart."""
    widths = [max(len(row[j]) for row in rows) for j in range(len(rows[0]))]
    return [
        "  ".join(
            c.ljust(w) if j == 0 else c.rjust(w)
            for j, (c, w) in enumerate(zip(row, widths, strict=True))
        )
        for row in rows
    ]


def _num(v: float | None, nd: int) -> str:
    return "n/a" if v is None or math.isnan(v) else f"{v:.{nd}f}"


def results_headline(
    out: Path, timing: bool = False, overall: list[dict[str, Any]] | None = None
) -> list[str]:
    """The headline numbers of a results folder: per localizer ATE RMSE, mean and max
    position error and the lost fraction (:func:`dynmap_sim.analysis.report.overall_stats`;
    ``overall``: those, when the report just computed them), with ``timing`` the time per
    scan too; goals reached and collisions when the results hold navigation measures, and
    why each run that missed its goal missed it (:func:`.navigation.missed_goal_lines`).
    Without any ground truth: that line and the time per scan only. No lines for a folder
    without runs."""
    with ResultsDB.open(out) as db:
        if not db.query("SELECT 1 FROM runs LIMIT 1"):
            return []
        stats = overall_stats(db) if overall is None else overall
        nav = db.nav_runs()
        goals = goals_reached_line(db)
        missed = missed_goal_lines(db)
        truth = has_ground_truth(db)
        update_header = db.update_time_header()

    if truth:
        table = [("localizer", "ATE RMSE [m]", "mean [m]", "max [m]", "lost")]
    else:
        table = [("localizer", "scans")]
    if timing:
        table[0] += (update_header,)
    for s in stats:
        lost = s["lost_fraction"]
        row: tuple[str, ...] = (
            (
                str(s["localizer"]),
                _num(s["ate_rmse_m"], 3),
                _num(s["mean_error_m"], 3),
                _num(s["max_error_m"], 3),
                "n/a" if math.isnan(lost) else f"{100.0 * lost:.1f} %",
            )
            if truth
            else (str(s["localizer"]), str(s["n_scans"]))
        )
        table.append(row + ((_num(s["update_ms_per_scan"], 2),) if timing else ()))
    lines = [] if truth else [f"{NO_GROUND_TRUTH}: the localizers are not scored"]
    lines += text_table(table)
    if nav:
        collisions = sum(int(n.collisions) for _, _, n in nav)
        lines.append(f"navigation: {goals}; {collisions} collisions")
        lines += [f"  {line}" for line in missed]
    return lines
