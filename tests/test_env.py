"""The Gymnasium env: checker, determinism, vector envs, episodes, action handling."""

import time
import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.error import ClosedEnvironmentError, ResetNeeded
from gymnasium.utils.env_checker import check_env

import dynmap_sim  # noqa: F401  (registers the envs)
from dynmap_sim.env import DynMapEnv
from dynmap_sim.errors import InputError
from dynmap_sim.registration import WORLDS_DIR
from dynmap_sim.types import BEAM_CLASSES, LaserSpec


@pytest.fixture(scope="module")
def apartment():
    env = DynMapEnv(world="apartment")
    yield env
    env.close()


@pytest.mark.parametrize(
    "env_id, kwargs",
    [
        ("dynmap_sim/Apartment-v0", {}),
        ("dynmap_sim/Lab-v0", {}),
        ("dynmap_sim/World-v0", {"world": str(WORLDS_DIR / "apartment.toml")}),
    ],
)
def test_check_env_passes_for_every_registered_env(env_id, kwargs):
    env = gymnasium.make(env_id, render_mode="rgb_array", **kwargs)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the checker warns about infinite Box bounds
        check_env(env.unwrapped, skip_render_check=False)
    env.reset(seed=0)
    env.step(np.array([0.2, 0.1], np.float32))
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    env.close()


def rollout(seed, n=500):
    env = DynMapEnv(world="lab")
    env.action_space.seed(seed)
    obs, info = env.reset(seed=seed, options={"day": 4, "run": 2})
    out = [obs["scan"], obs["odom"], info["truth"]["pose"]]
    for _ in range(n):
        obs, r, term, trunc, info = env.step(env.action_space.sample())
        out += [obs["scan"], obs["odom"], info["truth"]["pose"], np.array([r])]
        if term or trunc:
            obs, info = env.reset()
    return out


def test_same_seed_same_rollout():
    a, b = rollout(7), rollout(7)
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
    c = rollout(8, n=5)
    assert not all(np.array_equal(x, y) for x, y in zip(a[: len(c)], c, strict=False))


def test_async_vector_env():
    envs = gymnasium.make_vec("dynmap_sim/Apartment-v0", num_envs=2, vectorization_mode="async")
    try:
        obs, info = envs.reset(seed=[1, 2])
        assert obs["scan"].shape == (2, 683) and obs["odom"].shape == (2, 3)
        for _ in range(3):
            obs, rew, term, trunc, info = envs.step(np.array([[0.3, 0.0], [0.2, 0.1]], np.float32))
        assert rew.shape == (2,)
    finally:
        envs.close()


@pytest.mark.parametrize("bad", [[np.nan, 0.0], [0.0, np.inf], [-np.inf, 1.0]])
def test_non_finite_action_raises(apartment, bad):
    apartment.reset(seed=0)
    with pytest.raises(ValueError, match="finite"):
        apartment.step(np.array(bad, np.float32))


def test_wrong_shape_and_bad_options_raise(apartment):
    apartment.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        apartment.step(np.zeros(3))
    with pytest.raises(ValueError, match="day 99"):
        apartment.reset(options={"day": 99})
    with pytest.raises(ValueError, match="integer"):
        apartment.reset(options={"day": "one"})


def test_out_of_range_action_is_clipped(apartment):
    apartment.reset(seed=0)
    for _ in range(30):
        apartment.step(np.array([100.0, 0.0], np.float32))
    assert apartment.robot.twist[0] == pytest.approx(apartment.robot_params.max_v_mps)


def test_episode_is_one_run_and_next_run_without_options():
    env = DynMapEnv(world="lab", people=False)
    obs, info = env.reset(seed=3)
    assert info["truth"]["time"][:2] == (1, 1)
    _, info = env.reset()
    assert info["truth"]["time"][:2] == (1, 2)
    _, info = env.reset(options={"day": 5, "run": 3})
    assert info["truth"]["time"][:2] == (5, 3)
    assert info["truth"]["time"][2] == env.world.calendar.slot(5, 3).start_s
    _, info = env.reset()
    assert info["truth"]["time"][:2] == (6, 1)
    np.testing.assert_array_equal(obs["odom"], 0.0)
    np.testing.assert_allclose(info["truth"]["pose"], env.spec_world.robot.start)
    assert info["truth"]["people"].shape == (0, 3) and info["truth"]["n_people"] == 0


def test_observation_and_truth_contents(apartment):
    obs, info = apartment.reset(seed=0)
    spec = apartment.laser_spec
    assert isinstance(spec, LaserSpec) and obs["scan"].shape == (spec.n_beams,)
    assert obs["scan"].dtype == np.float32 and obs["odom"].dtype == np.float64
    assert not np.isnan(obs["scan"]).any()
    t = info["truth"]
    assert t["beam_class"].dtype == np.int8 and t["beam_object"].dtype == np.int32
    assert set(np.unique(t["beam_class"])) <= set(range(len(BEAM_CLASSES)))
    hit = t["beam_object"] >= 0
    assert hit.any() and np.all(t["beam_class"][~hit] == 0)
    # noise-free ranges agree with the readings within the noise
    ok = np.isfinite(obs["scan"]) & np.isfinite(t["range_m"])
    assert np.median(np.abs(obs["scan"][ok] - t["range_m"][ok])) < 0.05
    # fresh arrays every step
    obs2, *_ = apartment.step(np.zeros(2, np.float32))
    assert obs2["scan"] is not obs["scan"] and not np.shares_memory(obs2["odom"], obs["odom"])


def test_driving_the_route_with_truth_terminates():
    """A pure-pursuit driver on the true pose finishes the apartment route: terminated."""
    env = DynMapEnv(world="apartment", people=False)
    obs, info = env.reset(seed=0)
    route = env.spec_world.robot.route
    k = 1
    total, bumps = 0.0, 0
    for _ in range(env.max_episode_steps):
        x, y, th = info["truth"]["pose"]
        while k < len(route) - 1 and np.hypot(*(route[k] - (x, y))) < 0.4:
            k += 1
        gx, gy = route[k]
        bearing = np.arctan2(gy - y, gx - x) - th
        err = np.arctan2(np.sin(bearing), np.cos(bearing))
        v = 0.5 if abs(err) < 0.5 else 0.05
        obs, r, term, trunc, info = env.step(np.array([v, 2.0 * err], np.float32))
        total += r
        bumps += info["collision"]
        if term or trunc:
            break
    assert term and not trunc
    assert info["route_progress"] > 0.95
    # odometry drifts: mapped through the start pose it is near the truth, but not on it
    from dynmap_sim.se2 import compose

    odo_in_map = compose(env.spec_world.robot.start, obs["odom"])
    drift = np.hypot(*(odo_in_map[:2] - info["truth"]["pose"][:2]))
    assert 1e-3 < drift < 0.05 * env.route.length_m
    # reward = route progress [m] minus the collision penalty per bumper step
    assert total == pytest.approx(env.route.progress_m - env.collision_penalty * bumps)
    assert env.route.progress_m > env.route.length_m - 0.7


def test_teleport_moves_truth_not_odometry(apartment):
    apartment.reset(seed=0)
    apartment.teleport((4.0, 3.0, 0.5))
    obs, _, _, _, info = apartment.step(np.zeros(2, np.float32))
    np.testing.assert_allclose(info["truth"]["pose"], (4.0, 3.0, 0.5), atol=1e-9)
    np.testing.assert_allclose(obs["odom"], 0.0, atol=1e-9)
    with pytest.raises(ValueError, match="teleport"):
        apartment.teleport((np.nan, 0.0, 0.0))


def test_a_run_is_the_same_whatever_ran_before():
    a = DynMapEnv(world="lab")
    b = DynMapEnv(world="lab")
    a.reset(seed=5, options={"day": 2, "run": 1})
    for _ in range(20):
        a.step(np.array([0.4, 0.2], np.float32))
    oa, ia = a.reset(seed=5, options={"day": 3, "run": 2})
    ob, ib = b.reset(seed=5, options={"day": 3, "run": 2})
    for _ in range(30):
        oa, *_, ia = a.step(np.array([0.4, -0.1], np.float32))
        ob, *_, ib = b.step(np.array([0.4, -0.1], np.float32))
    np.testing.assert_array_equal(oa["scan"], ob["scan"])
    np.testing.assert_array_equal(oa["odom"], ob["odom"])
    np.testing.assert_array_equal(ia["truth"]["people"], ib["truth"]["people"])


def test_env_pickles_and_resumes_bit_for_bit():
    import pickle

    env = DynMapEnv(world="apartment")
    env.reset(seed=1)
    for _ in range(10):
        env.step(np.array([0.3, 0.1], np.float32))
    twin = pickle.loads(pickle.dumps(env))
    for _ in range(10):
        o1, r1, *_ = env.step(np.array([0.3, 0.1], np.float32))
        o2, r2, *_ = twin.step(np.array([0.3, 0.1], np.float32))
        np.testing.assert_array_equal(o1["scan"], o2["scan"])
        np.testing.assert_array_equal(o1["odom"], o2["odom"])
        assert r1 == r2


def test_world_spec_and_lms200_options():
    from dynmap_sim.world import load_world, resolve_world_path

    spec = load_world(resolve_world_path("apartment"))
    env = DynMapEnv(world=spec, sensor="lms200", sensor_options={"beams": 181, "mode": "cm"})
    obs, info = env.reset(seed=0)
    assert env.laser_spec.n_beams == 181 and env.laser_spec.range_max_m == 81.9
    assert obs["scan"].shape == (181,) and env.observation_space["scan"].shape == (181,)
    assert env.dt_s == env.laser_spec.scan_period_s
    assert env.metadata["render_fps"] == round(1 / env.dt_s)
    with pytest.raises(ValueError, match="unknown laser scanner"):
        DynMapEnv(world=spec, sensor="kinect")


def test_vector_env_with_different_crowds():
    """People arrays keep one shape (padded), so sub-envs in different runs batch."""
    from gymnasium.vector import SyncVectorEnv

    envs = SyncVectorEnv([lambda: DynMapEnv(world="lab"), lambda: DynMapEnv(world="lab")])
    envs.reset(seed=[0, 0])
    envs.envs[1].reset(seed=0, options={"day": 1, "run": 2})  # the lunch crowd
    *_, info = envs.step(np.zeros((2, 2), np.float32))
    people, n = info["truth"]["people"], info["truth"]["n_people"]
    assert people.shape[0] == 2 and n[0] < n[1]
    for k in range(2):
        assert np.all(np.isfinite(people[k, : n[k]]))
        assert np.all(np.isposinf(people[k, n[k] :, :2]))
    envs.close()


def test_new_seed_new_world_no_stale_caches():
    a = DynMapEnv(world="lab")
    a.reset(seed=1, options={"day": 4, "run": 1})
    a.step(np.array([0.3, 0.0], np.float32))
    oa, ia = a.reset(seed=2, options={"day": 9, "run": 2})
    ob, ib = DynMapEnv(world="lab").reset(seed=2, options={"day": 9, "run": 2})
    np.testing.assert_array_equal(oa["scan"], ob["scan"])
    np.testing.assert_array_equal(ia["truth"]["beam_object"], ib["truth"]["beam_object"])


def test_info_people_are_the_worlds_people_padded():
    env = DynMapEnv(world="lab")
    env.reset(seed=0, options={"day": 1, "run": 2})
    for _ in range(5):
        _, _, _, _, info = env.step(np.array([0.3, 0.2], np.float32))
    poses = env.unwrapped.world.people_poses()
    n = info["truth"]["n_people"]
    assert n == poses.shape[0] > 0
    np.testing.assert_array_equal(info["truth"]["people"][:n], poses)
    assert np.all(np.isposinf(info["truth"]["people"][n:, :2]))


def test_a_reset_that_raised_leaves_the_env_usable():
    """Through gymnasium.make (its wrappers included): a first reset that raised, then a
    good reset and a step work, and give the same numbers as without the failed reset."""
    env = gymnasium.make("dynmap_sim/Apartment-v0")
    with pytest.raises(ValueError, match=r"day 99 outside the calendar \(1\.\.28\)"):
        env.reset(seed=5, options={"day": 99})
    obs, _ = env.reset(seed=0, options={"day": 2})
    obs2, *_ = env.step(np.array([0.2, 0.0], np.float32))
    fresh = gymnasium.make("dynmap_sim/Apartment-v0")
    ref, _ = fresh.reset(seed=0, options={"day": 2})
    ref2, *_ = fresh.step(np.array([0.2, 0.0], np.float32))
    np.testing.assert_array_equal(obs["scan"], ref["scan"])
    np.testing.assert_array_equal(obs2["scan"], ref2["scan"])
    # a failed reset changes nothing: not the world's seed, not the run
    u = env.unwrapped
    before = (u.world_seed, u.day_run)
    with pytest.raises(ValueError):
        env.reset(seed=7, options={"day": 1, "run": 9})
    assert (u.world_seed, u.day_run) == before
    env.close()
    fresh.close()


@pytest.mark.parametrize(
    "options, msg",
    [
        ({"dayy": 3}, "reset options: unknown key(s) 'dayy'; known: 'day', 'run'"),
        ([1, 2], "reset options must be a dict with keys from ['day', 'run'], got [1, 2]"),
        ({"day": True}, "reset options: 'day' must be an integer, got True"),
    ],
)
def test_bad_reset_options_name_the_known_keys(apartment, options, msg):
    with pytest.raises(ValueError) as ei:
        apartment.reset(seed=0, options=options)
    assert str(ei.value) == msg


@pytest.mark.parametrize("seed", [-1, 1.5, "3", True])
def test_bad_reset_seed(apartment, seed):
    with pytest.raises(ValueError, match="reset seed must be None or an integer >= 0"):
        apartment.reset(seed=seed)


def test_world_env_needs_a_world():
    with pytest.raises(ValueError, match=r"dynmap_sim/World-v0 needs world=PATH"):
        gymnasium.make("dynmap_sim/World-v0")


@pytest.mark.parametrize(
    "kwargs, msg",
    [
        ({"max_episode_steps": -1}, "max_episode_steps must be an integer >= 1, got -1"),
        ({"max_episode_steps": 2.5}, "max_episode_steps must be an integer >= 1, got 2.5"),
        ({"collision_penalty": float("nan")}, "collision_penalty must be a finite number >= 0"),
        ({"render_size_px": 0}, "render_size_px must be an integer in 1..8192, got 0"),
        ({"goal_tolerance_m": -0.1}, "goal_tolerance_m must be a finite number > 0, got -0.1"),
        ({"dt_s": 0.0}, "dt_s must be a finite number in (0, 1] (seconds), got 0.0"),
        ({"dt_s": float("inf")}, "dt_s must be a finite number in (0, 1] (seconds), got inf"),
        ({"dt_s": 1e9}, "dt_s must be a finite number in (0, 1] (seconds), got 1000000000.0"),
        ({"encoder": 5}, "encoder must be None or a EncoderNoise, got 5"),
        ({"robot": "x"}, "robot must be None or a RobotParams, got 'x'"),
        ({"lidar_noise": "x"}, "lidar_noise must be None or a LidarNoise, got 'x'"),
        ({"sensor_options": {"scan_period_s": 5.0}}, "the sensor's scan_period_s must be in"),
        ({"people": "no"}, "people must be True or False, got 'no'"),
        ({"sensor_options": [1]}, "sensor_options must be a dict, got [1]"),
        (
            {"world": None},
            "world must be 'lab', 'apartment', a path to a world file or a WorldSpec",
        ),
        (
            {"sensor_options": {"scan_period_s": 0.0}},
            "the sensor's scan_period_s must be in (0, 1] s (it is the step period dt_s unless "
            "dt_s is given), got 0.0",
        ),
        (
            {"render_mode": "humans"},
            "render_mode 'humans' is not supported; render modes: None, 'human', 'rgb_array'",
        ),
    ],
)
def test_constructor_arguments_are_checked_with_their_value(kwargs, msg):
    with pytest.raises(InputError) as ei:
        DynMapEnv(**{"world": "apartment", **kwargs})
    assert str(ei.value).startswith(msg)
    if "max_episode_steps" in kwargs:
        return  # gymnasium.make takes it for its TimeLimit wrapper (-1: none, its convention)
    with pytest.raises(InputError) as ei:  # the same at gymnasium.make, before any step
        gymnasium.make("dynmap_sim/Apartment-v0", **kwargs)
    assert str(ei.value).startswith(msg)


def test_step_after_close_and_before_reset_raise():
    env = DynMapEnv(world="apartment")
    with pytest.raises(ResetNeeded, match="reset"):
        env.step(np.zeros(2, np.float32))
    env.reset(seed=0)
    env.step(np.zeros(2, np.float32))
    env.close()
    env.close()  # a no-op
    with pytest.raises(ClosedEnvironmentError, match="close"):
        env.step(np.zeros(2, np.float32))
    with pytest.raises(ClosedEnvironmentError, match="close"):
        env.reset(seed=0)


@pytest.mark.parametrize("end", ["truncated", "terminated"])
def test_step_after_the_episode_ended_needs_a_reset(end):
    env = DynMapEnv(world="apartment", max_episode_steps=3)
    env.reset(seed=0)
    if end == "terminated":  # the robot at the route's end, the route followed
        route = env.spec_world.robot.route
        env.route._k, env.route.progress_m = len(route) - 2, env.route.length_m
        env.robot.set_pose((*route[-1], 0.0))
    out = env.step(np.zeros(2, np.float32))
    while not (out[2] or out[3]):
        out = env.step(np.zeros(2, np.float32))
    assert out[2] == (end == "terminated") and out[3] == (end == "truncated")
    with pytest.raises(ResetNeeded, match="the episode has ended"):
        env.step(np.zeros(2, np.float32))
    env.reset()  # the next run
    _, _, terminated, truncated, _ = env.step(np.zeros(2, np.float32))
    assert not (terminated or truncated)


@pytest.mark.parametrize("dtype", [np.uint8, np.int64, np.float16, np.float32, np.float64])
def test_actions_of_any_real_dtype_are_cast_to_float64(dtype):
    """An action's value decides the step, whatever its dtype (documented cast)."""
    outs = []
    for action in (np.array([1, 0], dtype=dtype), np.array([1.0, 0.0])):
        env = DynMapEnv(world="apartment")
        env.reset(seed=1)
        for _ in range(5):
            obs, reward, *_ = env.step(action)
        outs.append((obs["odom"], obs["scan"], reward))
    np.testing.assert_array_equal(outs[0][0], outs[1][0])
    np.testing.assert_array_equal(outs[0][1], outs[1][1])
    assert outs[0][2] == outs[1][2]


def test_rgb_array_list_through_make_collects_frames():
    env = gymnasium.make("dynmap_sim/Apartment-v0", render_mode="rgb_array_list")
    env.reset(seed=0)
    env.step(np.array([0.2, 0.0], np.float32))
    frames = env.render()
    assert len(frames) == 2 and frames[0].dtype == np.uint8 and frames[0].ndim == 3
    env.close()


def test_human_render_mode_shows_every_frame_in_a_window():
    """``render_mode="human"``: a matplotlib window (off screen here: the Agg backend) shows
    the rgb_array frame at every reset and step; ``render()`` returns None; ``close()``
    closes the window. It needs nothing beyond the default install."""
    env = gymnasium.make("dynmap_sim/Apartment-v0", render_mode="human")
    twin = DynMapEnv(world="apartment", render_mode="rgb_array")
    env.reset(seed=0)
    twin.reset(seed=0)
    u = env.unwrapped
    window = u._window
    assert window is not None and not window.closed
    np.testing.assert_array_equal(window.pixels(), twin.render())
    action = np.array([0.3, 0.2], np.float32)
    env.step(action)
    twin.step(action)
    np.testing.assert_array_equal(window.pixels(), twin.render())
    assert env.render() is None
    env.close()
    assert u._window is None and window.closed
    twin.close()


def test_the_window_plays_at_the_scan_rate():
    from dynmap_sim.human_window import HumanWindow

    window = HumanWindow("t", fps=20)
    frame = np.zeros((40, 60, 3), np.uint8)
    t0 = time.monotonic()
    for _ in range(5):
        window.show(frame)
    assert time.monotonic() - t0 >= 4 / 20  # four waits of 1/20 s between five frames
    window.close()
    window.show(frame)  # after close: nothing
    assert window.closed


@pytest.mark.parametrize(
    "action",
    [np.array([0.1 + 1j, 0.0]), np.array([True, False]), [None, 0.1], "ab"],
    ids=["complex", "bool", "none", "str"],
)
def test_non_real_actions_are_refused(apartment, action):
    apartment.reset(seed=0)
    with pytest.raises(ValueError, match=r"action must be 2 real numbers \(v_mps, omega_radps\)"):
        apartment.step(action)


def test_world_facts_prior_is_what_a_walls_scenario_grants():
    """``WorldFacts.prior``: the start pose with its covariance, the static walls, bounds and
    route; the first run is day 1 run 1."""
    env = DynMapEnv(world="apartment")
    f = env.world_facts()
    p = f.prior(day=2, run=1, sigma_xy_m=0.1, sigma_theta_rad=0.02)
    np.testing.assert_array_equal(p.initial_pose, f.start_pose)
    np.testing.assert_allclose(np.diag(p.initial_pose_cov), [0.01, 0.01, 0.0004])
    np.testing.assert_array_equal(p.walls, f.wall_segments)
    np.testing.assert_array_equal(p.route, f.route)
    assert (p.day, p.run, p.first_run, p.bounds) == (2, 1, False, f.bounds)
    assert f.prior(day=1).first_run and f.prior(day=1, walls=False).walls is None


def test_world_facts_prior_without_a_pose_and_with_a_scenarios_route():
    """An unknown start grants no pose and no covariance; a scenario's own route replaces the
    world's (the experiment engine's episodes take their prior from here)."""
    f = DynMapEnv(world="apartment").world_facts()
    route = [[0.0, 0.0], [1.0, 2.0]]
    p = f.prior(day=3, run=2, known_pose=False, route=route)
    assert p.initial_pose is None and p.initial_pose_cov is None
    np.testing.assert_array_equal(p.route, route)
    assert (p.day, p.run, p.first_run) == (3, 2, False)
