"""``autonomous``: the agent's own navigation stack drives, on a localizer's estimate.

Hentschel & Wagner's robot drove itself (§7.1: "operated four weeks fully autonomously").
This driver is that robot's navigation: the
:class:`~dynmap_sim.agent.navigation.stack.NavigationStack` (route memory and A* on it, H&W
§5, §6.2; the stack's own costmap and grid A* replanning around a block, corridor following
with reactive avoidance, §6.3; a collision monitor and recovery, after nav2). It sees no
truth: each step it gets the scan, the odometry and the estimate of the localizer the
scenario names (``[driver] localizer = "<label>"``), which runs in lock-step with the
simulation; the prior's route is the route to drive (H&W Fig. 4), its end the run's goal.
"""

from __future__ import annotations

import json
from dataclasses import fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.navigation.stack import NavigationStack, StackParams
from dynmap_sim.experiments.drivers.driver import (
    Driver,
    DriverContext,
    RunStart,
    StepInput,
    register_driver,
)


@register_driver("autonomous")
class AutonomousDriver(Driver):
    """The navigation stack as a driver (module doc). ``params``: the top-level fields of
    :class:`~dynmap_sim.agent.navigation.stack.StackParams` (the cruise speed is the
    scenario's ``speed_mps``)."""

    needs_estimate = True

    def __init__(self, context: DriverContext, **params: Any) -> None:
        known = {f.name for f in fields(StackParams)} - {"speed_mps"}
        super().__init__(context, **{k: v for k, v in params.items() if k not in known})
        stack_params = StackParams(speed_mps=context.speed_mps, **params)
        self.stack = NavigationStack(context.laser, context.robot_radius_m, stack_params)
        self._step = 0
        self._n_events = 0

    def begin_run(self, start: RunStart) -> None:
        self.events = []
        self.skipped_waypoints = 0
        self._step = 0
        self._n_events = 0
        self.stack.begin_run(start.prior)

    @property
    def done(self) -> bool:
        return self.stack.done or self.stack.gave_up

    def act(self, step: StepInput) -> NDArray[np.float32]:
        assert step.estimate is not None  # the loop hands it (needs_estimate)
        action = self.stack.step(step.t_s, step.odom, step.scan, step.estimate)
        events = self.stack.events
        self.events += [
            (self._step, t, kind, detail) for t, kind, detail in events[self._n_events :]
        ]
        self._n_events = len(events)
        self._step += 1
        return action

    def stats(self) -> dict[str, float]:
        return self.stack.counters()

    def end_run(self) -> None:
        self.stack.end_run()

    def run_artifacts(self) -> dict[str, bytes]:
        """The route memory after the run (JSON, :meth:`RouteMemory.to_dict`, cf. H&W Fig. 8)
        and the last planned path (``(K, 2)`` float64 bytes)."""
        out: dict[str, bytes] = {}
        mem = self.stack.route_memory
        if mem is not None:
            out["route_memory.json"] = json.dumps(mem.to_dict()).encode()
        path = self.stack.planned_path()
        if path is not None:
            out["planned_path.f8"] = np.ascontiguousarray(path, dtype="<f8").tobytes()
        return out
