"""Read-only views of the ground truth, as the env hands them to the experiment engine.

The env's ``info["truth"]`` carries what changes every step (pose, beam labels, people); the
views here carry what an experiment needs besides: the calendar's runs, the world's fixed
facts (start pose, route, bounds, the static walls a scenario may grant as a prior) and a
snapshot of the current obstacles (for the truth-seeing ``tour`` operator and the figures).
They are plain frozen data with read-only arrays, so nothing downstream can change the
simulation through them. The agent never imports this module (an import contract).
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.types import Prior

FloatArray = NDArray[np.float64]


def read_only(a: NDArray[np.generic]) -> NDArray[np.generic]:
    """A read-only copy of ``a``."""
    out = np.array(a, copy=True)
    out.setflags(write=False)
    return out


@dataclass(frozen=True)
class RunSlot:
    """One run of the calendar: working ``day`` and ``run`` (1-based), ``date``, clock
    ``start_s`` [s since midnight]."""

    day: int
    run: int
    date: dt.date
    start_s: float


@dataclass(frozen=True)
class WorldFacts:
    """What does not change within a world: ``name``; ``bounds`` ``(xmin, ymin, xmax, ymax)``
    [m]; the robot's ``start_pose`` ``(3,)`` and ``route`` ``(K, 2)`` in the map frame; the
    static ``wall_segments`` ``(N, 4)`` (the 'walls' prior); the calendar's ``slots``."""

    name: str
    bounds: tuple[float, float, float, float]
    start_pose: FloatArray
    route: FloatArray
    wall_segments: FloatArray
    slots: tuple[RunSlot, ...]

    def prior(
        self,
        day: int,
        run: int = 1,
        first_run: bool | None = None,
        sigma_xy_m: float = 0.05,
        sigma_theta_rad: float = 0.05,
        walls: bool = True,
        known_pose: bool = True,
        route: ArrayLike | None = None,
    ) -> Prior:
        """The prior a scenario grants for run ``run`` of ``day``: with ``known_pose`` the start
        pose with a Gaussian of ``sigma_xy_m`` / ``sigma_theta_rad`` (``[prior] initial_pose =
        "known"``), with ``walls`` the static walls (H&W Fig. 4, ``[prior] map = "walls"``),
        the bounds, and ``route`` (default: the world's; a scenario may give its own);
        ``first_run`` defaults to day 1 run 1. The experiment engine's episodes take their
        prior from here, and so can a plain Gymnasium loop that drives an agent without it."""
        return Prior(
            initial_pose=np.array(self.start_pose, dtype=float) if known_pose else None,
            initial_pose_cov=(
                np.diag([sigma_xy_m**2, sigma_xy_m**2, sigma_theta_rad**2]) if known_pose else None
            ),
            walls=np.array(self.wall_segments, dtype=float) if walls else None,
            bounds=self.bounds,
            route=np.array(self.route if route is None else route, dtype=float),
            day=day,
            run=run,
            first_run=(day, run) == (1, 1) if first_run is None else first_run,
        )


def _no_index() -> NDArray[np.int32]:
    return read_only(np.zeros(0, dtype=np.int32))  # type: ignore[return-value]


@dataclass(frozen=True)
class ObstacleSnapshot:
    """The obstacles now [m]: ``segments`` ``(N, 4)`` with their ``segment_class`` (int8
    :class:`dynmap_sim.types.BeamClass`), ``circles`` ``(M, 3)`` ``x, y, r`` with their
    ``circle_class`` (people's legs included, class PERSON). ``segment_object`` /
    ``circle_object`` index ``object_ids``, the objects' ids (the indices of
    ``info["truth"]["beam_object"]``; empty when the producer does not say)."""

    segments: FloatArray
    segment_class: NDArray[np.int8]
    circles: FloatArray
    circle_class: NDArray[np.int8]
    segment_object: NDArray[np.int32] = field(default_factory=_no_index)
    circle_object: NDArray[np.int32] = field(default_factory=_no_index)
    object_ids: tuple[str, ...] = ()


@dataclass(frozen=True)
class PeopleSnapshot:
    """The people of the current run [m]: ``ids`` (the crowd's, fixed for a run), ``xy``
    ``(n, 2)`` their positions now and ``radius`` ``(n,)`` their bodies' radii."""

    ids: tuple[str, ...]
    xy: FloatArray
    radius: FloatArray
