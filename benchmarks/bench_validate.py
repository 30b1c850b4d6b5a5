"""Validation speed against the number of objects: the lab world with 100, 1,000 and 10,000
objects (small boxes on free floor, a tenth of them moved once by the schedule, in groups of
ten that a ``remove`` event each takes away).

For each size: the time ``parse_world`` takes (structure and meaning), the time per object,
and the ratio of that per-object time to the 100-object one (about 1 where validation grows
with the objects, N / 100 where it grows with their square). Reference, measured in the same
run on the same worlds: the objects-inside-walls check done the brute-force way (every pose
against every wall piece, no spatial index), whose time grows with objects x walls. Each
figure is the best of ``--repeat`` runs (other processes only add time).

    python benchmarks/bench_validate.py [--sizes 100,1000,10000] [--repeat 3] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import time
import tomllib
from pathlib import Path

import numpy as np

from dynmap_sim.world.loader import WORLDS_DIR, parse_world
from dynmap_sim.world.polygons import point_segment_distance, sat_separation, transform
from dynmap_sim.world.schedule import wall_pieces


def lab_with(n: int, seed: int = 0) -> dict:
    """The lab world's file dict with ``n`` extra 0.2 m boxes at least 0.4 m from every wall."""
    data = tomllib.loads((WORLDS_DIR / "lab.toml").read_text(encoding="utf-8"))
    segs = np.array(
        [
            [*a, *b]
            for w in data["walls"]
            for a, b in zip(w["points"], w["points"][1:], strict=False)
        ],
        dtype=np.float64,
    )
    x0, y0, x1, y1 = data["bounds"]
    rng = np.random.default_rng(seed)
    pts = np.zeros((0, 2))
    while len(pts) < n:
        cand = rng.uniform([x0 + 1, y0 + 1], [x1 - 1, y1 - 1], size=(2 * n, 2))
        cand = cand[point_segment_distance(cand, segs).min(axis=1) > 0.4]
        pts = np.concatenate([pts, cand])[:n]
    for i, (x, y) in enumerate(pts):
        data["objects"].append(
            {
                "id": f"bench_box_{i}",
                "kind": "furniture",
                "group": f"bench_group_{i // 10}",
                "size": [0.2, 0.2],
                "pose": [round(float(x), 3), round(float(y), 3), 0.0],
            }
        )
    for i in range(0, n, 10):
        day = 2 + (i // 10) % 20
        data["schedule"].append({"action": "remove", "group": f"bench_group_{i // 10}", "at": day})
        x, y = pts[i]
        data["schedule"].append(
            {
                "action": "move",
                "target": f"bench_box_{i}",
                "at": day,
                "pose": [round(float(x), 3), round(float(y), 3), 0.7854],
            }
        )
    return data


def brute_force_walls(data: dict) -> float:
    """Seconds for the reference: every object pose tested against every wall piece by SAT."""
    spec = parse_world(data)
    walls = wall_pieces(spec)
    t0 = time.perf_counter()
    for o in spec.objects:
        poly = transform(o.local_vertices(), o.pose)
        for _, wp in walls:
            if sat_separation(poly, wp) < -0.01:
                break
    return time.perf_counter() - t0


def _best(fn, repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="100,1000,10000")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    rows = []
    for n in (int(s) for s in args.sizes.split(",")):
        data = lab_with(n)
        t = _best(lambda d=data: parse_world(d), args.repeat)
        ref = min(brute_force_walls(data) for _ in range(args.repeat))
        rows.append({"objects": n, "validate_s": t, "per_object_us": 1e6 * t / n, "ref_s": ref})
    base = rows[0]["per_object_us"]
    print(f"{'objects':>8} {'validate s':>11} {'us/object':>10} {'ratio':>6} {'ref walls s':>12}")
    for r in rows:
        r["ratio"] = r["per_object_us"] / base
        print(
            f"{r['objects']:>8} {r['validate_s']:>11.3f} {r['per_object_us']:>10.1f} "
            f"{r['ratio']:>6.2f} {r['ref_s']:>12.3f}"
        )
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
