"""The results store: one SQLite database per experiment (DESIGN.md §6).

``results.db`` in the results folder holds, in WAL mode with one transaction per run:

* ``meta`` — scenario (JSON), its content hash, seed, day range, laser spec;
* ``localizers`` — index, label, class name, parameters;
* ``scans`` — per scan: day, run, step, time of day [s], true pose, collision flag;
* ``estimates`` — per scan and localizer: estimate, position / heading error, covariance
  diagonal and the extras (``scan_loglik``, ``lambda_min``, ``timescale``, ``safe_mode``);
* ``runs``, ``run_summaries``, ``day_summaries`` — per-run and per-day summaries;
* ``events`` — driver and experiment events (skipped waypoints, detours, kidnappings);
* ``point_classes`` — per run and localizer, the 4x4 point-class confusion matrix;
* ``timescale_counts`` — per run and localizer, how often each timescale λ1–λ5 was selected
  (every selection of every scan, B&D Fig. 12);
* ``geometry`` — the static segments of each run's world (for report figures);
* ``checkpoint`` — the pickled driver and RNG states, the next run to do, the scenario hash,
  the names and SHA-256 digests of the localizer files, and a SHA-256 of the blob, so a
  corrupt or mismatched checkpoint is refused.

The localizers of a checkpoint are pickled one file each, ``checkpoint/loc<k>-<next
index>.pkl`` next to ``results.db`` (written to a temporary name, then renamed), not into the
database: a large state (the dynamic maps are tens of MB) rewritten after every run would
churn the database's pages. The files are written before the transaction that names them
commits, and older ones are deleted after it, so a process killed at any moment leaves
either the whole run with its checkpoint or none of it.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import sqlite3
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.errors import InputError
from dynmap_sim.metrics import RunSummary, day_summary, n_onsets, scan_errors

DB_NAME = "results.db"
#: Folder (next to ``results.db``) of the checkpoint's localizer files.
CHECKPOINT_DIR = "checkpoint"

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
CREATE TABLE IF NOT EXISTS timescale_counts (
    loc INTEGER, day INTEGER, run INTEGER, counts BLOB, PRIMARY KEY (loc, day, run));
CREATE TABLE IF NOT EXISTS geometry (
    day INTEGER, run INTEGER, segments BLOB, segment_class BLOB, PRIMARY KEY (day, run));
CREATE TABLE IF NOT EXISTS checkpoint (
    id INTEGER PRIMARY KEY CHECK (id = 1), next_index INTEGER, next_day INTEGER,
    next_run INTEGER, scenario_hash TEXT, seed INTEGER, sha256 TEXT, blob BLOB, created TEXT);
"""

#: Timescales of Biber & Duckett's Table 1 (λ1-λ5), the length of ``timescale_counts`` rows.
N_TIMESCALES = 5

#: Per-scan extras a localizer may report, stored as columns of ``estimates``.
EXTRA_COLUMNS = ("scan_loglik", "lambda_min", "timescale", "safe_mode")


@dataclass
class RunRecord:
    """Everything one run produces, as arrays (written in bulk by :meth:`ResultsDB.write_run`).

    ``truth`` ``(T, 3)``; ``estimates`` ``(L, T, 3)``; ``cov_diag`` ``(L, T, 3)``; ``extras``
    ``(L, T, 4)`` in :data:`EXTRA_COLUMNS` order (NaN where not reported).
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
    extras: NDArray[np.float64]
    confusion: NDArray[np.int64]  # (L, 4, 4)
    terminated: bool
    route_progress: float
    skipped_waypoints: int
    wall_s: float
    events: list[tuple[int, float, str, str]]  # (step, t_s, kind, detail)
    segments: NDArray[np.float64] | None = None
    segment_class: NDArray[np.int8] | None = None
    update_s: NDArray[np.float64] | None = None  # (L,) wall time spent in each update()
    timescale_counts: NDArray[np.int64] | None = None  # (L, 5) selections of each timescale


@dataclass(frozen=True)
class Checkpoint:
    """The state to resume from: the next slot index, the state dict (driver, RNG; pickled
    into the database) and the pickled localizers (one file each)."""

    next_index: int
    next_day: int
    next_run: int
    state: dict[str, Any]
    localizers: tuple[bytes, ...] = ()


class ResultsDB:
    """One experiment's SQLite store (open with :meth:`create` or :meth:`open`)."""

    def __init__(self, path: Path, con: sqlite3.Connection) -> None:
        self.path = path
        self.con = con

    # ------------------------------------------------------------------ opening
    @classmethod
    def create(cls, out_dir: str | Path, overwrite: bool = False) -> ResultsDB:
        """Create a fresh database in ``out_dir``; refuse to clobber results unless asked."""
        d = Path(out_dir)
        d.mkdir(parents=True, exist_ok=True)
        path = d / DB_NAME
        if path.exists():
            if not overwrite:
                raise InputError(
                    f"{path} already holds results; pass --resume to continue them or "
                    "choose another --out"
                )
            for suffix in ("", "-wal", "-shm"):
                Path(str(path) + suffix).unlink(missing_ok=True)
            for f in (d / CHECKPOINT_DIR).glob("*.pkl*"):
                f.unlink()
        con = sqlite3.connect(path)
        con.execute("PRAGMA journal_mode=WAL")
        con.execute("PRAGMA synchronous=NORMAL")
        con.executescript(_SCHEMA)
        con.commit()
        return cls(path, con)

    @classmethod
    def open(cls, out_dir: str | Path) -> ResultsDB:
        """Open an existing results folder (or ``results.db`` path)."""
        p = Path(out_dir)
        path = p if p.suffix == ".db" else p / DB_NAME
        if not path.is_file():
            raise InputError(f"{path}: no results database here")
        try:
            con = sqlite3.connect(path)
            con.execute("PRAGMA journal_mode=WAL")
            con.execute("SELECT count(*) FROM meta").fetchone()
        except sqlite3.DatabaseError as exc:
            raise InputError(f"{path}: not a dynmap_sim results database ({exc})") from None
        return cls(path, con)

    def close(self) -> None:
        self.con.close()

    def __enter__(self) -> ResultsDB:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ meta
    def set_meta(self, **items: Any) -> None:
        with self.con:
            self.con.executemany(
                "INSERT OR REPLACE INTO meta VALUES (?, ?)",
                [(k, json.dumps(v)) for k, v in items.items()],
            )

    def meta(self) -> dict[str, Any]:
        return {k: json.loads(v) for k, v in self.con.execute("SELECT key, value FROM meta")}

    def set_localizers(self, rows: list[tuple[str, str, dict[str, Any]]]) -> None:
        with self.con:
            self.con.execute("DELETE FROM localizers")
            self.con.executemany(
                "INSERT INTO localizers VALUES (?, ?, ?, ?)",
                [(i, lab, name, json.dumps(p)) for i, (lab, name, p) in enumerate(rows)],
            )

    def labels(self) -> list[str]:
        return [r[0] for r in self.con.execute("SELECT label FROM localizers ORDER BY idx")]

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
        ONE transaction. Every number is computed by :mod:`dynmap_sim.metrics`."""
        d, r = rec.day, rec.run
        n_loc, n = rec.estimates.shape[:2]
        steps = np.arange(n)
        files = self._write_localizer_files(checkpoint) if checkpoint is not None else []
        with self.con:
            # a run that was written before a crash (cannot happen with one transaction, but
            # a resumed experiment may redo a run whose checkpoint was older) is replaced
            for table in (
                "scans",
                "estimates",
                "run_summaries",
                "point_classes",
                "timescale_counts",
                "geometry",
            ):
                self.con.execute(f"DELETE FROM {table} WHERE day=? AND run=?", (d, r))
            self.con.execute("DELETE FROM runs WHERE day=? AND run=?", (d, r))
            self.con.execute("DELETE FROM events WHERE day=? AND run=?", (d, r))
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
                        rec.extras[k],
                    ]
                )
                self.con.executemany(
                    "INSERT INTO estimates VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?,?,?)", tab.tolist()
                )
                self.con.execute(
                    "INSERT INTO point_classes VALUES (?,?,?,?)",
                    (k, d, r, np.ascontiguousarray(rec.confusion[k], dtype="<i8").tobytes()),
                )
                if rec.timescale_counts is not None and rec.timescale_counts[k].any():
                    counts = np.ascontiguousarray(rec.timescale_counts[k], dtype="<i8")
                    self.con.execute(
                        "INSERT INTO timescale_counts VALUES (?,?,?,?)",
                        (k, d, r, counts.tobytes()),
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
        if checkpoint is not None:
            self._remove_stale_localizer_files({name for name, _ in files})

    def _day_summaries(self, day: int, n_loc: int) -> list[dict[str, float]]:
        """Summaries of all scans of ``day`` per localizer (reads uncommitted rows too)."""
        out = []
        for k in range(n_loc):
            rows = self.con.execute(
                "SELECT err_m, err_theta_rad, scan_loglik, lambda_min FROM estimates "
                "WHERE loc=? AND day=?",
                (k, day),
            ).fetchall()
            a = np.array(rows, dtype=np.float64).reshape(-1, 4)
            s = day_summary(a[:, 0], a[:, 1], a[:, 2], a[:, 3])
            out.append({"loc": k, "day": day, **s.to_dict()})
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
            tmp.write_bytes(blob)
            os.replace(tmp, path)
            out.append((name, hashlib.sha256(blob).hexdigest()))
        return out

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
        self.con.execute(
            "INSERT OR REPLACE INTO checkpoint VALUES (1, ?, ?, ?, ?, ?, ?, ?, datetime('now'))",
            (
                cp.next_index,
                cp.next_day,
                cp.next_run,
                scenario_hash,
                seed,
                hashlib.sha256(blob).hexdigest(),
                blob,
            ),
        )

    # ------------------------------------------------------------------ reading
    def load_checkpoint(self, scenario_hash: str, seed: int) -> Checkpoint | None:
        """The last checkpoint, verified; None when the experiment has none yet.

        Raises :class:`InputError` when it is corrupt or belongs to another scenario/seed.
        """
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
        if blob is None or hashlib.sha256(bytes(blob)).hexdigest() != digest:
            raise InputError(f"{self.path}: the checkpoint is corrupt (checksum mismatch)")
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
        return {
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

    def timescale_counts_per_day(self, loc: int) -> tuple[np.ndarray, np.ndarray]:
        """Days and ``(n_days, 5)`` counts of every timescale selection of localizer ``loc``
        (empty when it selected none, or the results predate these counts)."""
        per_day: dict[int, np.ndarray] = {}
        for day, blob in self.con.execute(
            "SELECT day, counts FROM timescale_counts WHERE loc=? ORDER BY day, run", (loc,)
        ):
            c = np.frombuffer(blob, dtype="<i8")
            per_day[int(day)] = per_day.get(int(day), np.zeros_like(c)) + c
        days = np.array(sorted(per_day), dtype=int)
        counts = np.array([per_day[d] for d in days], dtype=np.int64)
        return days, counts.reshape(len(days), N_TIMESCALES)

    def geometry(self, day: int, run: int) -> tuple[np.ndarray, np.ndarray] | None:
        row = self.con.execute(
            "SELECT segments, segment_class FROM geometry WHERE day=? AND run=?", (day, run)
        ).fetchone()
        if row is None:
            return None
        seg = np.frombuffer(row[0], dtype="<f8").reshape(-1, 4)
        return seg, np.frombuffer(row[1], dtype="i1")


def _none_if_nan(v: Any) -> Any:
    if isinstance(v, float | np.floating) and not np.isfinite(v):
        return None
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.floating):
        return float(v)
    return v
