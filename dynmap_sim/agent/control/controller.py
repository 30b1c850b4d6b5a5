"""The Controller role: ``(v, omega)`` commands that follow a path.

A controller is given a path (``set_path``) and asked every control step for a command at the
robot's pose, with the clearance grid it may regulate its speed by and an optional external
speed limit (nav2's controller server takes its speed limits from outside the same way).
Implementations register by name (``pure-pursuit``); a user's own class is named
``"package.module:ClassName"``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid
from dynmap_sim.registry import Registry

FloatArray = NDArray[np.float64]

#: An external speed limit: a factor in [0, 1] on the forward speed, asked only when the
#: controller is about to drive along the path (not while it turns on the spot or is done).
SpeedLimit = Callable[[], float]


class Controller(ABC):
    """Follows a polyline path; see the module doc."""

    #: Registry name (set by :func:`register_controller`).
    name: str = "controller"

    def __init__(self, speed_mps: float, min_clearance_m: float) -> None:
        """``speed_mps``: the cruise speed; ``min_clearance_m``: the hard clearance (robot
        radius plus a safety margin) [m]. Subclasses take their own tunables as keywords."""
        self.speed_mps = float(speed_mps)
        self.min_clearance_m = float(min_clearance_m)

    @abstractmethod
    def set_path(self, path: FloatArray | None) -> None:
        """Follow ``path`` ``(K, 2)`` [m] from its first vertex on (None: stop)."""

    @property
    @abstractmethod
    def segment(self) -> int:
        """Index of the path segment being followed (its start vertex)."""

    @property
    @abstractmethod
    def done(self) -> bool:
        """True when there is no path or its end is reached."""

    @abstractmethod
    def command(
        self, pose: FloatArray, grid: ClearanceGrid, speed_limit: SpeedLimit | None = None
    ) -> NDArray[np.float32]:
        """The command ``[v_mps, omega_radps]`` at ``pose`` (map frame)."""


#: The controller registry.
CONTROLLERS: Registry[Controller] = Registry(
    "controller",
    Controller,
    builtin_modules=(
        "dynmap_sim.agent.control.pure_pursuit",
        "dynmap_sim.agent.control.corridor_follower",
    ),
)

#: Class decorator: make a :class:`Controller` available under a name.
register_controller = CONTROLLERS.register
