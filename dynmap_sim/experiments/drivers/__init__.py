"""Drivers: who steers the robot during an experiment (part of the simulation, not the agent).

* :mod:`.driver` — the Driver role, what a driver is given, and the registry;
* :mod:`.tour` — ``tour``, the scripted operator of the papers (sees the truth).
"""

from dynmap_sim.experiments.drivers.driver import (
    DRIVERS,
    Driver,
    DriverContext,
    RunStart,
    StepInput,
    make_driver,
    register_driver,
)
from dynmap_sim.experiments.drivers.tour import TourDriver, TourParams, clip_route

__all__ = [
    "DRIVERS",
    "Driver",
    "DriverContext",
    "RunStart",
    "StepInput",
    "TourDriver",
    "TourParams",
    "clip_route",
    "make_driver",
    "register_driver",
]
