"""Fuzz: a mutated valid world file either loads or raises WorldFileError, nothing else."""

import copy
import datetime as dt

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dynmap_sim.world import World, WorldFileError, parse_world

VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-5, 40),
    st.floats(-10, 50),
    st.sampled_from([float("nan"), float("inf"), -float("inf"), 0.0, 1e9]),
    st.text(max_size=6),
    st.dates(dt.date(2023, 12, 1), dt.date(2024, 2, 1)),
    st.lists(st.floats(-2, 8), max_size=5),
    st.lists(st.lists(st.floats(-1, 7), min_size=2, max_size=2), max_size=4),
    st.just({}),
)


def _paths(node, prefix=()):
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, (*prefix, i))


def _mutate(data, path, op, value):
    node = data
    for key in path[:-1]:
        node = node[key]
    last = path[-1]
    if op == "delete":
        del node[last]
    elif op == "extra" and isinstance(node, dict):
        node[f"x_{last}"] = value
    else:
        node[last] = value


@settings(
    max_examples=150,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(data=st.data())
def test_mutated_world_loads_or_raises_world_file_error(base_world, data):
    paths = [p for p in _paths(base_world) if p]
    mutations = data.draw(
        st.lists(
            st.tuples(st.sampled_from(paths), st.sampled_from(["set", "delete", "extra"]), VALUES),
            min_size=1,
            max_size=3,
        )
    )
    world_data = copy.deepcopy(base_world)
    for path, op, value in mutations:
        try:
            _mutate(world_data, path, op, value)
        except (KeyError, IndexError, TypeError):
            continue  # the path no longer exists after an earlier mutation
    try:
        spec = parse_world(world_data, "fuzz.toml")
    except WorldFileError as exc:
        assert exc.errors and all(isinstance(m, str) for _, m in exc.errors)
        return
    world = World(spec, seed=0)  # a file that loads must also run
    world.reset(world.calendar.n_days, world.calendar.runs_per_day)
    world.step(0.1)
