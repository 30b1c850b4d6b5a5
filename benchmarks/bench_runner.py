"""The runner's overhead over the bare env + driver + localizer loop (target: ratio <= 1.10),
and the parallel runner (localizers in ``--workers`` processes) against the sequential one.

Both loops run the same scenario (same seed, days, driver and localizers). The reference is
the minimum a caller needs: ``env.reset``, the driver's action, ``env.step``, every
localizer's ``update`` and the run/day hooks. The runner adds the per-scan bookkeeping, the
metrics, the SQLite writes, the checkpoint after every run and the progress bar.

    python benchmarks/bench_runner.py                       # ci-apartment, whole route, days 1-7
    python benchmarks/bench_runner.py --scenario worlds/scenarios/ci-apartment-mcl.toml

First the point-class scoring of a run (scan by scan against held scans scored at once, the
same sums), then absolute times and the ratios (wall clock and process CPU time; CPU time is the
steadier one on a shared machine); the best of ``--repeat`` runs of each loop counts. The
parallel runner's estimates are compared with the sequential one's (they must be identical).
"""

from __future__ import annotations

import argparse
import os
import resource
import sqlite3
import tempfile
import time
from pathlib import Path

import numpy as np

from dynmap_sim.agent.localization.localizer import make_localizer
from dynmap_sim.experiments.drivers import (
    DriverContext,
    RunStart,
    StepInput,
    clip_route,
    make_driver,
)
from dynmap_sim.experiments.runner import localizer_seeds, make_env, run_experiment
from dynmap_sim.experiments.scenario import load_scenario
from dynmap_sim.types import Odometry, Scan

ROOT = Path(__file__).resolve().parents[1]


def bare_loop(scenario, days, seed):
    """env + driver + localizers, nothing stored. Returns (wall s, CPU s, scans).

    The clocks start before the env is built, as in the runner."""
    t0, c0 = time.perf_counter(), time.process_time()
    env = make_env(scenario)
    u = env.unwrapped
    rngs = localizer_seeds(seed, len(scenario.localizers))
    locs = [
        make_localizer(c.name, laser=u.laser_spec, rng=rngs[k + 1], **c.params)
        for k, c in enumerate(scenario.localizers)
    ]
    d = scenario.driver
    facts = u.world_facts()
    context = DriverContext(
        route=clip_route(np.asarray(facts.route, float), d.route_fraction),
        speed_mps=d.speed_mps,
        robot_radius_m=float(u.robot_radius_m),
        dt_s=float(u.laser_spec.scan_period_s),
        laser=u.laser_spec,
    )
    driver = make_driver(d.kind, context, dict(d.params))
    slots = [s for s in u.world.calendar.slots if days[0] <= s.day <= days[1]]
    max_steps = (
        None if d.max_run_s is None else int(round(d.max_run_s / u.laser_spec.scan_period_s))
    )
    n = 0
    for i, slot in enumerate(slots):
        obs, info = env.reset(seed=seed, options={"day": slot.day, "run": slot.run})
        pc = scenario.prior  # as the runner's episode loop grants it
        prior = facts.prior(
            slot.day, slot.run, first_run=i == 0, walls=pc.map == "walls",
            sigma_xy_m=pc.initial_pose_sigma_xy_m, sigma_theta_rad=pc.initial_pose_sigma_theta_rad,
        )  # fmt: skip
        for loc in locs:
            loc.begin_run(prior)
        start = np.asarray(info["truth"]["pose"], dtype=np.float64)
        driver.begin_run(RunStart(prior, start, u.obstacles()))
        step, term, trunc, coll = 0, False, False, False
        while True:
            t = float(info["truth"]["time"][2])
            odom, scan = Odometry(np.array(obs["odom"], float), t), Scan(obs["scan"], t)
            for loc in locs:
                loc.update(odom, scan)
            n += 1
            if term or trunc or driver.done or (max_steps is not None and step >= max_steps):
                break
            a = driver.act(
                StepInput(
                    t, odom, scan, bumped=coll,
                    pose=info["truth"]["pose"], people=info["truth"]["people"],
                )
            )  # fmt: skip
            obs, _, term, trunc, info = env.step(a)
            coll = bool(info["collision"])
            step += 1
        for loc in locs:
            loc.end_run()
        if i + 1 == len(slots) or slots[i + 1].day != slot.day:
            for loc in locs:
                loc.end_day()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    env.close()
    return wall, cpu, n


def _children_cpu_s():
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def runner_loop(scenario, days, seed, workers=1):
    """The runner. Returns (wall s, CPU s of this process and its finished workers, scans,
    estimates table)."""
    with tempfile.TemporaryDirectory() as tmp:
        t0, c0, k0 = time.perf_counter(), time.process_time(), _children_cpu_s()
        out = run_experiment(
            scenario, out_dir=Path(tmp) / "r", days=days, seed=seed, progress=True, workers=workers
        )
        wall = time.perf_counter() - t0
        cpu = time.process_time() - c0 + _children_cpu_s() - k0
        con = sqlite3.connect(out / "results.db")
        n = con.execute("SELECT count(*) FROM scans").fetchone()[0]
        est = con.execute("SELECT * FROM estimates ORDER BY loc, day, run, step").fetchall()
        con.close()
    return wall, cpu, n, est


def bench_scoring(repeat: int, n_scans: int = 1350, n_beams: int = 683) -> None:
    """A run's point-class scoring (the bench's, for a localizer that reports point classes,
    e.g. the steering adaptive-memory): scan by scan (``confusion_matrix`` and
    ``PointClassTally.add``, the reference) against held scans scored at once
    (``SCORE_BATCH`` at a time, ``add_scans``) on the same synthetic classes; the sums must
    be identical."""
    from dynmap_sim.experiments.localizer_pool import SCORE_BATCH
    from dynmap_sim.metrics import PointClassTally, confusion_matrix

    rng = np.random.default_rng(0)
    shape = (n_scans, n_beams)
    pred = rng.integers(0, 4, shape).astype(np.int8)
    beam = rng.integers(0, 5, shape).astype(np.int8)
    ranges = rng.uniform(0.1, 4.0, shape).astype(np.float32)
    ranges[rng.random(shape) < 0.2] = np.inf
    truth = rng.integers(0, 4, shape).astype(np.int8)
    per_scan, batched = [], []
    for _ in range(repeat):
        c0 = time.process_time()
        one, conf1 = PointClassTally(), np.zeros((4, 4), np.int64)
        for k in range(n_scans):
            conf1 += confusion_matrix(beam[k], pred[k])
            one.add(pred[k], ranges[k], truth[k])
        per_scan.append(time.process_time() - c0)
        c0 = time.process_time()
        many, conf2 = PointClassTally(), np.zeros((4, 4), np.int64)
        for a in range(0, n_scans, SCORE_BATCH):
            rows = range(a, min(n_scans, a + SCORE_BATCH))
            p = np.stack([pred[k].astype(np.int64) for k in rows])
            conf2 += confusion_matrix(np.stack([beam[k] for k in rows]), p)
            many.add_scans(p, np.stack([ranges[k] for k in rows]),
                           np.stack([truth[k] for k in rows]))  # fmt: skip
        batched.append(time.process_time() - c0)
    same = (conf1 == conf2).all() and one.fraction_sum.tobytes() == many.fraction_sum.tobytes()
    a, b = min(per_scan), min(batched)
    print(
        f"point-class scoring, {n_scans} scans of {n_beams} beams: scan by scan "
        f"{1e6 * a / n_scans:.1f} us/scan, {SCORE_BATCH} at a time {1e6 * b / n_scans:.1f} "
        f"us/scan, ratio {a / b:.2f} (sums {'identical' if same else 'DIFFERENT'})"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--scenario",
        default=str(ROOT / "worlds/scenarios/ci-apartment.toml"),
        help="scenario TOML file both loops run",
    )
    ap.add_argument("--days", default="1-7", help="day range, e.g. 1-7")
    ap.add_argument("--seed", type=int, default=0, help="world and noise seed")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each loop (the best counts)")
    ap.add_argument(
        "--workers", type=int, default=2, help="worker processes of the parallel runner (0: skip)"
    )
    ap.add_argument(
        "--keep-time-limit",
        action="store_true",
        help="keep the scenario's max_run_s (default: drive whole routes)",
    )
    args = ap.parse_args()
    bench_scoring(args.repeat)
    scn = load_scenario(args.scenario)
    if not args.keep_time_limit:
        scn = scn.model_copy(update={"driver": scn.driver.model_copy(update={"max_run_s": None})})
        scn._source = load_scenario(args.scenario).source_path
    a, _, b = args.days.partition("-")
    days = (int(a), int(b or a))
    bare, run, par = [], [], []
    for _ in range(args.repeat):
        bare.append(bare_loop(scn, days, args.seed))
        run.append(runner_loop(scn, days, args.seed, workers=1))
        if args.workers > 0:
            par.append(runner_loop(scn, days, args.seed, workers=args.workers))
    tb, nb = min(b[0] for b in bare), bare[0][2]
    tr, nr = min(r[0] for r in run), run[0][2]
    cb, cr = min(b[1] for b in bare), min(r[1] for r in run)
    assert nb == nr, f"the loops saw different scan counts: {nb} vs {nr}"
    print(f"scenario {scn.name}, days {days[0]}-{days[1]}, localizers {', '.join(scn.labels)}")
    print(f"scans: {nr}  (best of {args.repeat} runs of each loop)")
    print(
        f"bare env + driver + localizers: {tb:8.3f} s wall {cb:8.3f} s CPU "
        f"({1e3 * cb / nb:.3f} ms/scan)"
    )
    print(
        f"runner (store, metrics, ckpt):  {tr:8.3f} s wall {cr:8.3f} s CPU "
        f"({1e3 * cr / nr:.3f} ms/scan)"
    )
    print(
        f"overhead ratio runner / bare:   {tr / tb:8.3f} wall {cr / cb:8.3f} CPU  (target <= 1.10)"
    )
    if par:
        tp, cp = min(p[0] for p in par), min(p[1] for p in par)
        same = all(p[3] == run[0][3] for p in par)
        print(
            f"runner, {args.workers} worker processes: {tp:8.3f} s wall {cp:8.3f} s CPU "
            f"(main + workers; estimates {'identical' if same else 'DIFFERENT'})"
        )
        print(
            f"parallel / sequential runner:   {tp / tr:8.3f} wall {cp / cr:8.3f} CPU  "
            f"(speed-up {tr / tp:.2f}x on {os.cpu_count()} cores)"
        )


if __name__ == "__main__":
    main()
