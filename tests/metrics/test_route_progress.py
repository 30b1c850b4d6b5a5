"""Truth-side route progress with detours (metrics.navigation.route_progress_with_detours)."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim.metrics import goal_reached, route_progress_with_detours

# A 40 m loop: east along y=0, north, west along y=10, south back to the start.
LOOP = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0], [0.0, 0.0]])


def _walk(*corners: tuple[float, float], step_m: float = 0.1) -> np.ndarray:
    """A track through ``corners`` with a point every ``step_m``."""
    pts = [np.asarray(corners[0], float)]
    for a, b in zip(corners[:-1], corners[1:], strict=True):
        a, b = np.asarray(a, float), np.asarray(b, float)
        n = max(int(np.ceil(np.hypot(*(b - a)) / step_m)), 1)
        pts += [a + (b - a) * k / n for k in range(1, n + 1)]
    return np.array(pts)


def test_the_whole_loop_driven_is_all_progress():
    track = _walk((0, 0), (10, 0), (10, 10), (0, 10), (0, 0))
    assert route_progress_with_detours(track, LOOP) == pytest.approx(1.0)


def test_standing_at_a_loops_start_is_no_progress_although_its_end_is_there():
    track = np.zeros((50, 2)) + [0.05, 0.02]
    assert route_progress_with_detours(track, LOOP) < 0.01  # its 5 cm along the first leg
    assert not goal_reached(False, 0.0, 0.05, track, LOOP)


def test_a_detour_round_a_block_counts_and_rejoins_ahead():
    """East side blocked at (10, 3..7): the robot leaves the route at (10, 2), goes round
    1.5 m east of it and rejoins at (10, 8); the env's tracker (2 m a step, 3 segments) would
    stall, this counts the skipped stretch as followed."""
    round_the_block = [(10, 2), (11.5, 3), (11.5, 7), (10, 8)]
    track = _walk((0, 0), (10, 0), *round_the_block, (10, 10), (0, 10), (0, 0))
    assert route_progress_with_detours(track, LOOP) == pytest.approx(1.0)
    assert goal_reached(False, 0.3, 0.0, track, LOOP)


def test_a_rejoin_may_not_skip_more_than_the_allowed_share():
    """Cutting straight across the loop from (5, 0) to (5, 10) skips 15 m of 40 (> 30 %)."""
    track = _walk((0, 0), (5, 0), (5, 10), (0, 10), (0, 0))
    progress = route_progress_with_detours(track, LOOP)
    assert progress == pytest.approx(5.0 / 40.0, abs=0.01)
    assert not goal_reached(False, progress, 0.0, track, LOOP)
    assert route_progress_with_detours(track, LOOP, max_skip_fraction=0.5) == pytest.approx(1.0)


def test_a_corridor_driven_out_and_back_stays_on_the_pass_being_driven():
    """Out along y=0 to x=8 and back on the same line: backing up 0.3 m on the way out
    does not jump to the way back, whose positions lie 4-16 m ahead (within the skip)."""
    route = np.array([[0.0, 0.0], [8.0, 0.0], [8.0, 0.2], [0.0, 0.2]])
    track = _walk((0, 0), (5, 0), (4.7, 0), (5.5, 0))
    assert route_progress_with_detours(track, route) == pytest.approx(5.5 / 16.2, abs=0.01)


def test_the_goal_needs_the_end_within_the_tolerance():
    track = _walk((0, 0), (10, 0), (10, 10), (0, 10), (0, 2))
    assert not goal_reached(False, 0.95, 2.0, track, LOOP)
    assert goal_reached(True, 0.0, 9.0)  # the env ended the episode at the goal
