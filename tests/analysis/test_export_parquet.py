"""``dynmap-sim export DIR --parquet OUT``: the tables read back match the results store."""

from __future__ import annotations

import importlib
import sqlite3
import sys
from pathlib import Path

import numpy as np
import pytest

pa = pytest.importorskip("pyarrow")
pytest.importorskip("adbc_driver_sqlite")
pq = pytest.importorskip("pyarrow.parquet")

from dynmap_sim.analysis.export_parquet import (  # noqa: E402
    Column,
    _Reader,
    export_parquet,
    parquet_paths,
    read_tables,
)
from dynmap_sim.cli import main  # noqa: E402
from dynmap_sim.experiments.results import ResultsDB  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
LABEL = pa.dictionary(pa.int8(), pa.string())

SCANS = {
    "localizer": LABEL,
    "day": pa.int16(),
    "run": pa.int16(),
    "step": pa.int32(),
    "date": pa.date32(),
    "t_s": pa.float64(),
    "truth_x_m": pa.float64(),
    "truth_y_m": pa.float64(),
    "truth_theta_rad": pa.float64(),
    "collision": pa.bool_(),
    "est_x_m": pa.float64(),
    "est_y_m": pa.float64(),
    "est_theta_rad": pa.float64(),
    "err_m": pa.float64(),
    "err_theta_rad": pa.float64(),
    "var_x_m2": pa.float64(),
    "var_y_m2": pa.float64(),
    "var_theta_rad2": pa.float64(),
    "scan_loglik": pa.float64(),
    "lambda_min": pa.float64(),
    "timescale": pa.int8(),
    "safe_mode": pa.bool_(),
}


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from dynmap_sim.analysis.scenarios import load_scenario
    from dynmap_sim.experiments.runner import run_experiment

    scn = load_scenario(ROOT / "worlds" / "scenarios" / "ci-apartment-mcl.toml")
    out = tmp_path_factory.mktemp("ci mcl")  # a space: the store is opened by URI
    return run_experiment(scn, out, progress=False, workers=1)


@pytest.fixture(scope="module")
def exported(results: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("pq") / "tables"
    written = export_parquet(results, out)
    assert [f.table for f in written] == ["scans", "runs", "days", "localizers"]
    for f in written:
        assert f.path.is_file() and f.bytes == f.path.stat().st_size
        assert f.rows == pq.read_metadata(f.path).num_rows
    assert sorted(p.name for p in out.iterdir()) == sorted(
        p.name for p in parquet_paths(out).values()
    )  # no temporary file left
    return out


def _store(results: Path, sql: str) -> list[tuple]:
    with ResultsDB.open(results) as db:
        return db.query(sql)


def test_schemas(exported: Path) -> None:
    scans = pq.read_schema(exported / "scans.parquet")
    assert dict(zip(scans.names, scans.types, strict=True)) == SCANS
    assert not scans.field("truth_x_m").nullable and scans.field("err_m").nullable
    assert b"[m]" in scans.field("err_m").metadata[b"doc"]
    runs = pq.read_schema(exported / "runs.parquet")
    assert runs.names[:4] == ["localizer", "day", "run", "date"]
    for name, typ in {
        "localizer": LABEL,
        "date": pa.date32(),
        "duration_s": pa.float64(),
        "terminated": pa.bool_(),
        "mean_error_m": pa.float64(),
        "rmse_m": pa.float64(),
        "n_lost_episodes": pa.int32(),
        "update_ms_per_scan": pa.float64(),
        "nav_goal_reached": pa.bool_(),
        "nav_path_length_m": pa.float64(),
        "nav_collisions": pa.int32(),
    }.items():
        assert runs.field(name).type == typ, name
    days = pq.read_schema(exported / "days.parquet")
    assert days.names == [
        "localizer",
        "day",
        "n_scans",
        "mean_error_m",
        "max_error_m",
        "rmse_m",
        "lost_fraction",
        "mean_heading_error_rad",
        "mean_scan_loglik",
        "mean_lambda_min",
    ]
    locs = pq.read_schema(exported / "localizers.parquet")
    assert dict(zip(locs.names, locs.types, strict=True)) == {
        "localizer": LABEL,
        "idx": pa.int16(),
        "name": pa.string(),
        "params_json": pa.string(),
    }
    meta = pq.read_schema(exported / "days.parquet").metadata[b"dynmap_sim"]
    assert b'"scenario_name": "ci-apartment-mcl"' in meta and b'"table": "days"' in meta


def test_row_counts_match_the_store(results: Path, exported: Path) -> None:
    for table, sql in {
        "scans": "SELECT count(*) FROM estimates",
        "runs": "SELECT count(*) FROM run_summaries",
        "days": "SELECT count(*) FROM day_summaries",
        "localizers": "SELECT count(*) FROM localizers",
    }.items():
        (n,) = _store(results, sql)[0]
        assert n > 0 and pq.read_metadata(exported / f"{table}.parquet").num_rows == n, table
    scans = pq.read_table(exported / "scans.parquet")
    (n_scans,) = _store(results, "SELECT count(*) FROM scans")[0]
    assert scans.num_rows == 3 * n_scans  # one row per scan and localizer
    counts = scans.column("localizer").value_counts().to_pylist()
    assert {c["values"]: c["counts"] for c in counts} == {
        "odometry": n_scans,
        "mcl-tuned": n_scans,
        "mcl-nav2": n_scans,
    }


def test_values_match_the_store(results: Path, exported: Path) -> None:
    scans = pq.read_table(exported / "scans.parquet")
    label = np.array(scans.column("localizer").to_pylist())
    day, run, step = (scans.column(c).to_numpy() for c in ("day", "run", "step"))
    rows = _store(
        results,
        "SELECT l.label, e.day, e.run, e.step, s.t_s, s.x, s.y, s.theta, e.x, e.y, e.err_m, "
        "e.err_theta_rad, e.scan_loglik FROM estimates e JOIN scans s USING (day, run, step) "
        "JOIN localizers l ON l.idx = e.loc WHERE e.step IN (0, 7, 150) ORDER BY e.loc DESC",
    )
    assert len(rows) >= 6
    for lab, d, r, s, t, tx, ty, tth, ex, ey, err, herr, ll in rows:
        (i,) = np.flatnonzero((label == lab) & (day == d) & (run == r) & (step == s))
        got = scans.slice(i, 1).to_pylist()[0]
        assert (got["t_s"], got["truth_x_m"], got["truth_y_m"]) == (t, tx, ty)
        assert got["truth_theta_rad"] == tth
        assert (got["est_x_m"], got["est_y_m"], got["err_m"]) == (ex, ey, err)
        assert got["err_theta_rad"] == herr
        assert got["scan_loglik"] == ll  # None for odometry, a number for static-mcl
    lab, d, r, date, mean, rmse = _store(
        results,
        "SELECT l.label, s.day, s.run, r.date, s.mean_error_m, s.rmse_m FROM run_summaries s "
        "JOIN runs r USING (day, run) JOIN localizers l ON l.idx = s.loc "
        "ORDER BY s.loc DESC, s.day DESC LIMIT 1",
    )[0]
    runs = pq.read_table(exported / "runs.parquet").to_pylist()
    got = next(x for x in runs if (x["localizer"], x["day"], x["run"]) == (lab, d, r))
    assert (str(got["date"]), got["mean_error_m"], got["rmse_m"]) == (date, mean, rmse)
    locs = pq.read_table(exported / "localizers.parquet").to_pylist()
    assert [(x["localizer"], x["name"]) for x in locs] == [
        ("odometry", "odometry"),
        ("mcl-tuned", "static-mcl"),
        ("mcl-nav2", "static-mcl"),
    ]
    assert locs[2]["params_json"] == '{"config": "nav2-default"}'


def test_adbc_and_sqlite3_read_the_same(results: Path) -> None:
    a, b = read_tables(results, engine="adbc"), read_tables(results, engine="sqlite3")
    for name in a:
        assert a[name].equals(b[name], check_metadata=True), name


def test_columns_that_start_null_keep_their_type(tmp_path: Path) -> None:
    """ADBC infers a type from the first batch; 3000 NULLs first must not make it int64."""
    path = tmp_path / "t.db"
    con = sqlite3.connect(path)
    con.execute("CREATE TABLE t (i INTEGER, v REAL, s TEXT)")
    con.executemany("INSERT INTO t VALUES (?, NULL, NULL)", [(i,) for i in range(3000)])
    con.execute("INSERT INTO t VALUES (3000, 2.5, 'x')")
    con.commit()
    con.close()
    cols = (
        Column("i", "i", pa.int32(), ""),
        Column("v", "v_m", pa.float64(), ""),
        Column("s", "s", pa.string(), ""),
    )
    for engine in ("adbc", "sqlite3"):
        rd = _Reader(path, engine)
        try:
            t = rd.table("SELECT i, v, s FROM t ORDER BY i", "SELECT count(*) FROM t", cols)
            empty = rd.table("SELECT i, v, s FROM t WHERE i < 0", "SELECT 0", cols)
        finally:
            rd.close()
        assert t.schema.types == [pa.int32(), pa.float64(), pa.string()]
        assert t.column("v_m").null_count == 3000 and t.column("v_m")[-1].as_py() == 2.5
        assert t.column("s")[-1].as_py() == "x"
        assert empty.num_rows == 0 and empty.schema.types == t.schema.types


def test_refuses_to_overwrite_without_force(results: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    assert main(["export", str(results), "--parquet", str(out)]) == 0
    assert "scans.parquet: " in capsys.readouterr().out
    before = (out / "scans.parquet").stat().st_mtime_ns
    assert main(["export", str(results), "--parquet", str(out)]) == 2
    err = capsys.readouterr().err
    assert "already exists" in err and "--force" in err
    assert (out / "scans.parquet").stat().st_mtime_ns == before
    assert main(["export", str(results), "--parquet", str(out), "--force"]) == 0
    assert "replaced the earlier file" in capsys.readouterr().out
    assert main(["export", str(results), "--parquet", str(results)]) == 2
    assert "is a results folder" in capsys.readouterr().err


def test_missing_extra_is_one_clear_line(
    results: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # as if not installed
    monkeypatch.delitem(sys.modules, "dynmap_sim.analysis.export_parquet")
    with pytest.raises(ImportError, match=r'pip install "dynmap-sim\[analysis\]"'):
        importlib.import_module("dynmap_sim.analysis.export_parquet")
    assert main(["export", str(results), "--parquet", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and 'pip install "dynmap-sim[analysis]"' in err
    assert "Traceback" not in err and not (tmp_path / "x").exists()


def test_pandas_loads_the_tables(exported: Path) -> None:
    pd = pytest.importorskip("pandas")
    scans = pd.read_parquet(exported / "scans.parquet")
    runs = pd.read_parquet(exported / "runs.parquet")
    assert isinstance(scans["localizer"].dtype, pd.CategoricalDtype)
    assert scans["err_m"].dtype == np.float64 and scans["day"].dtype == np.int16
    mean = scans.groupby("localizer", observed=True)["err_m"].mean()
    expect = runs.groupby("localizer", observed=True).apply(
        lambda g: np.average(g["mean_error_m"], weights=g["n_scans"]), include_groups=False
    )
    assert np.allclose(mean.sort_index(), expect.sort_index())


def test_polars_loads_the_tables(exported: Path) -> None:
    pl = pytest.importorskip("polars")
    scans = pl.read_parquet(exported / "scans.parquet")
    assert scans.schema["localizer"] in (pl.Categorical, pl.Enum) or isinstance(
        scans.schema["localizer"], pl.Categorical | pl.Enum
    )
    assert scans.schema["err_m"] == pl.Float64 and scans.schema["date"] == pl.Date
    days = pl.read_parquet(exported / "days.parquet")
    per_loc = scans.group_by("localizer", "day").agg(pl.col("err_m").max().alias("max_m"))
    joined = days.with_columns(pl.col("localizer").cast(pl.String)).join(
        per_loc.with_columns(pl.col("localizer").cast(pl.String)), on=["localizer", "day"]
    )
    assert joined.height == days.height
    assert np.allclose(joined["max_error_m"].to_numpy(), joined["max_m"].to_numpy())


def test_docs_parquet_snippet_runs(exported: Path, capsys) -> None:
    pytest.importorskip("pandas")
    pytest.importorskip("polars")
    page = (ROOT / "docs" / "results.md").read_text()
    section = page.split("## Parquet for pandas and polars", 1)[1].split("\n## ", 1)[0]
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    code = code.replace('"tables/ci-mcl"', repr(str(exported)))
    scope: dict = {}
    exec(compile(code, "docs/results.md", "exec"), scope)  # noqa: S102 - our own docs
    assert scope["worst"].height == 3 and len(scope["runs"]) > 0
    assert "mcl-tuned" in capsys.readouterr().out


def test_declared_diagnostics_become_typed_columns(tmp_path: Path) -> None:
    """A plug-in localizer's own per-scan diagnostics: scalars by their dtype, arrays as
    fixed-size lists (NULL where not reported)."""
    from experiments.test_results_store import hw_diagnostics, make_db, record

    db = make_db(tmp_path / "res")
    rec = record(1, 1)
    rec.diagnostics[0] = hw_diagnostics(20, day_done=True)
    db.write_run(rec, [], True, None, "h", 7)
    db.close()
    for engine in ("adbc", "sqlite3"):
        scans = read_tables(tmp_path / "res", engine)["scans"]
        assert scans.schema.field("point_class_counts").type == pa.list_(pa.int64(), 4)
        assert scans.schema.field("map_slot").type == pa.int64()
        assert scans.schema.field("n_tracked").type == pa.uint16()
        a = scans.filter(pa.compute.equal(scans.column("localizer"), "a"))
        counts = a.column("point_class_counts").to_pylist()
        assert counts[0] == [0, 2, 5, 40] and counts[3] is None
        assert a.column("map_slot").to_pylist()[:4] == [0, 1, 2, 0]
        b = scans.filter(pa.compute.equal(scans.column("localizer"), "b"))
        assert b.column("point_class_counts").null_count == b.num_rows
        assert set(b.column("scan_loglik").to_pylist()) == {-2.0}


def test_results_format_1_export(tmp_path: Path) -> None:
    """A folder written before declared diagnostics and navigation measures."""
    src = ROOT / "tests" / "data" / "pre-round-2" / "ci-apartment"
    written = {f.table: f for f in export_parquet(src, tmp_path / "pq")}
    (n,) = _store(src, "SELECT count(*) FROM estimates")[0]
    assert written["scans"].rows == n
    runs = pq.read_table(written["runs"].path)
    assert runs.column("nav_spl").null_count == runs.num_rows > 0
    meta = pq.read_schema(written["scans"].path).metadata[b"dynmap_sim"]
    assert b'"results_format": 1' in meta
