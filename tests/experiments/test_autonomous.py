"""The robot drives itself: the `autonomous` driver (the navigation stack on a lock-stepped
localizer's estimate) through the same code path as `dynmap-sim check`, its navigation
measures against the truth, the report's navigation files, and a steering localizer that
fails."""

import csv
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))

from dynmap_sim.analysis.report import write_report  # noqa: E402
from dynmap_sim.experiments.localizer_pool import LocalizerError  # noqa: E402
from dynmap_sim.experiments.results import ResultsDB  # noqa: E402
from dynmap_sim.experiments.runner import run_experiment  # noqa: E402
from dynmap_sim.experiments.scenario import parse_scenario  # noqa: E402
from dynmap_sim.testing import run_scenario  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def test_ci_autonomous_scenario_reaches_its_goals(tmp_path):
    result = run_scenario(ROOT / "worlds" / "scenarios" / "ci-apartment-autonomous.toml", tmp_path)
    assert result.passed, result.table()
    with ResultsDB.open(tmp_path) as db:
        nav = db.nav_runs()
        assert [(d, r) for d, r, _ in nav] == [(1, 1), (2, 1)]
        for _, _, s in nav:
            assert s.goal_reached == 1 and s.collisions == 0
            assert 0.5 < s.spl <= 1.0 and s.path_length_m > 5.0
        assert db.driver_artifacts("route_memory.json")
    files = {p.name for p in write_report(tmp_path)}
    assert {"nav_per_day.csv", "navigation_per_day.png", "route_memory.png"} <= files
    rows = list(csv.DictReader((tmp_path / "nav_per_day.csv").open()))
    assert [r["day"] for r in rows] == ["1", "2"] and rows[0]["goal_reached_fraction"] == "1.000000"
    assert "## Navigation" in (tmp_path / "summary.md").read_text()


def test_a_failing_steering_localizer_is_a_clear_error(tmp_path):
    scn = parse_scenario(
        {
            "name": "fails",
            "world": "apartment",
            "days": [2, 2],
            "driver": {"kind": "autonomous", "localizer": "bad", "max_run_s": 5.0},
            "prior": {"map": "walls"},
            "localizers": [{"name": "worker_localizers:FailingLocalizer", "label": "bad"}],
        },
        tmp_path / "s.toml",
    )
    with pytest.raises(LocalizerError, match="localizer 'bad' failed on day 2 run 1 at scan 4"):
        run_experiment(scn, out_dir=tmp_path / "o", progress=False)
