"""The results store's layout: its tables, their DDL and inserts, and how values are encoded.

The core tables whose columns are a dataclass's fields (``runs``, ``run_summaries``,
``day_summaries``, ``nav_runs``) are :class:`Table` s generated from the dataclass, so that a
column is written once, like the per-scan columns a localizer declares
(:class:`~dynmap_sim.types.Diagnostic`, added to ``estimates`` by
:func:`diagnostic_column_type`).
"""

from __future__ import annotations

import dataclasses
import io
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from dynmap_sim.errors import InputError
from dynmap_sim.metrics import DaySummary, NavRunSummary, RunSummary
from dynmap_sim.types import Diagnostic

DB_NAME = "results.db"
#: Folder (next to ``results.db``) of the checkpoint's localizer files.
CHECKPOINT_DIR = "checkpoint"
#: The lock file of a results folder (held by its one writer).
LOCK_NAME = ".results.lock"

#: The layout this version writes (``results_format`` in ``meta``; none: format 1).
RESULTS_FORMAT = 4
#: What each earlier results format lacks (why this version reads but does not continue it).
FORMAT_LACKS = {
    1: "before localizers declared their diagnostics",
    2: "before the seen-before point-class truth",
    3: "before the checksums of the stored rows and metadata",
}

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

_SQL_TYPES = {"int": "INTEGER", "float": "REAL", "str": "TEXT", "bool": "INTEGER"}


@dataclass(frozen=True)
class RunRow:
    """One ``runs`` row without its keys: the slot's ``date`` and ``start_s`` (time of day
    [s]), ``n_steps`` scans over ``duration_s`` of robot time, bumper onsets ``collisions``,
    the driver's ``skipped_waypoints``, ``route_progress`` (fraction), ``terminated`` (0/1:
    the route was finished) and the run's ``wall_s``."""

    date: str
    start_s: float
    n_steps: int
    duration_s: float
    collisions: int
    skipped_waypoints: int
    route_progress: float
    terminated: int
    wall_s: float


@dataclass(frozen=True)
class Table:
    """A table of ``keys`` (``(name, SQL type)``) followed by the fields of ``row``."""

    name: str
    keys: tuple[tuple[str, str], ...]
    row: type

    @property
    def fields(self) -> tuple[str, ...]:
        return tuple(f.name for f in dataclasses.fields(self.row))

    @property
    def columns(self) -> tuple[str, ...]:
        return tuple(k for k, _ in self.keys) + self.fields

    def ddl(self) -> str:
        types = {f.name: _SQL_TYPES[str(f.type)] for f in dataclasses.fields(self.row)}
        cols = [f"{k} {t}" for k, t in self.keys] + [f"{n} {types[n]}" for n in self.fields]
        pk = ", ".join(k for k, _ in self.keys)
        return f"CREATE TABLE IF NOT EXISTS {self.name} ({', '.join(cols)}, PRIMARY KEY ({pk}))"

    def insert(self, verb: str = "INSERT") -> str:
        return f"{verb} INTO {self.name} VALUES ({', '.join('?' * len(self.columns))})"

    def values(self, keys: tuple[Any, ...], row: Any) -> tuple[Any, ...]:
        """The row to insert: ``keys`` and ``row``'s fields (NaN as NULL)."""
        return (*keys, *(none_if_nan(getattr(row, n)) for n in self.fields))


RUNS = Table("runs", (("day", "INTEGER"), ("run", "INTEGER")), RunRow)
RUN_SUMMARIES = Table(
    "run_summaries", (("loc", "INTEGER"), ("day", "INTEGER"), ("run", "INTEGER")), RunSummary
)
DAY_SUMMARIES = Table("day_summaries", (("loc", "INTEGER"), ("day", "INTEGER")), DaySummary)
NAV_RUNS = Table("nav_runs", (("day", "INTEGER"), ("run", "INTEGER")), NavRunSummary)
#: The tables generated from dataclasses.
TABLES = (RUNS, RUN_SUMMARIES, DAY_SUMMARIES, NAV_RUNS)

_FIXED_SCHEMA = """
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
CREATE TABLE IF NOT EXISTS driver_artifacts (
    day INTEGER, run INTEGER, name TEXT, data BLOB, PRIMARY KEY (day, run, name));
CREATE TABLE IF NOT EXISTS digests (
    day INTEGER, run INTEGER, tbl TEXT, sha256 TEXT, PRIMARY KEY (day, run, tbl));
CREATE TABLE IF NOT EXISTS checkpoint (
    id INTEGER PRIMARY KEY CHECK (id = 1), next_index INTEGER, next_day INTEGER,
    next_run INTEGER, scenario_hash TEXT, seed INTEGER, sha256 TEXT, blob BLOB, created TEXT);
"""

#: Every table of a new store.
SCHEMA = _FIXED_SCHEMA + "".join(f"{t.ddl()};\n" for t in TABLES)

#: Made by the first run written with its ranges kept (an optional table: a store without it
#: simply has no scans; ``zlib`` level 1 of little-endian float32 rows).
SCAN_RANGES_TABLE = """CREATE TABLE IF NOT EXISTS scan_ranges (
    day INTEGER, run INTEGER, n_beams INTEGER, ranges BLOB, PRIMARY KEY (day, run))"""

#: Made with ``scan_ranges`` (optional like it): the people's ids (a JSON list; the crowd of a
#: run is fixed), radii (little-endian float64 ``(n,)``) and positions (zlib level 1 of
#: little-endian float32 ``(T, n, 2)``, NaN: not on the floor).
SCAN_PEOPLE_TABLE = """CREATE TABLE IF NOT EXISTS scan_people (
    day INTEGER, run INTEGER, n_people INTEGER, ids TEXT, radius BLOB, xy BLOB,
    PRIMARY KEY (day, run))"""


def diagnostic_column_type(x: Diagnostic) -> str:
    """The SQL type of a per-scan diagnostic's column."""
    if x.shape:
        return "BLOB"
    return "REAL" if np.dtype(x.dtype).kind == "f" else "INTEGER"


def to_blob(value: Any, x: Diagnostic) -> bytes | None:
    """A value's little-endian bytes in the declared dtype (None when any element is NaN)."""
    v = np.asarray(value)
    if v.dtype.kind == "f" and np.isnan(v).any():
        return None
    return np.ascontiguousarray(v, dtype=np.dtype(x.dtype).newbyteorder("<")).tobytes()


def from_blob(blob: bytes | None, x: Diagnostic) -> np.ndarray:
    if blob is None:
        return np.full(x.shape, np.nan)
    return np.frombuffer(blob, dtype=np.dtype(x.dtype).newbyteorder("<")).reshape(x.shape)


def column_values(values: list[Any], x: Diagnostic) -> np.ndarray:
    """A column of a per-scan diagnostic as float64 ``(N, *shape)`` (NaN: NULL)."""
    if not x.shape:
        return np.array([np.nan if v is None else v for v in values], dtype=np.float64)
    out = np.full((len(values), *x.shape), np.nan)
    for i, v in enumerate(values):
        if v is not None:
            out[i] = from_blob(v, x)
    return out


def encode_artifact(name: str, value: Any) -> tuple[str, bytes]:
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


def decode_artifact(kind: str, data: bytes) -> Artifact:
    if kind == "bytes":
        return bytes(data)
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def none_if_nan(v: Any) -> Any:
    """``v`` as SQLite stores it: NaN and infinities as NULL, numpy scalars as Python's."""
    if isinstance(v, float | np.floating) and not np.isfinite(v):
        return None
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.floating):
        return float(v)
    return v
