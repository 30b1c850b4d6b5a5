"""The Parquet export of a large results folder: time, rows, bytes, against references.

    dynmap-sim run worlds/scenarios/lab-5w.toml --out results/lab-full   # ~6 min or more
    python benchmarks/bench_export_parquet.py results/lab-full

Measured in the same process, best of ``--repeat`` each (wall clock and process CPU time;
CPU time is the steadier one on a shared machine):

* ``export --parquet`` — :func:`export_parquet` (ADBC reads, explicit schema, zstd files);
* ``sqlite3 read`` — the reference: the standard library reading the same tables
  (``scans``, ``estimates``, ``runs``, ``run_summaries``, ``day_summaries``, ``nav_runs``,
  ``localizers``) with one ``SELECT`` and ``fetchall`` each, nothing converted or written;
* ``export (sqlite3)`` — the same export reading with sqlite3 instead of ADBC (same files);
* ``export --tum`` — the TUM export of the same folder (one text file per localizer).

``--replicate-to N`` measures a copy of the folder whose days are repeated (day + k * the
last day, same dates) until it holds at least ``N`` scans: a store of the size of a longer
experiment with the same shape (e.g. 250,000 scans from a partial lab replica).

Prints one line per measurement with its ratios to the export (wall and CPU), the rows and
bytes of each Parquet file, and the size of ``results.db`` for comparison.
"""

from __future__ import annotations

import argparse
import shutil
import sqlite3
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from dynmap_sim.analysis.export import export_tum
from dynmap_sim.analysis.export_parquet import export_parquet
from dynmap_sim.experiments.results import DB_NAME

TABLES = (
    "scans",
    "estimates",
    "runs",
    "run_summaries",
    "day_summaries",
    "nav_runs",
    "localizers",
)


def sqlite3_read(db: Path) -> int:
    """Every row of the exported tables through sqlite3's ``fetchall``; rows read."""
    con = sqlite3.connect(db.resolve().as_uri() + "?mode=ro", uri=True)
    try:
        return sum(len(con.execute(f"SELECT * FROM {t}").fetchall()) for t in TABLES)
    finally:
        con.close()


def replicate(src: Path, dst: Path, scans: int) -> Path:
    """A copy of ``src/results.db`` in ``dst`` with its days repeated until ``scans``."""
    dst.mkdir(parents=True)
    con = sqlite3.connect(src / DB_NAME)
    try:
        con.execute(f"VACUUM INTO '{dst / DB_NAME}'")  # a consistent copy, also while written
    finally:
        con.close()
    con = sqlite3.connect(dst / DB_NAME)
    try:
        n, last = con.execute("SELECT count(*), max(day) FROM scans").fetchone()
        for k in range(1, -(-scans // n)):
            for table in TABLES[:-1]:  # every table with a day (not localizers)
                cols = [r[1] for r in con.execute(f"PRAGMA table_info({table})")]
                sel = ", ".join(f"day + {k * last}" if c == "day" else f'"{c}"' for c in cols)
                con.execute(f"INSERT INTO {table} SELECT {sel} FROM {table} WHERE day <= {last}")
            con.commit()
    finally:
        con.close()
    return dst


def best_of(repeat: int, fn: Callable[[], object]) -> tuple[float, float, object]:
    """(best wall s, best CPU s, last result) of ``repeat`` calls."""
    wall, cpu, out = float("inf"), float("inf"), None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return wall, cpu, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "dir", help="a results folder (e.g. of dynmap-sim run worlds/scenarios/lab-5w.toml)"
    )
    ap.add_argument("--repeat", type=int, default=3, help="best of N (default 3)")
    ap.add_argument(
        "--replicate-to", type=int, metavar="N", help="measure a copy enlarged to N scans"
    )
    args = ap.parse_args()
    src = Path(args.dir)
    if not (src / "results.db").is_file():
        ap.error(f"{src}: no results.db here (make one with dynmap-sim run ... --out {src})")
    tmp = Path(tempfile.mkdtemp(prefix="bench-pq-"))
    try:
        if args.replicate_to:
            src = replicate(src, tmp / "enlarged", args.replicate_to)
            print(f"{args.dir} with its days repeated to {args.replicate_to:,}+ scans:")
        db = src / DB_NAME
        pq_out, pq3_out, tum_out = tmp / "pq", tmp / "pq-sqlite3", tmp / "tum"
        w_pq, c_pq, files = best_of(args.repeat, lambda: export_parquet(src, pq_out, force=True))
        w_rd, c_rd, n_read = best_of(args.repeat, lambda: sqlite3_read(db))
        w_p3, c_p3, _ = best_of(
            args.repeat, lambda: export_parquet(src, pq3_out, force=True, engine="sqlite3")
        )
        w_tum, c_tum, tums = best_of(args.repeat, lambda: export_tum(src, tum_out))

        print(f"results folder {src}: results.db {db.stat().st_size:,} bytes")
        total = 0
        for f in files:  # type: ignore[union-attr]
            total += f.bytes
            print(f"  {f.path.name:<20} {f.rows:>10,} rows {f.bytes:>14,} bytes")
        print(
            f"  {'all Parquet files':<20} {'':>15} {total:>14,} bytes "
            f"({total / db.stat().st_size:.2f} x results.db)"
        )
        tum_bytes = sum(p.stat().st_size for p in tums)  # type: ignore[union-attr]
        print(f"  TUM files: {len(tums)} ({tum_bytes:,} bytes)")  # type: ignore[arg-type]
        print(
            f"{'measurement':<20} {'wall s':>8} {'CPU s':>8} {'wall ratio':>11} {'CPU ratio':>10}"
        )
        for name, w, c in (
            ("export --parquet", w_pq, c_pq),
            ("sqlite3 read", w_rd, c_rd),
            ("export (sqlite3)", w_p3, c_p3),
            ("export --tum", w_tum, c_tum),
        ):
            print(f"{name:<20} {w:>8.2f} {c:>8.2f} {w / w_pq:>11.2f} {c / c_pq:>10.2f}")
        (n_scans,) = sqlite3.connect(db).execute("SELECT count(*) FROM scans").fetchone()
        print(f"(sqlite3 read: {n_read:,} rows of {', '.join(TABLES)}; {n_scans:,} scans)")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
