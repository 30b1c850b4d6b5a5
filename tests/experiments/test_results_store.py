"""The SQLite results store: bulk rows, summaries, checkpoints and their integrity checks."""

import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from dynmap_sim.errors import InputError
from dynmap_sim.experiments.results import (
    RESULTS_FORMAT,
    Checkpoint,
    LocalizerDiagnostics,
    ResultsDB,
    RunRecord,
)
from dynmap_sim.types import Diagnostic

#: A results folder written by the version before declared diagnostics (results format 1).
FORMAT_1 = Path(__file__).resolve().parents[1] / "data" / "pre-round-2" / "ci-apartment"

LOGLIK = Diagnostic("scan_loglik", "float64")
COUNTS = Diagnostic("timescale_counts", "int64", (5,), per="run", counts_of="timescales")


def record(day, run, n=20, n_loc=2, offset=0.1):
    t = 100.0 + 0.1 * np.arange(n)
    truth = np.stack([0.1 * np.arange(n), np.zeros(n), np.zeros(n)], axis=1)
    est = np.stack([truth + [offset * (k + 1), 0.0, 0.0] for k in range(n_loc)])
    diagnostics = [LocalizerDiagnostics() for _ in range(n_loc)]
    # the second localizer reports a scan log-likelihood
    diagnostics[1] = LocalizerDiagnostics((LOGLIK,), {"scan_loglik": np.full(n, -2.0)})
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
        confusion=np.zeros((n_loc, 4, 4), np.int64),
        terminated=True,
        route_progress=1.0,
        skipped_waypoints=0,
        wall_s=0.5,
        events=[(3, 100.3, "detour", "waypoint 1")],
        segments=np.array([[0.0, 0.0, 1.0, 0.0]]),
        segment_class=np.array([1], np.int8),
        diagnostics=diagnostics,
    )


def make_db(tmp_path):
    return ResultsDB.create(
        tmp_path,
        meta={"first_date": "2026-01-05", "days": [1, 1], "seed": 7, "experiment_hash": "h"},
        localizers=[("a", "odometry", {}), ("b", "odometry", {"var_per_m": 0.1})],
    )


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
    make_db(tmp_path).close()  # a store without a finished run holds nothing to lose
    with make_db(tmp_path) as db:
        db.write_run(record(1, 1), [], True, None, "h", 7)
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
        for k, c in enumerate(([0] * 5, counts)):  # only the second selects
            rec.diagnostics[k] = LocalizerDiagnostics((COUNTS,), {}, {COUNTS.name: np.array(c)})
        db.write_run(rec, [], run == 2, None, "h", 7)
    days, counts = db.timescale_counts_per_day(1)
    assert days.tolist() == [1] and counts.tolist() == [[6, 1, 2, 3, 4]]
    days, counts = db.timescale_counts_per_day(0)
    assert len(days) == 0 and counts.shape == (0, 5)
    db.write_run(record(1, 2), [], True, None, "h", 7)  # a redone run replaces its counts
    assert db.timescale_counts_per_day(1)[1].tolist() == [[5, 0, 1, 2, 3]]
    db.close()


#: What a localizer like Hentschel & Wagner's might report: point-class counts per scan, the
#: chosen map slot, tracked objects; a per-run value from its own hook; a day artifact.
HW = (
    Diagnostic("point_class_counts", "int64", (4,), doc="unknown/dynamic/semi-static/static"),
    Diagnostic("map_slot", "int64", doc="the chosen map"),
    Diagnostic("n_tracked", "uint16"),
    Diagnostic("slot_counts", "int64", (3,), per="run", counts_of="map_slot"),
    Diagnostic("mean_speed", "float64", (2,), per="run"),
)


def hw_diagnostics(n, day_done):
    counts = np.tile([0, 2, 5, 40], (n, 1)).astype(float)
    counts[3] = np.nan  # not reported at scan 3
    return LocalizerDiagnostics(
        HW,
        {
            "point_class_counts": counts,
            "map_slot": np.arange(n, dtype=float) % 3,
            "n_tracked": np.full(n, 7.0),
        },
        {"slot_counts": np.array([7, 7, 6]), "mean_speed": np.array([0.5, 0.25])},
        {"objects": {"xy": np.zeros((3, 2)), "ids": np.arange(3)}, "log": b"\x00\x01"}
        if day_done
        else {},
    )


def test_a_new_localizer_declares_its_diagnostics_and_the_store_keeps_them(tmp_path):
    db = make_db(tmp_path)
    assert db.format == RESULTS_FORMAT == db.meta()["results_format"]
    for run in (1, 2):
        rec = record(1, run)
        rec.diagnostics[0] = hw_diagnostics(20, day_done=run == 2)
        db.write_run(rec, [], run == 2, None, "h", 7)
    assert db.declared(0) == HW and db.declared(1) == (LOGLIK,)
    d = db.per_scan(0)
    assert d["point_class_counts"].shape == (40, 4)
    np.testing.assert_array_equal(d["point_class_counts"][0], [0, 2, 5, 40])
    assert np.isnan(d["point_class_counts"][3]).all() and np.isnan(d["scan_loglik"]).all()
    assert d["map_slot"][:4].tolist() == [0, 1, 2, 0] and set(d["n_tracked"]) == {7.0}
    assert "map_slot" not in db.per_scan(1)  # declared by the other localizer only
    cols = [r[1] for r in db.query("PRAGMA table_info(estimates)")]
    assert cols[-3:] == ["point_class_counts", "map_slot", "n_tracked"]
    days, runs, speed = db.run_diagnostic(0, "mean_speed")
    assert days.tolist() == [1, 1] and runs.tolist() == [1, 2]
    np.testing.assert_array_equal(speed, [[0.5, 0.25], [0.5, 0.25]])
    days, per_day = db.run_diagnostic_per_day(0, "slot_counts")
    assert days.tolist() == [1] and per_day.tolist() == [[14, 14, 12]]
    ((day, objects),) = db.artifacts(0, "objects")
    assert day == 1 and objects["ids"].tolist() == [0, 1, 2]
    assert db.artifacts(0, "log") == [(1, b"\x00\x01")] and db.artifacts(1, "objects") == []
    db.close()


def test_declarations_that_cannot_be_stored_are_refused(tmp_path):
    db = make_db(tmp_path)
    for bad, match in (
        ((Diagnostic("err_m", "float64"),), "column of every estimate"),
        ((Diagnostic("scan_loglik", "float64", (2,)),), "must be a scalar"),
        ((LOGLIK, LOGLIK), "declared twice"),
    ):
        rec = record(1, 1)
        rec.diagnostics[0] = LocalizerDiagnostics(bad)
        with pytest.raises(InputError, match=match):
            db.write_run(rec, [], True, None, "h", 7)
    rec = record(1, 1)
    rec.diagnostics[0] = LocalizerDiagnostics((Diagnostic("slot", "int64"),))
    rec.diagnostics[1] = LocalizerDiagnostics((Diagnostic("slot", "float64"),))
    with pytest.raises(InputError, match="'slot' of localizer 1 is REAL but another"):
        db.write_run(rec, [], True, None, "h", 7)
    assert db.query("SELECT count(*) FROM scans")[0][0] == 0  # nothing of it was kept
    db.close()


def test_results_of_format_1_are_read_but_not_continued(tmp_path):
    old = tmp_path / "old"
    shutil.copytree(FORMAT_1, old)
    with ResultsDB.open(old) as db:
        assert db.format == 1 and db.declared(0) == ()
        d = db.per_scan(0)
        assert len(d["err_m"]) > 0 and set(d) >= {"scan_loglik", "timescale", "safe_mode"}
        assert db.artifacts(0, "map_snapshot") == []
        assert len(db.timescale_counts_per_day(0)[0]) == 0
        with pytest.raises(InputError, match="results format 1 .* not continued"):
            db.write_run(record(9, 1), [], True, None, "h", 0)
        meta = db.meta()
        with pytest.raises(InputError, match="results format 1"):
            db.load_checkpoint(meta["experiment_hash"], meta["seed"])
        assert db.load_checkpoint(meta["experiment_hash"], meta["seed"], to_resume=False)


def test_a_newer_format_is_refused(tmp_path):
    make_db(tmp_path).set_meta(results_format=RESULTS_FORMAT + 1)
    with pytest.raises(
        InputError, match=f"results format {RESULTS_FORMAT + 1}, written by a newer"
    ):
        ResultsDB.open(tmp_path)


def test_declarations_are_checked_where_they_are_made():
    from dynmap_sim.experiments.localizer_pool import DiagnosticsRecorder

    with pytest.raises(ValueError, match="lower case"):
        Diagnostic("Scan Loglik", "float64")
    with pytest.raises(ValueError, match="not numeric"):
        Diagnostic("note", "str")
    with pytest.raises(ValueError, match="counts_of needs per='run'"):
        Diagnostic("slots", "int64", (3,), counts_of="slot")

    class Twice:
        diagnostics = (LOGLIK, LOGLIK)

    with pytest.raises(InputError, match="distinct names"):
        DiagnosticsRecorder(Twice(), 3)

    class Undeclared:
        diagnostics = (COUNTS,)

        def run_diagnostics(self):
            return {"path_m": 1.0}

    rec = DiagnosticsRecorder(Undeclared(), 2)
    rec.scan(0, {"timescales": (0, 4, 4, 9)})  # 9 is no timescale: not counted
    assert rec.out.per_run["timescale_counts"].tolist() == [1, 0, 0, 0, 2]
    with pytest.raises(ValueError, match="'path_m' is not a declared per-run value"):
        rec.end_run(Undeclared())


def test_results_of_format_3_are_read_but_not_continued(tmp_path):
    """Format 3 (before the checksums) is read without them and refused for a resume."""
    with make_db(tmp_path) as db:
        db.write_run(record(1, 1), [], True, Checkpoint(1, 1, 2, {}), "h", 7)
        db.con.execute("DROP TABLE digests")
        db.set_meta(results_format=3)
    with ResultsDB.open(tmp_path) as db:
        assert db.format == 3 and len(db.per_scan(0)["err_m"]) == 20
        with pytest.raises(InputError, match="format 3 .*before the checksums.* not continued"):
            db.load_checkpoint("h", 7)
