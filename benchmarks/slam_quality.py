"""Quality of the first-run static SLAM on the shipped worlds, against the simulator's truth.

For each world, drives day 1 run 1 with the tour driver, runs
:class:`~dynmap_sim.agent.mapping.first_run.FirstRunMapper` on the recorded stream and prints

* the online (front-end) position error, mean and max;
* the ATE (RMSE, no alignment: the map frame is the prior's frame) of the optimized trajectory
  and of dead reckoning, for comparison;
* map accuracy: the fraction of occupied 5 cm cells whose centre lies within 5 cm of the
  true static geometry (segments and round objects of that run, people excluded);
* timing (front end per scan, back end);
* the correlative seed: how many scans it seeded, how many of those ICP from the odometry
  prediction refuted, and the front end's step error (against the truth's step) on the
  scans where the seed's result was kept and on the others.

    python benchmarks/slam_quality.py [--worlds apartment lab] [--seed 0]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
from mcl_global_kidnap import record  # same folder (benchmarks/)

from dynmap_sim import se2
from dynmap_sim.agent.mapping.first_run import FirstRunConfig, FirstRunMapper
from dynmap_sim.experiments.runner import make_env
from dynmap_sim.experiments.scenario import parse_scenario
from dynmap_sim.types import BeamClass, Odometry, Scan


def distance_to_geometry(points: np.ndarray, segs: np.ndarray, circles: np.ndarray) -> np.ndarray:
    """Distance [m] from points ``(N, 2)`` to the nearest segment or circle perimeter."""
    out = np.full(len(points), np.inf)
    for start in range(0, len(points), 2000):
        p = points[start : start + 2000, None, :]
        a, b = segs[None, :, :2], segs[None, :, 2:]
        ab = b - a
        t = np.clip(np.sum((p - a) * ab, -1) / np.maximum(np.sum(ab * ab, -1), 1e-12), 0, 1)
        d = np.min(np.linalg.norm(p - (a + t[..., None] * ab), axis=-1), axis=1)
        if len(circles):
            dc = np.abs(np.linalg.norm(p - circles[None, :, :2], axis=-1) - circles[None, :, 2])
            d = np.minimum(d, dc.min(axis=1))
        out[start : start + 2000] = d
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", nargs="+", default=["apartment", "lab"], help="shipped worlds")
    ap.add_argument("--seed", type=int, default=0, help="world and noise seed")
    ap.add_argument(
        "--mapper-params",
        type=json.loads,
        default={},
        help="first-run mapper parameters as JSON, e.g. '{\"seed_window\": [0, 0]}' (seed off)",
    )
    args = ap.parse_args()
    for world in args.worlds:
        laser, runs = record(world, 1, args.seed)
        run = runs[0]
        env = make_env(
            parse_scenario(
                {"name": "g", "world": world, "days": [1, 1], "localizers": [{"name": "odometry"}]}
            )
        )
        env.reset(seed=args.seed, options={"day": 1, "run": 1})
        geom = env.unwrapped.world.geometry
        segs = np.asarray(geom.segments, float)
        keep = np.asarray(geom.circle_class) != int(BeamClass.PERSON)
        circles = np.asarray(geom.circles, float)[keep]
        truth = run["truth"]
        mapper = FirstRunMapper(laser, truth[0], FirstRunConfig.from_params(**args.mapper_params))
        fe = mapper.slam
        est = np.empty_like(truth)
        kept = np.zeros(len(truth), dtype=bool)  # the seed's ICP result was kept
        t0 = time.perf_counter()
        for k, (o, r) in enumerate(zip(run["odom"], run["ranges"], strict=True)):
            n0 = fe.n_seeded - fe.n_seed_refuted
            est[k] = mapper.update(Odometry(o, 0.1 * k), Scan(r, 0.1 * k)).mean
            kept[k] = fe.n_seeded - fe.n_seed_refuted > n0
        t1 = time.perf_counter()
        # The front end's step error against the truth's step, on scans where the seed's
        # result was kept and on the others (where does the seed help or hurt).
        steps = [se2.between(est[k - 1], est[k]) for k in range(1, len(truth))]
        true_steps = [se2.between(truth[k - 1], truth[k]) for k in range(1, len(truth))]
        d_step = np.array(steps) - np.array(true_steps)
        e_step = np.hypot(d_step[:, 0], d_step[:, 1])
        a_step = np.degrees(np.abs(np.angle(np.exp(1j * d_step[:, 2]))))
        kept = kept[1:]
        smap = mapper.finish()
        t2 = time.perf_counter()
        e_on = np.hypot(*(est[:, :2] - truth[:, :2]).T)
        e_opt = np.hypot(*(smap.trajectory[:, :2] - truth[:, :2]).T)
        dead = np.array(
            [se2.compose(truth[0], se2.between(run["odom"][0], o)) for o in run["odom"]]
        )
        e_dead = np.hypot(*(dead[:, :2] - truth[:, :2]).T)
        occ = smap.grid.occupied_points()
        d = distance_to_geometry(occ, segs, circles)
        print(
            f"{world}: {len(truth)} scans, {len(smap.keyframes)} keyframes, "
            f"{smap.n_loop_closures} loop closures\n"
            f"  online error mean {e_on.mean():.3f} m max {e_on.max():.3f} m\n"
            f"  ATE (RMSE) optimized {np.sqrt(np.mean(e_opt**2)):.3f} m (max {e_opt.max():.3f}); "
            f"dead reckoning {np.sqrt(np.mean(e_dead**2)):.3f} m\n"
            f"  map: {len(occ)} occupied cells, {100 * np.mean(d <= 0.05):.1f} % within 5 cm "
            f"of true geometry (median {100 * np.median(d):.1f} cm)\n"
            f"  time: front end {1000 * (t1 - t0) / len(truth):.1f} ms/scan, "
            f"back end {t2 - t1:.1f} s",
            flush=True,
        )
        line = (
            f"  seed: {fe.n_seeded} scans seeded, {fe.n_seed_refuted} refuted by ICP from the "
            f"prediction; step error on the other scans {1000 * e_step[~kept].mean():.1f} mm "
            f"{a_step[~kept].mean():.2f} deg"
        )
        if kept.any():
            line += (
                f", on the {kept.sum()} kept {1000 * e_step[kept].mean():.1f} mm "
                f"{a_step[kept].mean():.2f} deg (max {1000 * e_step[kept].max():.0f} mm)"
            )
        print(line, flush=True)


if __name__ == "__main__":
    main()
