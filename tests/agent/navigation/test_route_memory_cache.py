"""The route memory's caches give what recomputation gives, and its locate kernel what the
closed-form projection onto each segment gives.

The geometry cache (segments, arc lengths) must be dropped wherever a waypoint moves or a
route is added, split, cut or forgotten; the search of ``locate`` must pick the nearest
segment by its rules (ties to the first, the tracked route, the continuity window).
"""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from dynmap_sim.agent.navigation import RouteMemory
from dynmap_sim.agent.navigation.route_tracking import locate_segment
from dynmap_sim.agent.navigation.routes import SegmentArrays, build_graph
from dynmap_sim.agent.planning.route_graph import project_onto_segments as _project

DAY_S = 86_400.0
DETOUR = [(0.0, 0.0), (3.0, 0.0), (3.0, 1.2), (7.0, 1.2), (7.0, 0.0), (10.0, 0.0)]


def straight(now_s: float = 0.0) -> RouteMemory:
    return RouteMemory.from_prior([[0.0, 0.0], [10.0, 0.0]], 0.2, 0.35, now_s)


def assert_cache_fresh(mem: RouteMemory) -> None:
    """The cached geometry equals a rebuild from the routes, bit for bit, and the graph one
    of a copy that never had a cache."""
    cached = mem.route_set.segments()
    fresh = copy.deepcopy(mem)
    fresh.route_set.changed()
    rebuilt = fresh.route_set.segments()
    for name in ("a", "b", "l", "rid", "seg", "fr", "to", "s0", "length"):
        np.testing.assert_array_equal(getattr(cached, name), getattr(rebuilt, name), name)
    assert cached.cum.keys() == mem.routes.keys()
    for rid, r in mem.routes.items():
        np.testing.assert_array_equal(cached.cum[rid], r.cumulative_m())
        assert cached.cum_list[rid] == r.cumulative_m().tolist()
        k = cached.rid == rid
        np.testing.assert_array_equal(cached.length[k], r.segment_lengths_m())
    assert mem.graph().edges == fresh.graph().edges


def test_the_cache_follows_adaptation_recording_splits_and_forgetting(drive_fn):
    mem = straight()
    assert_cache_fresh(mem)
    t = drive_fn(mem, [(0, 0.2), (10.3, 0.2)], 0.25, 10.0)  # waypoints adapt (move)
    assert mem.routes[0].xy[3, 1] > 0.0
    assert_cache_fresh(mem)
    mem.reset_run()
    drive_fn(mem, DETOUR, 0.25, t + 10.0)  # a new route, the prior split at both ends
    assert len(mem.routes) == 2
    assert_cache_fresh(mem)
    for day in range(1, 5):
        mem.reset_run()
        drive_fn(mem, DETOUR, 0.25, day * DAY_S)
        assert_cache_fresh(mem)
    assert mem.forget(4 * DAY_S + 1000.0) > 0  # the prior's middle is cut out
    assert len(mem.routes) == 3
    assert_cache_fresh(mem)
    mem.add_route([(1.0, 1.0), (2.0, 2.0)], 0.2, 0.35, 5 * DAY_S)
    assert_cache_fresh(mem)


def test_tracking_with_the_cache_learns_what_recomputation_learns(drive_fn):
    """Observing with the cache kept equals observing with it dropped before every step."""
    kept, dropped = straight(), straight()
    for t0, line in ((0.0, [(0, 0.2), (10.3, 0.2)]), (100.0, DETOUR), (200.0, DETOUR)):
        for mem in (kept, dropped):
            mem.reset_run()
        pts = np.asarray(line, float)
        for k, xy in enumerate(
            np.concatenate([np.linspace(pts[j], pts[j + 1], 40) for j in range(len(pts) - 1)])
        ):
            pose = [xy[0], xy[1], 0.0]
            dropped.route_set.changed()
            assert kept.observe(pose, t0 + 0.1 * k) == dropped.observe(pose, t0 + 0.1 * k)
    assert json.dumps(kept.to_dict()) == json.dumps(dropped.to_dict())  # NaN as text
    for r, q in zip(kept.routes.values(), dropped.routes.values(), strict=True):
        np.testing.assert_array_equal(r.wp, q.wp)


def first_min(dist: np.ndarray, among: np.ndarray) -> int | None:
    """The first index of ``among`` (sorted) with the least ``dist``, None when empty."""
    return None if among.size == 0 else int(among[np.argmin(dist[among])])


def test_the_locate_kernel_picks_the_segment_its_rules_name():
    """Random segments (zero-length ones, shared waypoints: exact ties): the kernel's pick
    is the nearest segment (the first of equal ones), else the tracked route's nearest when
    within 1e-9, else its nearest within the window along it when within ``continuity_m``,
    where a segment against the heading (when one is given) counts ``continuity_m``
    farther; its fraction, distance and projection are the closed-form projection's."""
    rng = np.random.default_rng(3)
    window, cont = 2.0, 0.35
    for trial in range(300):
        n = int(rng.integers(1, 60))
        a = rng.uniform(-5, 5, (n, 2))
        b = a + rng.normal(0, 1, (n, 2)) * (rng.random((n, 1)) > 0.05)  # some zero-length
        b[: n // 4] = np.roll(a, -1, axis=0)[: n // 4]  # shared waypoints: exact ties
        rid = rng.integers(0, 3, n).astype(np.int64)
        s0 = rng.uniform(0, 20, n)
        length = np.hypot(*(b - a).T)
        p = a[int(rng.integers(n))] if trial % 3 == 0 else rng.uniform(-5, 5, 2)
        prefer = None if trial % 4 == 0 else int(rng.integers(0, 3))
        along = None if trial % 5 == 0 else float(rng.uniform(0, 20))
        heading = math.nan if trial % 2 == 0 else float(rng.uniform(-math.pi, math.pi))
        got = locate_segment(
            p[0], p[1], heading, SegmentArrays(a, b, rid, s0, length),
            -1 if prefer is None else prefer, 0.0 if along is None else along,
            prefer is not None, along is not None, window, cont,
        )  # fmt: skip
        u, proj, true_dist = _project(p, a, b)
        dist = true_dist.copy()
        if not math.isnan(heading):
            dist[(b - a) @ np.array([math.cos(heading), math.sin(heading)]) < 0.0] += cont
        want = first_min(dist, np.arange(n))
        if prefer is not None:
            mine = np.flatnonzero(rid == prefer)
            k2 = first_min(dist, mine)
            if k2 is not None and dist[k2] <= dist[want] + 1e-9:
                want = k2
            if along is not None:
                near = mine[np.abs(s0[mine] + u[mine] * length[mine] - along) <= window]
                k3 = first_min(dist, near)
                if k3 is not None and dist[k3] <= dist[want] + cont:
                    want = k3
        k = got[0]
        assert k == want
        assert got[1] == pytest.approx(u[k], abs=1e-12)
        assert got[2] == pytest.approx(true_dist[k], abs=1e-12)
        np.testing.assert_allclose(got[3:], proj[k], atol=1e-12)


def test_locate_of_a_non_finite_position_is_none(drive_fn):
    mem = straight()
    drive_fn(mem, DETOUR, 0.25, 100.0)
    assert mem.locate([math.nan, 0.0, 0.0]) is None
    assert mem.observe([math.inf, 0.0, 0.0], 200.0) is None
    assert math.isfinite(mem.locate([1.0, 0.1]).along_m)


def test_the_graph_is_reused_only_while_its_inputs_are_the_same(drive_fn):
    mem = straight()
    g = mem.graph()
    assert mem.graph() is g  # nothing changed
    ids = mem.routes[0].ids
    mem.block((int(ids[3]), int(ids[4])))
    assert mem.graph() is not g and mem.graph().edges == build_graph(mem.route_set).edges
    assert math.isinf(next(e for e in mem.graph().edges if e.u == ids[3]).travel_time_s)
    mem.unblock((int(ids[3]), int(ids[4])))
    assert mem.graph().edges == g.edges
    mem.routes[0].wp[1:, 5] = 1.0  # edited in place: travel times learned elsewhere
    assert mem.graph().edges == build_graph(mem.route_set).edges
    assert all(e.learned for e in mem.graph().edges)
    drive_fn(mem, DETOUR, 0.25, 100.0)  # a new route, splits, learned times
    assert mem.graph().edges == build_graph(mem.route_set).edges
    assert any(e.route_id == 1 for e in mem.graph().edges)
