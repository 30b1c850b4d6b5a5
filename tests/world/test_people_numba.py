"""The people's step with the kernels of ``dynamics_numba`` (the numba backend) moves
everyone exactly as the numpy step does, bit for bit, with and without a robot."""

import numpy as np
import pytest

from dynmap_sim.world import World, load_world, resolve_world_path
from dynmap_sim.world.people import social_force as sf_module
from dynmap_sim.world.people.dynamics_numba import Kernels, numba_available


def _state(world: World) -> list[bytes]:
    c = world.crowd
    arrays = [c.pos, c.vel, c.goal, c.phase, c.stuck_s, c.best_goal_m, c.waypoint]
    return [np.ascontiguousarray(a).tobytes() for a in arrays] + [
        repr(world._forces.rng.bit_generator.state).encode(),
        world.geometry.circles.tobytes(),
    ]


def _robot_path(n: int, start: np.ndarray) -> list[np.ndarray]:
    """A robot that wanders through the crowd (evasion, comfort disc, goals it stands on)."""
    t = np.arange(n) * 0.1
    x = start[0] + 2.0 * np.sin(0.05 * t) + 0.02 * t
    y = start[1] + 1.5 * np.sin(0.07 * t)
    return [np.array([a, b, 0.0]) for a, b in zip(x, y, strict=True)]


def _compare(
    world_name: str, day: int, run: int, steps: int, python: bool, robot: bool, fused: bool = True
):
    spec = load_world(resolve_world_path(world_name))
    ref = World(spec, seed=0)
    fast = World(spec, seed=0)
    for w in (ref, fast):
        w.reset(day, run)
    fast.people_backend = "numba"  # the kernels (the check for numba is bypassed)
    fast._forces.backend = "numba"
    fast._forces._ops = sf_module.compiled_ops(python=python)
    if not fused:  # the parts between numpy's calls, not the one force kernel
        fast._forces._ops.social_force.args[0].force_mode = None
    assert fast.crowd.n > 0
    start = ref.crowd.pos[0]  # among the people: their goals, comfort discs, evasion
    for i, pose in enumerate(_robot_path(steps, start)):
        rp = pose if robot else None
        ref.step(0.1, robot_pose=rp)
        fast.step(0.1, robot_pose=rp)
        assert _state(fast) == _state(ref), f"step {i}"


@pytest.mark.parametrize("robot", [True, False])
def test_python_kernels_step_people_as_numpy(robot):
    _compare("lab", 1, 2, 60, python=True, robot=robot)


@pytest.mark.skipif(not numba_available(), reason="numba (extra 'fast') not installed")
@pytest.mark.parametrize(
    ("world", "day", "run", "robot"),
    [("lab", 1, 2, True), ("lab", 1, 2, False), ("lab", 3, 1, True), ("apartment", 15, 1, True)],
)
def test_compiled_kernels_step_people_as_numpy(world, day, run, robot):
    _compare(world, day, run, 600, python=False, robot=robot)


@pytest.mark.skipif(not numba_available(), reason="numba (extra 'fast') not installed")
@pytest.mark.parametrize("robot", [True, False])
def test_compiled_parts_without_the_one_force_kernel_step_people_as_numpy(robot):
    """The kernels between numpy's calls, where the force cannot be one kernel (numpy's
    complex arithmetic or exp not reproduced, or rows too long)."""
    _compare("lab", 1, 2, 200, python=False, robot=robot, fused=False)


@pytest.mark.parametrize("python", [True, False])
def test_row_sums_are_numpy_s_pairwise_sums(python):
    """``_row_sum`` gives ``np.sum`` of a row's real and imaginary parts bit for bit, for
    every length up to FORCE_MAX_COLS (once split beyond 64)."""
    if not python and not numba_available():
        pytest.skip("numba (extra 'fast') not installed")
    from dynmap_sim.world.people import dynamics_numba as dn

    def sums(x, out):  # type: ignore[no-untyped-def]
        for i in range(x.shape[0]):
            out[i] = dn._row_sum(x[i], x.shape[1])

    if python:
        kernel = sums
    else:
        import numba

        kernel = numba.njit(sums)
    rng = np.random.default_rng(7)
    for m in range(1, dn.FORCE_MAX_COLS + 1):
        z = rng.standard_normal((4, m)) * np.exp(rng.uniform(-8, 8, (4, m))) + 1j * (
            rng.standard_normal((4, m)) * np.exp(rng.uniform(-8, 8, (4, m)))
        )
        want = z.sum(axis=1)
        for part, ref in ((z.real.copy(), want.real), (z.imag.copy(), want.imag)):
            out = np.empty(4)
            kernel(part, out)
            assert out.tobytes() == ref.tobytes(), m


@pytest.mark.skipif(not numba_available(), reason="numba (extra 'fast') not installed")
def test_numba_env_moves_people_as_the_numpy_env():
    """The env with the fast extra's backend: people, legs and poses are the numpy env's."""
    from dynmap_sim.env import DynMapEnv

    envs = [DynMapEnv(world="lab", sensor_options={"backend": b}) for b in ("numpy", "numba")]
    assert envs[1].world.people_backend == "numba"
    for env in envs:
        env.reset(seed=0, options={"day": 1, "run": 2})
    for i in range(150):
        a = np.array([0.4, 0.6 * np.sin(0.05 * i)])
        infos = [env.step(a)[4] for env in envs]
        assert envs[0].world.crowd.pos.tobytes() == envs[1].world.crowd.pos.tobytes()
        p0, p1 = (info["truth"]["people"] for info in infos)
        assert p0.tobytes() == p1.tobytes()


def test_unknown_people_backend_is_refused():
    spec = load_world(resolve_world_path("lab"))
    with pytest.raises(ValueError, match="people backend"):
        World(spec, seed=0, people_backend="cuda")


@pytest.mark.parametrize("python", [True, False])
def test_rows_kernel_lists_the_grids_rows(python):
    """The broad phase's kernel gives SegmentGrid.rows, for points off the grid too."""
    if not python and not numba_available():
        pytest.skip("numba (extra 'fast') not installed")
    from dynmap_sim.world.people import Obstacles
    from dynmap_sim.world.people.dynamics_numba import candidate_rows

    rng = np.random.default_rng(4)
    kern = Kernels(python=python)
    for segs in (np.zeros((0, 4)), np.hstack([a := rng.uniform(0, 9, (30, 2)), a + 1.0])):
        obstacles = Obstacles(segs)
        pts = rng.uniform(-4.0, 14.0, (200, 2))
        z = np.ascontiguousarray(pts).view(np.complex128)[:, 0]
        got = candidate_rows(kern, obstacles, z)
        np.testing.assert_array_equal(got, obstacles.rows(z))
