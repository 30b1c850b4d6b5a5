"""The ``auto`` sensor backend, which scenario experiments use: the compiled casting, noise
model and people's step when numba is installed (numpy's casting where the compiled one
could not reproduce numpy's complex arithmetic), numpy's numbers bit for bit on every
install, and pickles that resume on an install with or without numba."""

import pickle

import numpy as np
import pytest

from dynmap_sim.env import DynMapEnv
from dynmap_sim.env_factory import SCENARIO_SENSOR_BACKEND, SimSpec, make_env, resolve_world
from dynmap_sim.jit import numba_available
from dynmap_sim.numpy_complex import numpy_complex_mode
from dynmap_sim.sensors.lidar import LIDAR_BACKENDS, make_lidar
from dynmap_sim.sensors.raycast import cast_scan
from dynmap_sim.world.people.social_force import NUMPY_OPS, SocialForce


def test_auto_uses_the_kernels_when_installed_and_exact():
    lidar = make_lidar("urg-04lx", backend="auto")
    exact = numba_available() and numpy_complex_mode() is not None
    assert (lidar._cast is cast_scan) == (not exact)
    assert (lidar._noise_scan is not None) == numba_available()
    people = SocialForce((), np.zeros((0, 4)), np.random.default_rng(0), backend="auto")
    assert (people.backend_ops() is NUMPY_OPS) == (not numba_available())


def test_unknown_lidar_backend_names_the_choices():
    with pytest.raises(ValueError, match="one of") as err:
        make_lidar("urg-04lx", backend="gpu")
    for name in LIDAR_BACKENDS:
        assert name in str(err.value)


def test_an_auto_lidar_pickles_without_its_kernels():
    """The kernels are resolved where the lidar is unpickled (a checkpoint taken with numba
    resumes without it)."""
    lidar = make_lidar("urg-04lx", backend="auto")
    state = lidar.__getstate__()
    assert state["_noise_scan"] is None and state["_cast"] is None
    back = pickle.loads(pickle.dumps(lidar))
    assert (back._noise_scan is not None) == numba_available()
    assert back._cast is lidar._cast


def test_auto_env_gives_the_numpy_env_numbers_bit_for_bit():
    """Scans, odometry and the people of the apartment's crowded day 15 and the lab's lunch
    run, stepped by an ``auto`` env and a ``numpy`` env."""
    for world, day, run in (("apartment", 15, 1), ("lab", 1, 2)):
        envs = [DynMapEnv(world=world, sensor_options={"backend": b}) for b in ("numpy", "auto")]
        assert envs[1].world.people_backend == "auto"
        for env in envs:
            env.reset(seed=3, options={"day": day, "run": run})
        for i in range(120):
            a = np.array([0.3, 0.5 * np.sin(0.07 * i)], dtype=np.float32)
            (o0, *_, i0), (o1, *_, i1) = (env.step(a) for env in envs)
            assert o0["scan"].tobytes() == o1["scan"].tobytes(), (world, i)
            assert o0["odom"].tobytes() == o1["odom"].tobytes(), (world, i)
            assert i0["truth"]["people"].tobytes() == i1["truth"]["people"].tobytes()


def test_scenario_envs_use_auto_unless_their_sensor_names_a_backend():
    assert SCENARIO_SENSOR_BACKEND == "auto"
    assert make_env(SimSpec(world=resolve_world("apartment"))).lidar.backend == "auto"
    named = make_env(
        SimSpec(world=resolve_world("apartment"), sensor_overrides={"backend": "numpy"})
    )
    assert named.lidar.backend == "numpy"
    assert named.world.people_backend == "numpy"
