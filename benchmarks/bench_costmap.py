"""Costmap and ``grid-astar`` costs: ``python benchmarks/bench_costmap.py [--scans N]``.

On a 10 m x 12 m apartment-like map at 5 cm (the prior's walls, plus boxes the prior does not
know), with URG-04LX scans (683 beams) along a drive through it, prints absolute times and
ratios against references measured in the same run:

1. ``Costmap.update`` per scan (obstacle layer: mark + clear all beams) against the existing
   one-scan tracer ``OccupancyGrid.from_scans`` on the same scan, and ``Costmap.clearance()``
   (the inflation: the compiled distance transform of
   :mod:`~dynmap_sim.agent.planning.costmap_kernels`) against ``build_clearance_grid`` of the
   same walls and scipy's ``distance_transform_edt`` of the same layers, and the follower's
   ``window_clearance``;
2. ``grid-astar`` per plan (search + string pulling) against ``grid-dijkstra`` on the same
   grid and queries (with and without its graph built);
3. ``plan_around`` (H&W §6.3 detour around a blocked path) per call.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
from scipy import ndimage

from dynmap_sim import se2
from dynmap_sim.agent.grid import OccupancyGrid
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid, build_clearance_grid
from dynmap_sim.agent.planning.costmap import Costmap, CostmapParams
from dynmap_sim.agent.planning.grid_astar import GridAStar, plan_around
from dynmap_sim.agent.planning.grid_dijkstra import GridDijkstra

# the synthetic geometry the agent tests use (one exact ray caster)
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_mcl import URG as URG_04LX  # noqa: E402
from synthetic_scans import box, raycast  # noqa: E402

#: the URG-04LX of the MCL benchmark, mounted 10 cm ahead of the robot's centre
URG = dataclasses.replace(URG_04LX, mount_pose=(0.1, 0.0, 0.0))
MIN_C, PREF_C = 0.25, 0.32  # robot radius 0.2 m + 5 cm; tour's preferred 0.2 + 0.12


def walls() -> np.ndarray:
    pts = np.array([[0, 0], [10, 0], [10, 12], [0, 12]], float)
    outer = np.concatenate([pts, np.roll(pts, -1, axis=0)], axis=1)
    inner = np.array([[0, 4, 7, 4], [3, 8, 10, 8], [5, 0, 5, 2.5], [7.5, 4, 7.5, 6]], float)
    return np.concatenate([outer, inner])


def clutter() -> np.ndarray:
    return np.concatenate([box(2, 1.5, 2.6, 2.1), box(6, 9.5, 7, 10.5), box(8.5, 5.5, 9.0, 6.0)])


def drive(n: int) -> np.ndarray:
    """Poses along a U-shaped drive through the three rooms."""
    way = np.array([[1, 1], [8.5, 1.0], [8.5, 3.0], [8.5, 6.0], [1.5, 6.0], [1.5, 10.5], [9, 10.5]])
    seg = np.hypot(*np.diff(way, axis=0).T)
    s = np.linspace(0, seg.sum() - 1e-9, n)
    k = np.searchsorted(np.cumsum(seg), s, side="right")
    u = (s - np.concatenate([[0], np.cumsum(seg)])[k]) / seg[k]
    xy = way[k] + u[:, None] * (way[k + 1] - way[k])
    th = np.arctan2(*(way[k + 1] - way[k])[:, ::-1].T)
    return np.c_[xy, th]


def best_of(fn, repeats: int) -> float:
    """Median wall time [s] of ``fn()`` over ``repeats`` calls."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scans", type=int, default=200, help="scans along the drive")
    ap.add_argument("--repeats", type=int, default=7, help="each time is the best of this many")
    args = ap.parse_args()
    segs = walls()
    world = np.concatenate([segs, clutter()])
    poses = drive(args.scans)
    lps = se2.compose(poses, np.broadcast_to(URG.mount_pose, poses.shape))
    scans = [raycast(lp, URG.angles(), world, URG.range_max_m) for lp in lps]

    print("1. costmap (10 m x 12 m + 1 m margin at 5 cm, 683-beam scans)")
    cm = Costmap(CostmapParams(), (0.0, 0.0, 10.0, 12.0))
    cm.set_static_segments(segs)
    cm.update(poses[0], scans[0], URG)  # compiles or loads the kernels
    cm.clear_obstacles()
    t0 = time.perf_counter()
    changed = sum(cm.update(p, r, URG) for p, r in zip(poses, scans, strict=True))
    t_update = (time.perf_counter() - t0) / len(scans)
    t_edt = best_of(lambda: (cm._changed(), cm.clearance()), args.repeats)
    occ = cm.occupied_mask()
    t_scipy = best_of(lambda: ndimage.distance_transform_edt(~occ), args.repeats)
    own = cm.clearance()  # a copy: the costmap's own clearance would be returned as is
    base = ClearanceGrid(own.origin, own.resolution_m, own.clearance_m.copy())
    t_win = best_of(
        lambda: [cm.window_clearance(base, p[:2], 1.6, 0.8) for p in poses[::10]], args.repeats
    ) / len(poses[::10])
    t_trace = best_of(
        lambda: OccupancyGrid.from_scans(poses[:1], scans[0][None], URG), args.repeats
    )
    t_ref = best_of(lambda: build_clearance_grid(segs, np.zeros((0, 3))), args.repeats)
    print(f"   grid {cm.shape[0]} x {cm.shape[1]} cells; {changed}/{len(scans)} scans changed it")
    print(f"   update per scan        {1e3 * t_update:7.2f} ms")
    print(f"   ref: OccupancyGrid.from_scans (1 scan) {1e3 * t_trace:7.2f} ms"
          f"  -> ratio update/ref {t_update / t_trace:.2f}")  # fmt: skip
    print(f"   clearance() (EDT)      {1e3 * t_edt:7.2f} ms")
    print(f"   ref: build_clearance_grid(walls)       {1e3 * t_ref:7.2f} ms"
          f"  -> ratio clearance/ref {t_edt / t_ref:.2f}")  # fmt: skip
    print(f"   ref: scipy distance_transform_edt      {1e3 * t_scipy:7.2f} ms"
          f"  -> ratio clearance/scipy {t_edt / t_scipy:.2f}")  # fmt: skip
    print(f"   window_clearance (1.6 m, 0.8 m) {1e3 * t_win:7.3f} ms")
    print(f"   per scan, update + clearance: {1e3 * (t_update + t_edt):.2f} ms "
          f"({100 * (t_update + t_edt) / 0.1:.1f} % of a 10 Hz scan period)")  # fmt: skip

    print("2. planners on the costmap's clearance (min 0.25 m, preferred 0.32 m)")
    grid = cm.clearance()
    queries = [((1, 1), (1, 11)), ((9, 1), (1, 6)), ((2.3, 3), (8.5, 11)), ((4, 1), (9, 7))]
    queries = [(np.array(a, float), np.array(b, float)) for a, b in queries]
    astar, dijk = GridAStar(MIN_C, PREF_C), GridDijkstra(MIN_C, PREF_C)
    for a, b in queries:  # warm up (numba compiles or loads its cache) and check lengths
        pa, pd = astar.plan(a, b, grid), dijk.plan(a, b, grid)
        la, ld = (float(np.hypot(*np.diff(p, axis=0).T).sum()) for p in (pa, pd))
        print(f"   {a} -> {b}: A* {la:5.2f} m, Dijkstra {ld:5.2f} m ({100 * (la / ld - 1):+.1f} %)")

    def per_plan(planner, fresh: bool = False) -> float:
        def run() -> None:
            for a, b in queries:
                if fresh:
                    planner.__dict__.update(planner.__getstate__())  # drop the cached graph
                planner.plan(a, b, grid)

        return best_of(run, args.repeats) / len(queries)

    t_as = per_plan(astar)
    t_as_fresh = per_plan(astar, fresh=True)
    t_dj = per_plan(dijk)
    t_dj_fresh = per_plan(dijk, fresh=True)
    ms = 1e3
    print(f"   grid-astar               {ms * t_as:7.2f} ms/plan, new grid {ms * t_as_fresh:7.2f}")
    print(f"   ref: grid-dijkstra       {ms * t_dj:7.2f} ms/plan, new grid {ms * t_dj_fresh:7.2f}")
    print(f"   ratio A*/Dijkstra on a new grid: {t_as_fresh / t_dj_fresh:.2f}")

    print("3. plan_around: a block on the path through the middle room")
    path = np.array([[1.5, 6.0], [8.8, 6.0]])
    blocked = Costmap(CostmapParams(), (0.0, 0.0, 10.0, 12.0))
    blocked.set_static_segments(np.concatenate([segs, box(4.0, 5.4, 4.6, 7.2)]))
    bgrid = blocked.clearance()
    here = np.array([2.5, 6.0])
    out = plan_around(path, here, bgrid, astar)
    t_pa = best_of(lambda: plan_around(path, here, bgrid, astar), args.repeats)
    length = float(np.hypot(*np.diff(out, axis=0).T).sum())
    print(f"   detour: {len(out)} vertices, {length:.2f} m; {1e3 * t_pa:.2f} ms/call")


if __name__ == "__main__":
    main()
