"""Export a results folder as Parquet tables (``dynmap-sim export DIR --parquet OUT``).

Four files in ``OUT``, each with an explicit Arrow schema (units in the column names, a
``doc`` in each field's metadata, the experiment's identity in the schema metadata under
``dynmap_sim``) and the localizer's label dictionary-encoded:

* ``scans.parquet`` — one row per scan and localizer: the truth (``truth_x_m`` ...), the
  localizer's estimate (``est_x_m`` ...), its errors (``err_m``, ``err_theta_rad``), the
  covariance diagonal, the per-scan diagnostics (NULL where a localizer does not report them);
* ``runs.parquet`` — one row per run and localizer: the run (``runs``), the localizer's
  summary of it (``run_summaries``) and the navigation measures (``nav_*``, NULL when the run
  was not measured); the run's own columns repeat for each localizer;
* ``days.parquet`` — one row per day and localizer (``day_summaries``);
* ``localizers.parquet`` — one row per localizer: label, registry name, parameters as JSON.

The store is read in bulk, one query per table, with ADBC's SQLite driver into Arrow
(``engine="sqlite3"``: the standard library's ``fetchall``, about 4x slower; same output).
ADBC infers a column's type from the first batch of rows and refuses a later batch of
another type, so a column that starts NULL (the odometry localizer reports no
``scan_loglik``; its rows come first) would fail: the batch is made as large as the table,
and every column is then cast to the explicit schema (an all-NULL column comes back as int64).
"""

from __future__ import annotations

import json
import os
import sqlite3
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from dynmap_sim.errors import InputError
from dynmap_sim.experiments.results import (
    DB_NAME,
    ESTIMATE_COLUMNS,
    SCAN_COLUMNS,
    ResultsDB,
)

try:
    import adbc_driver_sqlite.dbapi as adbc_sqlite
    import pyarrow as pa
    import pyarrow.parquet as pq
except ImportError as exc:  # pragma: no cover - depends on what is installed
    raise ImportError(
        f"the Parquet export needs the analysis extra ({exc.name} is not installed): "
        'pip install "dynmap-sim[analysis]"'
    ) from exc

Engine = Literal["adbc", "sqlite3"]

#: The files written, by table name.
TABLES = ("scans", "runs", "days", "localizers")

#: The localizer's label: dictionary-encoded (a handful of labels over millions of rows).
LABEL = pa.dictionary(pa.int8(), pa.string())


@dataclass(frozen=True)
class Column:
    """One output column: read as ``source`` (a SQL column of the table), written as
    ``name`` of ``type``."""

    source: str
    name: str
    type: pa.DataType
    doc: str
    nullable: bool = True


def _schema(columns: Sequence[Column]) -> pa.Schema:
    return pa.schema(
        [pa.field(c.name, c.type, c.nullable, metadata={"doc": c.doc}) for c in columns]
    )


#: Arrow types by their short name in the column tables below.
_TYPES = {
    "f64": pa.float64(),
    "i8": pa.int8(),
    "i16": pa.int16(),
    "i32": pa.int32(),
    "bool": pa.bool_(),
    "str": pa.string(),
    "date": pa.date32(),
}


def _columns(table: str) -> tuple[Column, ...]:
    """Columns from lines ``source name type [!] doc`` (name ``=``: the source's; ``!``:
    never NULL)."""
    out = []
    for line in table.strip().splitlines():
        source, name, kind, doc = line.split(maxsplit=3)
        required = doc.startswith("! ")
        name = source if name == "=" else name
        out.append(Column(source, name, _TYPES[kind], doc.removeprefix("! "), not required))
    return tuple(out)


_KEYS = _columns(
    """
day                    =                    i16  ! day of the experiment (1-based)
run                    =                    i16  ! run of the day (1-based)
"""
)
#: ``scans.parquet``: the truth (after the localizer, day, run; date after step)
SCAN_TRUTH = _columns(
    """
step                   =                    i32  ! scan index within the run (0-based)
t_s                    =                    f64  ! time of day of the scan [s since midnight]
x                      truth_x_m            f64  ! true x of the robot [m]
y                      truth_y_m            f64  ! true y of the robot [m]
theta                  truth_theta_rad      f64  ! true heading [rad]
collision              =                    bool ! the robot touched something
"""
)
SCAN_ESTIMATE = _columns(
    """
x                      est_x_m              f64    estimated x [m]
y                      est_y_m              f64    estimated y [m]
theta                  est_theta_rad        f64    estimated heading [rad]
err_m                  =                    f64    position error of the estimate [m]
err_theta_rad          =                    f64    heading error, absolute [rad]
var_x                  var_x_m2             f64    variance of x of the estimate [m^2]
var_y                  var_y_m2             f64    variance of y of the estimate [m^2]
var_theta              var_theta_rad2       f64    variance of the heading [rad^2]
scan_loglik            =                    f64    mean per-beam log-likelihood
lambda_min             =                    f64    smallest eigenvalue of the information
timescale              =                    i8     selected timescale, 0 = λ1 ... 4 = λ5
safe_mode              =                    bool   the map fell back to safe mode
"""
)
RUN = _columns(
    """
start_s                =                    f64    time of day the run started [s]
n_steps                =                    i32    scans in the run
duration_s             =                    f64    simulated duration [s]
collisions             =                    i32    collision onsets
skipped_waypoints      =                    i32    waypoints the driver skipped
route_progress         =                    f64    fraction of the route driven
terminated             =                    bool   the run reached its end
wall_s                 =                    f64    wall-clock time of the run [s]
"""
)
_SUMMARY = _columns(
    """
n_scans                =                    i32    scans summarised
mean_error_m           =                    f64    mean position error [m]
max_error_m            =                    f64    largest position error [m]
rmse_m                 =                    f64    RMS position error (ATE RMSE) [m]
lost_fraction          =                    f64    fraction of scans lost
mean_heading_error_rad =                    f64    mean heading error [rad]
mean_scan_loglik       =                    f64    mean of scan_loglik
mean_lambda_min        =                    f64    mean of lambda_min
"""
)
NAV = _columns(
    """
goal_reached           nav_goal_reached     bool   the robot reached its goal
time_s                 nav_time_s           f64    time to the goal or giving up [s]
path_length_m          nav_path_length_m    f64    driven path length [m]
shortest_path_m        nav_shortest_path_m  f64    shortest path [m]
spl                    nav_spl              f64    success weighted by path length
collisions             nav_collisions       i32    collisions while navigating
near_misses            nav_near_misses      i32    near misses while navigating
min_clearance_m        nav_min_clearance_m  f64    smallest clearance [m]
replans                nav_replans          i32    replans
recoveries             nav_recoveries       i32    recovery behaviours
stuck_s                nav_stuck_s          f64    time spent stuck [s]
gave_up                nav_gave_up          bool   the robot gave up
"""
)
LOCALIZER = _columns(
    """
idx                    =                    i16  ! the localizer's index in the experiment
name                   =                    str  ! registry name or package.module:Class
params                 params_json          str    parameters from the scenario, as JSON
"""
)
RUN_SUMMARY = _SUMMARY + _columns(
    """
n_lost_episodes        =                    i32    times the localizer got lost
n_recovered            =                    i32    lost episodes it recovered from
mean_time_to_recover_s =                    f64    mean time to recover after getting lost [s]
rpe_m                  =                    f64    relative pose error [m]
update_ms_per_scan     =                    f64    update() CPU time [ms/scan]
"""
)
_DATE = Column("date", "date", pa.date32(), "calendar date of the run", False)

_LABEL_DOC = "the localizer's label in the scenario"


@dataclass(frozen=True)
class ParquetFile:
    """One file written: its table name, path, rows and size [bytes]."""

    table: str
    path: Path
    rows: int
    bytes: int


# --------------------------------------------------------------------------- reading
class _Reader:
    """Bulk reads of whole tables into Arrow, one query each, in one read transaction."""

    def __init__(self, db_path: Path, engine: Engine) -> None:
        self.engine = engine
        uri = db_path.resolve().as_uri() + "?mode=ro"
        if engine == "adbc":
            self.con: Any = adbc_sqlite.connect(uri)  # not autocommit: one snapshot
        elif engine == "sqlite3":
            self.con = sqlite3.connect(uri, uri=True, isolation_level=None)
            self.con.execute("BEGIN")
        else:
            raise ValueError(f"engine must be 'adbc' or 'sqlite3', not {engine!r}")

    def close(self) -> None:
        self.con.close()

    def table(self, sql: str, count_sql: str, columns: Sequence[Column]) -> pa.Table:
        """Run ``sql`` (selecting ``columns``' sources in order) into a table of their
        output names and types."""
        cur = self.con.cursor()
        try:
            if self.engine == "adbc":
                cur.execute(count_sql)
                n = int(cur.fetchone()[0])
                # the type of each column is inferred from the first batch: make it all rows
                cur.adbc_statement.set_options(**{"adbc.sqlite.query.batch_rows": str(max(n, 1))})
                cur.execute(sql)
                arrays = cur.fetch_arrow_table().columns
            else:
                rows = cur.execute(sql).fetchall()
                cols = list(zip(*rows, strict=True)) if rows else [()] * len(columns)
                arrays = [pa.array(c) for c in cols]
        finally:
            cur.close()
        return pa.table(
            [_cast(a, c.type) for a, c in zip(arrays, columns, strict=True)],
            schema=_schema(columns),
        )


def _cast(a: pa.Array | pa.ChunkedArray, to: pa.DataType) -> pa.Array | pa.ChunkedArray:
    """``a`` as ``to``: a column that is NULL throughout comes back as int64 (ADBC) or null
    (sqlite3); dates are stored as ISO text."""
    if a.type.equals(to):
        return a
    return a.cast(to)


def _key(day: np.ndarray, run: np.ndarray, step: np.ndarray | None = None) -> np.ndarray:
    """One sortable int64 per (day, run[, step])."""
    k = (day.astype(np.int64) << 44) | (run.astype(np.int64) << 32)
    return k if step is None else k | step.astype(np.int64)


def _lookup(keys: np.ndarray, wanted: np.ndarray) -> pa.Array:
    """Row indices of ``wanted`` in sorted ``keys`` (NULL where absent), for ``take``."""
    if len(keys) == 0:
        return pa.nulls(len(wanted), pa.int64())
    i = np.clip(np.searchsorted(keys, wanted), 0, len(keys) - 1)
    found = keys[i] == wanted
    return pa.array(i, mask=~found)


def _np(t: pa.Table, name: str) -> np.ndarray:
    return t.column(name).to_numpy()


def _labels(loc: np.ndarray, idx: np.ndarray, labels: list[str]) -> pa.DictionaryArray:
    """The localizer column: ``loc`` (the store's index) as a dictionary of ``labels``."""
    pos = np.searchsorted(idx, loc)
    if len(loc) and (pos.max() >= len(idx) or not np.array_equal(idx[pos], loc)):
        raise InputError("the store has estimates of a localizer it does not list")
    return pa.DictionaryArray.from_arrays(pa.array(pos, pa.int8()), pa.array(labels, pa.string()))


# --------------------------------------------------------------------------- the tables
def _extra_scan_columns(db: ResultsDB) -> list[tuple[Column, tuple[int, ...]]]:
    """Declared per-scan diagnostics with a column of their own (not in every store)."""
    have = [row[1] for row in db.query("PRAGMA table_info(estimates)")]
    extra = [c for c in have if c not in ESTIMATE_COLUMNS and c not in SCAN_COLUMNS]
    declared: dict[str, Any] = {}
    for k in range(len(db.labels())):
        for x in db.declared(k):
            if x.per == "scan":
                declared.setdefault(x.name, x)
    out = []
    for name in extra:
        x = declared.get(name)
        if x is None:
            continue  # a column nobody declared (cannot be written by this version)
        dtype = np.dtype(x.dtype)
        value = pa.bool_() if dtype.kind == "b" else pa.from_numpy_dtype(dtype)
        if x.shape:
            value = pa.list_(value, int(np.prod(x.shape)))
        doc = x.doc + (f" (shape {list(x.shape)}, C order)" if x.shape else "")
        out.append((Column(name, name, value, doc), tuple(x.shape)))
    return out


def _from_blobs(a: pa.Array | pa.ChunkedArray, to: pa.DataType) -> pa.Array:
    """A BLOB diagnostic column (little-endian values, NULL: not reported) as fixed lists."""
    dtype = np.dtype(to.value_type.to_pandas_dtype()).newbyteorder("<")
    values = [None if b is None else np.frombuffer(b, dtype=dtype) for b in a.to_pylist()]
    return pa.array(values, type=to)


def _scans(
    db: ResultsDB, rd: _Reader, runs: pa.Table, idx: np.ndarray, labels: list[str]
) -> pa.Table:
    truth = rd.table(
        "SELECT day, run, step, t_s, x, y, theta, collision FROM scans ORDER BY day, run, step",
        "SELECT count(*) FROM scans",
        _KEYS + SCAN_TRUTH,
    )
    extra = _extra_scan_columns(db)
    blob_cols = {c.name for c, shape in extra if shape}
    read_extra = [replace(c, type=pa.binary()) if c.name in blob_cols else c for c, _ in extra]
    loc = Column("loc", "loc", pa.int16(), "", False)
    step = SCAN_TRUTH[0]
    est_cols = (loc, *_KEYS, step, *SCAN_ESTIMATE, *read_extra)
    names = ", ".join(f'"{c.source}"' for c in est_cols)
    est = rd.table(
        f"SELECT {names} FROM estimates ORDER BY loc, day, run, step",
        "SELECT count(*) FROM estimates",
        est_cols,
    )
    day, run, stp = _np(est, "day"), _np(est, "run"), _np(est, "step")
    at = _lookup(
        _key(_np(truth, "day"), _np(truth, "run"), _np(truth, "step")), _key(day, run, stp)
    )
    at_run = _lookup(_key(_np(runs, "day"), _np(runs, "run")), _key(day, run))
    columns: dict[str, Any] = {
        "localizer": _labels(_np(est, "loc"), idx, labels),
        "day": est.column("day"),
        "run": est.column("run"),
        "step": est.column("step"),
        "date": runs.column("date").take(at_run),
    }
    for c in SCAN_TRUTH[1:]:
        columns[c.name] = truth.column(c.name).take(at)
    for c in SCAN_ESTIMATE:
        columns[c.name] = est.column(c.name)
    for c, shape in extra:
        a = est.column(c.name)
        columns[c.name] = _from_blobs(a, c.type) if shape else a
    schema = _schema(
        (
            Column("loc", "localizer", LABEL, _LABEL_DOC, False),
            *_KEYS,
            step,
            _DATE,
            *SCAN_TRUTH[1:],
            *SCAN_ESTIMATE,
            *(c for c, _ in extra),
        )
    )
    return pa.table(list(columns.values()), schema=schema)


def _runs(db: ResultsDB, rd: _Reader) -> pa.Table:
    """``runs`` (day, run, date and :data:`RUN`), in day and run order."""
    cols = (*_KEYS, replace(_DATE, type=pa.string()), *RUN)
    sel = ", ".join(c.source for c in cols)
    t = rd.table(f"SELECT {sel} FROM runs ORDER BY day, run", "SELECT count(*) FROM runs", cols)
    return t.set_column(2, pa.field("date", pa.date32(), False), t.column("date").cast(pa.date32()))


def _per_run(
    db: ResultsDB, rd: _Reader, runs: pa.Table, idx: np.ndarray, labels: list[str]
) -> pa.Table:
    loc = Column("loc", "loc", pa.int16(), "", False)
    cols = (loc, *_KEYS, *RUN_SUMMARY)
    sel = ", ".join(c.source for c in cols)
    s = rd.table(
        f"SELECT {sel} FROM run_summaries ORDER BY loc, day, run",
        "SELECT count(*) FROM run_summaries",
        cols,
    )
    key = _key(_np(s, "day"), _np(s, "run"))
    at_run = _lookup(_key(_np(runs, "day"), _np(runs, "run")), key)
    if db.query("SELECT 1 FROM sqlite_master WHERE type='table' AND name='nav_runs'"):
        nav = rd.table(
            f"SELECT day, run, {', '.join(c.source for c in NAV)} FROM nav_runs ORDER BY day, run",
            "SELECT count(*) FROM nav_runs",
            (*_KEYS, *NAV),
        )
        at_nav = _lookup(_key(_np(nav, "day"), _np(nav, "run")), key)
        nav_cols = [nav.column(c.name).take(at_nav) for c in NAV]
    else:  # results that predate navigation measures
        nav_cols = [pa.nulls(s.num_rows, c.type) for c in NAV]
    schema = _schema(
        (
            Column("loc", "localizer", LABEL, _LABEL_DOC, False),
            *_KEYS,
            _DATE,
            *RUN,
            *RUN_SUMMARY,
            *NAV,
        )
    )
    arrays = [
        _labels(_np(s, "loc"), idx, labels),
        s.column("day"),
        s.column("run"),
        runs.column("date").take(at_run),
        *(runs.column(c.name).take(at_run) for c in RUN),
        *(s.column(c.name) for c in RUN_SUMMARY),
        *nav_cols,
    ]
    return pa.table(arrays, schema=schema)


def _per_day(rd: _Reader, idx: np.ndarray, labels: list[str]) -> pa.Table:
    loc = Column("loc", "loc", pa.int16(), "", False)
    cols = (loc, _KEYS[0], *_SUMMARY)
    sel = ", ".join(c.source for c in cols)
    d = rd.table(
        f"SELECT {sel} FROM day_summaries ORDER BY loc, day",
        "SELECT count(*) FROM day_summaries",
        cols,
    )
    schema = _schema((Column("loc", "localizer", LABEL, _LABEL_DOC, False), _KEYS[0], *_SUMMARY))
    arrays = [_labels(_np(d, "loc"), idx, labels), *d.columns[1:]]
    return pa.table(arrays, schema=schema)


def _localizers(rows: list[tuple[Any, ...]]) -> pa.Table:
    labels = [r[1] for r in rows]
    schema = _schema((Column("label", "localizer", LABEL, _LABEL_DOC, False), *LOCALIZER))
    arrays = [
        _labels(np.arange(len(rows)), np.arange(len(rows)), labels),
        pa.array([r[0] for r in rows], pa.int16()),
        pa.array([r[2] for r in rows], pa.string()),
        pa.array([r[3] for r in rows], pa.string()),
    ]
    return pa.table(arrays, schema=schema)


# --------------------------------------------------------------------------- writing
def _few_values(schema: pa.Schema) -> list[str]:
    """Columns worth Parquet's dictionary encoding (labels, keys, flags, dates): for the
    floats it costs time and makes files larger."""
    small = (pa.bool_(), pa.int8(), pa.int16(), pa.date32(), pa.string())
    return [f.name for f in schema if pa.types.is_dictionary(f.type) or f.type in small]


def parquet_paths(out: str | Path) -> dict[str, Path]:
    """The files :func:`export_parquet` writes into ``out``, by table."""
    return {name: Path(out) / f"{name}.parquet" for name in TABLES}


def read_tables(results_dir: str | Path, engine: Engine = "adbc") -> dict[str, pa.Table]:
    """The four tables of a results folder (see the module doc), in memory."""
    with ResultsDB.open(results_dir) as db:
        if not db.query("SELECT 1 FROM runs LIMIT 1"):
            raise InputError(f"{results_dir}: no finished run to export")
        meta = db.meta()
        loc_rows = db.query("SELECT idx, label, name, params FROM localizers ORDER BY idx")
        idx = np.array([r[0] for r in loc_rows], dtype=np.int64)
        labels = [r[1] for r in loc_rows]
        if len(labels) > 127:
            raise InputError(f"{results_dir}: {len(labels)} localizers (at most 127 here)")
        rd = _Reader(db.path, engine)
        try:
            runs = _runs(db, rd)
            tables = {
                "scans": _scans(db, rd, runs, idx, labels),
                "runs": _per_run(db, rd, runs, idx, labels),
                "days": _per_day(rd, idx, labels),
                "localizers": _localizers(loc_rows),
            }
        finally:
            rd.close()
    ident = {
        k: meta.get(k)
        for k in ("scenario_name", "world", "seed", "first_date", "experiment_hash")
        if k in meta
    }
    ident["results_format"] = meta.get("results_format", 1)
    return {
        name: t.replace_schema_metadata({"dynmap_sim": json.dumps({"table": name, **ident})})
        for name, t in tables.items()
    }


def export_parquet(
    results_dir: str | Path,
    out: str | Path,
    force: bool = False,
    engine: Engine = "adbc",
    compression: str = "zstd",
) -> list[ParquetFile]:
    """Write ``scans``, ``runs``, ``days`` and ``localizers.parquet`` of a results folder
    into ``out`` (created); existing files are refused unless ``force``. Each file is
    written under a temporary name and renamed, so a failure leaves no half file."""
    dst = Path(out)
    if dst.exists() and not dst.is_dir():
        raise InputError(f"--parquet {out}: is a file; give a folder")
    if (dst / DB_NAME).exists():
        raise InputError(f"--parquet {out}: is a results folder; give another folder")
    paths = parquet_paths(dst)
    held = [p for p in paths.values() if p.exists()]
    if held and not force:
        raise InputError(
            f"{held[0]} already exists; pass --force to replace the Parquet files in {out} "
            "or choose another folder"
        )
    tables = read_tables(results_dir, engine)
    try:
        dst.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create folder {out}: {exc.strerror or exc}") from None
    written = []
    for name, table in tables.items():
        path = paths[name]
        tmp = path.with_name(path.name + ".tmp")
        try:
            pq.write_table(
                table, tmp, compression=compression, use_dictionary=_few_values(table.schema)
            )
            os.replace(tmp, path)
        finally:
            tmp.unlink(missing_ok=True)
        written.append(ParquetFile(name, path, table.num_rows, path.stat().st_size))
    return written
