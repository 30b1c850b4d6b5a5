"""End to end on the real env: a ci scenario through the CLI's code path, regression checks,
reports, TUM export, and resume after ``kill -9``."""

import csv
import math
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from dynmap_sim.analysis.check import check_scenario
from dynmap_sim.analysis.export import export_tum
from dynmap_sim.analysis.report import PER_DAY_COLUMNS, write_report
from dynmap_sim.experiments.runner import run_experiment
from dynmap_sim.experiments.scenario import load_scenario, parse_scenario
from dynmap_sim.testing import run_scenario

ROOT = Path(__file__).resolve().parents[2]
CI = ROOT / "worlds" / "scenarios" / "ci-apartment.toml"


@pytest.fixture(scope="module")
def ci_results(tmp_path_factory):
    out = tmp_path_factory.mktemp("ci") / "res"
    run_experiment(load_scenario(CI), out_dir=out, progress=False)
    return out


def test_ci_scenario_passes_its_expectations():
    result = run_scenario(CI)
    assert result.passed
    text = result.table()
    assert "PASS" in text and "FAIL" not in text
    assert {r.criterion for r in result.rows} >= {"collisions", "mean error per day [m]"}


def test_a_failing_expectation_raises_with_the_table(tmp_path):
    data = {
        "name": "too-strict",
        "world": "apartment",
        "days": [1, 1],
        "driver": {"max_run_s": 8.0},
        "localizers": [{"name": "odometry"}],
        "expectations": {"localizers": {"odometry": {"max_error_m": 1e-9}}},
    }
    scn = parse_scenario(data, tmp_path / "strict.toml")
    res = check_scenario(scn, out_dir=tmp_path / "o", progress=False)
    assert not res.passed
    assert "FAIL" in res.table() and "max error [m]" in res.table()


def test_geometry_is_the_seeds_world(tmp_path):
    """The stored truth geometry (and the driver's) is that of the env's current world, also
    for a seed other than 0, where the env builds a new world on reset."""
    from dynmap_sim.experiments.results import ResultsDB
    from dynmap_sim.types import BeamClass
    from dynmap_sim.world import World, load_world

    data = {
        "name": "lab-seed",
        "world": "lab",
        "days": [5, 5],
        "driver": {"max_run_s": 2.0},
        "localizers": [{"name": "odometry"}],
    }
    scn = parse_scenario(data, tmp_path / "s.toml")
    out = run_experiment(scn, tmp_path / "o", seed=1, progress=False, workers=1)
    world = World(load_world(scn.world_path), seed=1)
    world.reset(5, 1)
    with ResultsDB.open(out) as db:
        seg, cls = db.geometry(5, 1)
    assert np.any(cls == int(BeamClass.EXHIBIT))  # the toaster exhibition (days 4-9)
    assert np.array_equal(seg, world.geometry.segments)


def test_per_day_csv_and_report(ci_results):
    paths = write_report(ci_results)
    names = {p.name for p in paths}
    assert {"per_day.csv", "summary.md", "error_per_day.png", "trajectories.png"} <= names
    with (ci_results / "per_day.csv").open() as fh:
        rows = list(csv.reader(fh))
    assert tuple(rows[0]) == PER_DAY_COLUMNS
    assert [r[0] for r in rows[1:]] == ["1", "2", "3"]
    assert all(r[1] == "odometry" for r in rows[1:])
    for r in rows[1:]:
        assert 0.0 <= float(r[2]) <= float(r[3])  # mean <= max
        assert math.isnan(float(r[6])) and math.isnan(float(r[7]))  # not reported: NaN
    md = (ci_results / "summary.md").read_text()
    assert "ATE RMSE" in md and "| odometry |" in md


def test_tum_export_matches_the_database(ci_results, tmp_path):
    paths = export_tum(ci_results, tmp_path / "tum")
    assert {p.name for p in paths} == {"truth.tum", "odometry.tum"}
    truth = np.loadtxt(tmp_path / "tum" / "truth.tum")
    est = np.loadtxt(tmp_path / "tum" / "odometry.tum")
    assert truth.shape == est.shape and truth.shape[1] == 8
    assert np.all(np.diff(truth[:, 0]) > 0)  # timestamps increase over the whole experiment
    # quaternion encodes the heading; the ATE from the files equals the database's
    con = sqlite3.connect(ci_results / "results.db")
    err = np.array([e for (e,) in con.execute("SELECT err_m FROM estimates ORDER BY day, step")])
    con.close()
    np.testing.assert_allclose(np.hypot(*(est[:, 1:3] - truth[:, 1:3]).T), err, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(truth[:, 4:8], axis=1), 1.0, atol=1e-9)


def _evo_ape():
    import shutil

    return shutil.which("evo_ape")


@pytest.mark.skipif(_evo_ape() is None, reason="evo is not installed (GPL: external tool only)")
def test_ate_equals_evo_ape(ci_results, tmp_path):
    from dynmap_sim.metrics import ate

    export_tum(ci_results, tmp_path)
    truth = np.loadtxt(tmp_path / "truth.tum")
    est = np.loadtxt(tmp_path / "odometry.tum")
    ours = ate(truth[:, [1, 2, 0]] * [1, 1, 0], est[:, [1, 2, 0]] * [1, 1, 0]).rmse
    zip_path = tmp_path / "ape.zip"
    subprocess.run(
        [
            _evo_ape(),
            "tum",
            str(tmp_path / "truth.tum"),
            str(tmp_path / "odometry.tum"),
            "--save_results",
            str(zip_path),
            "--no_warnings",
        ],
        check=True,
        capture_output=True,
        text=True,
    )
    import json
    import zipfile

    with zipfile.ZipFile(zip_path) as z:
        stats = json.loads(z.read("stats.json"))
    assert ours == pytest.approx(stats["rmse"], rel=1e-6, abs=1e-9)


@pytest.mark.skipif(_evo_ape() is None, reason="evo is not installed (GPL: external tool only)")
def test_rpe_equals_evo_rpe(tmp_path):
    """One run (no pairs across runs): our RPE over 10 frames equals evo_rpe --all_pairs."""
    import json
    import shutil
    import zipfile

    from dynmap_sim.metrics import rpe

    out = tmp_path / "one"
    run_experiment(load_scenario(CI), out_dir=out, days=(1, 1), progress=False)
    export_tum(out, tmp_path)
    truth = np.loadtxt(tmp_path / "truth.tum")
    est = np.loadtxt(tmp_path / "odometry.tum")
    head = lambda q: 2.0 * np.arctan2(q[:, 6], q[:, 7])  # noqa: E731
    ours = rpe(
        np.column_stack([truth[:, 1:3], head(truth)]),
        np.column_stack([est[:, 1:3], head(est)]),
        delta=10,
    ).translation.rmse
    zip_path = tmp_path / "rpe.zip"
    subprocess.run(
        [
            shutil.which("evo_rpe"),
            "tum",
            str(tmp_path / "truth.tum"),
            str(tmp_path / "odometry.tum"),
            "--delta",
            "10",
            "--delta_unit",
            "f",
            "--all_pairs",
            "--save_results",
            str(zip_path),
            "--no_warnings",
        ],
        check=True,
        capture_output=True,
        text=True,
    )
    with zipfile.ZipFile(zip_path) as z:
        stats = json.loads(z.read("stats.json"))
    assert ours == pytest.approx(stats["rmse"], rel=1e-6, abs=1e-9)


def _tables(db):
    con = sqlite3.connect(db)
    try:
        return [
            con.execute(sql).fetchall()
            for sql in (
                "SELECT * FROM scans ORDER BY day, run, step",
                "SELECT * FROM estimates ORDER BY loc, day, run, step",
                "SELECT * FROM day_summaries ORDER BY loc, day",
                "SELECT loc, day, run, n_scans, mean_error_m, max_error_m, rmse_m "
                "FROM run_summaries ORDER BY loc, day, run",
            )
        ]
    finally:
        con.close()


def test_kill_9_and_resume_match_an_unbroken_run(tmp_path):
    """A subprocess running the CLI is SIGKILLed mid-experiment; --resume finishes it with
    exactly the numbers of an unbroken run."""
    args = ["--days", "1-4", "--seed", "3", "-q"]
    full = tmp_path / "full"
    broken = tmp_path / "broken"
    cli = [sys.executable, "-m", "dynmap_sim.cli", "run", str(CI)]
    subprocess.run(cli + args + ["--out", str(full)], check=True, capture_output=True)
    proc = subprocess.Popen(cli + args + ["--out", str(broken)], stderr=subprocess.DEVNULL)
    db = broken / "results.db"
    deadline = time.monotonic() + 120
    done = 0
    while time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.02)
        if db.exists():
            try:
                con = sqlite3.connect(db, timeout=0.1)
                done = con.execute("SELECT count(*) FROM runs").fetchone()[0]
                con.close()
            except sqlite3.Error:
                continue
            if done >= 1:
                break
    if proc.poll() is None:
        os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL, "the experiment finished before it was killed"
    con = sqlite3.connect(db)
    n_before = con.execute("SELECT count(*) FROM runs").fetchone()[0]
    con.close()
    assert 1 <= n_before < 4
    res = subprocess.run(
        cli + args + ["--out", str(broken), "--resume"], capture_output=True, text=True
    )
    assert res.returncode == 0, res.stderr
    assert _tables(full / "results.db") == _tables(db)
