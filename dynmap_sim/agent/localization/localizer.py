"""The Localizer role (docs/architecture.md §5) and its registry.

A localizer is built once per experiment with the laser description and its own random
generator, then driven by the experiment runner::

    loc = make_localizer("static-mcl", laser=spec, rng=rng, config="tuned")
    for day, run in calendar:
        loc.begin_run(prior)
        for odom, scan in stream:
            est = loc.update(odom, scan)
        loc.end_run()
        ...
        loc.end_day()          # after the last run of a day

Localizers must be picklable: the runner checkpoints them after every run.

Users plug in their own class by ``"package.module:ClassName"``; built-in classes register
themselves with :func:`register_localizer` (:class:`dynmap_sim.registry.Registry`; a name
registered twice is an error).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from dynmap_sim.registry import Registry
from dynmap_sim.types import Diagnostic, LaserSpec, Odometry, PoseEstimate, Prior, Scan

if TYPE_CHECKING:
    from dynmap_sim.agent.grid import OccupancyGrid


class Localizer(ABC):
    """Base class of every localizer. Subclasses take their parameters as keyword arguments."""

    #: Registry name (set by :func:`register_localizer`).
    name: str = "localizer"

    #: The diagnostics this localizer reports, per scan (in ``PoseEstimate.extras``) and per
    #: run (:class:`~dynmap_sim.types.Diagnostic`). The results store keeps exactly these:
    #: a column or a table row each, made from the declaration; other extras are not stored.
    diagnostics: ClassVar[tuple[Diagnostic, ...]] = ()

    def __init__(self, laser: LaserSpec, rng: np.random.Generator, **params: Any) -> None:
        if params:
            raise TypeError(f"{type(self).__name__}: unknown parameters {sorted(params)}")
        self.laser = laser
        self.rng = rng

    @abstractmethod
    def begin_run(self, prior: Prior) -> None:
        """Start a run (one episode) with the prior knowledge the scenario grants."""

    @abstractmethod
    def update(self, odom: Odometry, scan: Scan) -> PoseEstimate:
        """Fuse one odometry reading and one scan; return the pose estimate in the map frame."""

    def end_run(self) -> None:  # noqa: B027 - optional hook
        """The run is over (B&D §4.4: offline learning of the run's timescale happens here)."""

    def end_day(self) -> None:  # noqa: B027 - optional hook
        """The day is over (B&D §4.4: daily timescales are learned here)."""

    def run_diagnostics(self) -> Mapping[str, Any]:
        """The values of the declared per-run diagnostics without ``counts_of``, asked for
        after :meth:`end_run`: name -> array-like of the declared shape (none: empty)."""
        return {}

    def day_artifacts(self) -> Mapping[str, bytes | Mapping[str, np.ndarray]]:
        """What this localizer hands over for the day, asked for after :meth:`end_day`:
        name -> bytes or named arrays (e.g. a compact snapshot of its map). The results store
        keeps them per day without pickling (``ResultsDB.artifacts``); empty: nothing today."""
        return {}


class MapUser(ABC):
    """Capability of a :class:`Localizer` that localizes on a fixed occupancy grid: it accepts
    one handed to it instead of making its own (e.g. ``static-mcl``, whose map otherwise comes
    from its map source, :mod:`dynmap_sim.agent.maps.map_source`).

    Whoever has a map for such localizers (replay's map from a log's poses) tests
    ``isinstance(loc, MapUser)`` and calls :meth:`set_map` before the first run.
    """

    @abstractmethod
    def set_map(self, grid: OccupancyGrid) -> None:
        """Localize on ``grid`` from now on; no map of its own is built any more."""


class ScanMapUser(ABC):
    """Capability of a :class:`Localizer` whose map is made of scans (e.g. ``dynamic-map``'s
    sample-based local maps, Biber & Duckett 2009 §4): it accepts scans at given poses as its
    first map instead of mapping its first run with its own SLAM.

    Whoever has poses for a log's scans (replay's ``--map-from-log-poses``, e.g. a reference
    log's corrected poses) tests ``isinstance(loc, ScanMapUser)`` and calls
    :meth:`set_map_from_scans` before the first run.
    """

    @abstractmethod
    def set_map_from_scans(
        self,
        poses: np.ndarray,
        ranges_m: Sequence[np.ndarray],
        run_poses: np.ndarray | None = None,
        run_odometry: np.ndarray | None = None,
    ) -> None:
        """Make the first map from scans ``ranges_m`` (each ``(n_beams,)`` [m], ``inf``: no
        return) taken at robot ``poses`` ``(K, 3)`` in the map frame; no first-run SLAM.
        ``run_poses`` and ``run_odometry`` ``(N, 3)``, when known: the poses (NaN: unknown)
        and the odometry of every scan of the run the map stands for, from which the
        localizer may acquire its odometry model (B&D §4.3's ``C_O``)."""


#: The localizer registry (built-in localizers register themselves on first lookup).
LOCALIZERS: Registry[Localizer] = Registry(
    "localizer",
    Localizer,
    builtin_modules=(
        "dynmap_sim.agent.localization.dead_reckoning",
        "dynmap_sim.agent.localization.particle_filter",
        "dynmap_sim.agent.localization.dynamic_map_localizer",
        "dynmap_sim.agent.localization.adaptive_memory.localizer",
        "dynmap_sim.agent.localization.fremen_localizer",
        "dynmap_sim.agent.localization.markov_grid_localizer",
    ),
)

#: Class decorator: make a :class:`Localizer` available under a name (a duplicate is an error).
register_localizer = LOCALIZERS.register


def make_localizer(
    name: str, *, laser: LaserSpec, rng: np.random.Generator, **params: Any
) -> Localizer:
    """Build the localizer registered as ``name`` (or ``"module:Class"``) with ``params``."""
    return LOCALIZERS.get(name)(laser=laser, rng=rng, **params)
