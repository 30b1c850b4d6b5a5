"""``ResultsDB``: opening, creating and closing a results store, its metadata, and writing a
run with its checkpoint in one transaction."""

from __future__ import annotations

import json
import os
import sqlite3
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from dynmap_sim.errors import InputError
from dynmap_sim.experiments.results.checkpoints import CheckpointStore
from dynmap_sim.experiments.results.folder import (
    DiskFullError,
    FolderLock,
    disk_full_is_clear,
    is_disk_full,
    no_space_left,
    orphaned_checkpoint,
)
from dynmap_sim.experiments.results.integrity import (
    check_complete,
    check_digests,
    check_integrity,
    check_meta,
    check_scans,
    cover_digest,
    value_hash,
    write_digests,
)
from dynmap_sim.experiments.results.reader import ResultsReader
from dynmap_sim.experiments.results.records import Checkpoint, RunRecord
from dynmap_sim.experiments.results.schema import (
    CHECKPOINT_DIR,
    DB_NAME,
    FORMAT_LACKS,
    RESULTS_FORMAT,
    SCHEMA,
    UPDATE_TIME_CPU,
)
from dynmap_sim.experiments.results.writer import RunWriter
from dynmap_sim.metrics import RunSummary

#: The name a new store is built under before it is renamed to ``results.db``.
NEW_DB_NAME = ".results.db.new"

Localizers = list[tuple[str, str, dict[str, Any]]]


class ResultsDB(ResultsReader):
    """One experiment's SQLite store (open with :meth:`create` or :meth:`open`)."""

    def __init__(self, path: Path, con: sqlite3.Connection, lock: FolderLock | None = None) -> None:
        self.path = path
        self.con = con
        self._lock = lock
        self._per_scan = None
        self._checkpoints = CheckpointStore(con, path)

    @property
    def checkpoint_dir(self) -> Path:
        return self.path.parent / CHECKPOINT_DIR

    # ------------------------------------------------------------------ opening
    @classmethod
    def create(
        cls,
        out_dir: str | Path,
        overwrite: bool = False,
        meta: Mapping[str, Any] | None = None,
        localizers: Localizers | None = None,
    ) -> ResultsDB:
        """Create a fresh store in ``out_dir`` with its ``meta`` and ``localizers``; refuse
        to clobber results unless asked (a store without a finished run is replaced: nothing
        is lost). The store is built under a temporary name and renamed into place, so the
        folder holds either a whole store or none, also when the disk fills up."""
        d = Path(out_dir)
        d.mkdir(parents=True, exist_ok=True)
        lock = FolderLock(d)  # refuses a second writer before anything is touched
        try:
            path = d / DB_NAME
            _clear_for_new(d, path, overwrite)
            items = {"results_format": RESULTS_FORMAT, "update_time": UPDATE_TIME_CPU}
            _build(d / NEW_DB_NAME, path, {**items, **(meta or {})}, localizers or [])
            os.replace(d / NEW_DB_NAME, path)
            _fsync_dir(d)
            db = cls(path, sqlite3.connect(path), lock)
            with disk_full_is_clear(d, str(path), lambda: 0):
                db.con.execute("PRAGMA journal_mode=WAL")
                db.con.execute("PRAGMA synchronous=NORMAL")
        except BaseException:
            lock.release()
            raise
        return db

    @classmethod
    def open(cls, out_dir: str | Path, lock: bool = False, verify: bool = True) -> ResultsDB:
        """Open an existing results folder (or ``results.db`` path); ``lock``: as its one
        writer (refused while another process writes there); ``verify``: refuse rows or
        metadata that were edited or damaged (:mod:`.integrity`)."""
        p = Path(out_dir)
        path = p if p.suffix == ".db" else p / DB_NAME
        if not path.is_file():
            raise InputError(f"{path}: no results database here")
        held = FolderLock(path.parent) if lock else None
        try:
            con = sqlite3.connect(path)
            con.execute("PRAGMA journal_mode=WAL")
            con.execute("SELECT count(*) FROM meta").fetchone()
        except sqlite3.DatabaseError as exc:
            if held is not None:
                held.release()
            if is_disk_full(exc) or no_space_left(path.parent):
                raise InputError(
                    f"{path}: cannot be read: the disk is full (SQLite needs a little room "
                    "beside the database to read it); free some space and try again"
                ) from None
            raise InputError(f"{path}: not a dynmap_sim results database ({exc})") from None
        db = cls(path, con, held)
        try:
            if verify:
                db.verify(deep=lock)
            fmt = db.format
            if fmt > RESULTS_FORMAT:
                raise InputError(
                    f"{path}: results format {fmt}, written by a newer dynmap_sim; this "
                    f"version reads results formats 1-{RESULTS_FORMAT}"
                )
        except BaseException:
            db.close()
            raise
        return db

    def verify(self, deep: bool = False) -> None:
        """Refuse a damaged file, edited metadata, or derived rows that do not match the
        per-scan rows (in one snapshot; :mod:`.integrity`; results formats before 4 are
        only checked for a damaged file and their metadata)."""
        con = self.con
        check_integrity(con, self.path)
        con.execute("BEGIN")
        try:
            rows = con.execute("SELECT key, value FROM meta").fetchall()
            guarded = self._guarded(rows)
            meta = check_meta(self.path, rows, guarded)
            if guarded:
                check_complete(con, self.path, meta)
                check_digests(con, self.path)
                check_scans(con, self.path, len(self.labels()), deep)
                row = self._checkpoints.row()
                if row is not None:
                    self._checkpoints.verify(row, cover_digest(con, self._checksums()))
        except sqlite3.DatabaseError as exc:
            raise InputError(f"{self.path}: the database cannot be read ({exc})") from None
        finally:
            con.rollback()

    def _guarded(self, rows: list[tuple[str, str]]) -> bool:
        """Whether the store has checksums: results format 4 on, or the table of digests
        with the meta row of the format gone."""
        fmt = dict(rows).get("results_format")
        if fmt is None:
            return self.has_table("digests")
        try:
            return int(json.loads(fmt)) >= 4
        except (TypeError, ValueError):
            return True  # check_meta names the value

    def close(self) -> None:
        """Close the database and release the folder's lock (safe to call twice)."""
        try:
            self.con.close()
        finally:
            if self._lock is not None:
                self._lock.release()

    def __enter__(self) -> ResultsDB:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ meta
    def set_meta(self, **items: Any) -> None:
        """Set meta values (and their checksums) in one transaction."""
        with disk_full_is_clear(self.path.parent, str(self.path), self._runs_kept), self.con:
            _put_meta(self.con, items, self._checksums() if self.has_table("digests") else None)

    def _checksums(self) -> dict[str, str]:
        row = self.con.execute("SELECT value FROM meta WHERE key = 'checksums'").fetchone()
        sums = json.loads(row[0]) if row is not None else {}
        return sums if isinstance(sums, dict) else {}

    def set_localizers(self, rows: Localizers) -> None:
        with disk_full_is_clear(self.path.parent, str(self.path), self._runs_kept), self.con:
            _put_localizers(self.con, rows)

    def _runs_kept(self) -> int:
        try:
            return int(self.con.execute("SELECT count(*) FROM runs").fetchone()[0])
        except sqlite3.Error:
            return -1

    def _require_current_format(self) -> None:
        if self.format != RESULTS_FORMAT:
            raise InputError(
                f"{self.path}: results format {self.format} (written by an earlier dynmap_sim, "
                f"{FORMAT_LACKS.get(self.format, 'of another layout')}) can be reported, "
                f"exported and checked but not continued by this version (format "
                f"{RESULTS_FORMAT}); start a new experiment with another --out"
            )

    # ------------------------------------------------------------------ writing
    def write_run(
        self,
        rec: RunRecord,
        run_summaries: list[RunSummary],
        day_done: bool,
        checkpoint: Checkpoint | None,
        scenario_hash: str,
        seed: int,
    ) -> None:
        """Write one run's rows, its summaries (``run_summaries[k]`` of localizer ``k``), the
        day's summaries (when ``day_done``: after the day's last run), their digests and the
        checkpoint, in ONE transaction. On a failure (a full disk: :class:`DiskFullError`)
        nothing of the run stays, files included."""
        self._require_current_format()
        cps, folder = self._checkpoints, self.path.parent
        files: list[tuple[str, str]] = []
        try:
            with disk_full_is_clear(folder, f"the checkpoint into {cps.folder}", self._runs_kept):
                files = cps.write_localizer_files(checkpoint) if checkpoint is not None else []
            what = f"day {rec.day} run {rec.run} into {self.path}"
            with disk_full_is_clear(folder, what, self._runs_kept):
                with self.con:
                    RunWriter(self.con, rec).write(run_summaries, day_done)
                    write_digests(self.con, rec.day, rec.run, day_done)
                    if checkpoint is not None:
                        cover = cover_digest(self.con, self._checksums())
                        cps.put(checkpoint, files, scenario_hash, seed, cover)
            # the main file alone holds every committed run (a copy of it, also after
            # kill -9); busy readers only postpone this (SQLite then returns, not raises)
            what = f"{self.path} from its write-ahead log, which holds day {rec.day} run {rec.run}"
            with disk_full_is_clear(folder, what, self._runs_kept):
                self.con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        except BaseException:
            cps.remove_uncommitted_files([name for name, _ in files])
            raise
        if checkpoint is not None:
            cps.remove_stale_files({name for name, _ in files})

    # ------------------------------------------------------------------ checkpoint
    def load_checkpoint(
        self, scenario_hash: str, seed: int, to_resume: bool = True
    ) -> Checkpoint | None:
        """The last checkpoint, verified; None when the experiment has none yet.

        Raises :class:`InputError` when it is corrupt or belongs to another scenario/seed, or
        (``to_resume``) when this version cannot continue the results (an older format).
        """
        if to_resume:
            self._require_current_format()
        cover = cover_digest(self.con, self._checksums()) if self.has_table("digests") else None
        return self._checkpoints.load(scenario_hash, seed, cover)


def _put_meta(
    con: sqlite3.Connection, items: Mapping[str, Any], sums: dict[str, str] | None
) -> None:
    """Insert meta ``items`` (and, with ``sums``, the checksums updated for them)."""
    rows = [(k, json.dumps(v)) for k, v in items.items()]
    if sums is not None:
        sums = {**sums, **{k: value_hash(t) for k, t in rows}}
        rows.append(("checksums", json.dumps(sums, sort_keys=True)))
    con.executemany("INSERT OR REPLACE INTO meta VALUES (?, ?)", rows)


def _put_localizers(con: sqlite3.Connection, rows: Localizers) -> None:
    con.execute("DELETE FROM localizers")
    con.executemany(
        "INSERT INTO localizers VALUES (?, ?, ?, ?)",
        [(i, lab, name, json.dumps(p)) for i, (lab, name, p) in enumerate(rows)],
    )


def _clear_for_new(d: Path, path: Path, overwrite: bool) -> None:
    """Remove what a new store replaces in folder ``d``; refuse earlier results unless
    ``overwrite`` (a store without a finished run holds none)."""
    orphan = orphaned_checkpoint(d)
    if not path.exists() and orphan is None:
        return
    if not overwrite and not (orphan is None and _holds_no_runs(path)):
        if orphan is not None:
            raise InputError(
                f"{path} is missing but {orphan} holds earlier runs (results.db "
                "was deleted or moved): put it back to --resume, or remove "
                f"{orphan} (or pass --force where offered) to start afresh"
            )
        raise InputError(
            f"{path} already holds results; pass --resume to continue them or choose another --out"
        )
    for suffix in ("", "-wal", "-shm"):
        Path(str(path) + suffix).unlink(missing_ok=True)
    for f in (d / CHECKPOINT_DIR).glob("*.pkl*"):
        f.unlink()


def _holds_no_runs(path: Path) -> bool:
    """``path`` is a store without a finished run or a checkpoint (False when unreadable)."""
    try:
        con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            runs = con.execute("SELECT count(*) FROM runs").fetchone()[0]
            cps = con.execute("SELECT count(*) FROM checkpoint").fetchone()[0]
        finally:
            con.close()
    except sqlite3.Error:
        return False
    return runs == 0 and cps == 0


def _build(tmp: Path, path: Path, meta: Mapping[str, Any], localizers: Localizers) -> None:
    """Build a store with ``meta`` and ``localizers`` at ``tmp`` (a full disk: nothing left
    of it, :class:`DiskFullError`)."""
    leftovers = [tmp, Path(f"{tmp}-journal")]
    for f in leftovers:
        f.unlink(missing_ok=True)
    try:
        con = sqlite3.connect(tmp)
        try:
            con.executescript(SCHEMA)
            with con:
                _put_meta(con, meta, {})
                _put_localizers(con, localizers)
        finally:
            con.close()
    except (OSError, sqlite3.Error) as exc:
        for f in leftovers:
            f.unlink(missing_ok=True)
        if is_disk_full(exc):
            raise DiskFullError(path.parent, str(path), None) from None
        raise InputError(f"{path}: cannot create a results database there ({exc})") from None
    except BaseException:
        for f in leftovers:
            f.unlink(missing_ok=True)
        raise


def _fsync_dir(d: Path) -> None:
    """Make the rename into ``d`` durable (where the platform allows it)."""
    try:
        fd = os.open(d, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
