"""Localizers in worker processes: the same numbers as in-process, resume across worker
counts, rebalancing, and errors that name the localizer (never a hang, no processes left)."""

import multiprocessing as mp
import os
import pickle
import sqlite3
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from fake_env import FakeEnv  # noqa: E402

from dynmap_sim.errors import InputError  # noqa: E402
from dynmap_sim.experiments.localizer_pool import LocalizerError  # noqa: E402
from dynmap_sim.experiments.runner import ExperimentRunner, default_workers  # noqa: E402
from dynmap_sim.experiments.scenario import parse_scenario  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
TABLES = (
    "SELECT * FROM estimates ORDER BY loc, day, run, step",
    "SELECT * FROM scans ORDER BY day, run, step",
    "SELECT * FROM day_summaries ORDER BY loc, day",
    "SELECT * FROM point_classes ORDER BY loc, day, run",
    "SELECT * FROM events ORDER BY day, run, step",
    "SELECT loc, day, run, n_scans, mean_error_m, max_error_m, rmse_m, mean_scan_loglik "
    "FROM run_summaries ORDER BY loc, day, run",
)


def scenario(tmp_path, localizers=None, **extra):
    data = {
        "name": "w",
        "world": str(ROOT / "worlds" / "apartment.toml"),
        "days": [1, 3],
        "driver": {"max_run_s": 5.0},
        "localizers": localizers
        or [
            {"name": "fake_env:RecordingLocalizer", "label": "rec"},
            {"name": "odometry", "label": "odo"},
            {"name": "worker_localizers:PidLocalizer", "label": "pid"},
        ],
    }
    data.update(extra)
    if data["days"][1] >= 2:
        data.setdefault("kidnappings", [{"day": 2, "time_s": "random", "pose": "random"}])
    return parse_scenario(data, tmp_path / "s.toml")


def run(scn, out, workers, resume=False, stop_after=None):
    r = ExperimentRunner(
        scn, out, scn.days, 0, resume=resume, overwrite=not resume, env=FakeEnv(), workers=workers
    )
    r.run(progress=False, stop_after=stop_after)
    return r


def tables(out):
    con = sqlite3.connect(out / "results.db")
    try:
        return [con.execute(sql).fetchall() for sql in TABLES]
    finally:
        con.close()


def test_workers_give_the_numbers_of_the_sequential_runner(tmp_path):
    scn = scenario(tmp_path)
    seq = run(scn, tmp_path / "seq", workers=1)
    par = run(scn, tmp_path / "par", workers=2)
    assert tables(tmp_path / "seq") == tables(tmp_path / "par")
    # the localizers really ran elsewhere, and got the same calls
    pids = par.localizers()[2].pids
    assert len(pids) == 3 and os.getpid() not in pids
    # one BLAS thread per worker (the workers are the parallelism); ours is untouched
    assert par.localizers()[2].blas_threads == os.environ.get("OPENBLAS_NUM_THREADS", "1")
    assert seq.localizers()[2].blas_threads == os.environ.get("OPENBLAS_NUM_THREADS")
    assert seq.localizers()[0].calls == par.localizers()[0].calls
    assert not mp.active_children()


def test_resume_across_worker_counts(tmp_path):
    scn = scenario(tmp_path)
    run(scn, tmp_path / "full", workers=1)
    run(scn, tmp_path / "broken", workers=2, stop_after=2)
    r = run(scn, tmp_path / "broken", workers=1, resume=True)
    assert r.start_index == 2
    assert tables(tmp_path / "full") == tables(tmp_path / "broken")
    assert len(r.localizers()[0].calls) == 3 * 3
    # only the last checkpoint's localizer files are kept
    names = sorted(p.name for p in (tmp_path / "broken" / "checkpoint").iterdir())
    assert names == ["loc0-3.pkl", "loc1-3.pkl", "loc2-3.pkl"]


def test_a_failing_localizer_is_named_and_the_workers_stop(tmp_path):
    scn = scenario(
        tmp_path,
        localizers=[
            {"name": "odometry"},
            {"name": "worker_localizers:FailingLocalizer", "label": "burning"},
        ],
    )
    with pytest.raises(LocalizerError, match=r"'burning' failed on day 2 run 1 at scan 4.*fire"):
        run(scn, tmp_path / "o", workers=2)
    assert not mp.active_children()
    con = sqlite3.connect(tmp_path / "o" / "results.db")
    assert con.execute("SELECT day FROM runs").fetchall() == [(1,)]
    con.close()
    with pytest.raises(LocalizerError, match="'burning' failed on day 2 run 1 at scan 4"):
        run(scn, tmp_path / "o1", workers=1)


def test_a_dying_worker_is_reported_not_waited_for(tmp_path):
    scn = scenario(
        tmp_path,
        days=[1, 1],
        localizers=[{"name": "odometry"}, {"name": "worker_localizers:DyingLocalizer"}],
    )
    with pytest.raises(LocalizerError, match=r"DyingLocalizer.*died on day 1 run 1 \(exit code 3"):
        run(scn, tmp_path / "o", workers=2)
    assert not mp.active_children()


def test_an_unpicklable_localizer_is_named_before_any_worker_starts(tmp_path):
    scn = scenario(
        tmp_path,
        days=[1, 1],
        localizers=[
            {"name": "odometry"},
            {"name": "fake_env:UnpicklableLocalizer", "label": "bad one"},
        ],
    )
    with pytest.raises(InputError, match="'bad one'.*cannot be pickled"):
        run(scn, tmp_path / "o", workers=2)
    assert not mp.active_children()


def test_the_pool_does_not_wait_for_its_workers_and_reports_a_failed_start(tmp_path):
    """The workers start (imports, the localizers' states) while the first run is simulated;
    a worker that cannot take its localizers is reported, by name, at the first result."""
    from dynmap_sim.experiments.localizer_pool import LocalizerPool

    scn = scenario(tmp_path, days=[1, 1])
    r = ExperimentRunner(scn, tmp_path / "o", scn.days, 0, resume=False, env=FakeEnv())
    sim = r._simulate(0)[0]
    states = [pickle.dumps(loc) for loc in r.localizers()]
    states[1] = b"not a pickled localizer"
    pool = LocalizerPool(scn.labels, states, 2)
    try:
        assert all(w.owed == 1 for w in pool.workers)  # their replies not waited for
        pool.submit(sim.stream)
        with pytest.raises(LocalizerError, match=rf"worker process .*{scn.labels[1]!r}"):
            pool.result()
    finally:
        pool.close()
    assert not mp.active_children()


def test_rebalancing_moves_localizers_and_keeps_the_numbers(tmp_path):
    from dynmap_sim.experiments.localizer_pool import LocalizerPool

    scn = scenario(tmp_path)
    r = ExperimentRunner(scn, tmp_path / "o", scn.days, 0, resume=False, env=FakeEnv())
    sims = [r._simulate(i)[0] for i in range(3)]
    seq = r._start_localizers()  # in-process: the reference
    ref = []
    for s in sims:
        seq.submit(s.stream)
        ref.append(seq.result())
    fresh = ExperimentRunner(scn, tmp_path / "o2", scn.days, 0, resume=False, env=FakeEnv())
    states = [pickle.dumps(loc) for loc in fresh.localizers()]
    pool = LocalizerPool(scn.labels, states, 2)
    try:
        assert [w.locs for w in pool.workers] == [[0, 2], [1]]
        got = []
        for k, s in enumerate(sims):
            if k == 1:  # pretend the last run said: rec and pid together are the slow worker
                pool.busy_s = [6.0, 1.0, 5.0]
            pool.submit(s.stream)  # rebalances first
            if k == 1:
                assert sorted(sorted(w.locs) for w in pool.workers) == [[0], [1, 2]]
            got.append(pool.result())
    finally:
        pool.close()
    for a, b in zip(ref, got, strict=True):
        for oa, ob in zip(a, b, strict=True):
            np.testing.assert_array_equal(oa.estimates, ob.estimates)
            assert oa.diagnostics.per_scan.keys() == ob.diagnostics.per_scan.keys()
            for name, values in oa.diagnostics.per_scan.items():
                np.testing.assert_array_equal(values, ob.diagnostics.per_scan[name])
            np.testing.assert_array_equal(oa.confusion, ob.confusion)
    assert not mp.active_children()


def test_three_runs_in_flight_and_a_rebalance_between_keep_the_numbers(tmp_path):
    """The pool takes further runs before the first is collected (LocalizerPool.depth); a
    rebalance then collects the runs in flight first and moves the localizers' states after
    them: the outputs are the in-process ones, in order."""
    from dynmap_sim.experiments.localizer_pool import LocalizerPool

    scn = scenario(tmp_path, days=[1, 4])
    r = ExperimentRunner(scn, tmp_path / "o", scn.days, 0, resume=False, env=FakeEnv())
    sims = [r._simulate(i)[0] for i in range(4)]
    seq = r._start_localizers()
    ref = []
    for s in sims:
        seq.submit(s.stream)
        ref.append(seq.result())
    fresh = ExperimentRunner(scn, tmp_path / "o2", scn.days, 0, resume=False, env=FakeEnv())
    pool = LocalizerPool(scn.labels, [pickle.dumps(loc) for loc in fresh.localizers()], 2)
    try:
        assert pool.depth == 3
        for s in sims[:3]:
            pool.submit(s.stream)
        with pytest.raises(RuntimeError, match="not collected"):
            pool.submit(sims[3].stream)
        got = [pool.result()]
        pool.busy_s = [6.0, 1.0, 5.0]  # calls for a move while runs 2 and 3 are in flight
        pool.submit(sims[3].stream)
        assert sorted(sorted(w.locs) for w in pool.workers) == [[0], [1, 2]]
        got += [pool.result(), pool.result(), pool.result()]
    finally:
        pool.close()
    for a, b in zip(ref, got, strict=True):
        for oa, ob in zip(a, b, strict=True):
            np.testing.assert_array_equal(oa.estimates, ob.estimates)
            np.testing.assert_array_equal(oa.cov_diag, ob.cov_diag)
    assert not mp.active_children()


@pytest.mark.skipif(not hasattr(os, "setpriority"), reason="no os.setpriority here")
def test_light_workers_yield_the_cpu_once_and_only_with_one_localizer_each(tmp_path):
    """A worker whose localizer took under LIGHT_WORKER_SHARE of the busiest one's time gets
    LIGHT_WORKER_NICE; the busiest keeps its priority; workers sharing localizers never."""
    from dynmap_sim.experiments.localizer_pool import LIGHT_WORKER_NICE, LocalizerPool

    scn = scenario(tmp_path)
    fresh = ExperimentRunner(scn, tmp_path / "o", scn.days, 0, resume=False, env=FakeEnv())
    states = [pickle.dumps(loc) for loc in fresh.localizers()]
    base = os.getpriority(os.PRIO_PROCESS, 0)
    for n_workers, expect in ((3, [LIGHT_WORKER_NICE, base, base]), (2, [base, base])):
        pool = LocalizerPool(scn.labels, states, n_workers)
        try:
            pool.busy_s = [1.0, 6.0, 3.5]  # rec light, pid over half the busiest
            pool._yield_light_workers()
            nice = [os.getpriority(os.PRIO_PROCESS, w.proc.pid) for w in pool.workers]
            assert nice == [max(e, base) for e in expect]
            pool.busy_s = [9.0, 6.0, 5.0]  # never undone (only root could)
            pool._yield_light_workers()
            assert [os.getpriority(os.PRIO_PROCESS, w.proc.pid) for w in pool.workers] == nice
        finally:
            pool.close()
    assert not mp.active_children()


def test_default_workers(tmp_path, monkeypatch):
    monkeypatch.setattr("os.cpu_count", lambda: 4)
    assert default_workers(1) == 1
    assert default_workers(5) == 2  # robot time unknown (no max_run_s): worth the start-up
    assert default_workers(5, robot_time_s=120.0) == 1  # a CI-sized experiment: in-process
    assert default_workers(5, robot_time_s=121.0) == 2
    assert default_workers(2, robot_time_s=1e4) == 2
    # one more localizer than the count: each its own worker (no rebalancing stalls)
    monkeypatch.setattr("os.cpu_count", lambda: 2)
    assert default_workers(4, robot_time_s=1e4, n_steered=1) == 3  # the H&W replica
    assert default_workers(3, robot_time_s=1e4) == 3
    assert default_workers(4, robot_time_s=1e4) == 2  # the main job: two more, shared
    assert default_workers(6, robot_time_s=1e4) == 2  # the lab's six
    monkeypatch.setattr("os.cpu_count", lambda: 1)
    assert default_workers(3, robot_time_s=1e4) == 1
    assert default_workers(3, robot_time_s=1e4, n_steered=1) == 1  # one worker holds both
    # the runner's automatic choice: 3 runs of at most 5 s each
    scn = scenario(tmp_path)
    runner = ExperimentRunner(scn, tmp_path / "o", scn.days, 0, False, env=FakeEnv(), workers=None)
    assert runner.workers == 1


def test_real_env_static_mcl_bit_identical_with_workers(tmp_path):
    """The real env and particle filters (first-run SLAM on day 1, MCL on day 2)."""
    from dynmap_sim.experiments.runner import run_experiment
    from dynmap_sim.experiments.scenario import load_scenario

    scn = load_scenario(ROOT / "worlds" / "scenarios" / "ci-apartment-mcl.toml")
    scn = scn.model_copy(update={"driver": scn.driver.model_copy(update={"max_run_s": 4.0})})
    scn._source = load_scenario(ROOT / "worlds" / "scenarios" / "ci-apartment-mcl.toml").source_path
    for w in (1, 2):
        run_experiment(scn, out_dir=tmp_path / f"w{w}", progress=False, workers=w)
    assert tables(tmp_path / "w1") == tables(tmp_path / "w2")
    assert len(tables(tmp_path / "w1")[0]) == 3 * 2 * 41
