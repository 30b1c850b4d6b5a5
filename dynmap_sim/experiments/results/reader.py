"""Reading a results store: per-scan arrays, per-run diagnostics, artifacts, navigation and
the kept scans (a :class:`ResultsReader` is the read half of ``ResultsDB``)."""

from __future__ import annotations

import json
import math
import sqlite3
import zlib
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.experiments.results.integrity import parse_meta
from dynmap_sim.experiments.results.records import PeopleTrack
from dynmap_sim.experiments.results.schema import (
    NAV_RUNS,
    RUN_TABLES,
    SCAN_COLUMNS,
    UPDATE_TIME_CPU,
    Artifact,
    column_values,
    decode_artifact,
    from_blob,
)
from dynmap_sim.metrics import NavRunSummary, PointClassTally
from dynmap_sim.types import Diagnostic


class ResultsReader:
    """The reading methods of a results store at ``path`` over connection ``con``."""

    path: Path
    con: sqlite3.Connection
    #: :meth:`per_scan`'s arrays by (loc, day, run) once :meth:`remember_per_scan`
    _per_scan: dict[tuple[int, int | None, int | None], dict[str, Any]] | None = None

    def remember_per_scan(self) -> None:
        """From now on keep :meth:`per_scan`'s arrays and hand out copies of them again: for
        a reader of finished results that asks for the same localizer's scans many times
        (the report); they are not refreshed when runs are written afterwards."""
        if self._per_scan is None:
            self._per_scan = {}

    def meta(self) -> dict[str, Any]:
        return parse_meta(self.path, self.con.execute("SELECT key, value FROM meta").fetchall())

    def update_time_header(self) -> str:
        """The column header of ``update_ms_per_scan``: CPU time in folders created since
        :data:`UPDATE_TIME_CPU` is recorded, wall time in older ones (a folder begun before
        and resumed since mixes both; it keeps the older label)."""
        cpu = self.meta().get("update_time") == UPDATE_TIME_CPU
        return "update CPU [ms/scan]" if cpu else "update wall [ms/scan]"

    def labels(self) -> list[str]:
        return [r[0] for r in self.con.execute("SELECT label FROM localizers ORDER BY idx")]

    @property
    def format(self) -> int:
        """The results format of this database (1: written before ``results_format``)."""
        row = self.con.execute("SELECT value FROM meta WHERE key = 'results_format'").fetchone()
        return 1 if row is None else int(json.loads(row[0]))

    def has_table(self, name: str) -> bool:
        row = self.con.execute(
            "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (name,)
        ).fetchone()
        return row is not None

    def declared(self, loc: int) -> tuple[Diagnostic, ...]:
        """The diagnostics localizer ``loc`` declared (none in results format 1)."""
        if not self.has_table("diagnostics"):
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
                out[x.name] = column_values([row[j] for row in rows], x)
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
        elif x is not None and self.has_table("run_diagnostics"):
            rows = self.con.execute(
                "SELECT day, run, value FROM run_diagnostics WHERE loc=? AND name=? "
                "ORDER BY day, run",
                (loc, name),
            ).fetchall()
            values = [from_blob(b, x) for _, _, b in rows]
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
        if not self.has_table("point_class_truth"):
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
        if not self.has_table("artifacts"):
            return []
        rows = self.con.execute(
            "SELECT day, kind, data FROM artifacts WHERE loc=? AND name=? ORDER BY day",
            (loc, name),
        ).fetchall()
        return [(int(day), decode_artifact(kind, data)) for day, kind, data in rows]

    def nav_runs(self) -> list[tuple[int, int, NavRunSummary]]:
        """``(day, run, NavRunSummary)`` of every stored run (empty for results that
        predate navigation measures)."""
        if not self.has_table("nav_runs"):
            return []
        names = list(NAV_RUNS.fields)
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
        if not self.has_table("scan_ranges"):
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
        if not self.has_table("scan_people"):
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
        if not self.has_table("driver_artifacts"):
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
