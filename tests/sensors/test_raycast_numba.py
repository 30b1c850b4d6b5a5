"""The optional numba backend gives the same ranges as the numpy caster (within 1e-9 m)."""

import numpy as np
import pytest

from dynmap_sim.sensors.lidar import NOISELESS, make_lidar
from dynmap_sim.sensors.raycast import SegmentCache, beam_directions, cast_scan
from dynmap_sim.sensors.raycast_numba import cast_scan_numba, numba_available

pytestmark = pytest.mark.skipif(not numba_available(), reason="numba (extra 'fast') not installed")


def test_numba_matches_numpy_on_random_geometry():
    rng = np.random.default_rng(11)
    p = rng.uniform(-8.0, 8.0, (200, 2))
    ang = rng.uniform(0.0, 2.0 * np.pi, 200)
    segs = np.column_stack(
        [p, p + rng.uniform(0.1, 3.0, (200, 1)) * np.c_[np.cos(ang), np.sin(ang)]]
    )
    circ = np.column_stack([rng.uniform(-6.0, 6.0, (40, 2)), rng.uniform(0.05, 0.25, 40)])
    cache = SegmentCache.build(segs)
    for amin, inc, n in [(-2.0862, 2 * np.pi / 1024, 683), (-np.pi, 2 * np.pi / 720, 720)]:
        cl, sl = beam_directions(amin, inc, n)
        for _ in range(10):
            pose = (*rng.uniform(-3.0, 3.0, 2), rng.uniform(-np.pi, np.pi))
            r0, h0 = cast_scan(pose, amin, inc, cl, sl, 5.6, cache, circ)
            r1, h1 = cast_scan_numba(pose, amin, inc, cl, sl, 5.6, cache, circ)
            np.testing.assert_array_equal(np.isfinite(r0), np.isfinite(r1))
            fin = np.isfinite(r0)
            assert np.max(np.abs(r0[fin] - r1[fin]), initial=0.0) < 1e-9
            assert np.mean(h0 == h1) > 0.99  # ties at shared endpoints may pick either


def test_numba_backend_in_the_lidar():
    segs = np.array([[3.0, -5.0, 3.0, 5.0]])

    class G:
        segments = segs
        segment_object = np.array([0], np.int32)
        segment_class = np.array([1], np.int8)
        circles = np.empty((0, 3))
        circle_object = np.empty(0, np.int32)
        circle_class = np.empty(0, np.int8)
        static_version = 0

    a = make_lidar("urg-04lx", noise=NOISELESS, backend="numba").scan(
        np.zeros(3), G, np.random.default_rng(0)
    )
    b = make_lidar("urg-04lx", noise=NOISELESS).scan(np.zeros(3), G, np.random.default_rng(0))
    np.testing.assert_allclose(a.true_range_m, b.true_range_m, atol=1e-9)
    with pytest.raises(ValueError, match="backend"):
        make_lidar("urg-04lx", backend="cuda")


def test_numba_matches_numpy_in_the_lab_with_the_lunch_crowd():
    """Issue 13: on a world's geometry with people's legs moving, the two casters' ranges
    agree to 1e-9 m on every beam (the hit shape may differ only on exact ties)."""
    from dynmap_sim.env import DynMapEnv

    env = DynMapEnv(world="lab")
    env.reset(seed=0, options={"day": 1, "run": 2})  # the run with the most people (18)
    a = make_lidar("urg-04lx", noise=NOISELESS)
    b = make_lidar("urg-04lx", noise=NOISELESS, backend="numba")
    worst = 0.0
    for k in range(60):
        env.step(np.array([0.4, 0.5 * np.sin(0.2 * k)]))
        pose, geom = env.robot.pose, env.world.geometry
        (r0, h0), (r1, h1) = a.cast(pose, geom), b.cast(pose, geom)
        np.testing.assert_array_equal(np.isfinite(r0), np.isfinite(r1))
        fin = np.isfinite(r0)
        worst = max(worst, float(np.max(np.abs(r0[fin] - r1[fin]), initial=0.0)))
        assert np.mean(h0 == h1) > 0.99
    assert worst < 1e-9
