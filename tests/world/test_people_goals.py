"""Goal choice evaluates several tries in one pass and gives the one-at-a-time loop's goals."""

import math

import numpy as np
import pytest

from dynmap_sim.world.people import Obstacles
from dynmap_sim.world.people.params import GOAL_TOL_M
from dynmap_sim.world.people.spawning import pick_goal, random_point
from dynmap_sim.world.polygons import polygon_edges
from dynmap_sim.world.spec import PeopleSpec


def _reference_pick_goal(obstacles, rng, pop, frm, r, avoid=None):
    """The one-try-at-a-time loop :func:`pick_goal` must match, draw for draw."""
    for _ in range(20):
        if pop.goals:
            g = np.array(pop.goals[int(rng.integers(len(pop.goals)))], dtype=float)
        else:
            g = random_point(obstacles, rng, pop, r)
            if g is None:
                continue
        gx, gy = float(g[0]), float(g[1])
        if avoid is not None and math.hypot(gx - avoid[0][0], gy - avoid[0][1]) < avoid[1] + r:
            continue
        if math.hypot(gx - frm[0], gy - frm[1]) > GOAL_TOL_M and obstacles.visible(frm, g):
            return g
    return frm.copy()


def _room_obstacles() -> Obstacles:
    """A 10 m x 8 m room with a grid of 0.6 m boxes and a large table (closed outlines)."""

    def box(x0, y0, x1, y1):
        return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)

    # walls: four thin boxes around the room (a closed outline of the room itself would put
    # every point of it inside an obstacle)
    outlines = [box(-0.1, -0.1, 10.1, 0), box(-0.1, 8, 10.1, 8.1)]
    outlines += [box(-0.1, 0, 0, 8), box(10, 0, 10.1, 8)]
    for x in (2.0, 4.5, 7.0):
        for y in (2.0, 5.5):
            outlines.append(box(x, y, x + 0.6, y + 0.6))
    outlines.append(box(3.0, 3.2, 7.5, 4.6))
    edges = [polygon_edges(p) for p in outlines]
    starts = np.cumsum([0] + [len(e) for e in edges[:-1]]).astype(np.int64)
    return Obstacles(np.concatenate(edges), outline_starts=starts)


POPS = {
    "one area": PeopleSpec(id="a", count=1, areas=((0.3, 0.3, 9.7, 7.7),)),
    "areas": PeopleSpec(
        id="b", count=1, areas=((0.3, 0.3, 4.0, 7.7), (6.0, 0.3, 9.7, 7.7), (3.0, 3.2, 7.5, 4.6))
    ),
    # mostly covered by the table: random_point often needs several batches of 8
    "crowded area": PeopleSpec(id="c", count=1, areas=((2.8, 2.9, 7.9, 5.2),)),
    "goals": PeopleSpec(
        id="d", count=1, areas=((0.3, 0.3, 9.7, 7.7),), goals=((1.0, 1.0), (9.0, 7.0), (5.0, 6.5))
    ),
}


@pytest.mark.parametrize("name", POPS)
@pytest.mark.parametrize("with_avoid", [False, True])
def test_pick_goal_matches_the_one_at_a_time_loop(name, with_avoid):
    obstacles = _room_obstacles()
    pop = POPS[name]
    a, b = np.random.default_rng(3), np.random.default_rng(3)
    found = 0
    pts = np.random.default_rng(9).uniform((0.3, 0.3), (9.7, 7.7), (40, 2))
    for frm in pts:
        avoid = (frm + (0.8, 0.1), 0.5) if with_avoid else None
        got = pick_goal(obstacles, a, pop, frm, 0.22, avoid)
        want = _reference_pick_goal(obstacles, b, pop, frm, 0.22, avoid)
        assert np.array_equal(got, want)
        assert a.bit_generator.state == b.bit_generator.state  # the same draws, in order
        found += not np.array_equal(got, frm)
    assert found >= 10  # picks do find goals (the test is not about people who pause)


def test_visible_many_is_visible_per_point():
    obstacles = _room_obstacles()
    rng = np.random.default_rng(0)
    a = np.array([1.0, 1.0])
    bs = rng.uniform(0.0, 10.0, (200, 2))
    many = obstacles.visible_many(a, bs)
    assert many.tolist() == [obstacles.visible(a, b) for b in bs]
    assert 0 < many.sum() < len(bs)
