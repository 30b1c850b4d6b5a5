"""A* on the route graph by travel time (H&W §6.2, eq. 18), blocked edges (§6.3)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from dynmap_sim.agent.navigation import Edge, RouteGraph, RouteMemory, RouteMemoryParams
from dynmap_sim.agent.planning.route_astar import START, astar, heuristic_speed_mps, plan_route

#: Two ways from (0, 0) to (4, 0): straight (4 m) and over (2, 1.5) (5 m).
SHORT = [(0.0, 0.0), (2.0, 0.0), (4.0, 0.0)]
LONG = [(0.0, 0.0), (2.0, 1.5), (4.0, 0.0)]


def two_ways(short_s=None, long_s=None) -> RouteMemory:
    """The short way is the prior; the long one a learned route joined at both ends.
    ``*_s``: learned travel time per segment (None: never driven)."""
    mem = RouteMemory.from_prior(SHORT, 0.2, 0.35, 0.0, densify=False)
    tt = None if long_s is None else [np.nan, long_s, long_s]
    mem.add_route(LONG, 0.2, 0.35, 0.0, travel_time_s=tt)
    if short_s is not None:
        mem.routes[0].wp[1:, 5] = short_s
    return mem


def test_unlearned_edges_cost_length_over_v_and_the_shorter_way_wins():
    path = plan_route(two_ways().graph(), [0.0, 0.0], [4.0, 0.0])
    assert path.xy[:, 1].max() == 0.0
    assert path.travel_time_s == pytest.approx(4.0 / 0.2)
    np.testing.assert_allclose(path.half_width_m, 0.35)
    np.testing.assert_allclose(path.v_max_mps, 0.2)


def test_the_faster_way_by_learned_travel_time_wins_not_the_shorter():
    # people on the short way: 30 s per segment there; the long way was driven in 10 s each
    mem = two_ways(short_s=30.0, long_s=10.0)
    path = plan_route(mem.graph(), [0.0, 0.0], [4.0, 0.0])
    np.testing.assert_allclose(path.xy, LONG)
    assert path.travel_time_s == pytest.approx(20.0)
    # the edges taken, joins of coincident waypoints included (to the long way at the
    # prior's start, back to the prior's end, the goal node)
    a, b, c = (int(i) for i in mem.routes[1].ids)
    assert path.edges == ((0, a), (a, b), (b, c), (c, int(mem.routes[0].ids[-1])))
    assert path.node_ids[0] != START  # the start coincides with a node


def test_a_blocked_edge_is_avoided_and_unblocking_restores_it():
    mem = two_ways(short_s=5.0, long_s=10.0)
    ids = mem.routes[0].ids
    edge = (int(ids[1]), int(ids[2]))
    assert plan_route(mem.graph(), [0, 0], [4, 0]).xy[:, 1].max() == 0.0
    mem.block(edge)
    path = plan_route(mem.graph(), [0, 0], [4, 0])
    assert path.xy[:, 1].max() == pytest.approx(1.5)
    mem.unblock(edge)
    assert plan_route(mem.graph(), [0, 0], [4, 0]).xy[:, 1].max() == 0.0
    # both ways blocked: unreachable
    mem.block(edge)
    long_ids = mem.routes[1].ids
    mem.block((int(long_ids[0]), int(long_ids[1])))
    assert plan_route(mem.graph(), [0, 0], [4, 0]) is None


def test_the_start_is_projected_onto_the_nearest_segment():
    corner = [(0.0, 0.0), (4.0, 0.0), (4.0, 4.0)]
    mem = RouteMemory.from_prior(corner, 0.2, 0.35, 0.0, densify=False)
    path = plan_route(mem.graph(), [1.0, 0.2], [4.0, 4.0])
    assert path.node_ids[0] == START
    np.testing.assert_allclose(path.xy, [(1.0, 0.0), (4.0, 0.0), (4.0, 4.0)])
    assert path.travel_time_s == pytest.approx((3.0 + 4.0) / 0.2)


#: Reverse edges at their default cost, named: these tests need them on.
REVERSE = RouteMemoryParams(reverse_cost_factor=1.5)


def test_empty_and_unreachable():
    assert plan_route(RouteMemory().graph(), [0, 0], [1, 1]) is None
    directed = RouteMemoryParams(reverse_cost_factor=math.inf)
    mem = RouteMemory.from_prior(SHORT, 0.2, 0.35, 0.0, directed, densify=False)
    assert plan_route(mem.graph(), [4.0, 0.0], [0.0, 0.0]) is None  # routes are directed


@pytest.mark.parametrize("factor", [1.0, 1.5, 3.0])
def test_a_route_is_driven_backwards_at_its_reverse_cost(factor):
    """Against the route's direction the plan follows the segments back, each at the
    factor times its travel time (2 m at 0.2 m/s: 10 s forward)."""
    params = RouteMemoryParams(reverse_cost_factor=factor)
    mem = RouteMemory.from_prior(SHORT, 0.2, 0.35, 0.0, params, densify=False)
    plan = plan_route(mem.graph(), [4.0, 0.0], [0.0, 0.0])
    np.testing.assert_allclose(plan.xy, [(4.0, 0.0), (2.0, 0.0), (0.0, 0.0)])
    assert plan.travel_time_s == pytest.approx(2 * 10.0 * factor)
    assert plan.edges == ((1, 0),)  # the start's edge back to waypoint 1 is the projection's
    forward = plan_route(mem.graph(), [0.0, 0.0], [4.0, 0.0])
    assert forward.travel_time_s == pytest.approx(20.0)  # the route's direction: its own cost


def test_a_robot_mid_segment_goes_back_along_it_when_that_is_shorter():
    """On the tracked segment the plan may enter the graph backwards at the reverse cost; a
    closer entry (the start waypoint straight ahead of it, at ``v_h``) is cheaper still."""
    mem = RouteMemory.from_prior([(0.0, 0.0), (10.0, 0.0)], 0.2, 0.35, 0.0, REVERSE, densify=False)
    mem.add_route([(0.0, 0.0), (0.0, 5.0)], 0.2, 0.35, 0.0)  # from the start, away
    for start_on, back_s in (((0, 1), 1.5 * 1.0 / 0.2), (None, 1.0 / 0.2)):
        plan = plan_route(mem.graph(), [1.0, 0.0], [0.0, 5.0], start_on=start_on)
        np.testing.assert_allclose(plan.xy, [(1.0, 0.0), (0.0, 0.0), (0.0, 5.0)], atol=1e-12)
        assert plan.travel_time_s == pytest.approx(back_s + 5.0 / 0.2, rel=1e-9)


def test_a_block_holds_both_ways():
    mem = RouteMemory.from_prior(SHORT, 0.2, 0.35, 0.0, REVERSE, densify=False)
    mem.block((0, 1))
    g = mem.graph()
    costs = {(e.u, e.v): e.travel_time_s for e in g.edges}
    assert math.isinf(costs[(0, 1)]) and math.isinf(costs[(1, 0)])
    assert math.isfinite(costs[(1, 2)]) and math.isfinite(costs[(2, 1)])
    assert plan_route(g, [4.0, 0.0], [0.0, 0.0]) is None  # the way back is blocked too
    mem.unblock((1, 0))  # seen free from the other side
    assert not mem.blocked


@st.composite
def graphs(draw):
    """Random directed graphs: nodes in a 10 m square, edges with travel times unrelated to
    their lengths (learned times can be anything), some blocked."""
    n = draw(st.integers(2, 12))
    coord = st.floats(0.0, 10.0, allow_nan=False)
    xy = np.array([[draw(coord), draw(coord)] for _ in range(n)])
    pairs = draw(
        st.lists(
            st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)).filter(lambda p: p[0] != p[1]),
            max_size=4 * n,
            unique=True,
        )
    )
    edges = []
    for u, v in pairs:
        cost = draw(st.one_of(st.floats(0.01, 100.0), st.just(math.inf)))
        length = float(np.hypot(*(xy[u] - xy[v])))
        edges.append(Edge(u, v, length, cost, True, 0.35, 0))
    v_max = draw(st.floats(0.05, 1.0))
    g = RouteGraph(np.arange(n), xy, np.full(n, v_max), np.full(n, 0.35), edges)
    return g, draw(st.integers(0, n - 1)), draw(st.integers(0, n - 1))


@settings(max_examples=200, deadline=None)
@given(graphs())
def test_astar_cost_equals_dijkstra_and_h_never_overestimates(case):
    g, s, t = case
    n = len(g.node_ids)
    finite = [e for e in g.edges if math.isfinite(e.travel_time_s)]
    m = csr_matrix(
        ([e.travel_time_s for e in finite], ([e.u for e in finite], [e.v for e in finite])),
        shape=(n, n),
    )
    dist = dijkstra(m, directed=True)
    found = astar(g, s, t)
    if math.isinf(dist[s, t]):
        assert found is None
    else:
        cost, nodes, edges = found
        assert cost == pytest.approx(dist[s, t], rel=1e-9, abs=1e-9)
        assert nodes[0] == s and nodes[-1] == t
        assert sum(e.travel_time_s for e in edges) == pytest.approx(cost)
    # admissible: h(n) <= true cost to the goal, for every node that reaches it
    v_h = heuristic_speed_mps(g)
    for k in range(n):
        if math.isfinite(dist[k, t]):
            assert np.hypot(*(g.xy[k] - g.xy[t])) / v_h <= dist[k, t] + 1e-9


def test_leaving_a_loops_goal_ignores_a_join_from_the_start_to_it():
    """A loop route cut in two (forgetting): its start and its end are one spot on two routes,
    joined at no cost. From the start, with ``leave_goal_m``, the plan drives the loop."""
    mem = RouteMemory.from_prior([(0.0, 0.0), (0.0, 3.0), (3.0, 3.0)], 0.2, 0.35, 0.0)
    mem.add_route([(3.0, 3.0), (3.0, 0.0), (0.0, 0.0)], 0.2, 0.35, 0.0)
    g = mem.graph()
    goal = int(mem.routes[1].ids[-1])
    assert any(e.v == goal and e.route_id == -1 for e in g.edges)  # the join start -> goal
    stay = plan_route(g, (0.0, 0.0), (0.0, 0.0), 0.2, goal_id=goal)
    assert stay is not None and stay.travel_time_s == 0.0  # already there
    loop = plan_route(g, (0.0, 0.0), (0.0, 0.0), 0.2, goal_id=goal, leave_goal_m=1.0)
    assert loop is not None
    assert np.sum(np.hypot(*np.diff(loop.xy, axis=0).T)) == pytest.approx(12.0, abs=0.05)
    assert loop.node_ids[-1] == goal and (3.0, 3.0) in map(tuple, loop.xy.round(6))
    # the goal is still found when the start is farther than leave_goal_m (already left)
    back = plan_route(g, (3.0, 1.5), (0.0, 0.0), 0.2, goal_id=goal, leave_goal_m=1.0)
    assert back is not None and back.node_ids[-1] == goal
    assert np.sum(np.hypot(*np.diff(back.xy, axis=0).T)) == pytest.approx(4.5, abs=0.05)
