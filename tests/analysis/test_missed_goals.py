"""Runs that missed their goal are named in the headline and summary, with the reason."""

import numpy as np

from dynmap_sim.analysis.headline import results_headline
from dynmap_sim.analysis.navigation import missed_goal_lines
from dynmap_sim.experiments.results import LocalizerDiagnostics, ResultsDB, RunRecord
from dynmap_sim.metrics import NavRunSummary

STUCK = (
    "stuck for 40 s near (2.5, 1.0) on the way to the goal: no progress after 3 recoveries (stuck)"
)


def nav(reached: bool, gave_up: bool) -> NavRunSummary:
    return NavRunSummary(
        goal_reached=int(reached),
        time_s=60.0,
        path_length_m=5.0,
        shortest_path_m=5.0,
        spl=1.0 if reached else 0.0,
        collisions=0,
        near_misses=0,
        min_clearance_m=0.3,
        replans=0,
        recoveries=0 if reached else 3,
        stuck_s=0.0 if reached else 40.0,
        gave_up=int(gave_up),
    )


def record(
    day: int, run: int, reached: bool, events: list, progress: float = 1.0, gave_up: bool = False
) -> RunRecord:
    n = 5
    truth = np.stack([0.1 * np.arange(n), np.zeros(n), np.zeros(n)], axis=1)
    return RunRecord(
        day=day,
        run=run,
        date="2026-01-05",
        start_s=0.0,
        t_s=0.1 * np.arange(n),
        truth=truth,
        collision=np.zeros(n, bool),
        estimates=truth[None].copy(),
        cov_diag=np.full((1, n, 3), 0.01),
        confusion=np.zeros((1, 4, 4), np.int64),
        terminated=True,
        route_progress=progress,
        skipped_waypoints=0,
        wall_s=0.1,
        events=events,
        diagnostics=[LocalizerDiagnostics()],
        nav=nav(reached, gave_up),
    )


def test_a_run_that_missed_its_goal_is_named_with_the_reason(tmp_path):
    meta = {"first_date": "2026-01-05", "days": [1, 3], "seed": 0, "experiment_hash": "h"}
    with ResultsDB.create(tmp_path, meta=meta, localizers=[("a", "odometry", {})]) as db:
        db.write_run(
            record(1, 1, True, [(4, 0.4, "goal", "0.1 m from the goal")]), [], True, None, "h", 0
        )
        stuck = record(3, 2, False, [(4, 0.4, "unreachable", STUCK)], gave_up=True)
        db.write_run(stuck, [], True, None, "h", 0)
        db.write_run(record(3, 3, False, [], progress=0.55), [], True, None, "h", 0)
        lines = missed_goal_lines(db)
    assert lines == [
        f"day 3 run 2: goal not reached: {STUCK}",
        "day 3 run 3: goal not reached: the driver stopped after 60 s with 55 % of the route "
        "followed",
    ]
    headline = results_headline(tmp_path)
    assert any("goal reached in 1 of 3 runs" in line for line in headline)
    assert [line.strip() for line in headline[-2:]] == lines
