"""Global localization and kidnapping recovery of static-mcl on the apartment.

1. Records the apartment's runs (days 1..N) with the tour driver: odometry, scans, truth.
2. Builds the static map with ``static-mcl``'s first-run SLAM on day 1 (known start pose).
3. **Global localization**: 20 trials; each starts a copy of the localizer with no initial
   pose (particles uniform over the free space) at a random point of a later day's run and
   drives on. Converged = error < 0.2 m and staying below it for the next 10 s; reported
   is the fraction converged within 30 s of driving and the times.
4. **Kidnapping**: 20 trials; a tracking localizer (known start) is, at a random time, fed
   the sensor stream of another place of the route while its odometry continues smoothly
   (the true robot was carried away; odometry does not notice). Recovered = error back
   below 0.2 m (and staying there 10 s); reported is the fraction recovered within 30 s.

    python benchmarks/mcl_global_kidnap.py [--config tuned] [--days 4] [--trials 20]
"""

from __future__ import annotations

import argparse
import pickle
import tempfile
import time
from pathlib import Path

import numpy as np

from dynmap_sim import se2
from dynmap_sim.agent.localization.particle_filter import CONFIGS, StaticMCL
from dynmap_sim.experiments.replay import json_or_text
from dynmap_sim.experiments.runner import ExperimentRunner
from dynmap_sim.experiments.scenario import parse_scenario
from dynmap_sim.types import Odometry, Prior, Scan


def record(world: str, days: int, seed: int) -> tuple[object, list[dict[str, np.ndarray]]]:
    """Drive the route with the tour operator on run 1 of days 1..days, through the
    experiment engine's episode loop; return the laser spec and per-day streams."""
    sc = parse_scenario(
        {"name": "rec", "world": world, "days": [1, days], "localizers": [{"name": "odometry"}]}
    )
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        runner = ExperimentRunner(sc, Path(tmp), (1, days), seed, resume=False)
        try:
            for i, slot in enumerate(runner.slots):
                episode = runner.loop.run(i, runner.state)
                if slot.run != 1:
                    continue
                s = episode.stream
                out.append(
                    {"odom": s.odom, "ranges": s.scans, "truth": episode.truth, "t": s.stamps_s}
                )
        finally:
            runner.db.close()
    return runner.laser, out


def feed(loc: StaticMCL, odom: np.ndarray, ranges: np.ndarray, t0: float = 0.0) -> np.ndarray:
    est = np.empty((len(odom), 3))
    for k in range(len(odom)):
        est[k] = loc.update(Odometry(odom[k], t0 + 0.1 * k), Scan(ranges[k], t0 + 0.1 * k)).mean
    return est


def settle_time(err: np.ndarray, dt_s: float = 0.1, hold_s: float = 10.0) -> float:
    """First time [s] the error is < 0.2 m and stays so for ``hold_s`` (inf if never)."""
    ok = err < 0.2
    hold = int(hold_s / dt_s)
    for k in range(len(err)):
        if ok[k] and ok[k : k + hold].all():
            return k * dt_s
    return float("inf")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--config",
        default="tuned",
        choices=sorted(CONFIGS),
        help="static-mcl configuration (default: tuned; tuned-end-points: tuned before its "
        "see-through term)",
    )
    ap.add_argument("--days", type=int, default=4, help="apartment runs to record (default: 4)")
    ap.add_argument("--trials", type=int, default=20, help="trials of each kind (default: 20)")
    ap.add_argument("--seed", type=int, default=0, help="world and noise seed (default: 0)")
    ap.add_argument(
        "--override",
        action="append",
        default=[],
        help="MCLConfig field=value (repeatable; the value as JSON, else as text)",
    )
    args = ap.parse_args()
    if args.days < 1 or args.trials < 1:
        ap.error("--days and --trials must be at least 1")
    if args.seed < 0:
        ap.error("--seed must be >= 0")
    overrides = {k: json_or_text(v) for k, _, v in (o.partition("=") for o in args.override)}
    t0 = time.perf_counter()
    laser, runs = record("apartment", args.days, args.seed)
    print(
        f"recorded {args.days} runs ({sum(len(r['t']) for r in runs)} scans) "
        f"in {time.perf_counter() - t0:.0f} s"
    )
    base = StaticMCL(
        laser, np.random.default_rng(args.seed), config=args.config, overrides=overrides
    )
    d1 = runs[0]
    base.begin_run(Prior(initial_pose=d1["truth"][0], first_run=True, day=1, run=1))
    feed(base, d1["odom"], d1["ranges"])
    base.end_run()
    blob = pickle.dumps(base)
    rng = np.random.default_rng(1000 + args.seed)
    later = runs[1:]
    window = 600  # 60 s of driving after the start / the kidnapping

    times = []
    for i in range(args.trials):
        run = later[i % len(later)]
        s = int(rng.integers(0, len(run["t"]) - window))
        loc = pickle.loads(blob)
        loc.rng = np.random.default_rng(i)
        loc.begin_run(Prior(initial_pose=None, day=2, run=1))
        est = feed(loc, run["odom"][s : s + window], run["ranges"][s : s + window])
        err = np.hypot(*(est[:, :2] - run["truth"][s : s + window, :2]).T)
        times.append(settle_time(err))
    times = np.array(times)
    ok = times <= 30.0
    print(
        f"global localization ({args.config}): converged within 30 s in {ok.sum()}/{len(ok)} "
        f"({100 * ok.mean():.0f} %); median {np.median(times):.1f} s, "
        f"times {np.round(times, 1).tolist()}"
    )

    rec_times = []
    for i in range(args.trials):
        run = later[i % len(later)]
        other = later[(i + 1) % len(later)]
        k = int(rng.integers(100, 300))  # kidnapped 10-30 s into the run
        s2 = int(rng.integers(0, len(other["t"]) - window))
        if np.hypot(*(other["truth"][s2, :2] - run["truth"][k, :2])) < 1.0:
            s2 = (s2 + len(other["t"]) // 2) % (len(other["t"]) - window)
        loc = pickle.loads(blob)
        loc.rng = np.random.default_rng(100 + i)
        loc.begin_run(Prior(initial_pose=run["truth"][0], day=2, run=1))
        feed(loc, run["odom"][:k], run["ranges"][:k])
        # Teleport: the scans come from the other place; odometry continues smoothly.
        ob = other["odom"][s2 : s2 + window]
        odo = np.array([se2.compose(run["odom"][k - 1], se2.between(ob[0], o)) for o in ob])
        est = feed(loc, odo, other["ranges"][s2 : s2 + window], t0=0.1 * k)
        err = np.hypot(*(est[:, :2] - other["truth"][s2 : s2 + window, :2]).T)
        rec_times.append(settle_time(err))
    rec_times = np.array(rec_times)
    ok = rec_times <= 30.0
    print(
        f"kidnapping ({args.config}): recovered within 30 s in {ok.sum()}/{len(ok)} "
        f"({100 * ok.mean():.0f} %); median {np.median(rec_times):.1f} s, "
        f"times {np.round(rec_times, 1).tolist()}"
    )
    print(f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
