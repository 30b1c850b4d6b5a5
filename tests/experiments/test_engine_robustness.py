"""The engine under misuse and faults (issue 14's reliability audit): one writer per results
folder, checkpoints that cover their fields, a main database file that holds every committed
run, a full disk said clearly, and localizers that break their contract named in one line."""

from __future__ import annotations

import errno
import multiprocessing as mp
import shutil
import sqlite3
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from fake_env import FakeEnv  # noqa: E402
from test_workers import run, scenario, tables  # noqa: E402

from dynmap_sim.cli import main  # noqa: E402
from dynmap_sim.errors import InputError  # noqa: E402
from dynmap_sim.experiments import results as results_mod  # noqa: E402
from dynmap_sim.experiments.localizer_pool import LocalizerContractError  # noqa: E402
from dynmap_sim.experiments.results import DiskFullError, ResultsDB  # noqa: E402
from dynmap_sim.experiments.results.checkpoints import CheckpointStore  # noqa: E402
from dynmap_sim.experiments.runner import ExperimentRunner  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
LOCS = [{"name": "fake_env:RecordingLocalizer", "label": "rec"}, {"name": "odometry"}]


def scn2(tmp_path, **extra):
    return scenario(tmp_path, localizers=LOCS, **extra)


def runner(scn, out, resume=False):
    return ExperimentRunner(
        scn, out, scn.days, 0, resume=resume, overwrite=False, env=FakeEnv(), workers=1
    )


# ---------------------------------------------------------------------- one writer per folder
def test_a_second_writer_is_refused_while_the_first_holds_the_folder(tmp_path):
    scn = scn2(tmp_path)
    out = tmp_path / "o"
    first = runner(scn, out)
    for resume in (False, True):
        with pytest.raises(InputError, match="another dynmap-sim process .* is writing results"):
            runner(scn, out, resume=resume)
    first.run(progress=False)
    ref = tables(out)
    # the lock went with the first writer; the results are whole and continue
    again = runner(scn, out, resume=True)
    assert again.start_index == len(again.slots)
    again.run(progress=False)
    assert tables(out) == ref


def _hold_the_folder(out: str, ready, release) -> None:  # in another process
    ResultsDB.create(out)
    ready.set()
    release.wait(30)


def test_a_writer_in_another_process_is_refused_and_the_results_stay_intact(tmp_path, capsys):
    ctx = mp.get_context("spawn")
    ready, release = ctx.Event(), ctx.Event()
    out = tmp_path / "o"
    proc = ctx.Process(target=_hold_the_folder, args=(str(out), ready, release))
    proc.start()
    try:
        assert ready.wait(60)
        path = ROOT / "worlds" / "scenarios" / "ci-apartment.toml"
        for extra in ([], ["--resume"]):
            assert main(["run", str(path), "--out", str(out), "-q", *extra]) == 2
            err = capsys.readouterr().err.strip()
            assert len(err.splitlines()) == 1 and "Traceback" not in err
            assert f"{out}: another dynmap-sim process (pid {proc.pid}) is writing" in err
    finally:
        release.set()
        proc.join(30)
    assert proc.exitcode == 0
    # the lock died with its process (however it ended)
    ResultsDB.create(out, overwrite=True).close()


# ---------------------------------------------------------------------- checkpoints
@pytest.mark.parametrize("value", [0, 1, 99, -1])
def test_an_edited_next_index_is_refused_as_corrupt(tmp_path, value):
    scn = scn2(tmp_path)
    out = tmp_path / "o"
    run(scn, out, workers=1, stop_after=2)
    con = sqlite3.connect(out / "results.db")
    with con:
        con.execute("UPDATE checkpoint SET next_index = ?", (value,))
    con.close()
    with pytest.raises(InputError, match="checkpoint is corrupt"):
        runner(scn, out, resume=True)
    # the refused resume let go of the folder (whose checkpoint a reader refuses too)
    runner(scn, out.parent / "other").db.close()
    ResultsDB.open(out, lock=True, verify=False).close()
    with pytest.raises(InputError, match="checkpoint is corrupt"):
        ResultsDB.open(out)


def test_every_checkpoint_field_is_covered_by_the_checksum(tmp_path):
    db = ResultsDB.create(tmp_path)
    cp = results_mod.Checkpoint(1, 1, 2, {"x": 1})
    from test_results_store import record

    db.write_run(record(1, 1), [], True, cp, "h", 7)
    for col, value in [("next_day", 5), ("next_run", 9), ("next_index", 2)]:
        with db.con:
            db.con.execute(f"UPDATE checkpoint SET {col} = ?", (value,))
        with pytest.raises(InputError, match="corrupt"):
            db.load_checkpoint("h", 7)
        db.write_run(record(1, 1), [], True, cp, "h", 7)  # a good one again
    assert db.load_checkpoint("h", 7).next_index == 1
    db.close()


def test_a_deleted_results_db_with_its_checkpoint_left_is_not_a_silent_restart(tmp_path, capsys):
    scn = scn2(tmp_path)
    out = tmp_path / "o"
    run(scn, out, workers=1, stop_after=2)
    for suffix in ("", "-wal", "-shm"):
        Path(f"{out}/results.db{suffix}").unlink(missing_ok=True)
    for resume in (False, True):
        with pytest.raises(InputError, match=r"results.db is missing but .*checkpoint holds"):
            runner(scn, out, resume=resume)
    assert sorted(p.name for p in (out / "checkpoint").iterdir())  # nothing removed


def test_the_main_database_file_alone_holds_every_committed_run(tmp_path):
    scn = scn2(tmp_path)
    out = tmp_path / "o"
    r = runner(scn, out)
    seen = []
    write = r._write

    def write_and_copy(*args):  # copy results.db alone while the writer is still open
        done = write(*args)
        copy = tmp_path / f"copy{len(seen)}.db"
        shutil.copy(out / "results.db", copy)
        con = sqlite3.connect(f"file:{copy}?mode=ro", uri=True)
        seen.append(con.execute("SELECT count(*) FROM runs").fetchone()[0])
        con.close()
        return done

    r._write = write_and_copy
    r.run(progress=False)
    assert seen == [1, 2, 3]


# ---------------------------------------------------------------------- a full disk
def _full(*_a, **_k):
    raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_keeps_the_finished_runs_and_leaves_no_tmp_files(tmp_path, monkeypatch):
    scn = scn2(tmp_path)
    out = tmp_path / "o"
    run(scn, out, workers=1, stop_after=1)
    real = Path.write_bytes

    def half_then_full(self, data):  # a partial temporary file, then the disk is full
        real(self, data[: len(data) // 2])
        _full()

    monkeypatch.setattr(Path, "write_bytes", half_then_full)
    with pytest.raises(DiskFullError, match="the disk is full"):
        run(scn, out, workers=1, resume=True)
    monkeypatch.undo()
    assert not list(out.rglob("*.tmp"))
    con = sqlite3.connect(out / "results.db")
    assert con.execute("SELECT count(*) FROM runs").fetchone()[0] == 1
    con.close()
    assert sorted(p.name for p in (out / "checkpoint").iterdir()) == ["loc0-1.pkl", "loc1-1.pkl"]
    # SQLite's own "database or disk is full"
    real_put = CheckpointStore.put

    def full_db(self, *a):
        real_put(self, *a)
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr(CheckpointStore, "put", full_db)
    with pytest.raises(DiskFullError):
        run(scn, out, workers=1, resume=True)
    monkeypatch.undo()
    assert sorted(p.name for p in (out / "checkpoint").iterdir()) == ["loc0-1.pkl", "loc1-1.pkl"]
    # after freeing space, --resume ends with the numbers of an unbroken experiment
    run(scn, out, workers=1, resume=True)
    run(scn, tmp_path / "full", workers=1)
    assert tables(out) == tables(tmp_path / "full")


def test_the_cli_says_the_disk_is_full_in_one_line(tmp_path, monkeypatch, capsys):
    path = ROOT / "worlds" / "scenarios" / "ci-apartment.toml"
    out = tmp_path / "o"
    monkeypatch.setattr(CheckpointStore, "write_localizer_files", _full)
    assert main(["run", str(path), "--out", str(out), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert err.startswith("error: the disk is full")
    # the first run failed: the message says so (not "the runs finished so far are kept")
    assert f"no run had finished; {out} holds the experiment's store" in err and "--resume" in err
    monkeypatch.undo()
    assert main(["run", str(path), "--out", str(out), "-q"]) == 0  # it starts afresh
    capsys.readouterr()
    # the report: said clearly too
    assert main(["run", str(path), "--out", str(tmp_path / "r"), "-q"]) == 0
    capsys.readouterr()
    monkeypatch.setattr(Path, "write_text", _full)
    assert main(["report", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "the disk is full" in err
    assert "the results are kept" in err and "dynmap-sim report" in err


# ---------------------------------------------------------------------- localizer contracts
@pytest.mark.parametrize(
    ("cls", "words"),
    [
        ("NoneLocalizer", r"update\(\) must return a PoseEstimate, got None"),
        ("FlatMeanLocalizer", r"with a \(3,\) mean of finite numbers .*got shape \(2,\)"),
        ("InfiniteCovLocalizer", r"finite \(3, 3\) covariance, got non-finite values"),
    ],
)
@pytest.mark.parametrize("workers", [1, 2])
def test_a_localizer_that_breaks_its_contract_is_named_with_the_rule_run_and_scan(
    tmp_path, cls, words, workers
):
    scn = scenario(
        tmp_path,
        days=[1, 1],
        localizers=[{"name": "odometry"}, {"name": f"worker_localizers:{cls}", "label": "bad"}],
    )
    scan = 2 if cls == "InfiniteCovLocalizer" else 0
    # in-process the class itself; from a worker process an InputError with its message
    with pytest.raises(LocalizerContractError if workers == 1 else InputError) as ei:
        run(scn, tmp_path / "o", workers=workers)
    msg = str(ei.value)
    assert len(msg.splitlines()) == 1, msg
    assert f"localizer 'bad' (worker_localizers.{cls}) broke the Localizer contract" in msg
    assert f"on day 1 run 1 at scan {scan}" in msg
    import re

    assert re.search(words, msg), msg
    assert "workers.py" not in msg and "bench.py" not in msg
    assert not mp.active_children()


def test_the_cli_shows_a_broken_contract_without_a_traceback(tmp_path, capsys):
    (tmp_path / "mine.py").write_text(
        "import numpy as np\n"
        "from dynmap_sim.agent.localization.dead_reckoning import DeadReckoning\n"
        "class Bad(DeadReckoning):\n"
        "    def update(self, odom, scan):\n"
        "        return None\n"
    )
    s = tmp_path / "s.toml"
    s.write_text(
        f'name = "c"\nworld = "{ROOT / "worlds" / "apartment.toml"}"\ndays = [1, 1]\n'
        '[driver]\nmax_run_s = 2.0\n[[localizers]]\nname = "mine:Bad"\n'
    )
    assert main(["run", str(s), "--out", str(tmp_path / "o"), "-q", "--workers", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    assert "localizer 'mine:Bad' (mine.Bad) broke the Localizer contract on day 1 run 1" in err
