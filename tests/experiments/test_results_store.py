"""The SQLite results store: bulk rows, summaries, checkpoints and their integrity checks."""

import sqlite3

import numpy as np
import pytest

from dynmap_sim.errors import InputError
from dynmap_sim.experiments.results import Checkpoint, ResultsDB, RunRecord


def record(day, run, n=20, n_loc=2, offset=0.1):
    t = 100.0 + 0.1 * np.arange(n)
    truth = np.stack([0.1 * np.arange(n), np.zeros(n), np.zeros(n)], axis=1)
    est = np.stack([truth + [offset * (k + 1), 0.0, 0.0] for k in range(n_loc)])
    extras = np.full((n_loc, n, 4), np.nan)
    extras[1, :, 0] = -2.0  # the second localizer reports a scan log-likelihood
    return RunRecord(
        day=day,
        run=run,
        date="2026-01-05",
        start_s=100.0,
        t_s=t,
        truth=truth,
        collision=np.zeros(n, bool),
        estimates=est,
        cov_diag=np.full((n_loc, n, 3), 0.01),
        extras=extras,
        confusion=np.zeros((n_loc, 4, 4), np.int64),
        terminated=True,
        route_progress=1.0,
        skipped_waypoints=0,
        wall_s=0.5,
        events=[(3, 100.3, "detour", "waypoint 1")],
        segments=np.array([[0.0, 0.0, 1.0, 0.0]]),
        segment_class=np.array([1], np.int8),
    )


def make_db(tmp_path):
    db = ResultsDB.create(tmp_path)
    db.set_meta(first_date="2026-01-05", days=[1, 1])
    db.set_localizers([("a", "odometry", {}), ("b", "odometry", {"var_per_m": 0.1})])
    return db


def test_write_run_rows_summaries_and_checkpoint(tmp_path):
    db = make_db(tmp_path)
    cp = Checkpoint(1, 1, 2, {"x": np.arange(3)})
    db.write_run(record(1, 1), [], True, cp, "h", 7)
    assert db.query("SELECT count(*) FROM scans")[0][0] == 20
    assert db.query("SELECT count(*) FROM estimates")[0][0] == 40
    d = db.per_scan(0)
    np.testing.assert_allclose(d["err_m"], 0.1)
    assert np.isnan(d["scan_loglik"]).all()
    np.testing.assert_allclose(db.per_scan(1)["scan_loglik"], -2.0)
    days = db.query("SELECT loc, mean_error_m, mean_scan_loglik FROM day_summaries ORDER BY loc")
    assert days[0][1] == pytest.approx(0.1) and days[0][2] is None
    assert days[1][1] == pytest.approx(0.2) and days[1][2] == pytest.approx(-2.0)
    got = db.load_checkpoint("h", 7)
    assert got is not None and got.next_index == 1 and got.next_run == 2
    np.testing.assert_array_equal(got.state["x"], np.arange(3))
    seg, cls = db.geometry(1, 1)
    np.testing.assert_array_equal(seg, [[0, 0, 1, 0]])
    db.close()


def test_mismatched_or_corrupt_checkpoint_is_refused(tmp_path):
    db = make_db(tmp_path)
    db.write_run(record(1, 1), [], True, Checkpoint(1, 1, 2, {"x": 1}), "h", 7)
    with pytest.raises(InputError, match="different scenario"):
        db.load_checkpoint("other", 7)
    with pytest.raises(InputError, match="seed 7"):
        db.load_checkpoint("h", 8)
    blob = bytearray(db.query("SELECT blob FROM checkpoint")[0][0])
    blob[len(blob) // 2] ^= 0xFF
    with db.con:
        db.con.execute("UPDATE checkpoint SET blob=?", (bytes(blob),))
    with pytest.raises(InputError, match="corrupt"):
        db.load_checkpoint("h", 7)
    db.close()


def test_existing_results_are_not_clobbered_and_garbage_is_refused(tmp_path):
    make_db(tmp_path).close()
    with pytest.raises(InputError, match="already holds results"):
        ResultsDB.create(tmp_path)
    ResultsDB.create(tmp_path, overwrite=True).close()
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "results.db").write_bytes(b"this is not sqlite" * 100)
    with pytest.raises(InputError, match="not a dynmap_sim results database"):
        ResultsDB.open(bad)
    with pytest.raises(InputError, match="no results database"):
        ResultsDB.open(tmp_path / "nowhere")


def test_a_run_is_all_or_nothing(tmp_path):
    """A failure in the middle of write_run leaves no partial rows (one transaction)."""
    db = make_db(tmp_path)
    rec = record(1, 1)
    rec.events = [(1, 0.0, "x")]  # malformed: 3 fields instead of 4 -> fails mid-transaction
    with pytest.raises((sqlite3.Error, ValueError)):
        db.write_run(rec, [], True, Checkpoint(1, 1, 2, {}), "h", 0)
    assert db.query("SELECT count(*) FROM scans")[0][0] == 0
    assert db.query("SELECT count(*) FROM checkpoint")[0][0] == 0
    db.close()


def test_timescale_selection_counts_add_up_per_day(tmp_path):
    db = make_db(tmp_path)
    for run, counts in ((1, [5, 0, 1, 2, 3]), (2, [1, 1, 1, 1, 1])):
        rec = record(1, run)
        rec.timescale_counts = np.array([[0] * 5, counts], np.int64)  # only the second selects
        db.write_run(rec, [], run == 2, None, "h", 7)
    days, counts = db.timescale_counts_per_day(1)
    assert days.tolist() == [1] and counts.tolist() == [[6, 1, 2, 3, 4]]
    days, counts = db.timescale_counts_per_day(0)
    assert len(days) == 0 and counts.shape == (0, 5)
    db.write_run(record(1, 2), [], True, None, "h", 7)  # a redone run replaces its counts
    assert db.timescale_counts_per_day(1)[1].tolist() == [[5, 0, 1, 2, 3]]
    db.close()
