"""A driver that steers on a localizer's estimate: that localizer runs in lock-step with the
simulation, the driver gets exactly the estimates that are stored, and the numbers are those
of the localizer bench (in-process or in workers) for everyone else."""

import sqlite3
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from fake_env import FakeEnv  # noqa: E402

from dynmap_sim.experiments.runner import ExperimentRunner  # noqa: E402
from dynmap_sim.experiments.scenario import ScenarioFileError, parse_scenario  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def scenario(tmp_path, steer="odo-a", kind="lockstep_driver:EstimateFollower"):
    return parse_scenario(
        {
            "name": "lockstep",
            "world": str(ROOT / "worlds" / "apartment.toml"),
            "days": [1, 2],
            "driver": {"kind": kind, "localizer": steer, "max_run_s": 5.0},
            "localizers": [
                {"name": "fake_env:RecordingLocalizer", "label": "rec"},
                {"name": "odometry", "label": "odo-a"},
                {"name": "odometry", "label": "odo-b"},
            ],
        },
        tmp_path / "s.toml",
    )


def run(scn, out, workers=1, stop_after=None, resume=False):
    r = ExperimentRunner(
        scn, out, scn.days, 0, resume=resume, overwrite=not resume, env=FakeEnv(), workers=workers
    )
    r.run(progress=False, stop_after=stop_after)
    return r


def estimates(out, loc):
    con = sqlite3.connect(out / "results.db")
    try:
        rows = con.execute(
            "SELECT x, y, theta FROM estimates WHERE loc=? ORDER BY day, run, step", (loc,)
        ).fetchall()
    finally:
        con.close()
    return np.array(rows)


def test_the_driver_steers_on_the_stored_estimates(tmp_path):
    r = run(scenario(tmp_path), tmp_path / "o")
    seen = np.array([p for run_ in r.state.driver.seen for p in run_])
    stored = estimates(tmp_path / "o", 1)
    # one estimate per recorded scan; the driver acts on all but each run's last one
    assert len(stored) == 2 * 51 and len(seen) == 2 * 50
    keep = np.ones(len(stored), bool)
    keep[[50, 101]] = False
    np.testing.assert_array_equal(seen, stored[keep])
    # it drove 1 m forward by its estimate (the fake odometry overestimates by 2 %)
    assert 0.9 < np.hypot(*(stored[50, :2] - stored[0, :2])) < 1.05
    # the lock-stepped localizer and its twin on the bench give the same numbers
    np.testing.assert_array_equal(stored, estimates(tmp_path / "o", 2))


def test_workers_and_resume_give_the_same_numbers(tmp_path):
    scn = scenario(tmp_path)
    run(scn, tmp_path / "one")
    run(scn, tmp_path / "two", workers=2)
    run(scn, tmp_path / "broken", stop_after=1)
    run(scn, tmp_path / "broken", resume=True)
    for loc in range(3):
        ref = estimates(tmp_path / "one", loc)
        np.testing.assert_array_equal(ref, estimates(tmp_path / "two", loc))
        np.testing.assert_array_equal(ref, estimates(tmp_path / "broken", loc))


def test_the_steering_localizer_must_exist(tmp_path):
    with pytest.raises(ScenarioFileError) as ei:
        scenario(tmp_path, steer="nope")
    assert "no localizer has label 'nope'" in dict(ei.value.errors)["driver.localizer"]
    with pytest.raises(ScenarioFileError) as ei:
        scenario(tmp_path, steer=None)
    assert "steers on a localizer's estimate" in dict(ei.value.errors)["driver.localizer"]
