"""Benchmark of the dynamic map (Biber & Duckett §3–4): ``python benchmarks/bench_dynamic_map.py``.

Prints
1. sample-set update throughput: the vectorized :class:`SampleSets.update` against a per-ray
   Python loop implementing the same §3.1 rule, measured in the same run (ratio + absolute);
2. scans/s of the ``dynamic-map`` localizer on synthetic URG-04LX scans (683 beams) of an
   L-shaped room after one learned day (first-run SLAM + two runs), and the time of the
   offline (end-of-run / end-of-day) updates;
3. memory per local map (Table 1: 329,400 samples, 658,800 bytes);
4. the time per call of the hot paths: ICP (``match_scan``), ``PointMap`` construction
   (normals), the per-scan log-likelihoods of a local map and the robust estimates of a
   lambda1 and a lambda5 sub-map.

By default (without ``--synthetic``) it instead records a scenario's sensor stream once
(``--scenario``, ``--days``; the simulation with the steering localizer only, cached in
``--cache``) and replays ``dynamic-map`` on it as the runner does (its rng is the runner's
generator child); the days before ``--timed-from`` (day 1: the first-run SLAM, which the
other 27 days of the H&W replica do not do) are replayed once, untimed, and each timed
replay starts from their pickled state. It prints scans/s of CPU (``time.process_time``)
with a reference measured in the same process on the same stream (``static-mcl`` walls-only
on the prior walls, as the H&W replica runs it) and their ratio, the CPU of the end-of-
run/day learning, and with ``--profile`` the CPU per stage [ms/scan] from cProfile.
``--fingerprint`` prints a SHA-256 of everything ``dynamic-map`` returns on the replay
(estimates, covariances, extras) and of its map's samples after it: a change meant to be
faster must leave it unchanged. ``--synthetic`` runs the sections above.
"""

from __future__ import annotations

import argparse
import cProfile
import hashlib
import pickle
import pstats
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from dynmap_sim import se2
from dynmap_sim.agent.localization.localizer import make_localizer
from dynmap_sim.agent.mapping.scan_matcher import PointMap, match_scan
from dynmap_sim.agent.mapping.scan_points import scan_points_base, voxel_downsample
from dynmap_sim.agent.maps.dynamic_map import DynamicMap
from dynmap_sim.agent.maps.local_map import LocalMap
from dynmap_sim.agent.maps.sample_set import SampleSets, robust_estimates
from dynmap_sim.cli import day_range
from dynmap_sim.types import LaserSpec, Prior

# the synthetic geometry the agent tests use (one exact ray caster, one drifting stream)
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from synthetic_scans import box, drifting_stream, polyline_path, raycast  # noqa: E402

URG = LaserSpec(
    name="urg-04lx",
    n_beams=683,
    angle_min_rad=-2.0862,
    angle_increment_rad=2 * np.pi / 1024,
    range_min_m=0.02,
    range_max_m=5.6,
    scan_period_s=0.1,
    time_increment_s=0.0,
)


def loop_update(s: SampleSets, ray: np.ndarray, val: np.ndarray, rng: np.random.Generator):
    """Reference: the §3.1 rule one ray at a time in Python (same semantics as the vector code)."""
    n = s.n_samples
    k = int(round(s.update_ratio * n))
    for r in np.unique(ray):
        m = val[ray == r]
        cnt = int(s.count[r])
        new = rng.choice(m, size=min(k, len(m)), replace=False)
        n_add = min(len(new), n - cnt)
        s.samples_mm[r, cnt : cnt + n_add] = new[:n_add]
        if len(new) > n_add:
            slots = rng.choice(cnt, size=len(new) - n_add, replace=False)
            s.samples_mm[r, slots] = new[n_add:]
        s.count[r] = cnt + n_add


def bench_sample_sets(rng: np.random.Generator, repeats: int) -> None:
    print("1. sample-set update (§3.1), compiled vs per-ray Python loop")
    for name, n_rays, n_samples, u, per_ray in (
        ("lambda1 (360 x 5, u=0.2), 2 meas/ray", 360, 5, 0.2, 2),
        ("lambda5 (1440 x 100, u=0.05), 40 meas/ray", 1440, 100, 0.05, 40),
    ):
        ray = np.repeat(np.arange(n_rays), per_ray)
        val = rng.integers(500, 5000, ray.size).astype(np.uint16)
        a = SampleSets(n_rays, n_samples, u)
        b = SampleSets(n_rays, n_samples, u)
        a.update(np.repeat(np.arange(n_rays), n_samples), np.full(n_rays * n_samples, 1000), rng)
        b.samples_mm[:] = a.samples_mm
        b.count[:] = a.count
        t0 = time.perf_counter()
        for _ in range(repeats):
            a.update(ray, val, rng)
        t_vec = (time.perf_counter() - t0) / repeats
        t0 = time.perf_counter()
        reps_loop = max(1, repeats // 10)
        for _ in range(reps_loop):
            loop_update(b, ray, val, rng)
        t_loop = (time.perf_counter() - t0) / reps_loop
        mps = ray.size / t_vec
        print(
            f"   {name}: compiled {t_vec * 1e3:.3f} ms/update ({mps / 1e6:.2f} M meas/s), "
            f"loop {t_loop * 1e3:.2f} ms/update -> speed-up x{t_loop / t_vec:.1f}"
        )


def _world() -> np.ndarray:
    pts = np.array([[0, 0], [12, 0], [12, 4], [7, 4], [7, 9], [0, 9]], float)
    walls = np.concatenate([pts, np.roll(pts, -1, axis=0)], axis=1)
    return np.concatenate(
        [walls, box(2, 2, 2.4, 2.4), box(9, 0, 10, 0.6), box(1, 6, 3, 6.5), box(4, 7, 4.5, 8)]
    )


def _route(step_m: float = 0.035) -> np.ndarray:
    corners = np.array([[1, 1], [10.5, 1.2], [11, 3], [5.5, 2.5], [5.5, 8], [1.2, 8], [1, 4]])
    return polyline_path(corners, step_m=step_m, turn_step_rad=0.1)


def _stream(truth, segs, rng):
    return drifting_stream(truth, segs, URG, rng)


def bench_localizer(rng: np.random.Generator) -> None:
    print("2. dynamic-map localizer on synthetic URG-04LX scans (683 beams, 12 m x 9 m L-room)")
    truth = _route()
    segs = _world()
    streams = [_stream(truth, segs, rng) for _ in range(3)]
    loc = make_localizer("dynamic-map", laser=URG, rng=np.random.default_rng(1))
    odo = make_localizer("odometry", laser=URG, rng=np.random.default_rng(1))
    timings = []
    for run, stream in enumerate(streams, start=1):
        for lz in (loc, odo):
            lz.begin_run(Prior(initial_pose=truth[0].copy(), day=1, run=run, first_run=run == 1))
        t0 = time.perf_counter()
        ests = [loc.update(o, s) for o, s in stream]
        t_scan = time.perf_counter() - t0
        t0 = time.perf_counter()
        loc.end_run()
        t_end = time.perf_counter() - t0
        err = np.hypot(*(np.array([e.mean[:2] for e in ests]) - truth[:, :2]).T)
        what = "first-run SLAM" if run == 1 else "localization"
        print(
            f"   run {run} ({what}): {len(stream)} scans in {t_scan:.2f} s = "
            f"{len(stream) / t_scan:.0f} scans/s; end_run {t_end * 1e3:.0f} ms; "
            f"mean error {err.mean() * 100:.1f} cm; local maps {len(loc.dmap)}"
        )
        timings.append((len(stream), t_scan))
    t0 = time.perf_counter()
    loc.end_day()
    print(f"   end_day (lambda3-5 from {3 * len(truth)} scans): {time.perf_counter() - t0:.2f} s")
    # day 2: the learned map, with a reference: dead reckoning on the same stream
    stream = _stream(truth, segs, rng)
    loc.begin_run(Prior(initial_pose=truth[0].copy(), day=2, run=1))
    odo.begin_run(Prior(initial_pose=truth[0].copy(), day=2, run=1))
    t0, c0 = time.perf_counter(), time.process_time()
    ests = [loc.update(o, s) for o, s in stream]
    t_dm, c_dm = time.perf_counter() - t0, time.process_time() - c0
    t0 = time.perf_counter()
    for o, s in stream:
        odo.update(o, s)
    t_odo = time.perf_counter() - t0
    err = np.hypot(*(np.array([e.mean[:2] for e in ests]) - truth[:, :2]).T)
    ts = np.bincount([e.extras["timescale"] for e in ests if e.extras["timescale"] >= 0], None, 5)
    print(
        f"   day 2 run 1: {len(stream) / t_dm:.0f} scans/s wall, {len(stream) / c_dm:.0f} scans/s "
        f"of CPU time (odometry reference "
        f"{len(stream) / t_odo:.0f} scans/s, ratio x{t_dm / t_odo:.0f}); mean error "
        f"{err.mean() * 100:.1f} cm; timescale usage {ts.tolist()}; "
        f"safe mode {np.mean([e.extras['safe_mode'] for e in ests]) * 100:.1f} %"
    )
    fast = pickle.loads(pickle.dumps(loc))
    fast.end_run()
    fast.config = replace(fast.config, min_update_dist_m=0.1, min_update_angle_rad=0.1)
    fast.begin_run(Prior(initial_pose=truth[0].copy(), day=2, run=2))
    c0 = time.process_time()
    ests = [fast.update(o, s) for o, s in stream]
    c_fast = time.process_time() - c0
    err = np.hypot(*(np.array([e.mean[:2] for e in ests]) - truth[:, :2]).T)
    print(
        f"   same stream with min_update_dist_m = min_update_angle_rad = 0.1: "
        f"{len(stream) / c_fast:.0f} scans/s of CPU time, mean error {err.mean() * 100:.1f} cm, "
        f"{np.mean([e.extras.get('skipped', False) for e in ests]) * 100:.0f} % scans skipped"
    )
    print(f"   pickled localizer: {len(pickle.dumps(loc)) / 1e6:.1f} MB for {len(loc.dmap)} maps")


def bench_memory() -> None:
    lm = LocalMap([0.0, 0.0])
    print("3. memory per local map (Table 1)")
    print(
        f"   {lm.n_samples_capacity} samples, {lm.sample_bytes} bytes of samples "
        f"({lm.sample_bytes / 1e6:.3f} MB; paper: 329 400 samples, 0.63 MB), "
        f"{lm.nbytes} bytes with per-ray counts, pickled {len(pickle.dumps(lm))} bytes"
    )


def _per_call_s(fn, repeats: int) -> float:
    fn()  # warm-up (numba: load or compile)
    t0 = time.perf_counter()
    for _ in range(repeats):
        fn()
    return (time.perf_counter() - t0) / repeats


def bench_kernels(rng: np.random.Generator, repeats: int) -> None:
    print("4. hot paths, time per call")
    segs = _world()
    truth = _route()[::40]
    scans = [raycast(p, URG.angles(), segs, URG.range_max_m) for p in truth]
    scans = [r + rng.normal(0.0, 0.01, r.shape) for r in scans]
    base = [scan_points_base(URG, r) for r in scans]
    local = voxel_downsample(
        np.concatenate([se2.transform_points(truth[k], base[k]) for k in range(6, 18)]), 0.03
    )
    pts = base[12][:: max(1, len(base[12]) // 400)]
    init = truth[12] + [0.05, -0.03, 0.02]
    prior = np.diag([400.0, 400.0, 2500.0])
    target = PointMap(local)
    t_icp = _per_call_s(
        lambda: match_scan(pts, target, init, prior_mean=init, prior_info=prior,
                           max_correspondence_m=0.3, huber_m=0.02),
        repeats,
    )  # fmt: skip
    t_map = _per_call_s(lambda: PointMap(local), max(1, repeats // 4))
    print(f"   match_scan ({len(pts)} points, {len(local)}-point local map, with prior): "
          f"{t_icp * 1e3:.3f} ms")  # fmt: skip
    print(f"   PointMap({len(local)} points): {t_map * 1e3:.3f} ms")
    dmap = DynamicMap(max_range_m=URG.range_max_m)
    centre = truth[12]
    i = dmap.add_local_map(centre[:2], se2.transform_points(centre, base[12]), rng)
    near = [truth[k] for k in range(9, 16)]
    dmap.learn_offline(
        [1, 2, 3, 4], np.array(near), [se2.transform_points(p, scan_points_base(URG, r))
                                       for p, r in zip(near, scans[9:16], strict=True)], rng,
    )  # fmt: skip
    lm = dmap.local_maps[i]
    scan = se2.transform_points(truth[13], base[13])[::3]
    kw = {"sigma_min_m": 0.01, "min_outlier_ratio": 0.0}
    t_ll = _per_call_s(lambda: lm.scan_log_likelihoods(range(5), scan, **kw), repeats)
    print(f"   LocalMap.scan_log_likelihoods ({len(scan)} readings x 5 timescales): "
          f"{t_ll * 1e6:.0f} us")  # fmt: skip
    for level in (0, 4):
        sub = lm.sub[level]
        t_est = _per_call_s(lambda s=sub: robust_estimates(s.samples_mm, s.count), repeats)
        print(f"   robust_estimates of a {sub.n_rays} x {sub.n_samples} sub-map: "
              f"{t_est * 1e6:.0f} us")  # fmt: skip


# ---------------------------------------------------------------------- replay of a scenario
def record_streams(scenario_path: str, days: tuple[int, int], cache: Path) -> list:
    """The scenario's run streams (:class:`~dynmap_sim.experiments.localizer_pool.RunStream`) of
    ``days``: simulated with the steering localizer alone (the others do not change the
    stream), pickled to ``cache`` and read from there next time."""
    if cache.exists():
        with cache.open("rb") as f:
            return pickle.load(f)  # noqa: S301 - our own cache
    from dynmap_sim.analysis.scenarios import load_scenario
    from dynmap_sim.experiments.runner import ExperimentRunner

    sc = load_scenario(scenario_path)
    with tempfile.TemporaryDirectory() as out:
        runner = ExperimentRunner(sc, Path(out), days, sc.seeds[0], resume=False, workers=1)
        runner._start_localizers()  # sets the lock-stepped steering localizer
        streams = [runner.loop.run(i, runner.state, runner._steer).stream
                   for i in range(len(runner.slots))]  # fmt: skip
        runner.db.close()
    with cache.open("wb") as f:
        pickle.dump(streams, f, pickle.HIGHEST_PROTOCOL)
    return streams


def _replay_localizer(scenario_path: str, label: str):
    """A fresh localizer of the scenario's ``label`` with the runner's generator child."""
    from dynmap_sim.analysis.scenarios import load_scenario
    from dynmap_sim.experiments.runner import localizer_seeds, make_env

    sc = load_scenario(scenario_path)
    env = make_env(sc)
    laser = env.unwrapped.laser_spec
    env.close()
    rngs = localizer_seeds(sc.seeds[0], len(sc.localizers))
    k = sc.labels.index(label)
    c = sc.localizers[k]
    return make_localizer(c.name, laser=laser, rng=rngs[k + 1], **c.params)


def _replay(loc, streams, on_estimate=None) -> tuple[float, float, int]:
    """Feed the streams to ``loc`` as the runner does; CPU [s] of ``update`` and of the
    run/day hooks, and the number of scans."""
    from dynmap_sim.types import Odometry, Scan

    t_up = t_end = 0.0
    n = 0
    for st in streams:
        loc.begin_run(st.prior)
        for k in range(len(st.stamps_s)):
            t = float(st.stamps_s[k])
            odom = Odometry(pose=np.array(st.odom[k], dtype=np.float64), stamp_s=t)
            scan = Scan(ranges_m=np.array(st.scans[k], dtype=np.float32), stamp_s=t)
            c0 = time.process_time()
            e = loc.update(odom, scan)
            t_up += time.process_time() - c0
            if on_estimate is not None:
                on_estimate(e)
        n += len(st.stamps_s)
        c0 = time.process_time()
        loc.end_run()
        if st.last_of_day:
            loc.end_day()
        pickle.dumps(loc, pickle.HIGHEST_PROTOCOL)  # as the runner does after every run
        t_end += time.process_time() - c0
    return t_up, t_end, n


#: Functions whose cumulative CPU is reported per scan by ``--profile`` (name, label).
STAGES = (
    ("_match", "ICP with adaptive kappa (eq. 9)"),
    ("_current_point_map", "PointMap of the current map (normals)"),
    ("synthesize_current_map", "current-map synthesis (4.3)"),
    ("_set_current_map", "current map thinning/compare"),
    ("learn_online", "lambda1 online learning (4.4)"),
    ("scan_points_base", "scan points"),
    ("lambda_min", "lambda_min"),
    ("_store", "store (pose, scan)"),
    ("end_run", "end_run (lambda2)"),
    ("end_day", "end_day (lambda3-5)"),
)


def _prepared(args, label: str, streams) -> tuple[bytes, list]:
    """The pickled localizer ``label`` after the untimed runs (days before
    ``--timed-from``: the first-run SLAM of day 1 is not what the other days do), and the
    runs to time."""
    untimed = [s for s in streams if s.prior.day < args.timed_from]
    loc = _replay_localizer(args.scenario, label)
    _replay(loc, untimed)
    return pickle.dumps(loc, pickle.HIGHEST_PROTOCOL), streams[len(untimed) :]


def bench_replay(args) -> None:
    streams = record_streams(args.scenario, args.days, args.cache)
    dm_state, timed = _prepared(args, "dynamic-map", streams)
    ref_state, _ = _prepared(args, args.reference, streams)
    n = sum(len(s.stamps_s) for s in timed)
    print(f"replay: {args.scenario} days {args.days[0]}-{args.days[1]}: {len(streams)} runs; "
          f"timed: days {args.timed_from}-{args.days[1]}, {len(timed)} runs, "
          f"{n} scans")  # fmt: skip
    for rep in range(args.runs):
        t_ref, _, _ = _replay(pickle.loads(ref_state), timed)  # noqa: S301 - our own state
        t_dm, e_dm, _ = _replay(pickle.loads(dm_state), timed)  # noqa: S301
        print(f"  [{rep + 1}] dynamic-map {n / t_dm:6.0f} scans/s of CPU ({1e3 * t_dm / n:.3f} "
              f"ms/scan; run/day ends {e_dm:.2f} s); {args.reference} {n / t_ref:6.0f} "
              f"scans/s ({1e3 * t_ref / n:.3f} ms/scan); ratio dynamic-map/reference "
              f"{t_dm / t_ref:.3f}")  # fmt: skip
    if args.profile:
        loc = pickle.loads(dm_state)  # noqa: S301
        prof = cProfile.Profile(time.process_time)
        prof.enable()
        _replay(loc, timed)
        prof.disable()
        st = pstats.Stats(prof)
        cum: dict[str, float] = {}
        for (_, _, name), (_, _, _, ct, _) in st.stats.items():
            cum[name] = cum.get(name, 0.0) + ct
        print("  per stage [ms/scan of CPU, cProfile]:")
        for name, what in STAGES:
            print(f"    {what:40s} {1e3 * cum.get(name, 0.0) / n:8.3f}")
        st.sort_stats("tottime").print_stats(30)


def fingerprint(args) -> str:
    """SHA-256 of dynamic-map's outputs on the replay and of its map's samples after it."""
    streams = record_streams(args.scenario, args.days, args.cache)
    loc = _replay_localizer(args.scenario, "dynamic-map")
    h = hashlib.sha256()

    def add(e) -> None:
        h.update(np.ascontiguousarray(e.mean, dtype=np.float64).tobytes())
        h.update(np.ascontiguousarray(e.cov, dtype=np.float64).tobytes())
        for k in sorted(e.extras):
            h.update(k.encode())
            h.update(np.ascontiguousarray(e.extras[k]).tobytes())

    _, _, n = _replay(loc, streams, add)
    for lm in loc.dmap.local_maps:
        h.update(lm.centre.tobytes())
        for s in lm.sub:
            h.update(s.samples_mm.tobytes())
            h.update(s.count.tobytes())
            h.update(s.initialized.tobytes())
    h.update(np.asarray(loc.rng.random(4)).tobytes())  # the generator's position
    print(f"fingerprint of {n} scans, {len(loc.dmap)} local maps: {h.hexdigest()}")
    return h.hexdigest()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "--repeats", type=int, default=200, help="--synthetic: repetitions of each timed kernel"
    )
    p.add_argument("--seed", type=int, default=0, help="--synthetic: seed of the synthetic data")
    p.add_argument("--synthetic", action="store_true", help="the synthetic sections 1-4")
    p.add_argument(
        "--fingerprint",
        action="store_true",
        help="print the SHA-256 of the replay's outputs instead of timing them",
    )
    p.add_argument("--profile", action="store_true", help="also the CPU per stage (cProfile)")
    p.add_argument(
        "--scenario",
        default="worlds/scenarios/apartment-28d-hw.toml",
        help="scenario whose stream is recorded and replayed",
    )
    p.add_argument("--days", type=day_range, default=(1, 4), help="day range of the replay")
    p.add_argument("--timed-from", type=int, default=2, help="first timed day (see doc)")
    p.add_argument("--runs", type=int, default=3, help="timed replays (each with reference)")
    p.add_argument(
        "--reference",
        default="static-mcl walls",
        help="label of the scenario's reference localizer",
    )
    p.add_argument("--cache", type=Path, default=None,
                   help="recorded streams (default: a file in the temp folder)")  # fmt: skip
    args = p.parse_args()
    if args.cache is None:
        name = Path(args.scenario).stem
        args.cache = Path(tempfile.gettempdir()) / (
            f"bench_dynamic_map_{name}_d{args.days[0]}-{args.days[1]}.pkl"
        )
    if args.fingerprint:
        fingerprint(args)
        return
    if not args.synthetic:
        bench_replay(args)
        return
    rng = np.random.default_rng(args.seed)
    bench_sample_sets(rng, args.repeats)
    bench_localizer(rng)
    bench_memory()
    bench_kernels(rng, max(10, args.repeats // 2))


if __name__ == "__main__":
    main()
