"""The results store: one SQLite database per experiment.

``results.db`` in the results folder holds, in WAL mode with one transaction per run (results
format 3, ``results_format`` in ``meta``):

* ``meta`` — scenario (JSON), its content hash, seed, day range, laser spec, results format;
* ``localizers`` — index, label, class name, parameters;
* ``diagnostics`` — what each localizer declared it reports
  (:class:`~dynmap_sim.types.Diagnostic`: name, per scan or per run, dtype, shape, doc);
* ``scans`` — per scan: day, run, step, time of day [s], true pose, collision flag;
* ``estimates`` — per scan and localizer: estimate, position / heading error, covariance
  diagonal, and a column per declared per-scan diagnostic: those of :data:`SCAN_COLUMNS`
  (``scan_loglik``, ``lambda_min``, ``timescale``, ``safe_mode``) in every results folder,
  NULL where a localizer does not report them; any other is added when first written (REAL
  or INTEGER for a scalar, else a BLOB of the value's little-endian bytes);
* ``runs``, ``run_summaries``, ``day_summaries`` — per-run and per-day summaries;
* ``events`` — driver and experiment events (skipped waypoints, detours, kidnappings);
* ``point_classes`` — per run and localizer, the 4x4 point-class confusion matrix against the
  beam classes (:data:`~dynmap_sim.metrics.BEAM_TO_POINT_CLASS`: furniture always
  semi-static);
* ``point_class_truth`` — per run and localizer that reported point classes, the 4x4
  confusion against the seen-before truth (H&W §4.4: semi-static = an object not seen at its
  place in an earlier run, :mod:`dynmap_sim.metrics.point_classes`), the sum over scans of
  each reported class's share of the scan's valid readings, and the number of those scans
  (format 3);
* ``timescale_counts`` — the per-run diagnostic of that name: per run and localizer, how often
  each timescale λ1–λ5 was selected (every selection of every scan, B&D Fig. 12);
* ``run_diagnostics`` — every other declared per-run diagnostic, per run and localizer (the
  value's little-endian bytes);
* ``artifacts`` — what a localizer handed over after a day (``Localizer.day_artifacts``, e.g.
  the dynamic map's snapshot): bytes, or named arrays stored as ``.npz`` (read without pickle);
* ``geometry`` — the static segments of each run's world (for report figures);
* ``scan_ranges`` — per run, every scan's laser ranges (zlib of float32 rows), only for an
  experiment run with ``--keep-scans`` (``meta.keep_scans``; absent otherwise);
* ``scan_people`` — per run, the people's ids (JSON), body radii [m] and positions at every
  scan (zlib of float32 ``(T, n, 2)``), also only with ``--keep-scans`` (the engine's truth,
  for the bag export; folders written before it have no such table);
* ``checkpoint`` — the pickled driver and RNG states, the next run to do, the scenario hash,
  the names and SHA-256 digests of the localizer files, and a SHA-256 of the blob, so a
  corrupt or mismatched checkpoint is refused.

The localizers of a checkpoint are pickled one file each, ``checkpoint/loc<k>-<next
index>.pkl`` next to ``results.db`` (written to a temporary name, then renamed), not into the
database: a large state (the dynamic maps are tens of MB) rewritten after every run would
churn the database's pages. The files are written before the transaction that names them
commits, and older ones are deleted after it, so a process killed at any moment leaves
either the whole run with its checkpoint or none of it.

The checkpoint's checksum covers its fields (next run, scenario hash, seed) and its blob, so
an edited ``next_index`` is refused like a flipped bit. After each run the WAL is checkpointed
into ``results.db``, so the main file alone holds every committed run (a user may copy it
alone, also after ``kill -9``). A folder with a checkpoint but no ``results.db`` (deleted or
moved) is refused, not restarted.

One writer per results folder: :meth:`ResultsDB.create` and ``open(..., lock=True)`` take an
exclusive OS lock (``flock``) on ``.results.lock`` in the folder, released when the store is
closed or the process ends (also when killed); a second writer is refused at once.

A full disk (``ENOSPC``, SQLite's "database or disk is full") is a :class:`DiskFullError`:
the failed run's transaction is rolled back and its files removed (no ``.tmp`` left), so the
runs finished before are kept and ``--resume`` continues after them once there is space.

Results format 1 (no ``results_format`` in ``meta``: written before localizers declared their
diagnostics) has the same tables but ``diagnostics``, ``run_diagnostics`` and ``artifacts``;
format 2 has all but ``point_class_truth`` (written before the seen-before truth). Both are
read (report, export, check; what they lack is left out) but not continued: the
seen-before truth of a run depends on every run before it.
"""

from __future__ import annotations

import dataclasses
import errno
import hashlib
import io
import json
import math
import os
import pickle
import sqlite3
import zlib
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.errors import InputError
from dynmap_sim.metrics import (
    NavRunSummary,
    PointClassTally,
    RunSummary,
    day_summary,
    n_onsets,
    scan_errors,
)
from dynmap_sim.types import Diagnostic

DB_NAME = "results.db"
#: Folder (next to ``results.db``) of the checkpoint's localizer files.
CHECKPOINT_DIR = "checkpoint"
#: The lock file of a results folder (held by its one writer).
LOCK_NAME = ".results.lock"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS localizers (
    idx INTEGER PRIMARY KEY, label TEXT NOT NULL UNIQUE, name TEXT NOT NULL, params TEXT);
CREATE TABLE IF NOT EXISTS scans (
    day INTEGER, run INTEGER, step INTEGER, t_s REAL, x REAL, y REAL, theta REAL,
    collision INTEGER, PRIMARY KEY (day, run, step)) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS estimates (
    loc INTEGER, day INTEGER, run INTEGER, step INTEGER, x REAL, y REAL, theta REAL,
    err_m REAL, err_theta_rad REAL, var_x REAL, var_y REAL, var_theta REAL,
    scan_loglik REAL, lambda_min REAL, timescale INTEGER, safe_mode INTEGER,
    PRIMARY KEY (loc, day, run, step)) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS runs (
    day INTEGER, run INTEGER, date TEXT, start_s REAL, n_steps INTEGER, duration_s REAL,
    collisions INTEGER, skipped_waypoints INTEGER, route_progress REAL, terminated INTEGER,
    wall_s REAL, PRIMARY KEY (day, run));
CREATE TABLE IF NOT EXISTS run_summaries (
    loc INTEGER, day INTEGER, run INTEGER, n_scans INTEGER, mean_error_m REAL,
    max_error_m REAL, rmse_m REAL, lost_fraction REAL, mean_heading_error_rad REAL,
    mean_scan_loglik REAL, mean_lambda_min REAL, n_lost_episodes INTEGER,
    n_recovered INTEGER, mean_time_to_recover_s REAL, rpe_m REAL, update_ms_per_scan REAL,
    PRIMARY KEY (loc, day, run));
CREATE TABLE IF NOT EXISTS day_summaries (
    loc INTEGER, day INTEGER, n_scans INTEGER, mean_error_m REAL, max_error_m REAL,
    rmse_m REAL, lost_fraction REAL, mean_heading_error_rad REAL, mean_scan_loglik REAL,
    mean_lambda_min REAL, PRIMARY KEY (loc, day));
CREATE TABLE IF NOT EXISTS events (
    day INTEGER, run INTEGER, step INTEGER, t_s REAL, kind TEXT, detail TEXT);
CREATE TABLE IF NOT EXISTS point_classes (
    loc INTEGER, day INTEGER, run INTEGER, confusion BLOB, PRIMARY KEY (loc, day, run));
CREATE TABLE IF NOT EXISTS point_class_truth (
    loc INTEGER, day INTEGER, run INTEGER, confusion BLOB, fraction_sum BLOB, n_scans INTEGER,
    PRIMARY KEY (loc, day, run));
CREATE TABLE IF NOT EXISTS timescale_counts (
    loc INTEGER, day INTEGER, run INTEGER, counts BLOB, PRIMARY KEY (loc, day, run));
CREATE TABLE IF NOT EXISTS geometry (
    day INTEGER, run INTEGER, segments BLOB, segment_class BLOB, PRIMARY KEY (day, run));
CREATE TABLE IF NOT EXISTS diagnostics (
    loc INTEGER, name TEXT, per TEXT, dtype TEXT, shape TEXT, counts_of TEXT, doc TEXT,
    PRIMARY KEY (loc, name));
CREATE TABLE IF NOT EXISTS run_diagnostics (
    loc INTEGER, day INTEGER, run INTEGER, name TEXT, value BLOB,
    PRIMARY KEY (loc, day, run, name));
CREATE TABLE IF NOT EXISTS artifacts (
    loc INTEGER, day INTEGER, name TEXT, kind TEXT, data BLOB, PRIMARY KEY (loc, day, name));
CREATE TABLE IF NOT EXISTS nav_runs (
    day INTEGER, run INTEGER, goal_reached INTEGER, time_s REAL, path_length_m REAL,
    shortest_path_m REAL, spl REAL, collisions INTEGER, near_misses INTEGER,
    min_clearance_m REAL, replans INTEGER, recoveries INTEGER, stuck_s REAL, gave_up INTEGER,
    PRIMARY KEY (day, run));
CREATE TABLE IF NOT EXISTS driver_artifacts (
    day INTEGER, run INTEGER, name TEXT, data BLOB, PRIMARY KEY (day, run, name));
CREATE TABLE IF NOT EXISTS checkpoint (
    id INTEGER PRIMARY KEY CHECK (id = 1), next_index INTEGER, next_day INTEGER,
    next_run INTEGER, scenario_hash TEXT, seed INTEGER, sha256 TEXT, blob BLOB, created TEXT);
"""

#: Made by the first run written with its ranges kept (an optional table: a store without it
#: simply has no scans; ``zlib`` level 1 of little-endian float32 rows: 2.7 kB a scan
#: of 683 beams, 2.3 kB compressed, as the noise fills the mantissas).
_SCAN_RANGES_TABLE = """CREATE TABLE IF NOT EXISTS scan_ranges (
    day INTEGER, run INTEGER, n_beams INTEGER, ranges BLOB, PRIMARY KEY (day, run))"""

#: Made with ``scan_ranges`` (optional like it): the people's ids (a JSON list; the crowd of a
#: run is fixed), radii (little-endian float64 ``(n,)``) and positions (zlib level 1 of
#: little-endian float32 ``(T, n, 2)``, NaN: not on the floor).
_SCAN_PEOPLE_TABLE = """CREATE TABLE IF NOT EXISTS scan_people (
    day INTEGER, run INTEGER, n_people INTEGER, ids TEXT, radius BLOB, xy BLOB,
    PRIMARY KEY (day, run))"""

#: The layout this version writes (``results_format`` in ``meta``; none: format 1).
RESULTS_FORMAT = 3

#: ``update_time`` in ``meta``: what ``update_ms_per_scan`` measures in folders created since
#: it is written (a localizer thread's CPU time); folders without it hold wall times.
UPDATE_TIME_CPU = "cpu"

#: Per-scan diagnostics with a column of ``estimates`` in every results format (NULL where a
#: localizer does not declare or report them), and the column's type.
SCAN_COLUMNS = {
    "scan_loglik": "REAL",
    "lambda_min": "REAL",
    "timescale": "INTEGER",
    "safe_mode": "INTEGER",
}

#: Per-run diagnostics with a table of their own (``loc, day, run, counts``; int64 values,
#: rows only where a value is not all zero), as in results format 1.
RUN_TABLES = ("timescale_counts",)

#: The columns of ``estimates`` that are not diagnostics.
ESTIMATE_COLUMNS = (
    "loc",
    "day",
    "run",
    "step",
    "x",
    "y",
    "theta",
    "err_m",
    "err_theta_rad",
    "var_x",
    "var_y",
    "var_theta",
)

#: A day artifact: bytes, or named arrays of numbers.
Artifact = bytes | dict[str, np.ndarray]


@dataclass
class LocalizerDiagnostics:
    """One localizer's diagnostics of one run: ``declared`` (its ``Localizer.diagnostics``),
    ``per_scan`` name -> ``(T, *shape)`` float64 (NaN: not reported at that scan),
    ``per_run`` name -> value of the declared shape, ``artifacts`` name -> what it handed
    over after ``end_day`` (empty but after a day's last run)."""

    declared: tuple[Diagnostic, ...] = ()
    per_scan: dict[str, NDArray[np.float64]] = field(default_factory=dict)
    per_run: dict[str, NDArray[Any]] = field(default_factory=dict)
    artifacts: dict[str, Artifact] = field(default_factory=dict)


@dataclass
class PeopleTrack:
    """The people of one run: ``ids``, ``radius_m`` ``(n,)`` and ``xy`` ``(T, n, 2)`` [m]
    at each scan (NaN: not on the floor)."""

    ids: tuple[str, ...]
    radius_m: NDArray[np.float64]
    xy: NDArray[np.float64]


@dataclass
class RunRecord:
    """Everything one run produces, as arrays (written in bulk by :meth:`ResultsDB.write_run`).

    ``truth`` ``(T, 3)``; ``estimates`` ``(L, T, 3)``; ``cov_diag`` ``(L, T, 3)``;
    ``diagnostics`` one :class:`LocalizerDiagnostics` per localizer (empty: none declared).
    """

    day: int
    run: int
    date: str
    start_s: float
    t_s: NDArray[np.float64]
    truth: NDArray[np.float64]
    collision: NDArray[np.bool_]
    estimates: NDArray[np.float64]
    cov_diag: NDArray[np.float64]
    confusion: NDArray[np.int64]  # (L, 4, 4)
    terminated: bool
    route_progress: float
    skipped_waypoints: int
    wall_s: float
    events: list[tuple[int, float, str, str]]  # (step, t_s, kind, detail)
    segments: NDArray[np.float64] | None = None
    segment_class: NDArray[np.int8] | None = None
    update_s: NDArray[np.float64] | None = None  # (L,) CPU time of each localizer's update()
    diagnostics: list[LocalizerDiagnostics] = field(default_factory=list)
    #: the run's navigation measures (None: not measured)
    nav: NavRunSummary | None = None
    #: what the driver handed over after the run (name -> bytes)
    driver_artifacts: dict[str, bytes] = field(default_factory=dict)
    #: per localizer, its point classes against the seen-before truth (empty: none)
    point_tallies: list[PointClassTally] = field(default_factory=list)
    #: the laser ranges ``(T, n_beams)`` [m], REP-117, kept with ``run --keep-scans``
    ranges: NDArray[np.float32] | None = None
    #: the people at each scan, kept with ``run --keep-scans`` (None: not kept)
    people: PeopleTrack | None = None

    def scan_diagnostic(self, loc: int, name: str) -> NDArray[np.float64] | None:
        """Per-scan values ``(T, ...)`` of diagnostic ``name`` of localizer ``loc`` (None
        when it did not declare it)."""
        if loc >= len(self.diagnostics):
            return None
        return self.diagnostics[loc].per_scan.get(name)


@dataclass(frozen=True)
class Checkpoint:
    """The state to resume from: the next slot index, the state dict (driver, RNG; pickled
    into the database) and the pickled localizers (one file each)."""

    next_index: int
    next_day: int
    next_run: int
    state: dict[str, Any]
    localizers: tuple[bytes, ...] = ()


class DiskFullError(InputError):
    """The disk filled up while the store wrote ``what`` into results ``folder``; what was
    committed before is kept (the CLI says how to continue)."""

    def __init__(self, folder: Path, what: str) -> None:
        super().__init__(f"the disk is full (no space left writing {what})")
        self.folder = folder
        self.what = what


def is_disk_full(exc: BaseException) -> bool:
    """True for ``ENOSPC``/``EDQUOT`` and SQLite's "database or disk is full"."""
    if isinstance(exc, DiskFullError):
        return True
    if isinstance(exc, OSError):
        return exc.errno in (errno.ENOSPC, errno.EDQUOT)
    if isinstance(exc, sqlite3.Error):
        code = getattr(exc, "sqlite_errorcode", None)
        return code == sqlite3.SQLITE_FULL or "disk is full" in str(exc)
    return False


class FolderLock:
    """An exclusive OS lock (``flock``) on ``<folder>/.results.lock``: one writer per results
    folder. Released by :meth:`release` or when the process ends, however it ends."""

    def __init__(self, folder: Path) -> None:
        self.fd: int | None = None
        try:
            import fcntl
        except ImportError:  # pragma: no cover - not POSIX: no lock
            return
        fd = os.open(folder / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            try:
                pid = os.read(fd, 32).decode("ascii", "replace").strip()
            except OSError:
                pid = ""
            os.close(fd)
            who = f" (pid {pid})" if pid.isdigit() else ""
            raise InputError(
                f"{folder}: another dynmap-sim process{who} is writing results here; "
                "one writer per folder: wait until it ends (--resume then continues its "
                "results) or choose another --out"
            ) from None
        try:
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
        except OSError:
            pass  # the pid is only for the message; the lock holds without it
        self.fd = fd

    def release(self) -> None:
        if self.fd is not None:
            os.close(self.fd)  # closing the descriptor releases the flock
            self.fd = None


def orphaned_checkpoint(folder: str | Path) -> Path | None:
    """What holds earlier runs in ``folder`` although it has no ``results.db`` (checkpoint
    files, or a write-ahead log with content), else None."""
    d = Path(folder)
    if (d / DB_NAME).exists():
        return None
    wal = d / (DB_NAME + "-wal")
    if wal.is_file() and wal.stat().st_size > 0:
        return wal
    cp = d / CHECKPOINT_DIR
    if cp.is_dir() and any(cp.glob("*.pkl")):
        return cp
    return None


def _checkpoint_digest(idx: Any, nd: Any, nr: Any, h: Any, seed: Any, blob: bytes) -> str:
    """The checkpoint's checksum: its fields and its blob (``v2:`` + SHA-256)."""
    head = json.dumps([int(idx), int(nd), int(nr), str(h), int(seed)]).encode()
    return "v2:" + hashlib.sha256(head + b"\0" + blob).hexdigest()


class ResultsDB:
    """One experiment's SQLite store (open with :meth:`create` or :meth:`open`)."""

    def __init__(self, path: Path, con: sqlite3.Connection, lock: FolderLock | None = None) -> None:
        self.path = path
        self.con = con
        self._lock = lock
        #: :meth:`per_scan`'s arrays by (loc, day, run) once :meth:`remember_per_scan`
        self._per_scan: dict[tuple[int, int | None, int | None], dict[str, Any]] | None = None

    def remember_per_scan(self) -> None:
        """From now on keep :meth:`per_scan`'s arrays and hand out copies of them again: for
        a reader of finished results that asks for the same localizer's scans many times
        (the report); they are not refreshed when runs are written afterwards."""
        if self._per_scan is None:
            self._per_scan = {}

    @contextmanager
    def _disk_full_is_clear(self, what: str) -> Iterator[None]:
        """Turn a full disk into :class:`DiskFullError` (the rest passes through)."""
        try:
            yield
        except (OSError, sqlite3.Error) as exc:
            if is_disk_full(exc):
                raise DiskFullError(self.path.parent, what) from None
            raise

    # ------------------------------------------------------------------ opening
    @classmethod
    def create(cls, out_dir: str | Path, overwrite: bool = False) -> ResultsDB:
        """Create a fresh database in ``out_dir``; refuse to clobber results unless asked."""
        d = Path(out_dir)
        d.mkdir(parents=True, exist_ok=True)
        lock = FolderLock(d)  # refuses a second writer before anything is touched
        try:
            path = d / DB_NAME
            orphan = orphaned_checkpoint(d)
            if path.exists() or orphan is not None:
                if not overwrite:
                    if orphan is not None:
                        raise InputError(
                            f"{path} is missing but {orphan} holds earlier runs (results.db "
                            "was deleted or moved): put it back to --resume, or remove "
                            f"{orphan} (or pass --force where offered) to start afresh"
                        )
                    raise InputError(
                        f"{path} already holds results; pass --resume to continue them or "
                        "choose another --out"
                    )
                for suffix in ("", "-wal", "-shm"):
                    Path(str(path) + suffix).unlink(missing_ok=True)
                for f in (d / CHECKPOINT_DIR).glob("*.pkl*"):
                    f.unlink()
            try:
                db = cls(path, sqlite3.connect(path), lock)
                with db._disk_full_is_clear(str(path)):
                    db.con.execute("PRAGMA journal_mode=WAL")
                    db.con.execute("PRAGMA synchronous=NORMAL")
                    db.con.executescript(_SCHEMA)
                    db.con.commit()
                    db.set_meta(results_format=RESULTS_FORMAT, update_time=UPDATE_TIME_CPU)
            except sqlite3.OperationalError as exc:  # e.g. a folder SQLite cannot write in
                raise InputError(
                    f"{path}: cannot create a results database there ({exc})"
                ) from None
        except BaseException:
            lock.release()
            raise
        return db

    @classmethod
    def open(cls, out_dir: str | Path, lock: bool = False) -> ResultsDB:
        """Open an existing results folder (or ``results.db`` path); ``lock``: as its one
        writer (refused while another process writes there)."""
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
            raise InputError(f"{path}: not a dynmap_sim results database ({exc})") from None
        db = cls(path, con, held)
        fmt = db.format
        if fmt > RESULTS_FORMAT:
            db.close()
            raise InputError(
                f"{path}: results format {fmt}, written by a newer dynmap_sim; this version "
                f"reads results formats 1-{RESULTS_FORMAT}"
            )
        return db

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
        with self._disk_full_is_clear(str(self.path)), self.con:
            self.con.executemany(
                "INSERT OR REPLACE INTO meta VALUES (?, ?)",
                [(k, json.dumps(v)) for k, v in items.items()],
            )

    def meta(self) -> dict[str, Any]:
        return {k: json.loads(v) for k, v in self.con.execute("SELECT key, value FROM meta")}

    def update_time_header(self) -> str:
        """The column header of ``update_ms_per_scan``: CPU time in folders created since
        :data:`UPDATE_TIME_CPU` is recorded, wall time in older ones (a folder begun before
        and resumed since mixes both; it keeps the older label)."""
        cpu = self.meta().get("update_time") == UPDATE_TIME_CPU
        return "update CPU [ms/scan]" if cpu else "update wall [ms/scan]"

    def set_localizers(self, rows: list[tuple[str, str, dict[str, Any]]]) -> None:
        with self._disk_full_is_clear(str(self.path)), self.con:
            self.con.execute("DELETE FROM localizers")
            self.con.executemany(
                "INSERT INTO localizers VALUES (?, ?, ?, ?)",
                [(i, lab, name, json.dumps(p)) for i, (lab, name, p) in enumerate(rows)],
            )

    def labels(self) -> list[str]:
        return [r[0] for r in self.con.execute("SELECT label FROM localizers ORDER BY idx")]

    @property
    def format(self) -> int:
        """The results format of this database (1: written before ``results_format``)."""
        row = self.con.execute("SELECT value FROM meta WHERE key = 'results_format'").fetchone()
        return 1 if row is None else int(json.loads(row[0]))

    def _require_current_format(self) -> None:
        if self.format != RESULTS_FORMAT:
            raise InputError(
                f"{self.path}: results format {self.format} (written by an earlier dynmap_sim, "
                + (
                    "before localizers declared their diagnostics"
                    if self.format == 1
                    else "before the seen-before point-class truth"
                )
                + ") can be reported, exported and "
                f"checked but not continued by this version (format {RESULTS_FORMAT}); start a "
                "new experiment with another --out"
            )

    def _has_table(self, name: str) -> bool:
        row = self.con.execute(
            "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (name,)
        ).fetchone()
        return row is not None

    def declared(self, loc: int) -> tuple[Diagnostic, ...]:
        """The diagnostics localizer ``loc`` declared (none in results format 1)."""
        if not self._has_table("diagnostics"):
            return ()
        rows = self.con.execute(
            "SELECT name, dtype, shape, per, doc, counts_of FROM diagnostics WHERE loc = ? "
            "ORDER BY rowid",
            (loc,),
        ).fetchall()
        return tuple(
            Diagnostic(name, dtype, tuple(json.loads(shape)), per, doc or "", counts_of)
            for name, dtype, shape, per, doc, counts_of in rows
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
        day's summaries (when ``day_done``: after the day's last run) and the checkpoint, in
        ONE transaction. Every number is computed by :mod:`dynmap_sim.metrics`. On a failure
        (a full disk: :class:`DiskFullError`) nothing of the run stays, files included."""
        self._require_current_format()
        files: list[tuple[str, str]] = []
        try:
            with self._disk_full_is_clear(f"the checkpoint into {self.checkpoint_dir}"):
                files = self._write_localizer_files(checkpoint) if checkpoint is not None else []
            with self._disk_full_is_clear(f"day {rec.day} run {rec.run} into {self.path}"):
                self._write_run_rows(
                    rec, run_summaries, day_done, checkpoint, files, scenario_hash, seed
                )
                # the main file alone holds every committed run (a copy of it, also after
                # kill -9); busy readers only postpone this (SQLite then returns, not raises)
                self.con.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        except BaseException:
            self._remove_uncommitted_files([name for name, _ in files])
            raise
        if checkpoint is not None:
            self._remove_stale_localizer_files({name for name, _ in files})

    def _write_run_rows(
        self,
        rec: RunRecord,
        run_summaries: list[RunSummary],
        day_done: bool,
        checkpoint: Checkpoint | None,
        files: list[tuple[str, str]],
        scenario_hash: str,
        seed: int,
    ) -> None:
        """The transaction of :meth:`write_run`."""
        d, r = rec.day, rec.run
        n_loc, n = rec.estimates.shape[:2]
        steps = np.arange(n)
        diags = rec.diagnostics or [LocalizerDiagnostics() for _ in range(n_loc)]
        with self.con:
            # a run that was written before a crash (cannot happen with one transaction, but
            # a resumed experiment may redo a run whose checkpoint was older) is replaced
            for table in (
                "scans",
                "estimates",
                "run_summaries",
                "point_classes",
                "point_class_truth",
                "timescale_counts",
                "run_diagnostics",
                "geometry",
                "nav_runs",
                "driver_artifacts",
            ):
                self.con.execute(f"DELETE FROM {table} WHERE day=? AND run=?", (d, r))
            self.con.execute("DELETE FROM runs WHERE day=? AND run=?", (d, r))
            self.con.execute("DELETE FROM events WHERE day=? AND run=?", (d, r))
            self._declare(diags)
            # one float64 table per insert, converted once; SQLite stores NaN as NULL and
            # turns whole-number reals into integers in INTEGER columns
            ones = np.ones(n)
            scan_tab = np.column_stack(
                [d * ones, r * ones, steps, rec.t_s, rec.truth, rec.collision.astype(float)]
            )
            self.con.executemany("INSERT INTO scans VALUES (?,?,?,?,?,?,?,?)", scan_tab.tolist())
            for k in range(n_loc):
                est = rec.estimates[k]
                err, herr = scan_errors(rec.truth, est)
                g = diags[k]
                on_scan = [x for x in g.declared if x.per == "scan"]
                scalars = [x for x in on_scan if not x.shape]
                arrays = [x for x in on_scan if x.shape]
                none = np.full(n, np.nan)
                tab = np.column_stack(
                    [
                        k * ones,
                        d * ones,
                        r * ones,
                        steps,
                        est,
                        err,
                        herr,
                        rec.cov_diag[k],
                        *[g.per_scan.get(x.name, none).reshape(n) for x in scalars],
                    ]
                )
                rows = tab.tolist()
                for x in arrays:
                    values = g.per_scan.get(x.name, np.full((n, *x.shape), np.nan))
                    for row, v in zip(rows, values, strict=True):
                        row.append(_blob(v, x))
                cols = ESTIMATE_COLUMNS + tuple(f'"{x.name}"' for x in scalars + arrays)
                self.con.executemany(
                    f"INSERT INTO estimates ({', '.join(cols)}) "
                    f"VALUES ({', '.join('?' * len(cols))})",
                    rows,
                )
                self.con.execute(
                    "INSERT INTO point_classes VALUES (?,?,?,?)",
                    (k, d, r, np.ascontiguousarray(rec.confusion[k], dtype="<i8").tobytes()),
                )
                tally = rec.point_tallies[k] if k < len(rec.point_tallies) else None
                if tally is not None and (tally.n_scans or tally.confusion.any()):
                    self.con.execute(
                        "INSERT INTO point_class_truth VALUES (?,?,?,?,?,?)",
                        (
                            k,
                            d,
                            r,
                            np.ascontiguousarray(tally.confusion, dtype="<i8").tobytes(),
                            np.ascontiguousarray(tally.fraction_sum, dtype="<f8").tobytes(),
                            int(tally.n_scans),
                        ),
                    )
                self._write_run_diagnostics(k, d, r, g)
                for name, value in g.artifacts.items():
                    self.con.execute(
                        "INSERT OR REPLACE INTO artifacts VALUES (?,?,?,?,?)",
                        (k, d, name, *_encode_artifact(name, value)),
                    )
            self.con.execute(
                "INSERT INTO runs VALUES (?,?,?,?,?,?,?,?,?,?,?)",
                (
                    d,
                    r,
                    rec.date,
                    rec.start_s,
                    n,
                    float(rec.t_s[-1] - rec.t_s[0]) if n else 0.0,
                    n_onsets(rec.collision),
                    rec.skipped_waypoints,
                    rec.route_progress,
                    int(rec.terminated),
                    rec.wall_s,
                ),
            )
            self.con.executemany(
                "INSERT INTO events VALUES (?,?,?,?,?,?)",
                [(d, r, s, t, kind, det) for s, t, kind, det in rec.events],
            )
            if rec.segments is not None:
                self.con.execute(
                    "INSERT INTO geometry VALUES (?,?,?,?)",
                    (
                        d,
                        r,
                        np.ascontiguousarray(rec.segments, dtype="<f8").tobytes(),
                        np.ascontiguousarray(rec.segment_class, dtype="i1").tobytes(),
                    ),
                )
            if rec.nav is not None:
                nav = rec.nav.to_dict()
                self.con.execute(
                    f"INSERT INTO nav_runs VALUES (?,?,{','.join('?' * len(nav))})",
                    (d, r, *(_none_if_nan(v) for v in nav.values())),
                )
            self.con.executemany(
                "INSERT INTO driver_artifacts VALUES (?,?,?,?)",
                [(d, r, name, data) for name, data in rec.driver_artifacts.items()],
            )
            if rec.ranges is not None:
                self.con.execute(_SCAN_RANGES_TABLE)
                ranges = np.ascontiguousarray(rec.ranges, dtype="<f4")
                self.con.execute(
                    "INSERT OR REPLACE INTO scan_ranges VALUES (?,?,?,?)",
                    (d, r, ranges.shape[1], zlib.compress(ranges.tobytes(), 1)),
                )
            if rec.people is not None:
                p = rec.people
                xy = np.ascontiguousarray(p.xy, dtype="<f4").reshape(n, len(p.ids), 2)
                self.con.execute(_SCAN_PEOPLE_TABLE)
                self.con.execute(
                    "INSERT OR REPLACE INTO scan_people VALUES (?,?,?,?,?,?)",
                    (
                        d,
                        r,
                        len(p.ids),
                        json.dumps(list(p.ids)),
                        np.ascontiguousarray(p.radius_m, dtype="<f8").tobytes(),
                        zlib.compress(xy.tobytes(), 1),
                    ),
                )
            for k, s in enumerate(run_summaries):
                self.con.execute(
                    "INSERT INTO run_summaries VALUES (:loc, :day, :run, :n_scans, "
                    ":mean_error_m, :max_error_m, :rmse_m, :lost_fraction, "
                    ":mean_heading_error_rad, :mean_scan_loglik, :mean_lambda_min, "
                    ":n_lost_episodes, :n_recovered, :mean_time_to_recover_s, :rpe_m, "
                    ":update_ms_per_scan)",
                    {"loc": k, "day": d, "run": r}
                    | {key: _none_if_nan(v) for key, v in s.to_dict().items()},
                )
            for s in self._day_summaries(d, n_loc) if day_done else []:
                self.con.execute(
                    "INSERT OR REPLACE INTO day_summaries VALUES (:loc, :day, :n_scans, "
                    ":mean_error_m, :max_error_m, :rmse_m, :lost_fraction, "
                    ":mean_heading_error_rad, :mean_scan_loglik, :mean_lambda_min)",
                    {k: _none_if_nan(v) for k, v in s.items()},
                )
            if checkpoint is not None:
                self._put_checkpoint(checkpoint, files, scenario_hash, seed)

    def _declare(self, diags: list[LocalizerDiagnostics]) -> None:
        """Record each localizer's declarations; add a column to ``estimates`` for each
        per-scan diagnostic that has none yet (in the open transaction)."""
        cols = {
            name: str(kind).upper()
            for _, name, kind, *_ in self.con.execute("PRAGMA table_info(estimates)")
        }
        for k, g in enumerate(diags):
            names = [x.name for x in g.declared]
            for x in g.declared:
                where = f"diagnostic {x.name!r} of localizer {k}"
                if names.count(x.name) > 1:
                    raise InputError(f"{where} is declared twice")
                self.con.execute(
                    "INSERT OR REPLACE INTO diagnostics VALUES (?,?,?,?,?,?,?)",
                    (k, x.name, x.per, x.dtype, json.dumps(list(x.shape)), x.counts_of, x.doc),
                )
                if x.per != "scan":
                    continue
                kind = _column_type(x)
                if x.name in ESTIMATE_COLUMNS:
                    raise InputError(f"{where}: {x.name!r} is a column of every estimate")
                if x.name in SCAN_COLUMNS and x.shape:
                    raise InputError(f"{where} must be a scalar (a column since format 1)")
                have = cols.get(x.name)
                if have is None:
                    self.con.execute(f'ALTER TABLE estimates ADD COLUMN "{x.name}" {kind}')
                    cols[x.name] = kind
                elif have != kind and x.name not in SCAN_COLUMNS:
                    raise InputError(f"{where} is {kind} but another localizer declared it {have}")

    def _write_run_diagnostics(self, k: int, d: int, r: int, g: LocalizerDiagnostics) -> None:
        for x in g.declared:
            if x.per != "run" or x.name not in g.per_run:
                continue
            value = np.asarray(g.per_run[x.name]).reshape(x.shape)
            if x.name in RUN_TABLES:
                if value.any():
                    counts = np.ascontiguousarray(value, dtype="<i8")
                    self.con.execute(
                        f"INSERT INTO {x.name} VALUES (?,?,?,?)", (k, d, r, counts.tobytes())
                    )
            else:
                self.con.execute(
                    "INSERT INTO run_diagnostics VALUES (?,?,?,?,?)",
                    (k, d, r, x.name, _blob(value, x)),
                )

    def _day_summaries(self, day: int, n_loc: int) -> list[dict[str, float]]:
        """Summaries of all scans of ``day`` per localizer (reads uncommitted rows too); the
        errors of the scans with truth (a replay's scans without a reference pose have none),
        ``n_scans`` of all."""
        out = []
        for k in range(n_loc):
            rows = self.con.execute(
                "SELECT e.err_m, e.err_theta_rad, e.scan_loglik, e.lambda_min, s.x IS NOT NULL "
                "FROM estimates e JOIN scans s USING (day, run, step) WHERE e.loc=? AND e.day=?",
                (k, day),
            ).fetchall()
            a = np.array(rows, dtype=np.float64).reshape(-1, 5)
            m = a[:, 4] > 0
            s = day_summary(a[m, 0], a[m, 1], a[:, 2], a[:, 3])
            out.append({"loc": k, "day": day, **s.to_dict(), "n_scans": len(a)})
        return out

    @property
    def checkpoint_dir(self) -> Path:
        return self.path.parent / CHECKPOINT_DIR

    def _write_localizer_files(self, cp: Checkpoint) -> list[tuple[str, str]]:
        """Write each pickled localizer atomically (temp file + rename); (name, sha256)s."""
        out = []
        if cp.localizers:
            self.checkpoint_dir.mkdir(exist_ok=True)
        for k, blob in enumerate(cp.localizers):
            name = f"loc{k}-{cp.next_index}.pkl"
            path = self.checkpoint_dir / name
            tmp = path.with_name(name + ".tmp")
            try:
                tmp.write_bytes(blob)
                os.replace(tmp, path)
            except BaseException:
                tmp.unlink(missing_ok=True)
                self._remove_uncommitted_files([name for name, _ in out])
                raise
            out.append((name, hashlib.sha256(blob).hexdigest()))
        return out

    def _remove_uncommitted_files(self, names: list[str]) -> None:
        """Remove localizer files of a write that failed (never those the stored
        checkpoint names)."""
        if not names:
            return
        keep: set[str] = set()
        try:
            row = self.con.execute("SELECT blob FROM checkpoint WHERE id = 1").fetchone()
            if row is not None and row[0] is not None:
                content = pickle.loads(bytes(row[0]))  # noqa: S301 - our own checkpoint
                keep = {name for name, _ in content.get("localizer_files", ())}
        except Exception:  # noqa: BLE001 - unreadable: keep every file but the new ones
            pass
        for name in names:
            if name not in keep:
                (self.checkpoint_dir / name).unlink(missing_ok=True)

    def _remove_stale_localizer_files(self, keep: set[str]) -> None:
        if self.checkpoint_dir.is_dir():
            for f in self.checkpoint_dir.iterdir():
                if f.name not in keep and f.name.endswith((".pkl", ".pkl.tmp")):
                    f.unlink(missing_ok=True)

    def _put_checkpoint(
        self, cp: Checkpoint, files: list[tuple[str, str]], scenario_hash: str, seed: int
    ) -> None:
        content = {"format": 2, "state": cp.state, "localizer_files": files}
        blob = pickle.dumps(content, protocol=pickle.HIGHEST_PROTOCOL)
        digest = _checkpoint_digest(
            cp.next_index, cp.next_day, cp.next_run, scenario_hash, seed, blob
        )
        self.con.execute(
            "INSERT OR REPLACE INTO checkpoint VALUES (1, ?, ?, ?, ?, ?, ?, ?, datetime('now'))",
            (cp.next_index, cp.next_day, cp.next_run, scenario_hash, seed, digest, blob),
        )

    # ------------------------------------------------------------------ reading
    def load_checkpoint(
        self, scenario_hash: str, seed: int, to_resume: bool = True
    ) -> Checkpoint | None:
        """The last checkpoint, verified; None when the experiment has none yet.

        Raises :class:`InputError` when it is corrupt or belongs to another scenario/seed, or
        (``to_resume``) when this version cannot continue the results (an older format).
        """
        if to_resume:
            self._require_current_format()
        try:
            row = self.con.execute(
                "SELECT next_index, next_day, next_run, scenario_hash, seed, sha256, blob "
                "FROM checkpoint WHERE id = 1"
            ).fetchone()
        except sqlite3.DatabaseError as exc:
            raise InputError(f"{self.path}: cannot read the checkpoint ({exc})") from None
        if row is None:
            return None
        idx, nd, nr, h, s, digest, blob = row
        if h != scenario_hash:
            raise InputError(
                f"{self.path}: the checkpoint belongs to a different scenario or world file "
                "(their content changed); start a new experiment with another --out"
            )
        if s != seed:
            raise InputError(f"{self.path}: the checkpoint was made with seed {s}, not {seed}")
        corrupt = InputError(
            f"{self.path}: the checkpoint is corrupt (checksum mismatch: its fields or its "
            "state were changed); it cannot be resumed: start a new experiment with another --out"
        )
        if blob is None or not isinstance(digest, str):
            raise corrupt
        if digest.startswith("v2:"):  # covers the fields too
            try:
                expected = _checkpoint_digest(idx, nd, nr, h, s, bytes(blob))
            except (TypeError, ValueError):
                raise corrupt from None
        else:  # written before the checksum covered the fields: the blob alone
            expected = hashlib.sha256(bytes(blob)).hexdigest()
        if expected != digest:
            raise corrupt
        try:
            content = pickle.loads(bytes(blob))  # noqa: S301 - our own checksummed blob
        except Exception as exc:  # noqa: BLE001 - any failure means unusable
            raise InputError(f"{self.path}: the checkpoint cannot be loaded ({exc})") from None
        if not (isinstance(content, dict) and content.get("format") == 2):
            # the first format: everything (localizers included, as objects) in the blob
            state = dict(content)
            locs = tuple(
                pickle.dumps(x, pickle.HIGHEST_PROTOCOL) for x in state.pop("localizers", [])
            )
            return Checkpoint(int(idx), int(nd), int(nr), state, locs)
        locs = []
        for name, digest in content["localizer_files"]:
            path = self.checkpoint_dir / name
            try:
                data = path.read_bytes()
            except OSError as exc:
                raise InputError(
                    f"{path}: cannot read the checkpoint's localizer ({exc})"
                ) from None
            if hashlib.sha256(data).hexdigest() != digest:
                raise InputError(f"{path}: the checkpoint is corrupt (checksum mismatch)")
            locs.append(data)
        return Checkpoint(int(idx), int(nd), int(nr), content["state"], tuple(locs))

    def query(self, sql: str, params: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
        return self.con.execute(sql, params).fetchall()

    def per_scan(self, loc: int, day: int | None = None, run: int | None = None) -> dict[str, Any]:
        """Per-scan arrays of one localizer (optionally one day / run), joined with truth."""
        memo = self._per_scan
        if memo is not None and (loc, day, run) in memo:
            return {k: v.copy() for k, v in memo[(loc, day, run)].items()}
        where, params = "e.loc = ?", [loc]
        if day is not None:
            where += " AND e.day = ?"
            params.append(day)
        if run is not None:
            where += " AND e.run = ?"
            params.append(run)
        rows = self.con.execute(
            "SELECT e.day, e.run, e.step, s.t_s, s.x, s.y, s.theta, e.x, e.y, e.theta, "
            "e.err_m, e.err_theta_rad, e.scan_loglik, e.lambda_min, e.timescale, e.safe_mode "
            "FROM estimates e JOIN scans s ON s.day = e.day AND s.run = e.run "
            f"AND s.step = e.step WHERE {where} ORDER BY e.day, e.run, e.step",
            params,
        ).fetchall()
        a = np.array(rows, dtype=np.float64).reshape(-1, 16)
        out = {
            "day": a[:, 0].astype(int),
            "run": a[:, 1].astype(int),
            "step": a[:, 2].astype(int),
            "t_s": a[:, 3],
            "truth": a[:, 4:7],
            "estimate": a[:, 7:10],
            "err_m": a[:, 10],
            "err_theta_rad": a[:, 11],
            "scan_loglik": a[:, 12],
            "lambda_min": a[:, 13],
            "timescale": a[:, 14],
            "safe_mode": a[:, 15],
        }
        extra = [x for x in self.declared(loc) if x.per == "scan" and x.name not in SCAN_COLUMNS]
        if extra:
            names = ", ".join(f'e."{x.name}"' for x in extra)
            rows = self.con.execute(
                f"SELECT {names} FROM estimates e WHERE {where} ORDER BY e.day, e.run, e.step",
                params,
            ).fetchall()
            for j, x in enumerate(extra):
                out[x.name] = _column_values([row[j] for row in rows], x)
        if memo is not None:
            memo[(loc, day, run)] = {k: v.copy() for k, v in out.items()}
        return out

    def run_diagnostic(self, loc: int, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Days, runs and values ``(n_runs, *shape)`` of the per-run diagnostic ``name`` of
        localizer ``loc``, in day and run order (``timescale_counts``: only runs with a
        selection; empty when there are none, or the results predate them)."""
        x = next((x for x in self.declared(loc) if x.name == name and x.per == "run"), None)
        if name in RUN_TABLES:
            sql = f"SELECT day, run, counts FROM {name} WHERE loc=? ORDER BY day, run"
            rows = self.con.execute(sql, (loc,)).fetchall()
            values = [np.frombuffer(b, dtype="<i8") for _, _, b in rows]
            shape = x.shape if x is not None else (values[0].shape if values else (0,))
        elif x is not None and self._has_table("run_diagnostics"):
            rows = self.con.execute(
                "SELECT day, run, value FROM run_diagnostics WHERE loc=? AND name=? "
                "ORDER BY day, run",
                (loc, name),
            ).fetchall()
            values = [_from_blob(b, x) for _, _, b in rows]
            shape = x.shape
        else:
            rows, values, shape = [], [], ()
        days = np.array([int(row[0]) for row in rows], dtype=int)
        runs = np.array([int(row[1]) for row in rows], dtype=int)
        return days, runs, np.array(values).reshape(len(rows), *shape)

    def run_diagnostic_per_day(self, loc: int, name: str) -> tuple[np.ndarray, np.ndarray]:
        """Days and the per-day sums ``(n_days, *shape)`` of a per-run diagnostic."""
        days, _, values = self.run_diagnostic(loc, name)
        uniq = np.unique(days)
        sums = [values[days == day].sum(axis=0) for day in uniq]
        return uniq, np.array(sums, dtype=values.dtype).reshape(len(uniq), *values.shape[1:])

    def point_class_truth_per_day(self, loc: int) -> dict[int, PointClassTally]:
        """Localizer ``loc``'s point classes against the seen-before truth, summed per day
        (day -> :class:`~dynmap_sim.metrics.PointClassTally`; empty before results format 3
        or when it reported none)."""
        out: dict[int, PointClassTally] = {}
        if not self._has_table("point_class_truth"):
            return out
        rows = self.con.execute(
            "SELECT day, confusion, fraction_sum, n_scans FROM point_class_truth WHERE loc = ? "
            "ORDER BY day, run",
            (loc,),
        ).fetchall()
        for day, conf, frac, n in rows:
            t = out.setdefault(int(day), PointClassTally())
            t.merge(
                PointClassTally(
                    np.frombuffer(conf, dtype="<i8").reshape(4, 4).astype(np.int64),
                    np.frombuffer(frac, dtype="<f8").astype(np.float64),
                    int(n),
                )
            )
        return out

    def timescale_counts_per_day(self, loc: int) -> tuple[np.ndarray, np.ndarray]:
        """Days and ``(n_days, n_timescales)`` counts of every timescale selection of
        localizer ``loc`` (empty when it selected none, or the results predate these counts)."""
        return self.run_diagnostic_per_day(loc, "timescale_counts")

    def artifacts(self, loc: int, name: str) -> list[tuple[int, Artifact]]:
        """``[(day, artifact), ...]`` that localizer ``loc`` handed over as ``name``, by day
        (bytes, or named arrays; none in results format 1)."""
        if not self._has_table("artifacts"):
            return []
        rows = self.con.execute(
            "SELECT day, kind, data FROM artifacts WHERE loc=? AND name=? ORDER BY day",
            (loc, name),
        ).fetchall()
        return [(int(day), _decode_artifact(kind, data)) for day, kind, data in rows]

    def nav_runs(self) -> list[tuple[int, int, NavRunSummary]]:
        """``(day, run, NavRunSummary)`` of every stored run (empty for results that
        predate navigation measures)."""
        if not self._has_table("nav_runs"):
            return []
        names = [f.name for f in dataclasses.fields(NavRunSummary)]
        rows = self.con.execute(
            f"SELECT day, run, {', '.join(names)} FROM nav_runs ORDER BY day, run"
        ).fetchall()
        return [
            (
                int(row[0]),
                int(row[1]),
                NavRunSummary.from_dict(
                    {n: math.nan if v is None else v for n, v in zip(names, row[2:], strict=True)}
                ),
            )
            for row in rows
        ]

    def scan_ranges(self, day: int, run: int) -> NDArray[np.float32] | None:
        """The run's laser ranges ``(T, n_beams)`` [m] (REP-117: +inf no return, -inf too
        close), or None when the experiment did not keep them (``run --keep-scans``)."""
        if not self._has_table("scan_ranges"):
            return None
        row = self.con.execute(
            "SELECT n_beams, ranges FROM scan_ranges WHERE day=? AND run=?", (day, run)
        ).fetchone()
        if row is None:
            return None
        return np.frombuffer(zlib.decompress(row[1]), dtype="<f4").reshape(-1, int(row[0]))

    def scan_people(self, day: int, run: int) -> PeopleTrack | None:
        """The run's people at every scan (:class:`PeopleTrack`, positions ``(T, n, 2)``
        [m]), or None when the experiment did not keep them (``run --keep-scans``; folders
        written before the people were kept have none)."""
        if not self._has_table("scan_people"):
            return None
        row = self.con.execute(
            "SELECT n_people, ids, radius, xy FROM scan_people WHERE day=? AND run=?",
            (day, run),
        ).fetchone()
        if row is None:
            return None
        n = int(row[0])
        xy = np.frombuffer(zlib.decompress(row[3]), dtype="<f4").astype(np.float64)
        return PeopleTrack(
            tuple(json.loads(row[1])),
            np.frombuffer(row[2], dtype="<f8").copy(),
            xy.reshape(-1, n, 2) if n else np.zeros((self._n_steps(day, run), 0, 2)),
        )

    def _n_steps(self, day: int, run: int) -> int:
        row = self.con.execute(
            "SELECT n_steps FROM runs WHERE day=? AND run=?", (day, run)
        ).fetchone()
        return 0 if row is None else int(row[0])

    def driver_artifacts(self, name: str) -> list[tuple[int, int, bytes]]:
        """``(day, run, data)`` of the driver's artifact ``name``, by run."""
        if not self._has_table("driver_artifacts"):
            return []
        return [
            (int(d), int(r), bytes(b))
            for d, r, b in self.con.execute(
                "SELECT day, run, data FROM driver_artifacts WHERE name=? ORDER BY day, run",
                (name,),
            )
        ]

    def geometry(self, day: int, run: int) -> tuple[np.ndarray, np.ndarray] | None:
        row = self.con.execute(
            "SELECT segments, segment_class FROM geometry WHERE day=? AND run=?", (day, run)
        ).fetchone()
        if row is None:
            return None
        seg = np.frombuffer(row[0], dtype="<f8").reshape(-1, 4)
        return seg, np.frombuffer(row[1], dtype="i1")


def _column_type(x: Diagnostic) -> str:
    """The SQL type of a per-scan diagnostic's column."""
    if x.shape:
        return "BLOB"
    return "REAL" if np.dtype(x.dtype).kind == "f" else "INTEGER"


def _blob(value: Any, x: Diagnostic) -> bytes | None:
    """A value's little-endian bytes in the declared dtype (None when any element is NaN)."""
    v = np.asarray(value)
    if v.dtype.kind == "f" and np.isnan(v).any():
        return None
    return np.ascontiguousarray(v, dtype=np.dtype(x.dtype).newbyteorder("<")).tobytes()


def _from_blob(blob: bytes | None, x: Diagnostic) -> np.ndarray:
    if blob is None:
        return np.full(x.shape, np.nan)
    return np.frombuffer(blob, dtype=np.dtype(x.dtype).newbyteorder("<")).reshape(x.shape)


def _column_values(values: list[Any], x: Diagnostic) -> np.ndarray:
    """A column of a per-scan diagnostic as float64 ``(N, *shape)`` (NaN: NULL)."""
    if not x.shape:
        return np.array([np.nan if v is None else v for v in values], dtype=np.float64)
    out = np.full((len(values), *x.shape), np.nan)
    for i, v in enumerate(values):
        if v is not None:
            out[i] = _from_blob(v, x)
    return out


def _encode_artifact(name: str, value: Any) -> tuple[str, bytes]:
    """``("bytes", data)`` or ``("npz", data)`` of named arrays (no pickles)."""
    if isinstance(value, bytes | bytearray | memoryview):
        return "bytes", bytes(value)
    if isinstance(value, Mapping):
        arrays = {str(k): np.asarray(v) for k, v in value.items()}
        if all(a.dtype.kind in "biuf" for a in arrays.values()):
            buf = io.BytesIO()
            np.savez_compressed(buf, **arrays)  # type: ignore[arg-type]
            return "npz", buf.getvalue()
    raise InputError(
        f"day artifact {name!r}: bytes or named arrays of numbers, not {type(value).__name__}"
    )


def _decode_artifact(kind: str, data: bytes) -> Artifact:
    if kind == "bytes":
        return bytes(data)
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _none_if_nan(v: Any) -> Any:
    if isinstance(v, float | np.floating) and not np.isfinite(v):
        return None
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.floating):
        return float(v)
    return v
