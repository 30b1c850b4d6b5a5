"""Run a scenario from Python and read the results database directly.

    python examples/run_from_python.py [SCENARIO] [OUT_DIR]

The results folder holds ``results.db`` (SQLite); any SQLite client reads it. Tables:
``scans`` (truth per scan), ``estimates`` (per scan and localizer), ``run_summaries``,
``day_summaries``, ``events``, ``localizers``, ``meta`` (see dynmap_sim/experiments/results/).
"""

from __future__ import annotations

import sqlite3
import sys
from pathlib import Path

from dynmap_sim.analysis.report import write_report
from dynmap_sim.experiments.runner import run_experiment
from dynmap_sim.experiments.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    scenario = sys.argv[1] if len(sys.argv) > 1 else ROOT / "worlds/scenarios/ci-apartment.toml"
    out_dir = Path(sys.argv[2]) if len(sys.argv) > 2 else Path("results/python-example")
    out = run_experiment(load_scenario(scenario), out_dir=out_dir, progress=True, overwrite=True)
    write_report(out)
    con = sqlite3.connect(out / "results.db")
    rows = con.execute(
        "SELECT l.label, d.day, d.mean_error_m, d.max_error_m FROM day_summaries d "
        "JOIN localizers l ON l.idx = d.loc ORDER BY d.day, l.idx"
    ).fetchall()
    con.close()
    print(f"{'localizer':<24}{'day':>4}{'mean [m]':>10}{'max [m]':>10}")
    for label, day, mean, mx in rows:
        print(f"{label:<24}{day:>4}{mean:>10.3f}{mx:>10.3f}")
    print(f"report in {out}/summary.md")


if __name__ == "__main__":
    main()
