"""Benchmark of the dynamic map (Biber & Duckett §3–4): ``python benchmarks/bench_dynamic_map.py``.

Prints
1. sample-set update throughput: the vectorized :class:`SampleSets.update` against a per-ray
   Python loop implementing the same §3.1 rule, measured in the same run (ratio + absolute);
2. scans/s of the ``dynamic-map`` localizer on synthetic URG-04LX scans (683 beams) of an
   L-shaped room after one learned day (first-run SLAM + two runs), and the time of the
   offline (end-of-run / end-of-day) updates;
3. memory per local map (Table 1: 329,400 samples, 658,800 bytes).
"""

from __future__ import annotations

import argparse
import pickle
import sys
import time
from pathlib import Path

import numpy as np

from dynmap_sim.agent.localizer import make_localizer
from dynmap_sim.agent.maps.local_map import LocalMap
from dynmap_sim.agent.maps.sample_set import SampleSets
from dynmap_sim.types import LaserSpec, Prior

# the synthetic geometry the agent tests use (one exact ray caster, one drifting stream)
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from synthetic_scans import box, drifting_stream, polyline_path  # noqa: E402

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
    print("1. sample-set update (§3.1), vectorized vs per-ray Python loop")
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
            f"   {name}: vectorized {t_vec * 1e3:.3f} ms/update ({mps / 1e6:.2f} M meas/s), "
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
    fast.min_update_dist_m, fast.min_update_angle_rad = 0.1, 0.1
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


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=200)
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    rng = np.random.default_rng(args.seed)
    bench_sample_sets(rng, args.repeats)
    bench_localizer(rng)
    bench_memory()


if __name__ == "__main__":
    main()
