"""The Driver role: who steers the robot during a run (an experiment role, not an agent role).

A driver is built once per experiment with a :class:`DriverContext` and its own parameters
(``[driver] params`` of the scenario), then driven by the episode loop::

    driver.begin_run(RunStart(...))        # after env.reset
    while not driver.done:
        action = driver.act(StepInput(...))  # every control step
    driver.end_run()

What a driver may see is declared, not assumed:

* ``sees_truth = True`` — the papers' human operator (``tour``): :class:`StepInput` and
  :class:`RunStart` carry the true pose, the people and the obstacles. Without it they are
  None, and the driver steers on what the robot senses;
* ``needs_estimate = True`` — the driver steers on a localizer's estimate, the one the
  scenario names (``[driver] localizer = "<label>"``), in lock-step with the simulation: the
  episode loop runs that localizer scan by scan and hands its estimate in
  :attr:`StepInput.estimate`, and those very outputs are stored for it, while the other
  localizers ride along on the recorded stream (H&W §7.3 compared static MCL this way).

Drivers are pickled into the checkpoint after every run; keep them picklable. A user's own
driver is named ``"package.module:ClassName"`` in the scenario.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.registry import Registry
from dynmap_sim.truth import ObstacleSnapshot
from dynmap_sim.types import LaserSpec, Odometry, PoseEstimate, Prior, Scan

FloatArray = NDArray[np.float64]

#: A driver event: ``(step, t_s, kind, detail)`` (e.g. ``detour``, ``wait_for_person``).
Event = tuple[int, float, str, str]


@dataclass(frozen=True)
class DriverContext:
    """What every driver is told about the experiment: the ``route`` ``(K, 2)`` to drive
    [m, map frame], the cruise ``speed_mps``, the robot's ``robot_radius_m``, the control
    period ``dt_s`` and the ``laser`` the scans come from."""

    route: FloatArray
    speed_mps: float
    robot_radius_m: float
    dt_s: float
    laser: LaserSpec


@dataclass(frozen=True)
class RunStart:
    """The start of a run: the agent's ``prior``; with ``sees_truth``, the true
    ``start_pose`` and the ``obstacles`` (else None)."""

    prior: Prior
    start_pose: FloatArray | None = None
    obstacles: ObstacleSnapshot | None = None


@dataclass(frozen=True)
class StepInput:
    """One control step: time ``t_s`` [s since midnight], the sensors (``odom``, ``scan``),
    ``bumped`` (the bumper was pressed in the last step), the steering localizer's
    ``estimate`` (with ``needs_estimate``), and with ``sees_truth`` the true ``pose`` and
    ``people`` ``(P, 3)`` (padding rows are inf)."""

    t_s: float
    odom: Odometry
    scan: Scan
    bumped: bool = False
    estimate: PoseEstimate | None = None
    pose: FloatArray | None = None
    people: FloatArray | None = None


class Driver(ABC):
    """Base class of every driver; see the module doc."""

    #: Registry name (set by :func:`register_driver`).
    name: str = "driver"
    #: True: the driver is given the truth (a human operator). False: only the sensors.
    sees_truth: ClassVar[bool] = False
    #: True: the driver steers on the estimate of the localizer the scenario names.
    needs_estimate: ClassVar[bool] = False

    def __init__(self, context: DriverContext, **params: Any) -> None:
        if params:
            raise TypeError(f"{type(self).__name__}: unknown parameters {sorted(params)}")
        self.context = context
        #: this run's events; the episode loop stores them
        self.events: list[Event] = []
        #: route waypoints the driver gave up on in this run
        self.skipped_waypoints = 0

    @abstractmethod
    def begin_run(self, start: RunStart) -> None:
        """A run starts (after ``env.reset``)."""

    @abstractmethod
    def act(self, step: StepInput) -> NDArray[np.float32]:
        """The command ``[v_mps, omega_radps]`` for this step."""

    @property
    @abstractmethod
    def done(self) -> bool:
        """True when the driver has finished the run (the loop stops)."""

    def teleported(self, pose: FloatArray, t_s: float) -> None:  # noqa: B027 - optional hook
        """The true robot was moved to ``pose`` (a kidnapping; only told to drivers that
        see the truth)."""

    def end_run(self) -> None:  # noqa: B027 - optional hook
        """The run is over; drop what need not go into the checkpoint."""

    def stats(self) -> dict[str, float]:
        """This run's counts for the navigation measures (asked before :meth:`end_run`):
        ``replans``, ``recoveries``, ``stuck_s``, ``gave_up``; missing keys count 0."""
        return {}

    def run_artifacts(self) -> dict[str, bytes]:
        """What the driver hands over after a run for figures (asked after :meth:`end_run`),
        name -> bytes (e.g. JSON of its route memory); stored with the run."""
        return {}


#: The driver registry.
DRIVERS: Registry[Driver] = Registry(
    "driver",
    Driver,
    builtin_modules=(
        "dynmap_sim.experiments.drivers.tour",
        "dynmap_sim.experiments.drivers.autonomous",
    ),
)

#: Class decorator: make a :class:`Driver` available under a name.
register_driver = DRIVERS.register


def make_driver(kind: str, context: DriverContext, params: dict[str, Any]) -> Driver:
    """Build the driver registered as ``kind`` (or ``"module:Class"``) with ``params``."""
    return DRIVERS.get(kind)(context, **params)
