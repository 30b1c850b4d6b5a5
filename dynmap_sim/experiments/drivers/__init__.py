"""Drivers: who steers the robot during an experiment (part of the simulation, not the agent).

``tour`` is the scripted operator of the papers (:mod:`.tour`).
"""

from dynmap_sim.experiments.drivers.tour import TourDriver, TourParams, clip_route

__all__ = ["TourDriver", "TourParams", "clip_route"]
