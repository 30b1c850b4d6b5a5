"""What guards a results folder against edits and damage: checksums of the metadata and of
every run's rows, and the derived tables checked against the per-scan rows they summarize.

* ``meta``'s ``checksums`` row holds the SHA-256 of every other row's value (written with it
  in one transaction), so an edited seed, a value that is not JSON or a deleted row is named;
* ``digests`` holds, per run (and per day for ``day_summaries``, run 0), the SHA-256 of the
  rows of each of :data:`GUARDED` (``runs``, ``run_summaries``, ``events``, ...);
* the per-scan rows are checked by SQL: each run's ``scans`` and ``estimates`` as many as
  ``runs.n_steps``, each ``day_summaries`` row's count, mean and largest error those of the
  day's scans, and (before a resume) each ``err_m`` the distance of its estimate from the
  truth;
* the checkpoint's checksum covers :func:`cover_digest` (the metadata's and the runs'
  digests), so a run deleted with its digests is refused too.

Results formats before 4 have none of these; they are read as they are.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import sqlite3
from pathlib import Path
from typing import Any

from dynmap_sim.errors import InputError

#: Meta keys every results folder has (a reader needs them).
REQUIRED_META = ("days", "seed")
#: Meta keys that change after the experiment began (not part of its identity; ``complete``
#: is checked against the stored runs instead of its checksum: :func:`check_complete`).
MUTABLE_META = ("complete", "checksums")
#: The per-run tables guarded by a digest of their rows, with the order of a run's rows.
GUARDED = (
    ("runs", "day"),
    ("run_summaries", "loc"),
    ("nav_runs", "day"),
    ("events", "rowid"),
    ("point_classes", "loc"),
    ("point_class_truth", "loc"),
    ("timescale_counts", "loc"),
    ("run_diagnostics", "loc, name"),
)
#: The per-day table guarded by a digest (stored as run 0 of its day).
GUARDED_DAY = ("day_summaries", "loc")
#: How far a stored error may be from the one recomputed by SQL [m] (rounding only).
TOLERANCE_M = 1e-9


class DamagedResults(InputError):
    """A results folder whose rows or metadata were edited or damaged."""

    def __init__(self, path: Path, what: str) -> None:
        super().__init__(
            f"{path}: {what}; the results cannot be trusted: rerun the experiment into "
            "another --out (or restore the folder from a copy)"
        )


def value_hash(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def rows_digest(rows: list[tuple[Any, ...]]) -> str:
    """SHA-256 of rows as SQLite returns them (exact: ``repr`` of floats round-trips)."""
    return hashlib.sha256(repr(rows).encode()).hexdigest()


def write_digests(con: sqlite3.Connection, day: int, run: int, day_done: bool) -> None:
    """Record the digests of run ``(day, run)``'s rows (and of its day's summaries when
    ``day_done``), in the open transaction."""
    out = []
    for table, order in GUARDED:
        rows = con.execute(
            f"SELECT * FROM {table} WHERE day=? AND run=? ORDER BY {order}", (day, run)
        ).fetchall()
        out.append((day, run, table, rows_digest(rows)))
    if day_done:
        table, order = GUARDED_DAY
        rows = con.execute(f"SELECT * FROM {table} WHERE day=? ORDER BY {order}", (day,))
        out.append((day, 0, table, rows_digest(rows.fetchall())))
    con.executemany("INSERT OR REPLACE INTO digests VALUES (?,?,?,?)", out)


def meta_identity(checksums: dict[str, str]) -> str:
    """The digest of the experiment's metadata (every row but :data:`MUTABLE_META`)."""
    keep = {k: v for k, v in sorted(checksums.items()) if k not in MUTABLE_META}
    return value_hash(json.dumps(keep))


def cover_digest(con: sqlite3.Connection, checksums: dict[str, str]) -> str:
    """What the checkpoint's checksum covers: the metadata's identity and every digest."""
    rows = con.execute("SELECT day, run, tbl, sha256 FROM digests ORDER BY day, run, tbl")
    return value_hash(meta_identity(checksums) + rows_digest(rows.fetchall()))


def parse_meta(path: Path, rows: list[tuple[str, str]]) -> dict[str, Any]:
    """``meta``'s rows as values; one clear error for a value that is not JSON."""
    out = {}
    for key, text in rows:
        try:
            out[key] = json.loads(text)
        except (TypeError, ValueError) as exc:
            raise DamagedResults(path, f"meta value {key!r} is not JSON ({exc})") from None
    return out


def check_meta(path: Path, rows: list[tuple[str, str]], guarded: bool) -> dict[str, Any]:
    """The parsed ``meta``, checked: required keys present and (``guarded``: a folder with
    checksums) every value its checksum."""
    meta = parse_meta(path, rows)
    if guarded:
        sums = meta.get("checksums")
        if not isinstance(sums, dict):
            raise DamagedResults(path, "meta has no checksums row (meta rows were deleted)")
        texts = dict(rows)
        missing = sorted(k for k in sums if k not in texts)
        changed = sorted(
            k for k, t in texts.items() if k not in MUTABLE_META and sums.get(k) != value_hash(t)
        )
        parts = [f"rows deleted: {', '.join(missing)}"] if missing else []
        parts += [f"values changed: {', '.join(changed)}"] if changed else []
        if parts:
            raise DamagedResults(path, f"the meta table was edited ({'; '.join(parts)})")
    missing = [k for k in REQUIRED_META if k not in meta]
    if missing:
        raise DamagedResults(
            path,
            f"meta lacks {', '.join(missing)} (its rows were deleted or it was not "
            "written by dynmap_sim)",
        )
    return meta


def check_complete(con: sqlite3.Connection, path: Path, meta: dict[str, Any]) -> None:
    """A folder marked ``complete`` holds a run for each of its slots."""
    slots = meta.get("slots")
    if meta.get("complete") is True and isinstance(slots, list):
        n = con.execute("SELECT count(*) FROM runs").fetchone()[0]
        if n != len(slots):
            raise DamagedResults(
                path,
                f"meta says the experiment is complete but {n} of its {len(slots)} runs are stored",
            )


def check_integrity(con: sqlite3.Connection, path: Path) -> None:
    """Refuse a damaged database file (SQLite's quick check)."""
    try:
        bad = [r[0] for r in con.execute("PRAGMA quick_check(3)").fetchall() if r[0] != "ok"]
    except sqlite3.DatabaseError as exc:
        bad = [str(exc)]
    if bad:
        raise DamagedResults(path, f"the database file is damaged ({'; '.join(bad)})")


def check_digests(con: sqlite3.Connection, path: Path) -> None:
    """Every guarded table's rows match their run's (or day's) digest, and every run has
    digests."""
    stored = {(d, r, t): s for d, r, t, s in con.execute("SELECT * FROM digests")}
    tables = [*GUARDED, GUARDED_DAY]
    for table, order in tables:
        day_only = table == GUARDED_DAY[0]
        cols = [c[1] for c in con.execute(f"PRAGMA table_info({table})")]
        di = cols.index("day")
        ri = None if day_only else cols.index("run")
        by = "day" if day_only else "day, run"
        rows = con.execute(f"SELECT * FROM {table} ORDER BY {by}, {order}").fetchall()
        groups = {
            key: list(g)
            for key, g in itertools.groupby(
                rows, key=lambda row: (row[di], 0 if ri is None else row[ri])
            )
        }
        want = {(d, r) for d, r, t in stored if t == table}
        for key in sorted(set(groups) - want):
            raise DamagedResults(path, f"{_where(key)} has {table} rows without a checksum")
        for d, r in sorted(want):
            if rows_digest(groups.get((d, r), [])) != stored[(d, r, table)]:
                raise DamagedResults(
                    path, f"the {table} rows of {_where((d, r))} do not match their checksum"
                )
    runs = {(d, r) for d, r in con.execute("SELECT day, run FROM runs")}
    for d, r in sorted({(d, r) for d, r, t in stored if t == "runs"} - runs):
        raise DamagedResults(path, f"{_where((d, r))} was deleted from the runs table")


def check_scans(con: sqlite3.Connection, path: Path, n_loc: int, deep: bool = False) -> None:
    """The per-scan rows agree with ``runs`` and ``day_summaries`` (see the module doc);
    ``deep``: each error is also the distance of its estimate from the truth (a join of
    every estimate with its scan, the slowest check, so only before a resume: the readers'
    numbers come from the errors, which the day summaries check)."""
    steps = {}
    for d, r, n, got in con.execute(
        "SELECT r.day, r.run, r.n_steps, (SELECT count(*) FROM scans s WHERE s.day = r.day "
        "AND s.run = r.run) FROM runs r ORDER BY r.day, r.run"
    ):
        if n != got:
            raise DamagedResults(path, f"{_where((d, r))} has {got} scans, not {n}")
        steps[(d, r)] = n
    counts: dict[tuple[int, int], list[int]] = {}
    for _, d, r, n in con.execute("SELECT loc, day, run, count(*) FROM estimates GROUP BY 1, 2, 3"):
        counts.setdefault((d, r), []).append(n)
    for key in sorted(set(counts) | set(steps)):
        n = steps.get(key, 0)
        if counts.get(key, []) != [n] * n_loc:
            got = sum(counts.get(key, []))
            raise DamagedResults(path, f"{_where(key)} has {got} estimates, not {n_loc} x {n}")
    rows = con.execute(
        "SELECT loc, day, count(*), avg(err_m), max(err_m) FROM estimates GROUP BY loc, day"
    ).fetchall()
    days = {
        (loc, day): (n, mean, top)
        for loc, day, n, mean, top in con.execute(
            "SELECT loc, day, n_scans, mean_error_m, max_error_m FROM day_summaries"
        )
    }
    for loc, day, n, mean, top in rows:
        if (loc, day) in days and not _same_summary(days[(loc, day)], (n, mean, top)):
            raise DamagedResults(
                path,
                f"the day_summaries row of localizer {loc} on day {day} does not summarize "
                f"its scans (stored n, mean, max {days[(loc, day)]}, the scans give "
                f"{(n, mean, top)})",
            )
    if deep:
        _check_errors(con, path)


def _check_errors(con: sqlite3.Connection, path: Path) -> None:
    """Each stored error is the distance of its estimate from the truth."""
    dx = "(e.x - s.x) * (e.x - s.x) + (e.y - s.y) * (e.y - s.y)"
    rows = con.execute(
        "SELECT e.loc, e.day, "
        f"max(coalesce(abs(e.err_m - sqrt({dx})), "
        f"CASE WHEN e.err_m IS NULL AND sqrt({dx}) IS NULL THEN 0 ELSE 1 END)) "
        "FROM estimates e JOIN scans s USING (day, run, step) GROUP BY e.loc, e.day"
    )
    for loc, day, off in rows:
        if off is not None and off > TOLERANCE_M:
            raise DamagedResults(
                path,
                f"the per-scan errors (estimates.err_m) of localizer {loc} on day {day} are "
                "not the distances of its estimates from the truth",
            )


def _same_summary(stored: tuple[Any, ...], scans: tuple[Any, ...]) -> bool:
    if stored[0] != scans[0]:
        return False
    for a, b in zip(stored[1:], scans[1:], strict=True):
        if a is None or b is None:
            if (a is None) != (b is None):
                return False
        elif abs(a - b) > TOLERANCE_M * (1.0 + abs(b)):
            return False
    return True


def _where(key: tuple[int, int]) -> str:
    return f"day {key[0]}" if key[1] == 0 else f"day {key[0]} run {key[1]}"
