"""The lidar on a shipped world agrees with pymunk queries on the world's own space."""

import numpy as np
import pymunk
import pytest

from dynmap_sim.sensors.lidar import NOISELESS, make_lidar
from dynmap_sim.world import CATEGORY_STATIC, World, load_world, resolve_world_path


@pytest.mark.parametrize("name, day", [("lab", 4), ("apartment", 9)])
def test_lidar_matches_pymunk_on_world_space(name, day):
    spec = load_world(resolve_world_path(name))
    spec = spec.model_copy(update={"people": ()})
    world = World(spec, seed=0)
    world.reset(day, 1)
    lidar = make_lidar("urg-04lx", noise=NOISELESS)
    flt = pymunk.ShapeFilter(mask=CATEGORY_STATIC)
    route = spec.robot.route
    rng = np.random.default_rng(0)
    angles = lidar.spec.angles()
    r_max = lidar.spec.range_max_m
    n_hits = 0
    for k in range(0, len(route) - 1, max(1, (len(route) - 1) // 6)):
        x, y = route[k] + rng.uniform(0.2, 0.8) * (route[k + 1] - route[k])
        pose = np.array([x, y, rng.uniform(-np.pi, np.pi)])
        reading = lidar.scan(pose, world.geometry, rng)
        ref = np.full(angles.shape[0], np.inf)
        for i, a in enumerate(angles):
            end = (x + r_max * np.cos(pose[2] + a), y + r_max * np.sin(pose[2] + a))
            q = world.space.segment_query_first((x, y), end, 0.0, flt)
            if q is not None:
                ref[i] = q.alpha * r_max
        ours = reading.true_range_m
        np.testing.assert_array_equal(np.isfinite(ours), np.isfinite(ref))
        fin = np.isfinite(ref)
        assert np.max(np.abs(ours[fin] - ref[fin]), initial=0.0) < 1e-6
        n_hits += int(fin.sum())
        # finite readings carry a label; no-returns carry none
        assert np.all((reading.beam_object >= 0) == fin)
    assert n_hits > 500
