"""A results folder under a full disk and after edits or damage (issue 43 items 1, 3, 4): a
folder is a whole store or none, a full disk says what is kept and ``--resume`` then ends
with the numbers of an unbroken run; edited rows or metadata are refused in one line."""

from __future__ import annotations

import shutil
import sqlite3
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from fake_env import FakeEnv  # noqa: E402
from test_workers import run, scenario, tables  # noqa: E402

from dynmap_sim.errors import InputError  # noqa: E402
from dynmap_sim.experiments.results import DiskFullError, ResultsDB  # noqa: E402
from dynmap_sim.experiments.results import store as store_mod  # noqa: E402
from dynmap_sim.experiments.results.writer import RunWriter  # noqa: E402
from dynmap_sim.experiments.runner import ExperimentRunner  # noqa: E402

LOCS = [{"name": "fake_env:RecordingLocalizer", "label": "rec"}, {"name": "odometry"}]
FULL = sqlite3.OperationalError("database or disk is full")


def _raise_full(*_a, **_k):
    raise FULL


def fresh(scn, out, resume=False):
    """A runner that starts (or resumes) without --force (as the CLI's plain ``run``)."""
    return ExperimentRunner(
        scn, out, scn.days, 0, resume=resume, overwrite=False, env=FakeEnv(), workers=1
    )


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished experiment (3 days, two localizers) and its tables."""
    base = tmp_path_factory.mktemp("finished")
    scn = scenario(base, localizers=LOCS)
    run(scn, base / "o", workers=1)
    return scn, base / "o", tables(base / "o")


# ---------------------------------------------------------------------- a full disk
def test_a_full_disk_while_the_store_is_made_leaves_no_store(tmp_path, finished, monkeypatch):
    scn, _, ref = finished
    out = tmp_path / "o"
    monkeypatch.setattr(store_mod, "_put_localizers", _raise_full)
    with pytest.raises(DiskFullError) as err:
        fresh(scn, out)
    assert err.value.runs_kept is None and "nothing was stored" in err.value.what_is_kept()
    assert sorted(p.name for p in out.iterdir()) == [".results.lock"]  # no store, no temp
    monkeypatch.undo()
    fresh(scn, out).run(progress=False)  # the same command starts the experiment
    assert tables(out) == ref


@pytest.mark.parametrize("resume", [False, True])
def test_a_full_disk_in_the_first_run_leaves_a_store_that_starts_again(
    tmp_path, finished, monkeypatch, resume
):
    scn, _, ref = finished
    out = tmp_path / "o"
    monkeypatch.setattr(RunWriter, "_kept_scans", _raise_full)  # mid-transaction
    with pytest.raises(DiskFullError) as err:
        fresh(scn, out).run(progress=False)
    assert err.value.runs_kept == 0 and "no run had finished" in err.value.what_is_kept()
    monkeypatch.undo()
    with ResultsDB.open(out) as db:  # a valid store of this experiment, without runs
        assert db.meta()["checkpoint_format"] and db.query("SELECT count(*) FROM runs") == [(0,)]
    fresh(scn, out, resume=resume).run(progress=False)  # with or without --resume
    assert tables(out) == ref


def test_a_full_disk_after_runs_says_how_many_are_kept_and_resume_ends_unbroken(
    tmp_path, finished, monkeypatch
):
    scn, _, ref = finished
    out = tmp_path / "o"
    calls = {"n": 0}
    real = RunWriter.write

    def full_at_the_third(self, *a):
        calls["n"] += 1
        real(self, *a)
        if calls["n"] == 3:
            raise FULL

    monkeypatch.setattr(RunWriter, "write", full_at_the_third)
    with pytest.raises(DiskFullError) as err:
        fresh(scn, out).run(progress=False)
    assert err.value.runs_kept == 2
    assert "the 2 runs finished so far are kept" in err.value.what_is_kept()
    monkeypatch.undo()
    fresh(scn, out, resume=True).run(progress=False)
    assert tables(out) == ref


def test_reading_on_a_full_disk_says_the_disk_is_full(finished, monkeypatch):
    _, out, _ = finished

    class NoRoom:  # SQLite cannot make its shared-memory file: "disk I/O error"
        def execute(self, *_a):
            raise sqlite3.OperationalError("disk I/O error")

    monkeypatch.setattr(store_mod.sqlite3, "connect", lambda *_a, **_k: NoRoom())
    monkeypatch.setattr(store_mod, "no_space_left", lambda _folder: True)
    with pytest.raises(InputError, match="cannot be read: the disk is full"):
        ResultsDB.open(out)


# ---------------------------------------------------------------------- edits and damage
EDITS = {
    "DELETE FROM day_summaries WHERE day = 1": "day_summaries rows of day 1 do not match",
    "UPDATE meta SET value = '5' WHERE key = 'seed'": r"meta table was edited \(values "
    "changed: seed\\)",
    "UPDATE estimates SET err_m = err_m * 10": "the day_summaries row of localizer 0 on day 1 "
    "does not summarize its scans",
    "UPDATE runs SET collisions = 5 WHERE day = 3": "runs rows of day 3 run 1 do not match",
    "UPDATE run_summaries SET mean_error_m = 1": "run_summaries rows of day 1 run 1",
    "UPDATE day_summaries SET mean_error_m = 1, max_error_m = 1": "day_summaries rows",
    "UPDATE digests SET sha256 = 'x' WHERE tbl = 'day_summaries' AND day = 2": "day 2 do not",
    "DELETE FROM scans WHERE day = 2 AND step = 3": "day 2 run 1 has 50 scans, not 51",
    "DELETE FROM digests WHERE day = 2 AND tbl = 'run_summaries'": "day 2 run 1 has "
    "run_summaries rows without a checksum",
    "UPDATE meta SET value = '{not json' WHERE key = 'days'": "meta value 'days' is not JSON",
    "DELETE FROM meta WHERE key IN ('days', 'checkpoint_format')": r"rows deleted: "
    "checkpoint_format, days",
    "DELETE FROM meta": "meta has no checksums row",
    "DELETE FROM runs WHERE day = 3; DELETE FROM digests WHERE day = 3": "meta says the "
    "experiment is complete but 2 of its 3 runs are stored",
    "UPDATE checkpoint SET next_index = 2": "the checkpoint is corrupt",
}


@pytest.mark.parametrize(("sql", "words"), EDITS.items(), ids=list(range(len(EDITS))))
def test_an_edited_folder_is_refused_by_readers_and_resume(tmp_path, finished, sql, words):
    scn, out, _ = finished
    bad = tmp_path / "bad"
    shutil.copytree(out, bad)
    con = sqlite3.connect(bad / "results.db")
    con.executescript(sql)
    con.close()
    with pytest.raises(InputError, match=words) as err:
        ResultsDB.open(bad)
    assert "\n" not in str(err.value) and str(err.value).startswith(str(bad))
    with pytest.raises(InputError, match=words):
        fresh(scn, bad, resume=True)


def test_an_edited_estimate_is_refused_before_a_resume(tmp_path, finished):
    """The errors no longer the distances of the estimates: the writer checks every one
    (the readers' numbers come from the errors, which the day summaries guard)."""
    scn, out, _ = finished
    bad = tmp_path / "bad"
    shutil.copytree(out, bad)
    con = sqlite3.connect(bad / "results.db")
    con.executescript("UPDATE estimates SET x = x + 1 WHERE day = 2")
    con.close()
    with pytest.raises(InputError, match="estimates.err_m. of localizer 0 on day 2 are not"):
        fresh(scn, bad, resume=True)


def test_a_damaged_file_is_named_not_a_traceback(tmp_path, finished):
    _, out, _ = finished
    bad = tmp_path / "bad"
    shutil.copytree(out, bad)
    db = bad / "results.db"
    data = bytearray(db.read_bytes())
    mid = len(data) // 2
    data[mid : mid + 64] = b"\xff" * 64
    db.write_bytes(bytes(data))
    with pytest.raises(InputError, match=f"{db}: the database file is damaged"):
        ResultsDB.open(bad)


def test_garbage_appended_to_the_wal_loses_nothing(tmp_path, finished):
    _, out, ref = finished
    copy = tmp_path / "c"
    shutil.copytree(out, copy)
    with open(copy / "results.db-wal", "ab") as f:
        f.write(bytes(range(256)) * 20)
    ResultsDB.open(copy).close()
    assert tables(copy) == ref


def test_a_state_pickled_before_a_module_moved_still_loads():
    """A checkpoint pickled when ``DeadReckoning`` lived in ``dynmap_sim.agent.dead_reckoning``
    resumes: the unpickler looks the class up at its new place."""
    import pickle

    from dynmap_sim.agent.localization.dead_reckoning import DeadReckoning
    from dynmap_sim.experiments.results.checkpoints import MOVED_MODULES, load_state

    blob = pickle.dumps({"localizers": [DeadReckoning]}, protocol=2)  # GLOBAL "module\nname"
    new = b"dynmap_sim.agent.localization.dead_reckoning"
    old = b"dynmap_sim.agent.dead_reckoning"
    assert MOVED_MODULES[old.decode()] == new.decode()
    before = blob.replace(new + b"\n", old + b"\n")
    assert before != blob
    with pytest.raises(ModuleNotFoundError):
        pickle.loads(before)  # noqa: S301 - the test's own bytes
    assert load_state(before) == {"localizers": [DeadReckoning]}
