"""Sweeps: cells of scenarios x seeds x parameter values, run on a process pool or a Dask
cluster, resumed by skipping finished cells, failures recorded; the report's intervals."""

from __future__ import annotations

import csv
import json
import shutil
import sqlite3
import textwrap
import time
from pathlib import Path

import pytest

from dynmap_sim.cli import main
from dynmap_sim.errors import InputError
from dynmap_sim.experiments.scenario import load_scenario
from dynmap_sim.experiments.sweep import (
    SWEEP_INDEX,
    SweepFileError,
    SweepSpec,
    load_sweep_file,
    parse_seeds,
    parse_set,
    parse_value,
    resolve_cells,
)
from dynmap_sim.metrics import mean_interval, paired_difference

ROOT = Path(__file__).resolve().parents[2]
CI_MCL = ROOT / "worlds" / "scenarios" / "ci-apartment-mcl.toml"


def sweep_argv(*extra: str) -> list[str]:
    """``dynmap-sim sweep`` of ci-apartment-mcl, seeds 0-1, day 1, quiet, with ``extra``."""
    return ["sweep", str(CI_MCL), "--seeds", "0-1", "--days", "1-1", *extra, "-q"]


#: 2 seeds x 2 values of mcl-tuned's config, day 1 only, mcl-tuned and odometry: 4 cells of
#: a few seconds each.
TINY = sweep_argv(
    *("--set", "mcl-tuned.config=tuned,nav2-default"),
    *("--only", "odometry", "--only", "mcl-tuned", "--workers", "2"),
)


def day_summaries(sweep_dir: Path) -> dict[str, list[tuple]]:
    """Every cell's day_summaries rows, by cell folder."""
    out = {}
    for db in sorted((sweep_dir / "cells").glob("*/results.db")):
        with sqlite3.connect(db) as con:
            out[db.parent.name] = con.execute(
                "SELECT * FROM day_summaries ORDER BY loc, day"
            ).fetchall()
    return out


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """The tiny sweep through a local pool of 2 processes: (folder, exit status, seconds)."""
    out = tmp_path_factory.mktemp("sweep") / "tiny"
    t0 = time.perf_counter()
    status = main([*TINY, "--out", str(out)])
    return out, status, time.perf_counter() - t0


# ---------------------------------------------------------------------- arguments
def test_set_values_and_seeds_parse_with_errors_naming_the_argument():
    s = parse_set("static-mcl tuned.config=tuned, nav2-default")
    assert (s.label, s.key, s.values) == ("static-mcl tuned", "config", ("tuned", "nav2-default"))
    assert parse_set("a.b.n=1,2.5,true").values == (1, 2.5, True)
    assert parse_set("a.b.n=1").label == "a.b"  # the key is after the last dot
    assert [parse_value(t) for t in ("200", "0.5", "false", "x y")] == [200, 0.5, False, "x y"]
    for bad, says in [
        ("mcl.config", "no '='"),
        ("config=a,b", "LABEL.KEY"),
        ("mcl.=a", "LABEL.KEY"),
        ("mcl.config=", "empty value"),
        ("mcl.config=a,,b", "empty value"),
        ("mcl.config=a,a", "twice"),
    ]:
        with pytest.raises(InputError, match=says) as err:
            parse_set(bad)
        assert str(err.value).startswith(f"--set {bad}:")
    assert parse_seeds("0-3") == (0, 1, 2, 3)
    assert parse_seeds("0,2,5-6") == (0, 2, 5, 6)
    for bad in ("a", "3-1", "-1", "0,0", "0-99999999"):
        with pytest.raises(InputError, match="--seeds"):
            parse_seeds(bad)


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["--seeds", "x"], "argument --seeds: seeds look like"),
        (["--seeds", "0", "--set", "nope"], "argument --set: expected LABEL.KEY"),
        (["--seeds", "0", "--cluster", "nowhere"], "argument --cluster: expected tcp://"),
        (["--seeds", "0", "--workers", "0"], "argument --workers: must be at least 1"),
        (["--seeds", "0", "--set", "ghost.config=a"], "no localizer is labelled 'ghost'"),
        (["--seeds", "0", "--only", "ghost"], "--only ghost: no scenario has"),
        (["--seeds", "0", "--set", "mcl-tuned.config=tuned,bogus"], "config=bogus"),
        (["--seeds", "0", "--set", "mcl-tuned.bogus=1"], "unknown parameters ['bogus']"),
        (["--seeds", "0", "--days", "1-99"], "days"),
        ([], "--seeds is needed"),
    ],
)
def test_bad_values_are_one_line_errors_before_anything_runs(tmp_path, capsys, args, says):
    out = tmp_path / "sw"
    argv = ["sweep", str(CI_MCL), *args, "--out", str(out), "-q"]
    if says.startswith("argument"):  # argparse: usage and one error line, status 2
        with pytest.raises(SystemExit) as exit_:
            main(argv)
        assert exit_.value.code == 2
    else:
        assert main(argv) == 2
    err = capsys.readouterr().err
    assert says in err
    if not says.startswith("argument"):
        assert err.startswith("error: ") and err.count("\n") == 1  # one line
    assert not (out / "cells").exists()  # nothing ran


def test_a_sweep_file_is_validated_with_file_and_field(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text('scenarios = ["missing.toml"]\nseeds = "3-1"\nworkers = 2\n[set]\n"x" = [1]\n')
    with pytest.raises(SweepFileError) as err:
        load_sweep_file(f)
    text = str(err.value)
    assert str(f) in text
    assert "seeds: bad seed range '3-1'" in text
    assert "workers: Extra inputs are not permitted" in text
    f.write_text(f'scenarios = ["missing.toml", "{CI_MCL}"]\nseeds = [0]\n[set]\n"x" = [1]\n')
    with pytest.raises(SweepFileError) as err:
        load_sweep_file(f)
    assert "scenarios.0: no scenario file 'missing.toml'" in str(err.value)
    assert "set.x: expected LABEL.KEY" in str(err.value)


def test_the_shipped_sweep_file_resolves_to_four_cells():
    spec = load_sweep_file(ROOT / "worlds" / "sweeps" / "apartment-week.toml")
    cells = resolve_cells(spec)
    assert (spec.name, spec.days, len(cells)) == ("apartment-week", (1, 7), 4)
    assert [c.seed for c in cells] == [0, 1, 2, 3]
    assert all(c.localizers == ("static-mcl tuned", "dynamic-map") for c in cells)
    assert len({c.key for c in cells}) == 4


def test_cells_are_keyed_by_their_resolved_configuration():
    scn = load_scenario(CI_MCL)
    spec = SweepSpec((scn,), (0, 1), (1, 1), (parse_set("mcl-tuned.config=tuned,nav2-default"),))
    cells = resolve_cells(spec)
    assert [(c.seed, c.variant) for c in cells] == [
        (0, "mcl-tuned.config=tuned"),
        (1, "mcl-tuned.config=tuned"),
        (0, "mcl-tuned.config=nav2-default"),
        (1, "mcl-tuned.config=nav2-default"),
    ]
    assert len({c.key for c in cells}) == 4
    assert [c.key for c in resolve_cells(spec)] == [c.key for c in cells]  # stable
    other_days = resolve_cells(SweepSpec((scn,), (0,), (1, 2)))
    assert other_days[0].key not in {c.key for c in cells}
    # a value equal to the scenario's own is a cell of its own parameters, not a new one
    same = resolve_cells(SweepSpec((scn,), (0,), (1, 1), (parse_set("mcl-tuned.config=tuned"),)))
    assert same[0].key == cells[0].key


# ---------------------------------------------------------------------- running
def test_a_tiny_sweep_on_a_process_pool_writes_cells_index_and_report(tiny):
    out, status, _ = tiny
    assert status == 0
    index = json.loads((out / SWEEP_INDEX).read_text())
    assert len(index["cells"]) == 4
    assert {c["status"] for c in index["cells"]} == {"done"}
    assert len({c["host"] for c in index["cells"]}) >= 1
    for c in index["cells"]:
        assert (out / c["dir"] / "results.db").is_file()
    with (out / "sweep_summary.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0])[:3] == ["scenario", "variant", "localizer"]
    for col in ("day", "n_seeds", "mean_error_m", "ci95_low_m", "ci95_high_m"):
        assert col in rows[0]
    assert len(rows) == 4  # 2 variants x 2 localizers x 1 day
    # the csv's numbers are the interval over the cells' own day summaries
    row = next(r for r in rows if r["localizer"] == "mcl-tuned" and "=tuned" in r["variant"])
    seeds = [c for c in index["cells"] if c["variant"] == row["variant"]]
    errs = []
    for c in seeds:
        with sqlite3.connect(out / c["dir"] / "results.db") as con:
            errs.append(
                con.execute("SELECT mean_error_m FROM day_summaries WHERE loc=1").fetchone()[0]
            )
    m = mean_interval(errs)
    assert int(row["n_seeds"]) == 2
    assert float(row["mean_error_m"]) == pytest.approx(m.mean, abs=1e-6)
    assert float(row["ci95_low_m"]) == pytest.approx(m.low, abs=1e-6)
    assert float(row["ci95_high_m"]) == pytest.approx(m.high, abs=1e-6)
    with (out / "sweep_paired.csv").open() as fh:
        paired = list(csv.DictReader(fh))
    pairs = {(p["variant_a"], p["localizer_a"], p["variant_b"], p["localizer_b"]) for p in paired}
    assert (
        "mcl-tuned.config=tuned",
        "mcl-tuned",
        "mcl-tuned.config=tuned",
        "odometry",
    ) in pairs
    assert (
        "mcl-tuned.config=nav2-default",
        "mcl-tuned",
        "mcl-tuned.config=tuned",
        "mcl-tuned",
    ) in pairs  # the variants of the localizer whose parameter is swept
    assert (
        "mcl-tuned.config=nav2-default",
        "odometry",
        "mcl-tuned.config=tuned",
        "odometry",
    ) not in pairs
    md = (out / "sweep_summary.md").read_text()
    assert "Student t" in md
    assert "mcl-tuned [mcl-tuned.config=tuned] − odometry [mcl-tuned.config=tuned]" in md
    assert (out / "sweep_error_per_day.png").stat().st_size > 10_000


def test_the_same_sweep_resumes_by_skipping_finished_cells(tiny, tmp_path, capsys):
    out, _, first_s = tiny
    copy = tmp_path / "again"
    shutil.copytree(out, copy)
    before = day_summaries(copy)
    dbs = sorted((copy / "cells").glob("*/results.db"))
    mtimes = [p.stat().st_mtime_ns for p in dbs]
    t0 = time.perf_counter()
    assert main([*TINY, "--out", str(copy)]) == 0
    captured = capsys.readouterr()
    assert "4 cells, 0 run now, 4 done before, 0 failed" in captured.out
    assert "resuming" in captured.err
    assert day_summaries(copy) == before
    assert [p.stat().st_mtime_ns for p in dbs] == mtimes
    assert time.perf_counter() - t0 < first_s


def test_a_cell_killed_halfway_resumes_to_the_same_numbers(tiny, tmp_path, capsys):
    """A half-finished cell (its results.db incomplete) continues from its checkpoint; a
    missing cell runs again; the numbers equal the unbroken sweep's."""
    out, _, _ = tiny
    copy = tmp_path / "broken"
    shutil.copytree(out, copy)
    cells = sorted((copy / "cells").iterdir())
    shutil.rmtree(cells[0])
    with sqlite3.connect(cells[1] / "results.db") as con:
        con.execute("UPDATE meta SET value='false' WHERE key='complete'")
    assert main([*TINY, "--out", str(copy)]) == 0
    assert "4 cells, 2 run now, 2 done before" in capsys.readouterr().out
    assert day_summaries(copy) == day_summaries(out)


def test_another_sweep_in_the_same_folder_is_refused(tiny, tmp_path, capsys):
    out, _, _ = tiny
    args = [a if a != "0-1" else "0-2" for a in TINY]
    assert main([*args, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "holds another sweep" in err and "choose another --out" in err
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "notes.txt").write_text("mine")
    assert main([*TINY, "--out", str(tmp_path / "x")]) == 2
    assert "not empty and holds no sweep" in capsys.readouterr().err


BOOM = '''
from dynmap_sim.agent.localization.dead_reckoning import DeadReckoning


class Boom(DeadReckoning):
    """Dead reckoning that fails at run time when told to (the parameter validates)."""

    def __init__(self, laser, rng, fail=False, **params):
        super().__init__(laser, rng, **params)
        self.fail = bool(fail)

    def update(self, odom, scan):
        if self.fail:
            raise RuntimeError("boom: the parameter blew up at run time")
        return super().update(odom, scan)
'''


def test_a_failing_cell_is_recorded_and_the_others_finish(tmp_path, capsys):
    (tmp_path / "sweep_boom_loc.py").write_text(textwrap.dedent(BOOM))
    scn = tmp_path / "boom.toml"
    scn.write_text(
        textwrap.dedent(
            """
            name = "boom"
            world = "apartment"
            days = [1, 1]
            [driver]
            kind = "tour"
            max_run_s = 10.0
            [[localizers]]
            name = "sweep_boom_loc:Boom"
            label = "boom"
            """
        )
    )
    out = tmp_path / "sw"
    args = ["sweep", str(scn), "--seeds", "0", "--set", "boom.fail=false,true", "-q"]
    assert main([*args, "--out", str(out), "--workers", "2"]) == 1
    captured = capsys.readouterr()
    assert "2 cells, 1 run now, 0 done before, 1 failed" in captured.out
    assert "boom: the parameter blew up at run time" in captured.err
    index = json.loads((out / SWEEP_INDEX).read_text())
    by_variant = {c["variant"]: c for c in index["cells"]}
    assert by_variant["boom.fail=false"]["status"] == "done"
    bad = by_variant["boom.fail=true"]
    assert bad["status"] == "failed" and "blew up at run time" in bad["error"]
    assert "Traceback" in bad["traceback"]
    assert "Failed cells" in (out / "sweep_summary.md").read_text()
    # the same command retries the failed cell only
    assert main([*args, "--out", str(out)]) == 1
    assert "2 cells, 0 run now, 1 done before, 1 failed" in capsys.readouterr().out


# ---------------------------------------------------------------------- Dask
def test_a_sweep_runs_on_a_dask_cluster(tmp_path, capsys):
    distributed = pytest.importorskip("distributed")
    from dynmap_sim.experiments.sweep import make_executor

    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0"
    ) as cluster:
        address = cluster.scheduler_address
        with make_executor(2, cluster=address) as ex:  # pure=False: equal calls both run
            a, b = ex.submit(time.perf_counter_ns), ex.submit(time.perf_counter_ns)
            assert a.result() != b.result()
        out = tmp_path / "dask"
        args = sweep_argv("--only", "mcl-tuned", "--cluster", address, "--out", str(out))
        assert main(args) == 0
        assert "2 cells, 2 run now, 0 done before, 0 failed" in capsys.readouterr().out
        index = json.loads((out / SWEEP_INDEX).read_text())
        assert {c["status"] for c in index["cells"]} == {"done"}
        workers = set(cluster.scheduler.workers)
        assert len(workers) == 2
    with (out / "sweep_summary.csv").open() as fh:
        (row,) = list(csv.DictReader(fh))
    assert (row["localizer"], row["n_seeds"]) == ("mcl-tuned", "2")


def test_paired_rows_are_the_per_seed_differences(tiny):
    from dynmap_sim.analysis.sweep_report import load_sweep, paired_rows

    out, _, _ = tiny
    data = load_sweep(out)
    a, b, day, m = paired_rows(data)[0]
    x, y = data.errors[a][day], data.errors[b][day]
    want = paired_difference([x[s] for s in sorted(x)], [y[s] for s in sorted(y)])
    assert m == want and m.n == 2
