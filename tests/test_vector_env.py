"""The batched vector env (``vector_entry_point``): Gymnasium's VectorEnv API, NEXT_STEP
autoreset, and the same numbers as ``SyncVectorEnv`` / N single envs with the same seeds."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ClosedEnvironmentError, ResetNeeded
from gymnasium.vector import AutoresetMode, SyncVectorEnv

import dynmap_sim  # noqa: F401  (registers the envs)
from dynmap_sim.env import DynMapEnv
from dynmap_sim.vector_env import DynMapVectorEnv

N = 3
STEPS = 14
MAX_STEPS = 5  # short episodes: autoreset happens within the test


def _actions(n_steps: int, n_envs: int) -> np.ndarray:
    t = np.arange(n_steps)[:, None] * 0.1 + np.arange(n_envs)[None, :]
    return np.stack([0.3 + 0.2 * np.sin(t), 0.6 * np.cos(0.7 * t)], axis=-1).astype(np.float32)


def _assert_same(a, b) -> None:
    if isinstance(a, dict):
        assert set(a) == set(b)
        for k in a:
            _assert_same(a[k], b[k])
    elif isinstance(a, tuple):
        assert isinstance(b, tuple) and len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            _assert_same(x, y)
    else:
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        assert np.asarray(a).dtype == np.asarray(b).dtype


@pytest.fixture(scope="module")
def vec() -> DynMapVectorEnv:
    v = gym.make_vec("dynmap_sim/Apartment-v0", num_envs=N, max_episode_steps=MAX_STEPS)
    yield v
    v.close()


def test_make_vec_uses_the_vector_entry_point(vec) -> None:
    assert isinstance(vec, DynMapVectorEnv)
    assert vec.num_envs == N
    assert vec.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP


def test_spaces_are_the_batched_single_spaces(vec) -> None:
    single = DynMapEnv(world="apartment")
    assert vec.single_observation_space == single.observation_space
    assert vec.single_action_space == single.action_space
    assert vec.observation_space["scan"].shape == (N, single.observation_space["scan"].shape[0])
    assert vec.observation_space["odom"].shape == (N, 3)
    assert vec.action_space.shape == (N, 2)


def test_reset_and_step_shapes(vec) -> None:
    obs, info = vec.reset(seed=3)
    assert obs in vec.observation_space
    assert info["truth"]["pose"].shape == (N, 3)
    assert info["_truth"].all()
    obs, rew, term, trunc, info = vec.step(vec.action_space.sample())
    assert obs in vec.observation_space
    assert rew.shape == term.shape == trunc.shape == (N,)
    assert rew.dtype == np.float64 and term.dtype == trunc.dtype == np.bool_


def test_same_numbers_as_sync_vector_env_and_single_envs(vec) -> None:
    """Reset with a seed, step across two autoresets (NEXT_STEP): every observation, reward,
    flag and info equals SyncVectorEnv's, and sub-env i equals a single env seeded 7 + i."""
    sync = SyncVectorEnv(
        [lambda: DynMapEnv(world="apartment", max_episode_steps=MAX_STEPS) for _ in range(N)]
    )
    singles = [DynMapEnv(world="apartment", max_episode_steps=MAX_STEPS) for _ in range(N)]
    acts = _actions(STEPS, N)
    a_out, b_out = vec.reset(seed=7), sync.reset(seed=7)
    _assert_same(a_out, b_out)
    s_obs = [env.reset(seed=7 + i)[0] for i, env in enumerate(singles)]
    for i in range(N):
        np.testing.assert_array_equal(a_out[0]["scan"][i], s_obs[i]["scan"])
    done = np.zeros(N, dtype=bool)
    resets = 0
    for act in acts:
        a_out, b_out = vec.step(act), sync.step(act)
        _assert_same(a_out, b_out)
        for i, env in enumerate(singles):
            if done[i]:
                obs, rew, term, trunc = env.reset()[0], 0.0, False, False
                resets += 1
            else:
                obs, rew, term, trunc, _ = env.step(act[i])
            np.testing.assert_array_equal(a_out[0]["scan"][i], obs["scan"])
            np.testing.assert_array_equal(a_out[0]["odom"][i], obs["odom"])
            assert a_out[1][i] == rew and a_out[2][i] == term and a_out[3][i] == trunc
        done = a_out[2] | a_out[3]
    assert resets >= N  # the autoreset path was exercised
    sync.close()


def test_autoreset_next_step(vec) -> None:
    vec.reset(seed=0)
    act = np.zeros((N, 2), dtype=np.float32)
    for _ in range(MAX_STEPS - 1):
        _, _, term, trunc, _ = vec.step(act)
        assert not (term | trunc).any()
    _, _, term, trunc, info = vec.step(act)
    assert trunc.all()
    obs, rew, term, trunc, info = vec.step(act)  # the reset step
    assert (rew == 0.0).all() and not term.any() and not trunc.any()
    assert (info["stamp_s"] == 0.0).all()
    assert (obs["odom"] == 0.0).all()  # odometry starts at 0 each run


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="num_envs"):
        DynMapVectorEnv(num_envs=0, world="apartment")
    v = DynMapVectorEnv(num_envs=2, world="apartment")
    v.reset(seed=0)
    with pytest.raises(ValueError, match="shape"):
        v.step(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="env 1 must be finite"):
        v.step(np.array([[0.1, 0.0], [np.nan, 0.0]]))
    with pytest.raises(ValueError, match="real numbers"):
        v.step(np.array([["a", "b"], ["c", "d"]]))
    with pytest.raises(ValueError, match="seeds"):
        v.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match="World-v0"):
        gym.make_vec("dynmap_sim/World-v0", num_envs=2)


def test_same_numbers_with_people() -> None:
    """The lab's lunch crowd, across autoresets into the next runs: every sub-env's
    observation, reward, flags, people and true ranges equal a single env's with the same
    seed."""
    kw = {"world": "lab", "max_episode_steps": 12}
    n = 3
    vec = DynMapVectorEnv(num_envs=n, **kw)
    singles = [DynMapEnv(**kw) for _ in range(n)]
    opts = {"day": 1, "run": 2}
    obs, info = vec.reset(seed=4, options=opts)
    assert (info["truth"]["n_people"] > 10).all()
    for i, env in enumerate(singles):
        np.testing.assert_array_equal(
            obs["scan"][i], env.reset(seed=4 + i, options=opts)[0]["scan"]
        )
    _step_alongside(vec, singles, _actions(30, n))
    vec.close()


def _step_alongside(vec: DynMapVectorEnv, singles: list[DynMapEnv], acts: np.ndarray) -> int:
    """Step ``vec`` and, alongside, each single env with its row of ``acts`` (resetting it
    where the vector env autoresets): every field of sub-env ``i`` equals single env ``i``'s.
    The number of steps on which some but not all sub-envs reset."""
    n = len(singles)
    done = np.zeros(n, dtype=bool)
    subsets = 0
    for act in acts:
        obs, rew, term, trunc, info = vec.step(act)
        subsets += int(0 < done.sum() < n)
        for i, env in enumerate(singles):
            if done[i]:
                s_obs, s_info = env.reset()
                s_rew, s_term, s_trunc = 0.0, False, False
            else:
                s_obs, s_rew, s_term, s_trunc, s_info = env.step(act[i])
            np.testing.assert_array_equal(obs["scan"][i], s_obs["scan"])
            np.testing.assert_array_equal(obs["odom"][i], s_obs["odom"])
            assert (rew[i], term[i], trunc[i]) == (s_rew, s_term, s_trunc)
            for key, value in s_info["truth"].items():
                np.testing.assert_array_equal(info["truth"][key][i], value)
                assert np.asarray(info["truth"][key][i]).dtype == np.asarray(value).dtype
            for key in ("collision", "route_progress", "stamp_s"):
                assert info[key][i] == s_info[key]
        done = term | trunc
    return subsets


def test_same_numbers_when_sub_envs_end_at_different_steps() -> None:
    """Sub-envs that truncate at different steps: a step that resets some sub-envs and
    drives the others writes the driven ones' rows (a subset) with a single env's numbers."""
    kw = {"world": "lab", "max_episode_steps": 9}
    n = 3
    vec = DynMapVectorEnv(num_envs=n, **kw)
    singles = [DynMapEnv(**kw) for _ in range(n)]
    opts = {"day": 1, "run": 2}
    vec.reset(seed=11, options=opts)
    for i, env in enumerate(singles):
        env.reset(seed=11 + i, options=opts)
        env._steps = vec.envs[i]._steps = 3 * i  # sub-env i truncates 3 i steps earlier
    subsets = _step_alongside(vec, singles, _actions(20, n))
    assert subsets > 0
    vec.close()


def test_step_and_reset_after_close_and_step_before_reset_raise() -> None:
    vec = DynMapVectorEnv(num_envs=2, world="apartment")
    with pytest.raises(ResetNeeded, match="reset"):
        vec.step(np.zeros((2, 2), np.float32))
    vec.reset(seed=0)
    vec.step(np.zeros((2, 2), np.float32))
    vec.close()
    with pytest.raises(ClosedEnvironmentError, match="close"):
        vec.step(np.zeros((2, 2), np.float32))
    with pytest.raises(ClosedEnvironmentError, match="close"):
        vec.reset(seed=0)
