"""Time per static-mcl filter update at 500 / 2,000 / 5,000 particles x 60 beams.

One update = motion model + likelihood-field weights + KLD/low-variance resampling + cluster
estimate (everything AMCL does per laser update), in ``tuned``, i.e. with its see-through
walks and the distance filter in the weights. The reference, measured in the same run, is a
straightforward per-particle, per-beam Python loop of the end-point sensor model alone (no
walks) on a subset of particles, scaled to the full count (so the ratio is a lower bound).
The scan is random ranges and the particles partly random poses, so many readings see
through: the walks cost more here than while tracking.

    python benchmarks/bench_mcl.py [--repeats 30]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from dynmap_sim.agent.grid import OccupancyGrid
from dynmap_sim.agent.localization.particle_filter import TUNED, AMCLFilter
from dynmap_sim.types import LaserSpec

URG = LaserSpec(
    name="urg-04lx",
    n_beams=683,
    angle_min_rad=-2.0862,
    angle_increment_rad=2 * math.pi / 1024,
    range_min_m=0.02,
    range_max_m=5.6,
    scan_period_s=0.1,
    time_increment_s=0.0,
)


def room_grid() -> OccupancyGrid:
    pts = np.array([[0, 0], [8, 0], [8, 3], [5, 3], [5, 10], [0, 10]], float)
    walls = np.concatenate([pts, np.roll(pts, -1, axis=0)], axis=1)
    extra = np.array([[2, 2, 2.4, 2], [2.4, 2, 2.4, 2.4], [1, 6, 3, 6], [6.5, 0, 6.5, 0.6]])
    return OccupancyGrid.from_segments(np.concatenate([walls, extra]), free_seed_xy_m=(1, 1))


def reference_weights(f: AMCLFilter, particles: np.ndarray, ranges: np.ndarray) -> list[float]:
    """Per-particle, per-beam Python loop of the likelihood_field_prob model."""
    g = f.grid
    out = []
    r_sel = ranges[f.beams]
    for x, y, th in particles:
        logw = 0.0
        for r, a in zip(r_sel, f.angles, strict=True):
            if not (math.isfinite(r) and r < f.range_max):
                continue
            hx = x + r * math.cos(th + a)
            hy = y + r * math.sin(th + a)
            ix = int((hx - g.origin_xy_m[0]) // g.resolution_m)
            iy = int((hy - g.origin_xy_m[1]) // g.resolution_m)
            h, w = g.shape
            d = g.dist_m[iy, ix] if 0 <= ix < w and 0 <= iy < h else g.max_dist_m
            p = f.lf.z_hit * math.exp(-d * d / (2 * f.lf.sigma_hit**2)) + f.lf.z_rand / f.range_max
            logw += math.log(p)
        out.append(logw)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=30, help="each time is the best of this many")
    args = ap.parse_args()
    grid = room_grid()
    rng = np.random.default_rng(0)
    ranges = rng.uniform(0.5, 4.0, URG.n_beams).astype(np.float32)
    print(f"{'particles':>9} {'update ms':>10} {'sensor ms':>10} {'ref loop ms':>12} {'ratio':>7}")
    for n in (500, 2000, 5000):
        cfg = TUNED.__class__(**{**TUNED.__dict__, "min_particles": n, "max_particles": n})
        f = AMCLFilter(grid, URG, cfg)
        f.init_gaussian([2.0, 1.0, 0.3], np.diag([0.3, 0.3, 0.2]) ** 2, rng)
        odo = np.zeros(3)
        t_upd, t_sens = [], []
        for _ in range(args.repeats):
            f.particles = f.particles[:n] if len(f.particles) >= n else f.random_poses(n, rng)
            f.weights = np.full(len(f.particles), 1.0 / len(f.particles))
            new = odo + [0.25, 0.0, 0.05]
            t0 = time.perf_counter()
            f.predict(odo, new, rng)
            t1 = time.perf_counter()
            f.correct(ranges)
            t2 = time.perf_counter()
            f.resample(rng)
            f.estimate()
            t3 = time.perf_counter()
            odo = new
            t_upd.append(t3 - t0)
            t_sens.append(t2 - t1)
        sub = f.random_poses(100, rng)
        t0 = time.perf_counter()
        reference_weights(f, sub, ranges)
        t_ref = (time.perf_counter() - t0) * n / len(sub)
        upd = float(np.median(t_upd)) * 1e3
        sens = float(np.median(t_sens)) * 1e3
        print(f"{n:>9} {upd:>10.2f} {sens:>10.2f} {t_ref * 1e3:>12.1f} {t_ref * 1e3 / upd:>6.0f}x")
    print(f"beams per update: {len(AMCLFilter(grid, URG, TUNED).beams)} of {URG.n_beams}")


if __name__ == "__main__":
    main()
