"""Cost of the navigation stack per scan: ``python benchmarks/bench_navigation.py [--steps N]``.

The apartment (people off), the stack steering on a lock-stepped ``dynamic-map`` localizer
(Biber & Duckett) through :class:`~dynmap_sim.agent.navigation.policy.NavigationPolicy`: day 1
is the localizer's first run (it maps with its static SLAM front end), day 2 localizes on the
dynamic map learned from it. Per run it prints the mean time per scan of the localizer's
update (the reference, measured in the same run on the same scans) and of the stack's
``step`` (costmap update, route memory, planning, control, recovery, collision monitor), and
their ratio; issue 15's target is stack <= 20 % of the lock-stepped dynamic-map. The means
leave out each run's first scan, whose time (printed apart) includes one-off costs: loading
the numba kernels of both from numba's on-disk cache (or compiling them), ~0.1-1 s a process.
A second line gives the same from the thread's CPU time (``time.thread_time``): on a shared
machine it leaves out the time the process waited for a core, which the wall-clock times
(the target's measure) include. After the runs (``--days N``, days 1..N), a last line gives
the aggregate over all of them: the total time of the stack over the total time of
dynamic-map (first scans left out, as above), wall clock and thread CPU time.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from dynmap_sim.agent.localization.localizer import make_localizer
from dynmap_sim.agent.navigation.policy import NavigationPolicy
from dynmap_sim.agent.navigation.stack import NavigationStack
from dynmap_sim.env import DynMapEnv


class _Timed:
    """A localizer or a stack whose ``method`` calls are timed."""

    def __init__(self, inner, method: str) -> None:
        self.inner = inner
        self.method = method
        self.times: list[float] = []
        self.cpu_times: list[float] = []

    def __getattr__(self, name):
        attr = getattr(self.inner, name)
        if name != self.method:
            return attr

        def timed(*args, **kwargs):
            t0, c0 = time.perf_counter(), time.thread_time()
            out = attr(*args, **kwargs)
            self.times.append(time.perf_counter() - t0)
            self.cpu_times.append(time.thread_time() - c0)
            return out

        return timed


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=2000, help="scans per run at most")
    ap.add_argument("--days", type=int, default=2, help="runs (days 1..N)")
    args = ap.parse_args()
    env = DynMapEnv("apartment", people=False)
    u = env.unwrapped
    loc = make_localizer("dynamic-map", laser=u.laser_spec, rng=np.random.default_rng(0))
    stack = NavigationStack(u.laser_spec, u.robot_radius_m)
    policy = NavigationPolicy(loc, stack, use_localizer_map=False)
    t_loc, t_stack = _Timed(loc, "update"), _Timed(stack, "step")
    policy.localizer, policy.stack = t_loc, t_stack  # type: ignore[assignment]
    print("navigation stack vs lock-stepped dynamic-map, apartment, per scan (mean)")
    totals = np.zeros(4)  # seconds: dynamic-map, stack (wall); dynamic-map, stack (CPU)
    for day in range(1, args.days + 1):
        obs, info = env.reset(seed=0, options={"day": day})
        policy.reset(u.world_facts().prior(day))  # what a scenario grants
        for timed in (t_loc, t_stack):
            timed.times.clear()
            timed.cpu_times.clear()
        err, n, done, term = [], 0, False, False
        while n < args.steps and not done:
            obs, _, term, trunc, info = env.step(policy.act(obs))
            err.append(np.hypot(*(policy.estimate.mean[:2] - info["truth"]["pose"][:2])))
            n += 1
            done = term or trunc or policy.done
        policy.end_run()
        loc.end_day()
        a, b = 1e3 * np.mean(t_loc.times[1:]), 1e3 * np.mean(t_stack.times[1:])
        print(
            f"day {day}: {n} scans, dynamic-map {a:.2f} ms, stack {b:.2f} ms "
            f"(p95 {1e3 * np.percentile(t_stack.times[1:], 95):.2f} ms), stack/dynamic-map "
            f"{b / a:.1%} (target <= 20 %); goal reached {term}, replans {stack.replans}, "
            f"mean error {np.mean(err):.3f} m; first scan: dynamic-map "
            f"{1e3 * t_loc.times[0]:.0f} ms, stack {1e3 * t_stack.times[0]:.0f} ms"
        )
        a, b = 1e3 * np.mean(t_loc.cpu_times[1:]), 1e3 * np.mean(t_stack.cpu_times[1:])
        print(f"       thread CPU time: dynamic-map {a:.2f} ms, stack {b:.2f} ms, {b / a:.1%}")
        timings = (t_loc.times, t_stack.times, t_loc.cpu_times, t_stack.cpu_times)
        totals += [sum(t[1:]) for t in timings]
    loc_s, stack_s, loc_cpu_s, stack_cpu_s = totals.tolist()
    runs = "day 1" if args.days == 1 else f"days 1-{args.days}"
    print(
        f"{runs}, all scans: stack / dynamic-map {stack_s / loc_s:.1%} (total {stack_s:.2f} s / "
        f"{loc_s:.2f} s), thread CPU time {stack_cpu_s / loc_cpu_s:.1%} "
        f"({stack_cpu_s:.2f} s / {loc_cpu_s:.2f} s)"
    )


if __name__ == "__main__":
    main()
