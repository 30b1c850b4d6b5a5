"""The people's goal-choice queries: compiled (``world/people/obstacles_numba.py``) against
numpy's :class:`~dynmap_sim.world.people.obstacles.Obstacles`, measured in the same run.

On each shipped world (the lab's lunch run, the apartment's day 15), from a fixed draw of
candidate points in the world's bounds, as goal choice asks them: ``free_mask`` of 32 points
(one speculative batch of four tries of eight points) and ``visible_many`` from one point to
4 goals. Each figure is the best of ``--rounds`` rounds of ``--calls`` calls, numpy and
compiled alternating; the ratio is numpy's time over the kernels'. Every round also checks
that both answer the same booleans. Needs numba (the ``fast`` extra).

    python benchmarks/bench_people_queries.py [--calls 500] [--rounds 5]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from dynmap_sim.jit import numba_available
from dynmap_sim.numpy_complex import numpy_complex_mode
from dynmap_sim.world import World, load_world, resolve_world_path
from dynmap_sim.world.people.obstacles_numba import queries

CASES = (("lab", 1, 2), ("apartment", 15, 1))


def best_us(fn: Callable[[], Any], calls: int) -> float:
    """Time per call [us] of ``calls`` calls of ``fn``."""
    t = time.perf_counter()
    for _ in range(calls):
        fn()
    return (time.perf_counter() - t) / calls * 1e6


def compare(name: str, label: str, ask: Callable[[Any], Any], obs: Any, fast: Any,
            rounds: int, calls: int) -> None:  # fmt: skip
    """Print one row: the best round of numpy's and the kernels' ``ask``, alternating."""
    times: dict[str, list[float]] = {"numpy": [], "compiled": []}
    for _ in range(rounds):
        if not np.array_equal(ask(obs), ask(fast)):
            sys.exit(f"{name}: {label}: the compiled answer differs from numpy's")
        times["numpy"].append(best_us(lambda: ask(obs), calls))
        times["compiled"].append(best_us(lambda: ask(fast), calls))
    t_np, t_c = min(times["numpy"]), min(times["compiled"])
    print(f"| {name} | {label} | {t_np:.1f} | {t_c:.1f} | {t_np / t_c:.1f}x |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--calls", type=int, default=500, help="calls per timed round (>= 1)")
    ap.add_argument("--rounds", type=int, default=5, help="alternating rounds (>= 1)")
    args = ap.parse_args()
    if args.calls < 1 or args.rounds < 1:
        ap.error("--calls and --rounds must be >= 1")
    if not numba_available():
        sys.exit('needs numba: pip install -e ".[fast]"')
    if numpy_complex_mode() is None:
        sys.exit("numpy's complex loops match neither mode here: the people keep numpy's queries")
    rng = np.random.default_rng(0)
    print("| world | query | numpy [us] | compiled [us] | ratio |")
    print("|---|---|---|---|---|")
    for name, day, run in CASES:
        world = World(load_world(resolve_world_path(name)), seed=0)
        world.reset(day, run)
        obs = world._forces.obstacles
        lo, hi = obs.segments[:, :2].min(axis=0), obs.segments[:, :2].max(axis=0)
        pts = rng.uniform(lo, hi, (32, 2))
        fast, frm, goals = queries(obs), pts[0], pts[1:5]
        compare(name, "free_mask, 32 points", lambda q, p=pts: q.free_mask(p, 0.25), obs, fast,
                args.rounds, args.calls)  # fmt: skip
        compare(name, "visible_many, 4 goals", lambda q, a=frm, g=goals: q.visible_many(a, g),
                obs, fast, args.rounds, args.calls)  # fmt: skip


if __name__ == "__main__":
    main()
