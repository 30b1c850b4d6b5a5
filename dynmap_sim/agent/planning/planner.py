"""The Planner role: a collision-free path between two points on a clearance grid.

``plan(start, goal, grid) -> (K, 2) polyline or None``. Implementations register by name
(``grid-dijkstra``); a user's own class is named ``"package.module:ClassName"``. A planner
only knows the grid it is given, so the same class serves the truth-seeing ``tour`` operator
and the agent's own navigation.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid
from dynmap_sim.registry import Registry

FloatArray = NDArray[np.float64]


class Planner(ABC):
    """Plans on a :class:`ClearanceGrid`: never closer than ``min_clearance_m`` to an
    obstacle (robot radius plus a safety margin), preferring ``preferred_clearance_m``."""

    #: Registry name (set by :func:`register_planner`).
    name: str = "planner"

    def __init__(self, min_clearance_m: float, preferred_clearance_m: float) -> None:
        """Subclasses take their own tunables as keywords after these two."""
        self.min_clearance_m = float(min_clearance_m)
        self.preferred_clearance_m = float(max(preferred_clearance_m, min_clearance_m))

    @abstractmethod
    def plan(self, start: FloatArray, goal: FloatArray, grid: ClearanceGrid) -> FloatArray | None:
        """A polyline ``(K, 2)`` [m] from ``start`` to ``goal``, or None when unreachable."""


#: The planner registry.
PLANNERS: Registry[Planner] = Registry(
    "planner",
    Planner,
    builtin_modules=(
        "dynmap_sim.agent.planning.grid_dijkstra",
        "dynmap_sim.agent.planning.grid_astar",
    ),
)

#: Class decorator: make a :class:`Planner` available under a name.
register_planner = PLANNERS.register
