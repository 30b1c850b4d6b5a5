"""Route progress: monotone arc length, loops followed in order, done only at the end."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dynmap_sim.robot.route import RouteProgress

LOOP = np.array([[0, 0], [4, 0], [4, 3], [0, 3], [0, 0]], float)


def test_progress_along_a_loop_and_done_only_at_the_end():
    rp = RouteProgress(LOOP, goal_tolerance_m=0.3)
    assert rp.length_m == pytest.approx(14.0)
    assert not rp.done(0.0, 0.0)  # start == goal, but nothing driven yet
    # walk the loop 5 cm off the line, in 10 cm steps
    for s in np.arange(0.1, 14.0, 0.1):
        k = np.searchsorted([4.0, 7.0, 11.0], s, side="right")
        a, b = LOOP[k], LOOP[k + 1]
        seg_start = [0.0, 4.0, 7.0, 11.0][k]
        d = (b - a) / np.linalg.norm(b - a)
        x, y = a + (s - seg_start) * d + 0.05 * np.array([-d[1], d[0]])
        rp.update(x, y)
        assert rp.progress_m == pytest.approx(s, abs=0.06)
        if s <= 13.6 or s >= 13.8:  # goal tolerance 0.3 m (the walk is 5 cm off the line)
            assert rp.done(x, y) == (s >= 13.8)


def test_shortcut_across_the_loop_is_not_progress():
    rp = RouteProgress(LOOP)
    rp.update(1.0, 0.0)
    gained = rp.update(0.0, 2.9)  # next to the last leg: 10 m further along the route
    assert gained < 3.0 and rp.progress_m < 4.0


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-1, 5), st.floats(-1, 4)), min_size=1, max_size=30))
def test_progress_is_monotone_and_bounded(points):
    rp = RouteProgress(LOOP)
    last = 0.0
    for x, y in points:
        gained = rp.update(x, y)
        assert gained >= 0.0
        assert rp.progress_m >= last and rp.progress_m <= rp.length_m + 1e-9
        last = rp.progress_m
