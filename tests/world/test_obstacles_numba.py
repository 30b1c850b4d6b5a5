"""Goal choice's compiled geometry queries (``obstacles_numba``) answer as numpy's
:class:`~dynmap_sim.world.people.obstacles.Obstacles` does, boolean for boolean, on the
shipped worlds (compiled and plain-Python twins), and hand the cases they do not cover back."""

import numpy as np
import pytest

from dynmap_sim.numpy_complex import numpy_complex_mode
from dynmap_sim.world import World, load_world, resolve_world_path
from dynmap_sim.world.people.obstacles import Obstacles
from dynmap_sim.world.people.obstacles_numba import CompiledQueries, numba_available, queries

pytestmark = pytest.mark.skipif(
    numpy_complex_mode(python=True) is None,
    reason="numpy's complex loops match neither mode here: the people keep numpy's queries",
)


def world_obstacles(name: str, day: int, run: int) -> Obstacles:
    world = World(load_world(resolve_world_path(name)), seed=0)
    world.reset(day, run)
    return world._forces.obstacles


def compare(obs: Obstacles, q: CompiledQueries, trials: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    lo, hi = obs.segments[:, :2].min(axis=0), obs.segments[:, :2].max(axis=0)
    for _ in range(trials):
        pts = rng.uniform(lo, hi, (int(rng.integers(1, 40)), 2))
        r = float(rng.uniform(0.1, 0.35))
        np.testing.assert_array_equal(q.free_mask(pts, r), obs.free_mask(pts, r))
        np.testing.assert_array_equal(q.visible_many(pts[0], pts), obs.visible_many(pts[0], pts))
        assert q.visible(pts[0], pts[-1]) == obs.visible(pts[0], pts[-1])


@pytest.mark.skipif(not numba_available(), reason="numba (extra 'fast') not installed")
@pytest.mark.parametrize(("world", "day", "run"), [("lab", 1, 2), ("apartment", 15, 1)])
def test_compiled_queries_answer_as_numpy(world, day, run):
    obs = world_obstacles(world, day, run)
    q = queries(obs)
    assert isinstance(q, CompiledQueries)
    compare(obs, q, 200, seed=day)


def test_plain_python_queries_answer_as_numpy():
    obs = world_obstacles("lab", 1, 2)
    compare(obs, queries(obs, python=True), 3, seed=5)


def test_cases_without_the_grid_or_outlines_are_numpys_own():
    segs = np.array([[0.0, 0.0, 4.0, 0.0], [4.0, 0.0, 4.0, 3.0], [4.0, 3.0, 0.0, 0.0]])
    pts = np.array([[2.0, 0.5], [3.5, 2.0], [1.0, 2.0], [5.0, 1.0]])
    for obs in (Obstacles(segs, broad_phase=False), Obstacles(segs, outline_starts=np.array([0]))):
        q = queries(obs, python=True)
        for r in (0.1, 5.0):  # 5 m: wider than the grid lists segments for
            np.testing.assert_array_equal(q.free_mask(pts, r), obs.free_mask(pts, r))
        np.testing.assert_array_equal(q.visible_many(pts[0], pts), obs.visible_many(pts[0], pts))
    assert queries(Obstacles(np.zeros((0, 4))), python=True).free_mask(pts, 0.2).all()
