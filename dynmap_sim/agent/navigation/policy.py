"""The navigation stack as a Gymnasium policy: a baseline agent for a plain ``env.step`` loop.

:class:`NavigationPolicy` pairs a localizer (the Localizer role, e.g. ``static-mcl``) with a
:class:`~.stack.NavigationStack`: ``reset(prior)`` at the start of an episode, then
``act(obs)`` with each observation of the env (``obs["scan"]``, ``obs["odom"]``) returns the
action ``[v_mps, omega_radps]``. The policy stamps the observations itself (one scan period a
step), so it needs nothing from ``info``: it never sees the truth. It does not import
Gymnasium either: any loop that hands it the observation dict works.

Example (the apartment, day 1, steering on Biber & Duckett's dynamic map, which maps on
its first run)::

    import numpy as np
    from dynmap_sim.env import DynMapEnv
    from dynmap_sim.agent.localization.localizer import make_localizer
    from dynmap_sim.agent.navigation.policy import NavigationPolicy
    from dynmap_sim.agent.navigation.stack import NavigationStack
    from dynmap_sim.types import Prior

    env = DynMapEnv("apartment", people=False)
    obs, info = env.reset(seed=0, options={"day": 1})
    u = env.unwrapped
    facts = u.world_facts()  # what a scenario grants: start pose, route, walls, bounds
    prior = Prior(
        initial_pose=np.array(facts.start_pose),
        initial_pose_cov=np.diag([0.05**2, 0.05**2, 0.05**2]),
        walls=np.array(facts.wall_segments),
        bounds=facts.bounds,
        day=1, run=1, first_run=True,
        route=np.array(facts.route),
    )
    loc = make_localizer("dynamic-map", laser=u.laser_spec, rng=np.random.default_rng(0))
    policy = NavigationPolicy(loc, NavigationStack(u.laser_spec, u.robot_radius_m))
    policy.reset(prior)
    terminated = truncated = False
    while not (terminated or truncated or policy.done):
        obs, reward, terminated, truncated, info = env.step(policy.act(obs))
    policy.end_run()

Across episodes keep the same policy (its localizer and route memory learn): call
:meth:`NavigationPolicy.reset` with each run's prior; it ends the previous run first.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.grid import OccupancyGrid
from dynmap_sim.agent.localization.localizer import Localizer
from dynmap_sim.agent.navigation.stack import NavigationStack
from dynmap_sim.types import Odometry, PoseEstimate, Prior, Scan


class NavigationPolicy:
    """A localizer and a navigation stack as a policy (module doc).

    ``use_localizer_map``: when the localizer exposes an occupancy grid (``grid``, e.g.
    ``static-mcl``'s map), the stack's costmap takes it as its static layer at each reset
    (a first-run SLAM map knows the furniture; the prior's walls do not).
    """

    def __init__(
        self, localizer: Localizer, stack: NavigationStack, use_localizer_map: bool = True
    ) -> None:
        self.localizer = localizer
        self.stack = stack
        self.use_localizer_map = bool(use_localizer_map)
        self.period_s = float(stack.laser.scan_period_s)
        #: observations handed to :meth:`act` in this episode
        self.stamp = 0
        #: the localizer's last estimate (None before the first :meth:`act`)
        self.estimate: PoseEstimate | None = None
        self._running = False

    @property
    def done(self) -> bool:
        """The stack reached the goal or gave up: the policy only stops the robot now."""
        return self.stack.done or self.stack.gave_up

    def reset(self, prior: Prior) -> None:
        """Start an episode with the prior a scenario grants (``prior.route`` needed on the
        first episode); ends the previous one if it is still open."""
        if self._running:
            self.end_run()
        self.localizer.begin_run(prior)
        self.stack.begin_run(prior)
        grid = getattr(self.localizer, "grid", None)
        if self.use_localizer_map and isinstance(grid, OccupancyGrid):
            self.stack.set_static_map(grid)
        self.stamp = 0
        self.estimate = None
        self._running = True

    def act(self, obs: Mapping[str, Any]) -> NDArray[np.float32]:
        """The action ``[v_mps, omega_radps]`` (float32) for the env's observation dict."""
        if not self._running:
            raise RuntimeError("call reset(prior) before act()")
        t_s = self.stamp * self.period_s
        self.stamp += 1
        odom = Odometry(np.asarray(obs["odom"], dtype=np.float64).copy(), t_s)
        scan = Scan(np.asarray(obs["scan"], dtype=np.float32).copy(), t_s)
        self.estimate = self.localizer.update(odom, scan)
        return self.stack.step(t_s, odom, scan, self.estimate)

    def end_run(self) -> None:
        """End the episode: the localizer's and the stack's end-of-run learning."""
        if not self._running:
            return
        self._running = False
        self.localizer.end_run()
        self.stack.end_run()
