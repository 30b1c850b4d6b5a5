"""The world generator: typed worlds that validate, render, repeat byte for byte, carry every
family of change, and whose route a robot can follow on day 1."""

import numpy as np
import pytest

from dynmap_sim.world import World, load_world
from dynmap_sim.world.generator import (
    KINDS,
    PARAMS,
    GeneratorError,
    generate,
    generate_world,
    route_problems,
    write_world,
)
from dynmap_sim.world.generator.grid import astar, path_cost, rasterize
from dynmap_sim.world.polygons import polyline_clearance, segment_pair_distances
from dynmap_sim.world.route import route_clearances
from dynmap_sim.world.spec import WorldSpec

SMALL = {"days": 6}


@pytest.fixture(scope="module")
def worlds():
    return {k: generate(k, 0, SMALL) for k in KINDS}


@pytest.mark.parametrize("kind", KINDS)
def test_the_written_file_loads_to_the_same_spec(worlds, kind, tmp_path):
    g = worlds[kind]
    assert isinstance(g.spec, WorldSpec)
    out = tmp_path / "w.toml"
    write_world(kind, 0, out, SMALL)
    assert out.read_text(encoding="utf-8") == g.toml()
    assert load_world(out) == g.spec == generate_world(kind, 0, SMALL)


def test_same_seed_same_bytes_other_seed_other_world(worlds):
    again = generate("office", 0, SMALL)
    assert again.toml() == worlds["office"].toml()
    assert generate("office", 1, SMALL).toml() != again.toml()


def test_a_rate_leaves_the_floor_plan_as_it_was(worlds):
    other = generate("lab", 0, {**SMALL, "move_per_week": 6.0})
    assert other.data["walls"] == worlds["lab"].data["walls"]


@pytest.mark.parametrize("kind", KINDS)
def test_day_one_route_keeps_the_robot_radius_from_every_object(worlds, kind):
    """Exact geometry (segment-polygon distances), not the generator's grid."""
    spec = worlds[kind].spec
    w = World(spec, seed=0)
    for run in range(1, w.calendar.runs_per_day + 1):
        c = route_clearances(w.snapshot(1, run), spec.robot.route)
        assert min(c.values()) > 0.2, (kind, run, min(c, key=c.get))
    assert route_problems(spec, 0, 0.2, [(1, 1)]) == []


@pytest.mark.parametrize("kind", KINDS)
def test_the_route_is_a_closed_tour_with_out_and_back_legs(worlds, kind):
    route = worlds[kind].spec.robot.route
    assert np.allclose(route[0], route[-1])
    assert worlds[kind].spec.robot.route_length_m > 15.0
    # out and back: some leg is followed later by one running the opposite way alongside it
    legs = np.concatenate([route[:-1], route[1:]], axis=1)
    u = np.diff(route, axis=0) / np.linalg.norm(np.diff(route, axis=0), axis=1)[:, None]
    near = segment_pair_distances(legs, legs) < 0.5
    back = [(i, j) for i, j in zip(*np.nonzero(near), strict=True) if j > i and u[i] @ u[j] < -0.9]
    assert back, kind


def test_every_action_of_the_world_format_is_drawn(worlds):
    periodic = generate("lab", 0, {**SMALL, "periodic_doors": 1, "periodic_groups": 1})
    actions = {ev.action for g in [*worlds.values(), periodic] for ev in g.spec.schedule}
    assert actions == {
        "add",
        "remove",
        "install",
        "move",
        "open",
        "close",
        "present",
        "shuffle",
        "grow",
        "periodic",
    }
    assert all(g.spec.people for g in worlds.values())
    kinds = {o.kind for g in worlds.values() for o in g.spec.objects}
    assert {"furniture", "door", "exhibit", "wall", "robot"} <= kinds


def test_blocks_with_and_without_a_way_round_are_what_they_say(worlds):
    seen = set()
    for g in worlds.values():
        spec = g.spec
        w = World(spec, seed=0)
        for oid, how in g.blocks.items():
            ev = next(e for e in spec.schedule if e.action == "add" and e.target == oid)
            assert ev.blocks_route
            snap = w.snapshot(ev.at, ev.run)
            assert route_clearances(snap, spec.robot.route)[oid] < 0.2
            grid = rasterize(spec.bounds, [o.polygon for o in snap.objects])
            route, block = spec.robot.route, snap.by_id()[oid].polygon
            legs = [
                k
                for k in range(len(route) - 1)
                if polyline_clearance(route[k : k + 2], [block])[0] < 0.2
            ]
            way = all(
                astar(grid, path_cost(grid, 0.2), route[k], route[k + 1]) is not None for k in legs
            )
            assert legs and way == (how == "a way round"), (spec.name, oid)
            seen.add(how)
    assert seen == {"a way round", "no way round"}


def test_doors_that_close_are_off_the_route(worlds):
    for g in worlds.values():
        w = World(g.spec, seed=0)
        for ev in g.spec.schedule:
            if ev.action == "close":
                snap = w.snapshot(ev.at, ev.run)
                assert route_clearances(snap, g.spec.robot.route)[ev.target] > 0.2


@pytest.mark.parametrize(
    "kind,seed,params,msg",
    [
        ("castle", 0, {}, "unknown kind 'castle'; kinds: apartment, office, lab, hall"),
        ("lab", "x", {}, "the seed must be an integer, not 'x'"),
        ("lab", 1.5, {}, "the seed must be an integer"),
        ("lab", -1, {}, "the seed must be in 0..2**63-1"),
        ("lab", 0, {"days": 0}, "parameter days = 0 is outside its range 1..60"),
        ("lab", 0, {"days": "2.5"}, "parameter days must be an integer"),
        ("lab", 0, {"scale": "nan"}, "parameter scale = nan is outside its range"),
        ("lab", 0, {"colour": 1}, "unknown parameter 'colour'"),
        ("lab", 0, {"door_min_m": 1.2, "door_max_m": 0.9}, "door_min_m = 1.2 is larger"),
    ],
)
def test_bad_input_is_one_clear_line(kind, seed, params, msg):
    with pytest.raises(GeneratorError, match="^" + msg.replace("*", r"\*").replace("(", r"\(")):
        generate(kind, seed, params)


def test_every_parameter_has_a_sane_range():
    for p in PARAMS:
        assert p.lo <= p.default <= p.hi, p.name
        assert p.doc


def test_doorways_are_in_the_range_asked_for():
    g = generate("apartment", 3, {"door_min_m": 0.8, "door_max_m": 0.85, "days": 3})
    doors = [o for o in g.spec.objects if o.kind == "door"]
    assert doors and all(0.77 <= o.size[0] <= 0.84 for o in doors)  # leaf = opening - 2 cm


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_astar_finds_the_cheapest_path_dijkstra_finds(seed):
    """The compiled A* against scipy's Dijkstra on the same 8-connected cell graph."""
    from scipy.sparse import lil_matrix
    from scipy.sparse.csgraph import dijkstra

    from dynmap_sim.world.generator.grid import _astar_kernel

    rng = np.random.default_rng(seed)
    ny, nx = 14, 17
    cost = rng.uniform(1.0, 4.0, (ny, nx))
    cost[rng.random((ny, nx)) < 0.25] = np.inf
    cost[0, 0] = cost[-1, -1] = 1.0
    g = lil_matrix((ny * nx, ny * nx))
    for i in range(ny):
        for j in range(nx):
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    a, b = i + di, j + dj
                    if (di or dj) and 0 <= a < ny and 0 <= b < nx:
                        if np.isfinite(cost[i, j]) and np.isfinite(cost[a, b]):
                            step = np.hypot(di, dj)
                            g[i * nx + j, a * nx + b] = step * 0.5 * (cost[i, j] + cost[a, b])
    best = dijkstra(g.tocsr(), indices=0)[ny * nx - 1]
    path = _astar_kernel(cost, 0, ny * nx - 1)
    if not np.isfinite(best):
        assert len(path) == 0
        return
    i, j = np.divmod(path, nx)
    steps = np.hypot(np.diff(i), np.diff(j))
    total = float(np.sum(steps * 0.5 * (cost[i[:-1], j[:-1]] + cost[i[1:], j[1:]])))
    assert path[0] == 0 and path[-1] == ny * nx - 1 and steps.max() < 1.5
    assert total == pytest.approx(best, rel=1e-12)
