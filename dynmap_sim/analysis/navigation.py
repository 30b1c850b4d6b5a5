"""The navigation part of a report: ``nav_per_day.csv``, the measures per day, the route memory.

Every number comes from the store's ``nav_runs`` rows (:func:`dynmap_sim.metrics.nav_run_summary`,
measured against the truth) and is summarized per day by
:func:`dynmap_sim.metrics.nav_day_summary`. The route memory figure draws what an
``autonomous`` driver handed over after a run (cf. H&W Fig. 8).
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.metrics import NavDaySummary, NavRunSummary, nav_day_summary

#: Columns of ``nav_per_day.csv``, in order.
NAV_PER_DAY_COLUMNS = (
    "day",
    "runs",
    "goal_reached_fraction",
    "collisions",
    "near_misses",
    "min_clearance_m",
    "replans",
    "recoveries",
    "path_length_m",
    "spl",
    "time_s",
    "stuck_s",
)


def nav_per_day(db: ResultsDB) -> list[tuple[int, NavDaySummary]]:
    """``(day, NavDaySummary)`` for every day with stored navigation measures."""
    by_day: dict[int, list[NavRunSummary]] = {}
    for day, _, s in db.nav_runs():
        by_day.setdefault(day, []).append(s)
    return [(day, nav_day_summary(runs)) for day, runs in sorted(by_day.items())]


def _cell(v: Any) -> str:
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.6f}"
    return str(v)


def write_nav_per_day_csv(rows: list[tuple[int, NavDaySummary]], path: Path) -> Path:
    """``nav_per_day.csv`` (:data:`NAV_PER_DAY_COLUMNS`)."""
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(NAV_PER_DAY_COLUMNS)
        for day, s in rows:
            d = s.to_dict()
            w.writerow([day, *(_cell(d[c]) for c in NAV_PER_DAY_COLUMNS[1:])])
    return path


def goals_reached_line(db: ResultsDB) -> str:
    """``goal reached in R of N runs``, and how many runs the scenario's ``driver.max_run_s``
    stopped short of the goal (a time-limited smoke test is not a navigation failure)."""
    runs = [s for _, _, s in db.nav_runs()]
    reached = sum(s.goal_reached for s in runs)
    line = f"goal reached in {reached} of {len(runs)} runs"
    max_run_s = (db.meta().get("scenario") or {}).get("driver", {}).get("max_run_s")
    if max_run_s is not None:
        stopped = sum(not s.goal_reached and s.time_s >= max_run_s - 1e-9 for s in runs)
        if stopped:
            line += f" ({stopped} stopped by the scenario's max_run_s = {max_run_s:g} s)"
    return line


#: At most this many runs that missed their goal are named one by one (the rest counted).
MAX_MISSED_LINES = 5


def missed_goal_lines(db: ResultsDB) -> list[str]:
    """One sentence per run that did not reach its goal, saying why in words: the driver's
    ``unreachable`` event (the navigation stack's cause: no way, lost, stuck, with its
    figures), else a give-up or the driver stopping short of the route's end (the share of
    the route it followed, by the env); not the runs the scenario's ``driver.max_run_s``
    stopped (:func:`goals_reached_line` counts them: a smoke test's time limit). At most
    :data:`MAX_MISSED_LINES` runs, then how many more."""
    why = {
        (int(d), int(r)): str(detail)
        for d, r, detail in db.query(
            "SELECT day, run, detail FROM events WHERE kind = 'unreachable' ORDER BY rowid"
        )
    }
    progress = {
        (int(d), int(r)): float(p)
        for d, r, p in db.query("SELECT day, run, route_progress FROM runs")
    }
    max_run_s = (db.meta().get("scenario") or {}).get("driver", {}).get("max_run_s")
    lines = []
    limit = math.inf if max_run_s is None else max_run_s - 1e-9
    missed = [  # not the runs the time limit stopped (said in goals_reached_line)
        (d, r, s)
        for d, r, s in db.nav_runs()
        if not s.goal_reached and ((d, r) in why or s.time_s < limit)
    ]
    for day, run, s in missed[:MAX_MISSED_LINES]:
        if (day, run) in why:
            reason = why[(day, run)]
        elif s.gave_up:
            reason = f"the driver gave up after {s.time_s:.0f} s"
        else:  # the driver stopped where it took the goal to be
            share = progress.get((day, run), math.nan)
            reason = (
                f"the driver stopped after {s.time_s:.0f} s with {100.0 * share:.0f} % of "
                "the route followed"
            )
        lines.append(f"day {day} run {run}: goal not reached: {reason}")
    if len(missed) > MAX_MISSED_LINES:
        lines.append(f"and {len(missed) - MAX_MISSED_LINES} more runs without the goal")
    return lines


def nav_summary_lines(db: ResultsDB, rows: list[tuple[int, NavDaySummary]]) -> list[str]:
    """The ``summary.md`` section: totals over the experiment."""
    runs = [s for _, _, s in db.nav_runs()]
    spl = [s.spl for s in runs if math.isfinite(s.spl)]
    clear = [s.min_clearance_m for s in runs if math.isfinite(s.min_clearance_m)]
    return [
        "## Navigation (measured against the truth; per day in nav_per_day.csv)",
        "",
        f"- {goals_reached_line(db)}" + (f"; SPL {np.mean(spl):.3f}" if spl else ""),
        f"- collisions {sum(s.collisions for s in runs)}, near misses with people "
        f"{sum(s.near_misses for s in runs)}, smallest clearance "
        + (f"{min(clear):.3f} m" if clear else "n/a"),
        f"- replans {sum(s.replans for s in runs)}, recoveries {sum(s.recoveries for s in runs)}"
        f", stuck {sum(s.stuck_s for s in runs):.1f} s, gave up in {sum(s.gave_up for s in runs)} "
        "runs",
        f"- driven {sum(s.path_length_m for s in runs):.1f} m in "
        f"{sum(s.time_s for s in runs) / 60.0:.1f} min of robot time over {len(rows)} days",
        *(f"- {line}" for line in missed_goal_lines(db)),
    ]


def plot_nav_per_day(rows: list[tuple[int, NavDaySummary]], path: Path) -> Path:
    """Goal reached, SPL, collisions, near misses, replans and recoveries per day."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    days = np.array([d for d, _ in rows], dtype=float)
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(8, 5), sharex=True)
    a1.bar(days - 0.2, [s.goal_reached_fraction for _, s in rows], 0.4, label="goal reached")
    a1.bar(days + 0.2, [s.spl for _, s in rows], 0.4, label="SPL")
    a1.set_ylim(0, 1.05)
    a1.set_ylabel("fraction of runs / SPL")
    a1.legend(fontsize="small", loc="lower left")
    for key, marker in (
        ("collisions", "x"),
        ("near_misses", "o"),
        ("replans", "^"),
        ("recoveries", "s"),
    ):
        a2.plot(days, [getattr(s, key) for _, s in rows], marker, ls="-", lw=0.8, label=key)
    a2.set_ylabel("count per day")
    a2.set_xlabel("day")
    a2.xaxis.set_major_locator(MaxNLocator(integer=True))
    a2.legend(fontsize="small", ncol=4, loc="upper left")
    a1.set_title("Navigation per day (measured against the truth)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_route_memory(db: ResultsDB, path: Path, day: int | None = None) -> Path | None:
    """The driver's route memory after the last run of ``day`` (default: the last day with
    one) over that run's obstacles: the prior route, learned routes, blocked segments
    (cf. H&W Fig. 8). None when no run left a route memory."""
    import matplotlib.pyplot as plt

    mems = db.driver_artifacts("route_memory.json")
    if day is not None:
        mems = [m for m in mems if m[0] == day]
    if not mems:
        return None
    d, r, blob = mems[-1]
    mem = json.loads(blob.decode())
    fig, ax = plt.subplots(figsize=(6, 6))
    g = db.geometry(d, r)
    if g is not None:
        seg = g[0]
        ax.plot(np.stack([seg[:, 0], seg[:, 2]]), np.stack([seg[:, 1], seg[:, 3]]), "k", lw=0.8)
    blocked = {tuple(e) for e in mem["blocked"]}
    for route in mem["routes"]:
        xy = np.array([[w["x_m"], w["y_m"]] for w in route["waypoints"]]).reshape(-1, 2)
        style = (
            {"color": "tab:blue", "lw": 2} if route["prior"] else {"color": "tab:orange", "lw": 2}
        )
        ax.plot(xy[:, 0], xy[:, 1], **style)
        ax.plot(xy[:, 0], xy[:, 1], ".", color=style["color"], ms=4)
        ids = route["ids"]
        for j in range(1, len(ids)):
            if (ids[j - 1], ids[j]) in blocked:
                ax.plot(xy[j - 1 : j + 1, 0], xy[j - 1 : j + 1, 1], color="red", lw=3)
    ax.plot([], [], color="tab:blue", lw=2, label="prior route")
    ax.plot([], [], color="tab:orange", lw=2, label="learned routes")
    ax.plot([], [], color="red", lw=3, label="blocked")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"Route memory after day {d} run {r} (cf. H&W Fig. 8)", fontsize="small")
    ax.legend(fontsize="small", loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
