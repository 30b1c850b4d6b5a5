"""``grid-astar``: as optimal as Dijkstra, None when unreachable, keeps clearance; plan_around."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage
from scipy.sparse.csgraph import dijkstra
from synthetic_scans import box

from dynmap_sim.agent.planning.clearance_grid import (
    ClearanceGrid,
    build_clearance_grid,
    clearance_penalty,
)
from dynmap_sim.agent.planning.grid_astar import GridAStar, astar_cells, plan_around
from dynmap_sim.agent.planning.grid_dijkstra import GridDijkstra, _grid_graph
from dynmap_sim.agent.planning.planner import PLANNERS

RES = 0.05
MIN_C, PREF_C = 0.25, 0.32


def clearance_of(occ: np.ndarray, res: float = RES) -> ClearanceGrid:
    return ClearanceGrid(np.zeros(2), res, ndimage.distance_transform_edt(~occ) * res)


@st.composite
def grids(draw):
    h = draw(st.integers(4, 14))
    w = draw(st.integers(4, 14))
    seed = draw(st.integers(0, 2**31 - 1))
    density = draw(st.sampled_from([0.05, 0.15, 0.3]))
    rng = np.random.default_rng(seed)
    occ = rng.random((h, w)) < density
    free = ~occ
    cells = np.flatnonzero(free)
    if len(cells) < 2:
        occ[:] = False
        cells = np.arange(h * w)
    src, dst = rng.choice(cells, 2, replace=False)
    return occ, int(src), int(dst)


@settings(max_examples=60, deadline=None)
@given(case=grids())
def test_astar_cost_equals_dijkstra(case) -> None:
    occ, src, dst = case
    res = 1.0
    grid = clearance_of(occ, res)
    min_c, pref_c = 1.0, 2.5  # free: not an obstacle cell; penalties within 2.5 cells
    graph = _grid_graph(grid, min_c, pref_c)
    want = dijkstra(graph, indices=src)[dst]
    free = grid.clearance_m >= min_c
    pen = clearance_penalty(grid.clearance_m, pref_c)
    got = astar_cells(free, pen, res, src, dst)
    if not np.isfinite(want):
        assert got is None
        return
    cells, cost = got
    assert cost == pytest.approx(want, rel=1e-12, abs=1e-12)
    assert cells[0] == src and cells[-1] == dst and free.flat[cells].all()
    ij = np.stack([cells // occ.shape[1], cells % occ.shape[1]], axis=1)
    step = np.abs(np.diff(ij, axis=0))
    assert np.all(step.max(axis=1) == 1)  # 8-connected moves
    # the cells' path costs what A* says, edge by edge as in the Dijkstra graph
    edge = (
        np.where(step.sum(axis=1) == 2, np.sqrt(2), 1.0)
        * 0.5
        * (pen.flat[cells[1:]] + pen.flat[cells[:-1]])
    )
    assert edge.sum() == pytest.approx(cost, rel=1e-12)


def room() -> np.ndarray:
    pts = np.array([[0, 0], [10, 0], [10, 12], [0, 12]], float)
    walls = np.concatenate([pts, np.roll(pts, -1, axis=0)], axis=1)
    inner = np.array([[0, 4, 7, 4], [3, 8, 10, 8], [5, 0, 5, 2.5]], float)
    return np.concatenate([walls, inner, box(2, 1.5, 2.6, 2.1), box(6, 9.5, 7, 10.5)])


def path_length(p: np.ndarray) -> float:
    return float(np.hypot(*np.diff(p, axis=0).T).sum())


def min_clearance_along(p: np.ndarray, grid: ClearanceGrid) -> float:
    pts = np.concatenate([np.linspace(a, b, 200) for a, b in zip(p[:-1], p[1:], strict=True)])
    return float(grid.clearance_at(pts).min())


@pytest.mark.parametrize(
    ("start", "goal"), [((1, 1), (1, 11)), ((9, 1), (1, 6)), ((2.3, 3), (8, 11)), ((4, 1), (6, 1))]
)
def test_paths_keep_the_clearance_and_are_as_short_as_dijkstras(start, goal) -> None:
    grid = build_clearance_grid(room(), np.zeros((0, 3)), resolution_m=RES)
    astar, dijk = GridAStar(MIN_C, PREF_C), GridDijkstra(MIN_C, PREF_C)
    p = astar.plan(np.array(start, float), np.array(goal, float), grid)
    q = dijk.plan(np.array(start, float), np.array(goal, float), grid)
    assert p is not None and q is not None
    assert np.allclose(p[0], start) and np.allclose(p[-1], goal)
    # clearance: the hard limit, up to a cell's half diagonal between sampled cell centres
    assert min_clearance_along(p, grid) >= MIN_C - 0.5 * np.sqrt(2) * RES
    assert path_length(p) <= 1.02 * path_length(q) + RES


def test_unreachable_goal_gives_none() -> None:
    segs = np.concatenate([box(0, 0, 6, 4), [[3, 0, 3, 4]]])  # a wall splits the room
    grid = build_clearance_grid(segs, np.zeros((0, 3)), resolution_m=RES)
    planner = GridAStar(MIN_C, PREF_C)
    assert planner.plan(np.array([1.0, 2.0]), np.array([5.0, 2.0]), grid) is None
    assert planner.last_cost_m is None
    # a goal inside the inflated zone is not free either
    assert planner.plan(np.array([1.0, 2.0]), np.array([2.9, 2.0]), grid) is None


def test_direct_line_and_registry_and_pickle() -> None:
    grid = build_clearance_grid(box(0, 0, 6, 4), np.zeros((0, 3)), resolution_m=RES)
    planner = PLANNERS.get("grid-astar")(MIN_C, PREF_C)
    assert isinstance(planner, GridAStar) and planner.name == "grid-astar"
    p = planner.plan(np.array([1.0, 1.0]), np.array([5.0, 3.0]), grid)
    assert p.shape == (2, 2)
    back = pickle.loads(pickle.dumps(planner))
    assert back.min_clearance_m == MIN_C and back._layers_of is None


def corridor() -> tuple[np.ndarray, ClearanceGrid]:
    """A 3 m wide corridor 10 m long and a straight path along its middle, blocked at x = 5."""
    segs = np.array([[0, 0, 10, 0], [0, 3, 10, 3]], float)
    block = box(4.6, 0.9, 5.4, 2.1)  # leaves 0.9 m on either side
    grid = build_clearance_grid(np.concatenate([segs, block]), np.zeros((0, 3)), resolution_m=RES)
    return np.array([[0.5, 1.5], [3.0, 1.5], [7.0, 1.5], [9.5, 1.5]]), grid


def test_plan_around_a_block_rejoins_the_path_behind_it() -> None:
    path, grid = corridor()
    planner = GridAStar(MIN_C, PREF_C)
    here = np.array([2.0, 1.4])
    out = plan_around(path, here, grid, planner)
    assert out is not None
    assert np.allclose(out[0], here) and np.allclose(out[-1], path[-1])
    assert min_clearance_along(out, grid) >= MIN_C - 0.5 * np.sqrt(2) * RES
    # the detour ends on the path, behind the block (x > 5.4 + clearance), and keeps its rest
    on_path = out[np.abs(out[:, 1] - 1.5) < 1e-9]
    assert np.any((on_path[:, 0] > 5.6) & (on_path[:, 0] < 7.0))
    assert np.any(np.all(np.isclose(out, path[2]), axis=1))


def test_plan_around_without_a_block_and_with_a_blocked_end() -> None:
    path, grid = corridor()
    planner = GridAStar(MIN_C, PREF_C)
    here = np.array([7.5, 1.6])  # beyond the block: nothing in the way
    out = plan_around(path, here, grid, planner)
    assert np.allclose(out, [here, path[-1]])
    closed = build_clearance_grid(
        np.concatenate([box(-0.5, 0, 10, 3), [[8, 0, 8, 3]]]),  # closed: a wall at x = 8
        np.zeros((0, 3)),
        resolution_m=RES,
    )
    assert plan_around(path, np.array([2.0, 1.5]), closed, planner) is None


def test_plan_around_a_block_just_before_the_goal() -> None:
    path, grid = corridor()
    planner = GridAStar(MIN_C, PREF_C)
    short = np.array([[0.5, 1.5], [5.0, 1.5], [5.67, 1.5]])  # the first free point is its end
    out = plan_around(short, np.array([2.0, 1.5]), grid, planner)
    assert out is not None and np.allclose(out[-1], short[-1])
    assert np.all(np.hypot(*np.diff(out, axis=0).T) > 0)  # no repeated vertex


def test_plan_around_from_behind_a_wall_reaches_the_path_on_the_grid() -> None:
    """A robot on a detour, in a room whose wall separates it from the nearest point of the
    path (office floor, issue 15): the way back goes through the room's door, not through
    the wall, even though nothing blocks the path ahead of that point."""
    walls = np.array(
        [[0, 0, 10, 0], [0, 3, 4, 3], [5, 3, 10, 3], [0, 6, 10, 6], [0, 0, 0, 6], [10, 0, 10, 6]],
        float,
    )  # a corridor (y 0..3) and a room above it (y 3..6), the door at x 4..5
    grid = build_clearance_grid(walls, np.zeros((0, 3)), resolution_m=RES)
    planner = GridAStar(MIN_C, PREF_C)
    path = np.array([[9.5, 1.5], [5.0, 1.5], [0.5, 1.5]])  # heading west along the corridor
    here = np.array([8.0, 4.5])  # in the room, above the path's point (8, 1.5)
    out = plan_around(path, here, grid, planner)
    assert out is not None
    assert np.allclose(out[0], here) and np.allclose(out[-1], path[-1])
    assert min_clearance_along(out[1:], grid) >= MIN_C - 0.5 * np.sqrt(2) * RES
    crossing = out[np.abs(out[:, 1] - 3.0) < 0.6]  # through the door
    assert crossing.size and np.all((crossing[:, 0] > 4.0) & (crossing[:, 0] < 5.0))


@pytest.mark.parametrize(
    ("far", "clear"),
    [([np.inf, 0.0], False), ([np.nan, 1.0], False), ([1e308, 1e308], None), ([-1e200, 3.0], None)],
    ids=str,
)
def test_a_segment_to_a_non_finite_or_far_point_never_blows_up(far, clear) -> None:
    """A non-finite end is never clear; a finite end far off the grid is judged like any
    point off it (by the edge cells, as :meth:`cell_of` clips), in bounded time."""
    grid = build_clearance_grid(box(0.0, 0.0, 4.0, 3.0), np.zeros((0, 3)), resolution_m=0.05)
    inside = np.array([2.0, 1.5])
    assert grid.segment_clear(inside, inside + [0.5, 0.2], 0.2)
    got = grid.segment_clear(inside, np.array(far, dtype=float), 0.2)
    assert isinstance(got, bool) and (clear is None or got is clear)
