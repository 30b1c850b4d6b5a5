"""The compiled caster gives the numpy caster's ranges and hit indices bit for bit, in the
mode that reproduces numpy's complex arithmetic on this install (numba's build and its
plain-Python twin alike), and to rounding in the other."""

import numpy as np
import pytest

from dynmap_sim.numpy_complex import FUSED, PLAIN, cabs, cmul_im, cmul_re, numpy_complex_mode
from dynmap_sim.sensors.lidar import NOISELESS, make_lidar
from dynmap_sim.sensors.raycast import SegmentCache, beam_directions, cast_scan
from dynmap_sim.sensors.raycast_numba import cast_scan_numba, numba_available

needs_numba = pytest.mark.skipif(not numba_available(), reason="numba (extra 'fast') not installed")


def random_world(seed: int) -> tuple[SegmentCache, np.ndarray]:
    rng = np.random.default_rng(seed)
    p = rng.uniform(-8.0, 8.0, (200, 2))
    ang = rng.uniform(0.0, 2.0 * np.pi, 200)
    segs = np.column_stack(
        [p, p + rng.uniform(0.1, 3.0, (200, 1)) * np.c_[np.cos(ang), np.sin(ang)]]
    )
    circ = np.column_stack([rng.uniform(-6.0, 6.0, (40, 2)), rng.uniform(0.05, 0.25, 40)])
    return SegmentCache.build(segs), circ


def test_the_probe_finds_numpys_complex_arithmetic():
    """numpy 2 on x86-64 computes complex products and ``abs`` in one of the two modes."""
    mode = numpy_complex_mode(python=True)
    if mode is None:  # pragma: no cover - e.g. a numpy whose AVX-512 loops differ
        pytest.skip("numpy's complex loops match neither mode here: 'auto' casts with numpy")
    assert mode in (FUSED, PLAIN)
    a, b = 0.1 + 0.7j, -1.3 + 2.9j
    prod = np.multiply(np.array([a]), np.array([b]))[0]
    assert cmul_re(a.real, a.imag, b.real, b.imag, mode) == prod.real
    assert cmul_im(a.real, a.imag, b.real, b.imag, mode) == prod.imag
    assert cabs(3.0, 4.0, mode) == 5.0


def test_the_plain_kernel_matches_numpy_bit_for_bit():
    if numpy_complex_mode(python=True) is None:  # pragma: no cover
        pytest.skip("numpy's complex loops match neither mode here")
    cache, circ = random_world(11)
    amin, inc = -2.0862, 2 * np.pi / 1024
    cl, sl = beam_directions(amin, inc, 683)
    for pose in [(0.3, -0.2, 0.7), (-2.0, 1.5, -2.9)]:
        r0, h0 = cast_scan(pose, amin, inc, cl, sl, 5.6, cache, circ)
        r1, h1 = cast_scan_numba(pose, amin, inc, cl, sl, 5.6, cache, circ, python=True)
        assert r0.tobytes() == r1.tobytes() and h0.tobytes() == h1.tobytes()


@needs_numba
def test_numba_matches_numpy_on_random_geometry():
    rng = np.random.default_rng(12)
    cache, circ = random_world(11)
    exact = numpy_complex_mode() is not None
    for amin, inc, n in [(-2.0862, 2 * np.pi / 1024, 683), (-np.pi, 2 * np.pi / 720, 720)]:
        cl, sl = beam_directions(amin, inc, n)
        for _ in range(40):
            pose = (*rng.uniform(-3.0, 3.0, 2), rng.uniform(-np.pi, np.pi))
            r0, h0 = cast_scan(pose, amin, inc, cl, sl, 5.6, cache, circ)
            r1, h1 = cast_scan_numba(pose, amin, inc, cl, sl, 5.6, cache, circ)
            if exact:
                assert r0.tobytes() == r1.tobytes() and h0.tobytes() == h1.tobytes()
            else:  # pragma: no cover - a numpy whose complex loops neither mode matches
                fin = np.isfinite(r0)
                np.testing.assert_array_equal(fin, np.isfinite(r1))
                assert np.max(np.abs(r0[fin] - r1[fin]), initial=0.0) < 1e-9


@needs_numba
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


@needs_numba
def test_numba_matches_numpy_in_the_lab_with_the_lunch_crowd():
    """Issue 13: on a world's geometry with people's legs moving, the two casters give the
    same ranges and hit shapes on every beam."""
    from dynmap_sim.env import DynMapEnv

    env = DynMapEnv(world="lab")
    env.reset(seed=0, options={"day": 1, "run": 2})  # the run with the most people (18)
    a = make_lidar("urg-04lx", noise=NOISELESS)
    b = make_lidar("urg-04lx", noise=NOISELESS, backend="numba")
    exact = numpy_complex_mode() is not None
    for k in range(60):
        env.step(np.array([0.4, 0.5 * np.sin(0.2 * k)]))
        pose, geom = env.robot.pose, env.world.geometry
        (r0, h0), (r1, h1) = a.cast(pose, geom), b.cast(pose, geom)
        if exact:
            assert r0.tobytes() == r1.tobytes() and h0.tobytes() == h1.tobytes(), k
        else:  # pragma: no cover
            fin = np.isfinite(r0)
            assert np.max(np.abs(r0[fin] - r1[fin]), initial=0.0) < 1e-9
