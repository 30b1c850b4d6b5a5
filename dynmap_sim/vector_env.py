"""N robots in N worlds as one Gymnasium ``VectorEnv`` (the envs' ``vector_entry_point``).

``gymnasium.make_vec("dynmap_sim/Lab-v0", num_envs=8)`` builds a :class:`DynMapVectorEnv`:
``N`` :class:`~dynmap_sim.env.DynMapEnv` sub-envs whose observations are written straight
into preallocated batch arrays (``scan`` ``(N, n_beams)`` float32, ``odom`` ``(N, 3)``) and
whose infos are batched the way Gymnasium's own vector envs batch them (``VectorEnv._add_info``:
an array per key plus a ``_key`` mask), without ``SyncVectorEnv``'s per-step deep copies and
wrapper layers.

Semantics are those of ``SyncVectorEnv`` of the same sub-envs, number for number (the tests
check it): ``reset(seed=s)`` seeds sub-env ``i`` with ``s + i`` (or ``seed[i]`` for a list),
``options`` go to every sub-env; autoreset is Gymnasium's default
:attr:`~gymnasium.vector.AutoresetMode.NEXT_STEP`: the step after a sub-env terminated or was
truncated resets it (``reset()`` without seed: the next run of its calendar), ignores its
action and returns its first observation with reward 0 and ``terminated = truncated =
False``.

The sub-envs step one after another (each robot, world, scan and noise draw as a lone env
steps them: compiled kernels); their observations and infos are written field by field as
rows of the batch arrays (:meth:`~dynmap_sim.env.InfoRows.write_steps`).
``benchmarks/bench_peers.py --only vector`` times the whole against sequential envs.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.error import ClosedEnvironmentError, ResetNeeded
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from dynmap_sim.env import DynMapEnv, InfoRows


class DynMapVectorEnv(VectorEnv):
    """``num_envs`` :class:`DynMapEnv` sub-envs built with the same keyword arguments."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 1, **kwargs: Any) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        if kwargs.get("render_mode") is not None:
            raise ValueError("DynMapVectorEnv does not render; use gymnasium.make for frames")
        self.num_envs = num_envs
        self.envs = [DynMapEnv(**kwargs) for _ in range(num_envs)]
        first = self.envs[0]
        self.single_observation_space = first.observation_space
        self.single_action_space = first.action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.render_mode = None
        n_beams = self.single_observation_space["scan"].shape[0]
        self._rows = InfoRows(num_envs, n_beams, first.max_people)
        self._rewards = np.zeros(num_envs, dtype=np.float64)
        self._terminations = np.zeros(num_envs, dtype=np.bool_)
        self._truncations = np.zeros(num_envs, dtype=np.bool_)
        self._autoreset = np.zeros(num_envs, dtype=np.bool_)

    def _obs(self) -> dict[str, np.ndarray]:
        return {"scan": self._rows.scan.copy(), "odom": self._rows.odom.copy()}

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Reset every sub-env (seeds as ``SyncVectorEnv``: ``seed + i`` or ``seed[i]``);
        ``ClosedEnvironmentError`` after :meth:`close`."""
        if self.closed:
            raise ClosedEnvironmentError("reset() after close(): make a new vector env")
        if seed is None:
            seeds: list[int | None] = [None] * self.num_envs
        elif isinstance(seed, int) and not isinstance(seed, bool):
            seeds = [seed + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"reset: {len(seeds)} seeds for {self.num_envs} envs")
        for i, (env, s) in enumerate(zip(self.envs, seeds, strict=True)):
            self._rows.put(i, *env.reset(seed=s, options=options))
        self._autoreset[:] = False
        self._terminations[:] = False
        self._truncations[:] = False
        return self._obs(), self._rows.infos()

    def step(
        self, actions: Any
    ) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every sub-env with its row of ``actions`` ``(num_envs, 2)``; NEXT_STEP
        autoreset for those that ended on the previous step. ``ResetNeeded`` before the
        first :meth:`reset`, ``ClosedEnvironmentError`` after :meth:`close`."""
        if self.closed:
            raise ClosedEnvironmentError("step() after close(): make a new vector env")
        a = np.asarray(actions)
        if a.shape != (self.num_envs, 2):
            raise ValueError(f"actions must have shape ({self.num_envs}, 2), got {a.shape}")
        # the checks of DynMapEnv._drive, for all actions at once (those of envs that reset
        # are ignored, as SyncVectorEnv ignores them)
        if a.dtype.kind not in "iuf" and not self._autoreset.all():
            raise ValueError(
                f"actions must be real numbers (v_mps, omega_radps), got {a.dtype} values {a!r}"
            )
        a = a.astype(np.float64) if a.dtype.kind in "iuf" else np.zeros((self.num_envs, 2))
        bad = ~np.isfinite(a).all(axis=1) & ~self._autoreset
        if bad.any():
            i = int(bad.argmax())
            raise ValueError(
                f"action of env {i} must be finite (v_mps, omega_radps), got {a[i].tolist()}"
            )
        vw = a.tolist()
        driven: list[tuple[int, np.ndarray, bool]] = []  # (env, pose, collision)
        for i, env in enumerate(self.envs):
            if self._autoreset[i]:
                self._rows.put(i, *env.reset())
                self._rewards[i] = 0.0
                self._terminations[i] = False
                self._truncations[i] = False
            else:
                if not env._started:
                    raise ResetNeeded("call reset() before step()")
                pose, collision = env._drive_vw(*vw[i])
                driven.append((i, pose, collision))
        stepping = [self.envs[i] for i, _, _ in driven]
        for env, (i, pose, collision) in zip(stepping, driven, strict=True):
            env.world.step(env.dt_s, robot_pose=pose, robot_radius_m=env.robot_params.radius_m)
            _, _, r, term, trunc = env._score(pose, collision)
            self._rewards[i] = r
            self._terminations[i] = term
            self._truncations[i] = trunc
        if driven:
            poses = [p for _, p, _ in driven]
            casts = [
                e.lidar.cast(p, e.world.geometry) for e, p in zip(stepping, poses, strict=True)
            ]
            true_r = np.stack([c[0] for c in casts])
            hits = np.stack([c[1] for c in casts])
            noisy = np.stack(
                [
                    e.lidar.apply_noise(r, e._rng_lidar)
                    for e, r in zip(stepping, true_r, strict=True)
                ]
            )
            at = [i for i, _, _ in driven]
            collisions = [c for _, _, c in driven]
            self._rows.write_steps(stepping, at, poses, collisions, (true_r, hits), noisy)
        np.logical_or(self._terminations, self._truncations, out=self._autoreset)
        return (
            self._obs(),
            self._rewards.copy(),
            self._terminations.copy(),
            self._truncations.copy(),
            self._rows.infos(),
        )

    def close_extras(self, **kwargs: Any) -> None:
        for env in self.envs:
            env.close()


def make_vector_env(num_envs: int = 1, **kwargs: Any) -> DynMapVectorEnv:
    """The ``vector_entry_point`` of the registered envs (``World-v0`` needs ``world=``)."""
    if "world" not in kwargs:
        raise ValueError("dynmap_sim/World-v0 needs world=PATH (a world TOML file) or a WorldSpec")
    return DynMapVectorEnv(num_envs=num_envs, **kwargs)
