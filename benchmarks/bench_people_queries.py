"""The people's goal-choice queries (:class:`~dynmap_sim.world.people.obstacles.Obstacles`,
compiled loops): time per call on the shipped worlds.

On each shipped world (the lab's lunch run, the apartment's day 15), from a fixed draw of
candidate points in the world's bounds, as goal choice asks them: ``free_mask`` of 32 points
(one speculative batch of four tries of eight points) and ``visible_many`` from one point to
4 goals. Each figure is the best of ``--rounds`` rounds of ``--calls`` calls.

    python benchmarks/bench_people_queries.py [--calls 500] [--rounds 5]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from dynmap_sim.world import World, load_world, resolve_world_path

CASES = (("lab", 1, 2), ("apartment", 15, 1))


def best_us(fn: Callable[[], Any], calls: int, rounds: int) -> float:
    """The best round's time per call [us] of ``calls`` calls of ``fn``."""
    best = float("inf")
    for _ in range(rounds):
        t = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - t) / calls * 1e6)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=500, help="calls per timed round (>= 1)")
    ap.add_argument("--rounds", type=int, default=5, help="rounds (>= 1), the best kept")
    args = ap.parse_args()
    if args.calls < 1 or args.rounds < 1:
        ap.error("--calls and --rounds must be >= 1")
    rng = np.random.default_rng(0)
    print("| world | query | us per call |")
    print("|---|---|---|")
    for name, day, run in CASES:
        world = World(load_world(resolve_world_path(name)), seed=0)
        world.reset(day, run)
        obs = world._forces.obstacles
        lo, hi = obs.segments[:, :2].min(axis=0), obs.segments[:, :2].max(axis=0)
        pts = rng.uniform(lo, hi, (32, 2))
        frm, goals = pts[0], pts[1:5]
        for label, fn in (
            ("free_mask, 32 points", lambda p=pts, o=obs: o.free_mask(p, 0.25)),
            ("visible_many, 4 goals", lambda a=frm, g=goals, o=obs: o.visible_many(a, g)),
        ):
            print(f"| {name} | {label} | {best_us(fn, args.calls, args.rounds):.1f} |")


if __name__ == "__main__":
    main()
