"""The rows of one run, written in the open transaction of ``ResultsDB.write_run``.

Every number is computed by :mod:`dynmap_sim.metrics`; one float64 table per bulk insert,
converted once (SQLite stores NaN as NULL and turns whole-number reals into integers in
INTEGER columns).
"""

from __future__ import annotations

import dataclasses
import json
import sqlite3
import zlib

import numpy as np

from dynmap_sim.errors import InputError
from dynmap_sim.experiments.results.records import LocalizerDiagnostics, RunRecord
from dynmap_sim.experiments.results.schema import (
    DAY_SUMMARIES,
    ESTIMATE_COLUMNS,
    NAV_RUNS,
    RUN_SUMMARIES,
    RUN_TABLES,
    RUNS,
    SCAN_COLUMNS,
    SCAN_PEOPLE_TABLE,
    SCAN_RANGES_TABLE,
    RunRow,
    diagnostic_column_type,
    encode_artifact,
    to_blob,
)
from dynmap_sim.metrics import DaySummary, RunSummary, day_summary, n_onsets, scan_errors
from dynmap_sim.types import Diagnostic

#: The tables that hold rows of a run (a run written again replaces them).
RUN_ROW_TABLES = (
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
    "runs",
    "events",
    "digests",
)


def _le(a: np.ndarray, dtype: str) -> bytes:
    return np.ascontiguousarray(a, dtype=dtype).tobytes()


class RunWriter:
    """Writes the rows of run ``rec`` through ``con`` (inside the caller's transaction)."""

    def __init__(self, con: sqlite3.Connection, rec: RunRecord) -> None:
        self.con = con
        self.rec = rec
        self.n_loc, self.n = rec.estimates.shape[:2]
        self.diags = rec.diagnostics or [LocalizerDiagnostics() for _ in range(self.n_loc)]

    def write(self, run_summaries: list[RunSummary], day_done: bool) -> None:
        """Every row of the run, its summaries and (``day_done``) its day's summaries."""
        rec = self.rec
        d, r = rec.day, rec.run
        # a run that was written before (a resumed experiment may redo a run whose
        # checkpoint was older) is replaced
        for table in RUN_ROW_TABLES:
            self.con.execute(f"DELETE FROM {table} WHERE day=? AND run=?", (d, r))
        declare(self.con, self.diags)
        self._scans()
        for k in range(self.n_loc):
            self._estimates(k)
            self._point_classes(k)
            self._run_diagnostics(k)
            for name, value in self.diags[k].artifacts.items():
                self.con.execute(
                    "INSERT OR REPLACE INTO artifacts VALUES (?,?,?,?,?)",
                    (k, d, name, *encode_artifact(name, value)),
                )
        self._run_row()
        self._kept_scans()
        for k, s in enumerate(run_summaries):
            self.con.execute(RUN_SUMMARIES.insert(), RUN_SUMMARIES.values((k, d, r), s))
        if day_done:
            for k, s in enumerate(day_summaries(self.con, d, self.n_loc)):
                self.con.execute(
                    DAY_SUMMARIES.insert("INSERT OR REPLACE"), DAY_SUMMARIES.values((k, d), s)
                )

    def _scans(self) -> None:
        rec, n = self.rec, self.n
        ones = np.ones(n)
        tab = np.column_stack(
            [
                rec.day * ones,
                rec.run * ones,
                np.arange(n),
                rec.t_s,
                rec.truth,
                rec.collision.astype(float),
            ]
        )
        self.con.executemany("INSERT INTO scans VALUES (?,?,?,?,?,?,?,?)", tab.tolist())

    def _estimates(self, k: int) -> None:
        rec, n = self.rec, self.n
        est = rec.estimates[k]
        err, herr = scan_errors(rec.truth, est)
        g = self.diags[k]
        on_scan = [x for x in g.declared if x.per == "scan"]
        scalars = [x for x in on_scan if not x.shape]
        arrays = [x for x in on_scan if x.shape]
        ones, none = np.ones(n), np.full(n, np.nan)
        tab = np.column_stack(
            [
                k * ones,
                rec.day * ones,
                rec.run * ones,
                np.arange(n),
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
                row.append(to_blob(v, x))
        cols = ESTIMATE_COLUMNS + tuple(f'"{x.name}"' for x in scalars + arrays)
        self.con.executemany(
            f"INSERT INTO estimates ({', '.join(cols)}) VALUES ({', '.join('?' * len(cols))})",
            rows,
        )

    def _point_classes(self, k: int) -> None:
        rec = self.rec
        key = (k, rec.day, rec.run)
        self.con.execute(
            "INSERT INTO point_classes VALUES (?,?,?,?)", (*key, _le(rec.confusion[k], "<i8"))
        )
        tally = rec.point_tallies[k] if k < len(rec.point_tallies) else None
        if tally is not None and (tally.n_scans or tally.confusion.any()):
            self.con.execute(
                "INSERT INTO point_class_truth VALUES (?,?,?,?,?,?)",
                (
                    *key,
                    _le(tally.confusion, "<i8"),
                    _le(tally.fraction_sum, "<f8"),
                    int(tally.n_scans),
                ),
            )

    def _run_diagnostics(self, k: int) -> None:
        g, key = self.diags[k], (k, self.rec.day, self.rec.run)
        for x in g.declared:
            if x.per != "run" or x.name not in g.per_run:
                continue
            value = np.asarray(g.per_run[x.name]).reshape(x.shape)
            if x.name in RUN_TABLES:
                if value.any():
                    self.con.execute(
                        f"INSERT INTO {x.name} VALUES (?,?,?,?)", (*key, _le(value, "<i8"))
                    )
            else:
                self.con.execute(
                    "INSERT INTO run_diagnostics VALUES (?,?,?,?,?)",
                    (*key, x.name, to_blob(value, x)),
                )

    def _run_row(self) -> None:
        """The ``runs`` row, the events, the geometry, navigation and driver artifacts."""
        rec, n = self.rec, self.n
        d, r = rec.day, rec.run
        row = RunRow(
            date=rec.date,
            start_s=rec.start_s,
            n_steps=n,
            duration_s=float(rec.t_s[-1] - rec.t_s[0]) if n else 0.0,
            collisions=n_onsets(rec.collision),
            skipped_waypoints=rec.skipped_waypoints,
            route_progress=rec.route_progress,
            terminated=int(rec.terminated),
            wall_s=rec.wall_s,
        )
        self.con.execute(RUNS.insert(), RUNS.values((d, r), row))
        self.con.executemany(
            "INSERT INTO events VALUES (?,?,?,?,?,?)",
            [(d, r, s, t, kind, det) for s, t, kind, det in rec.events],
        )
        if rec.segments is not None:
            self.con.execute(
                "INSERT INTO geometry VALUES (?,?,?,?)",
                (d, r, _le(rec.segments, "<f8"), _le(rec.segment_class, "i1")),
            )
        if rec.nav is not None:
            self.con.execute(NAV_RUNS.insert(), NAV_RUNS.values((d, r), rec.nav))
        self.con.executemany(
            "INSERT INTO driver_artifacts VALUES (?,?,?,?)",
            [(d, r, name, data) for name, data in rec.driver_artifacts.items()],
        )

    def _kept_scans(self) -> None:
        """The ranges and the people of every scan (``run --keep-scans``)."""
        rec, n = self.rec, self.n
        d, r = rec.day, rec.run
        if rec.ranges is not None:
            self.con.execute(SCAN_RANGES_TABLE)
            ranges = np.ascontiguousarray(rec.ranges, dtype="<f4")
            self.con.execute(
                "INSERT OR REPLACE INTO scan_ranges VALUES (?,?,?,?)",
                (d, r, ranges.shape[1], zlib.compress(ranges.tobytes(), 1)),
            )
        if rec.people is not None:
            p = rec.people
            xy = np.ascontiguousarray(p.xy, dtype="<f4").reshape(n, len(p.ids), 2)
            self.con.execute(SCAN_PEOPLE_TABLE)
            self.con.execute(
                "INSERT OR REPLACE INTO scan_people VALUES (?,?,?,?,?,?)",
                (
                    d,
                    r,
                    len(p.ids),
                    json.dumps(list(p.ids)),
                    _le(p.radius_m, "<f8"),
                    zlib.compress(xy.tobytes(), 1),
                ),
            )


def declare(con: sqlite3.Connection, diags: list[LocalizerDiagnostics]) -> None:
    """Record each localizer's declarations; add a column to ``estimates`` for each
    per-scan diagnostic that has none yet (in the open transaction)."""
    cols = {
        name: str(kind).upper() for _, name, kind, *_ in con.execute("PRAGMA table_info(estimates)")
    }
    for k, g in enumerate(diags):
        names = [x.name for x in g.declared]
        for x in g.declared:
            where = f"diagnostic {x.name!r} of localizer {k}"
            if names.count(x.name) > 1:
                raise InputError(f"{where} is declared twice")
            con.execute(
                "INSERT OR REPLACE INTO diagnostics VALUES (?,?,?,?,?,?,?)",
                (k, x.name, x.per, x.dtype, json.dumps(list(x.shape)), x.counts_of, x.doc),
            )
            if x.per == "scan":
                _add_column(con, cols, x, where)


def _add_column(con: sqlite3.Connection, cols: dict[str, str], x: Diagnostic, where: str) -> None:
    kind = diagnostic_column_type(x)
    if x.name in ESTIMATE_COLUMNS:
        raise InputError(f"{where}: {x.name!r} is a column of every estimate")
    if x.name in SCAN_COLUMNS and x.shape:
        raise InputError(f"{where} must be a scalar (a column since format 1)")
    have = cols.get(x.name)
    if have is None:
        con.execute(f'ALTER TABLE estimates ADD COLUMN "{x.name}" {kind}')
        cols[x.name] = kind
    elif have != kind and x.name not in SCAN_COLUMNS:
        raise InputError(f"{where} is {kind} but another localizer declared it {have}")


def day_summaries(con: sqlite3.Connection, day: int, n_loc: int) -> list[DaySummary]:
    """Summaries of all scans of ``day`` per localizer (reads uncommitted rows too); the
    errors of the scans with truth (a replay's scans without a reference pose have none),
    ``n_scans`` of all."""
    out = []
    for k in range(n_loc):
        rows = con.execute(
            "SELECT e.err_m, e.err_theta_rad, e.scan_loglik, e.lambda_min, s.x IS NOT NULL "
            "FROM estimates e JOIN scans s USING (day, run, step) WHERE e.loc=? AND e.day=?",
            (k, day),
        ).fetchall()
        a = np.array(rows, dtype=np.float64).reshape(-1, 5)
        m = a[:, 4] > 0
        s = day_summary(a[m, 0], a[m, 1], a[:, 2], a[:, 3])
        out.append(dataclasses.replace(s, n_scans=len(a)))
    return out
