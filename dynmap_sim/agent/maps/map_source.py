"""Map sources: where a localizer that needs a fixed occupancy grid gets it from.

``static-mcl`` localizes on a map that never changes (H&W §7's static-MCL comparison, B&D
§5.3's static baselines). The map comes from a :class:`MapSource`, chosen by the scenario's
``map_source`` name:

* ``"first-run"`` (:class:`FirstRunMap`): built by the static SLAM of the experiment's first
  run (B&D §4: "an initial map is built from the first run ... by a classical static SLAM
  algorithm", :class:`~dynmap_sim.agent.mapping.first_run.FirstRunMapper`); while it builds,
  the source reports the SLAM front end's estimates;
* ``"prior-walls"`` (:class:`PriorWallsMap`): the walls the scenario's prior grants,
  rasterized to a 5 cm grid.

The protocol follows the localizer's runs: :meth:`MapSource.begin_run` (start building if
there is no map yet), :meth:`MapSource.update` while :attr:`MapSource.building`,
:meth:`MapSource.end_run` (the map is done), then :attr:`MapSource.grid` is
:attr:`MapSource.ready`. A map handed over from outside (replay's map from a log's poses)
is :meth:`MapSource.set_grid`.

``dynamic-map`` maps its first run with the same
:class:`~dynmap_sim.agent.mapping.first_run.FirstRunMapper`, but what it needs are the
keyframes (its initial local maps, B&D §4) and the corrected trajectory, not a grid: it uses
the mapper itself rather than a map source, which would render a grid it never reads and
keep the first run's keyframes in every checkpoint.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from dynmap_sim.agent.grid import OccupancyGrid
from dynmap_sim.agent.mapping.first_run import FirstRunConfig, FirstRunMapper, StaticMap
from dynmap_sim.types import LaserSpec, Odometry, PoseEstimate, Prior, Scan


class MapSource(ABC):
    """The source of a localizer's fixed map (see the module docstring). Picklable."""

    #: The ``map_source`` name.
    name: str = "map-source"

    def __init__(self) -> None:
        #: The map, once there is one; it never changes afterwards.
        self.grid: OccupancyGrid | None = None

    @property
    def ready(self) -> bool:
        """The map is there."""
        return self.grid is not None

    @property
    def building(self) -> bool:
        """The map is being built during this run: :meth:`update` gives the pose estimate."""
        return False

    def set_grid(self, grid: OccupancyGrid) -> None:
        """Use ``grid`` (a map from outside); nothing is built any more."""
        self.grid = grid

    @abstractmethod
    def begin_run(self, prior: Prior) -> None:
        """A run starts with ``prior``: make the map, or start building it, if there is none."""

    def update(self, odom: Odometry, scan: Scan) -> PoseEstimate:
        """Fuse one odometry reading and scan into the map being built; its pose estimate."""
        raise RuntimeError(f"map source {self.name!r}: update() while not building a map")

    def end_run(self) -> None:  # noqa: B027 - optional hook
        """The run is over: a map being built is finished."""


class PriorWallsMap(MapSource):
    """The prior's walls rasterized to a 5 cm grid, free space flood-filled from the prior's
    initial pose."""

    name = "prior-walls"

    def begin_run(self, prior: Prior) -> None:
        if self.grid is not None:
            return
        if prior.walls is None or len(prior.walls) == 0:
            raise ValueError("map_source='prior-walls' needs prior.walls")
        seed = None if prior.initial_pose is None else np.asarray(prior.initial_pose)[:2]
        self.grid = OccupancyGrid.from_segments(prior.walls, free_seed_xy_m=seed)


class FirstRunMap(MapSource):
    """The first run's static SLAM map (:class:`~dynmap_sim.agent.mapping.first_run.
    FirstRunMapper` with ``config``), built during the first run that finds no map."""

    name = "first-run"

    def __init__(self, laser: LaserSpec, config: FirstRunConfig) -> None:
        super().__init__()
        self.laser = laser
        self.config = config
        #: The whole SLAM result (trajectory, keyframes, grid) once built.
        self.static_map: StaticMap | None = None
        self._mapper: FirstRunMapper | None = None

    @property
    def building(self) -> bool:
        return self._mapper is not None

    def begin_run(self, prior: Prior) -> None:
        self._mapper = None
        if self.grid is None:  # the map is still to build: map during this run
            start = np.zeros(3) if prior.initial_pose is None else np.asarray(prior.initial_pose)
            self._mapper = FirstRunMapper(self.laser, start, self.config, prior.walls)

    def update(self, odom: Odometry, scan: Scan) -> PoseEstimate:
        if self._mapper is None:
            return super().update(odom, scan)
        return self._mapper.update(odom, scan)

    def end_run(self) -> None:
        if self._mapper is not None:
            self.static_map = self._mapper.finish()
            self.grid = self.static_map.grid
            self._mapper = None


#: The ``map_source`` names.
MAP_SOURCES = ("first-run", "prior-walls")


def make_map_source(
    name: str, laser: LaserSpec, mapper_params: dict[str, Any] | None = None
) -> MapSource:
    """The map source called ``name``; ``mapper_params`` (``"first-run"`` only) are
    :meth:`FirstRunConfig.from_params` fields.

    The first-run grid takes hits up to the sensor's range unless ``mapper_params`` say
    otherwise: :class:`FirstRunConfig`'s 3 m keeps walls sharper but left the lab's hallway
    walls out of the map, so MCL followed shuffled chairs there (32 % of lab scans lost on
    days 1-4, 6.7 % with the full range).
    """
    if name == "first-run":
        params = {"map_max_hit_range_m": laser.range_max_m, **(mapper_params or {})}
        return FirstRunMap(laser, FirstRunConfig.from_params(**params))
    if name == "prior-walls":
        if mapper_params:
            raise ValueError("mapper_params apply to map_source='first-run' only")
        return PriorWallsMap()
    raise ValueError(f"unknown map_source {name!r}; known: {MAP_SOURCES}")
