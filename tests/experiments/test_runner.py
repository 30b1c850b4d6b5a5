"""The runner's bookkeeping on a fast stand-in env: call order, same stream for all
localizers, resume equivalence, kidnapping, summaries (the real env: test_end_to_end.py)."""

import sqlite3
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from fake_env import FakeEnv  # noqa: E402

from dynmap_sim.errors import InputError  # noqa: E402
from dynmap_sim.experiments.runner import ExperimentRunner  # noqa: E402
from dynmap_sim.experiments.scenario import parse_scenario  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def scenario(tmp_path, **extra):
    data = {
        "name": "t",
        "world": str(ROOT / "worlds" / "apartment.toml"),
        "days": [1, 3],
        "driver": {"max_run_s": 5.0},
        "localizers": [
            {"name": "fake_env:RecordingLocalizer", "label": "rec"},
            {"name": "odometry", "label": "odo-a"},
            {"name": "odometry", "label": "odo-b"},
        ],
    }
    data.update(extra)
    return parse_scenario(data, tmp_path / "s.toml")


def run(scn, out, resume=False, env=None, stop_after=None, workers=1):
    env = env if env is not None else FakeEnv()
    r = ExperimentRunner(
        scn, out, scn.days, 0, resume=resume, overwrite=not resume, env=env, workers=workers
    )
    r.run(progress=False, stop_after=stop_after)  # stop_after: as if killed after some runs
    return r


def table(out, sql):
    con = sqlite3.connect(out / "results.db")
    try:
        return con.execute(sql).fetchall()
    finally:
        con.close()


def test_call_order_and_same_stream(tmp_path):
    scn = scenario(tmp_path, days=[1, 2])
    r = run(scn, tmp_path / "o")
    calls = r.localizers()[0].calls
    assert calls == [
        ("begin_run", 1, 1, True),
        ("end_run",),
        ("end_day",),
        ("begin_run", 2, 1, False),
        ("end_run",),
        ("end_day",),
    ]
    # the same class with the same params on the same stream gives the same numbers
    a = table(tmp_path / "o", "SELECT x, y, theta FROM estimates WHERE loc=1 ORDER BY day, step")
    b = table(tmp_path / "o", "SELECT x, y, theta FROM estimates WHERE loc=2 ORDER BY day, step")
    assert a == b and len(a) == 2 * 51
    # extras are stored; point classes are scored against the beam labels (all walls)
    ex = table(
        tmp_path / "o",
        "SELECT scan_loglik, lambda_min, timescale, safe_mode FROM estimates WHERE loc=0 LIMIT 1",
    )
    assert ex == [(-1.5, 100.0, 2, 0)]
    conf = table(tmp_path / "o", "SELECT confusion FROM point_classes WHERE loc=0")
    c = sum(np.frombuffer(b, "<i8").reshape(4, 4) for (b,) in conf)
    assert c[3, 3] == 8 * 2 * 51 and c.sum() == c[3, 3]
    days = table(
        tmp_path / "o", "SELECT day, loc, mean_scan_loglik FROM day_summaries ORDER BY day, loc"
    )
    assert [d[:2] for d in days] == [(1, 0), (1, 1), (1, 2), (2, 0), (2, 1), (2, 2)]
    assert days[0][2] == -1.5 and days[1][2] is None


def test_resume_gives_the_numbers_of_an_unbroken_run(tmp_path):
    scn = scenario(tmp_path)
    run(scn, tmp_path / "full")
    run(scn, tmp_path / "broken", stop_after=2)
    assert table(tmp_path / "broken", "SELECT count(*) FROM runs") == [(2,)]
    env = FakeEnv()
    r = run(scn, tmp_path / "broken", resume=True, env=env)
    assert r.start_index == 2 and [x[1:] for x in env.resets] == [(3, 1)]
    for sql in (
        "SELECT * FROM estimates ORDER BY loc, day, run, step",
        "SELECT * FROM scans ORDER BY day, run, step",
        "SELECT * FROM day_summaries ORDER BY loc, day",
        "SELECT loc, day, run, n_scans, mean_error_m, max_error_m FROM run_summaries "
        "ORDER BY loc, day, run",
    ):
        assert table(tmp_path / "full", sql) == table(tmp_path / "broken", sql)
    # the recording localizer's history spans the break: it was restored from the checkpoint
    assert len(r.localizers()[0].calls) == 3 * 3


def test_resume_refuses_other_seed_or_days(tmp_path):
    scn = scenario(tmp_path)
    run(scn, tmp_path / "o", stop_after=1)
    msg = r"seed 0 and days \[1, 3\], not seed 0 and days \[1, 2\]"
    with pytest.raises(InputError, match=msg):
        ExperimentRunner(scn, tmp_path / "o", (1, 2), 0, resume=True, env=FakeEnv())
    with pytest.raises(InputError, match="already holds results"):
        ExperimentRunner(scn, tmp_path / "o", scn.days, 0, resume=False, env=FakeEnv())


def test_kidnapping_teleports_the_robot_and_odometry_does_not_notice(tmp_path):
    scn = scenario(
        tmp_path,
        days=[1, 1],
        kidnappings=[{"day": 1, "time_s": 2.0, "pose": [6.0, 4.0, 0.0]}],
    )
    run(scn, tmp_path / "o")
    ev = table(tmp_path / "o", "SELECT step, kind FROM events WHERE kind='kidnap'")
    assert ev == [(20, "kidnap")]
    err = [
        e for (e,) in table(tmp_path / "o", "SELECT err_m FROM estimates WHERE loc=1 ORDER BY step")
    ]
    assert max(err[:20]) < 0.1 and min(err[21:]) > 1.0
    x = table(tmp_path / "o", "SELECT x, y FROM scans WHERE step=21")[0]
    assert abs(x[0] - 6.0) < 0.2 and abs(x[1] - 4.0) < 0.2


def test_days_outside_the_calendar_are_refused(tmp_path):
    scn = scenario(tmp_path)
    with pytest.raises(InputError, match="calendar"):
        ExperimentRunner(scn, tmp_path / "o", (40, 41), 0, resume=False, env=FakeEnv())


def test_check_rows_from_a_kidnapped_run(tmp_path):
    from dynmap_sim.analysis.check import evaluate

    scn = scenario(
        tmp_path,
        days=[1, 1],
        kidnappings=[{"day": 1, "time_s": 2.0, "pose": [6.0, 4.0, 0.0]}],
        expectations={
            "no_collisions": True,
            "localizers": {
                "odo-a": {"max_time_to_recover_s": 10.0, "lost_fraction": 0.5},
                "rec": {"mean_error_m": 10.0},
            },
        },
    )
    run(scn, tmp_path / "o")
    rows = {(r.subject, r.criterion): r for r in evaluate(scn, tmp_path / "o", 0)}
    assert rows[("robot", "collisions")].passed
    rec = rows[("odo-a", "time to recover [s]")]
    assert rec.measured == float("inf") and not rec.passed  # never recovers
    lost = rows[("odo-a", "lost fraction")]
    assert lost.measured == pytest.approx(30 / 51) and not lost.passed  # scans 21..50
    assert rows[("rec", "mean error per day [m]")].passed


def test_resume_refuses_a_changed_world_file(tmp_path):
    world = tmp_path / "world.toml"
    world.write_text((ROOT / "worlds" / "apartment.toml").read_text())
    scn = scenario(tmp_path, world=str(world))
    run(scn, tmp_path / "o", stop_after=1)
    world.write_text(world.read_text() + "\n# edited\n")
    with pytest.raises(InputError, match="scenario or its world file"):
        ExperimentRunner(scn, tmp_path / "o", scn.days, 0, resume=True, env=FakeEnv())


def test_an_unpicklable_localizer_is_named(tmp_path):
    scn = scenario(
        tmp_path,
        days=[1, 1],
        localizers=[
            {"name": "odometry"},
            {"name": "fake_env:UnpicklableLocalizer", "label": "bad one"},
        ],
    )
    with pytest.raises(InputError, match="'bad one'.*cannot be pickled"):
        run(scn, tmp_path / "o")
    assert table(tmp_path / "o", "SELECT count(*) FROM runs") == [(0,)]


def test_report_with_extras_and_point_classes(tmp_path):
    import csv

    from dynmap_sim.analysis.report import write_report

    scn = scenario(tmp_path, days=[1, 2])
    run(scn, tmp_path / "o")
    names = {p.name for p in write_report(tmp_path / "o")}
    assert {"likelihood_certainty.png", "summary.md"} <= names
    # B&D Figs. 10-13 per day, for the localizer that reports likelihood and timescales
    assert {"dyn_likelihood_per_day.png", "dyn_lambda_min_per_day.png"} <= names
    assert any(n.startswith("dyn_timescale_trend_") for n in names)
    assert any(n.startswith("dyn_timescale_usage_") for n in names)
    with (tmp_path / "o" / "per_day.csv").open() as fh:
        rows = [r for r in csv.DictReader(fh) if r["localizer"] == "rec"]
    assert [float(r["mean_scan_loglik"]) for r in rows] == [-1.5, -1.5]
    assert [float(r["mean_lambda_min"]) for r in rows] == [100.0, 100.0]
    md = (tmp_path / "o" / "summary.md").read_text()
    assert "## Point classes" in md and "| rec | static | 1.000 | 1.000 |" in md


@pytest.mark.parametrize("workers", [1, 2])
def test_declared_diagnostics_reach_the_store(tmp_path, workers):
    """A localizer's own diagnostics get columns and rows without any schema edit."""
    from dynmap_sim.experiments.results import ResultsDB

    scn = scenario(
        tmp_path,
        days=[1, 2],
        localizers=[
            {"name": "fake_env:DeclaringLocalizer", "label": "hw"},
            {"name": "odometry", "label": "odo"},
        ],
    )
    run(scn, tmp_path / "o", workers=workers)
    with ResultsDB.open(tmp_path / "o") as db:
        d = db.per_scan(0)
        n = len(d["step"])
        assert n == 2 * 51 and d["point_class_counts"].shape == (n, 4)
        np.testing.assert_array_equal(d["point_class_counts"][:, 3], np.tile(np.arange(1, 52), 2))
        np.testing.assert_array_equal(d["map_slot"], np.tile(np.arange(1, 52) % 3, 2))
        assert np.isnan(d["scan_loglik"]).all()  # it reports no standard diagnostic
        days, counts = db.run_diagnostic_per_day(0, "slot_counts")
        assert days.tolist() == [1, 2] and counts.tolist() == [[17, 17, 17]] * 2
        assert db.run_diagnostic(0, "path_m")[2].tolist() == pytest.approx([5.1, 5.1])
        notes = db.artifacts(0, "day_note")
        assert [(day, a["updates"].tolist()) for day, a in notes] == [(1, [51]), (2, [51])]
        assert db.declared(1) == () and "map_slot" not in db.per_scan(1)


@pytest.mark.parametrize(
    ("localizers", "max_run_s", "robot_s", "wall_s"),
    [
        (["odometry"], None, 60.0, 600 * 2.5e-3),  # 10 m at 0.5 m/s: 20 s a run
        (["odometry", "static-mcl", "dynamic-map"], None, 60.0, 600 * 5.5e-3),
        (["odometry"], 5.0, 15.0, 150 * 2.5e-3),  # stopped by max_run_s
    ],
)
def test_the_experiments_size_is_its_runs_robot_time_and_an_estimate(
    tmp_path, localizers, max_run_s, robot_s, wall_s
):
    from dynmap_sim.experiments.runner import experiment_size

    scn = parse_scenario(
        {
            "name": "size",
            "days": [1, 3],
            "world": str(ROOT / "worlds" / "apartment.toml"),
            "driver": {"speed_mps": 0.5, "max_run_s": max_run_s},
            "localizers": [{"name": n, "label": f"l{k}"} for k, n in enumerate(localizers)],
        },
        tmp_path / "s.toml",
    )
    route = np.array([[0.0, 0.0], [6.0, 0.0], [6.0, 4.0]])
    size = experiment_size(scn, 3, route, 0.1)
    assert (size.runs, size.robot_s) == (3, pytest.approx(robot_s))
    assert size.wall_s == pytest.approx(wall_s)


def test_validate_and_run_state_the_experiments_size(tmp_path, capsys):
    from dynmap_sim.cli import main

    path = ROOT / "worlds" / "scenarios" / "ci-apartment.toml"
    assert main(["validate", str(path)]) == 0
    assert f"{path}: OK (3 runs, 60 s of robot time, roughly " in capsys.readouterr().out
    assert main(["run", str(path), "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert err.startswith("ci-apartment: 3 runs, 60 s of robot time, roughly ")
