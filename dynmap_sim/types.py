"""Plain data types shared across the simulator, the agent and the metrics.

This module is the *only* place where the simulator side (``world/``, ``sensors/``,
``robot/``, ``env``) and the agent side (``agent/``) meet. It holds what a real robot would
also have: a description of its laser scanner, the readings it delivers, odometry, and the
prior knowledge a scenario grants. Ground truth never appears in these types.

Conventions (docs/architecture.md §4):

* poses are ``(x_m, y_m, theta_rad)`` float64 arrays, angles counter-clockwise from +x;
* frames follow REP-105: ``map -> odom -> base_link -> laser``;
* laser readings follow REP-117: ``+inf`` no return, ``-inf`` too close, ``NaN`` invalid.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Names of the ground-truth beam classes, indexed by :class:`BeamClass`.
BEAM_CLASSES: tuple[str, ...] = ("none", "wall", "furniture", "exhibit", "door", "person", "robot")


class BeamClass(IntEnum):
    """Semantic class of what a laser beam hit (ground truth, never given to the agent)."""

    NONE = 0
    WALL = 1
    FURNITURE = 2
    EXHIBIT = 3
    DOOR = 4
    PERSON = 5
    ROBOT = 6


@dataclass(frozen=True)
class LaserSpec:
    """What the agent knows about its laser scanner (a ROS ``sensor_msgs/LaserScan`` header).

    Angles are in radians in the laser frame; beam ``i`` points at
    ``angle_min_rad + i * angle_increment_rad``. The laser is mounted at
    ``mount_pose = (x_m, y_m, yaw_rad)`` in the robot's ``base_link`` frame.
    """

    name: str
    n_beams: int
    angle_min_rad: float
    angle_increment_rad: float
    range_min_m: float
    range_max_m: float
    scan_period_s: float
    time_increment_s: float
    mount_pose: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def angle_max_rad(self) -> float:
        """Angle of the last beam [rad]."""
        return self.angle_min_rad + (self.n_beams - 1) * self.angle_increment_rad

    def angles(self) -> FloatArray:
        """Beam angles in the laser frame [rad], shape ``(n_beams,)``."""
        return self.angle_min_rad + self.angle_increment_rad * np.arange(
            self.n_beams, dtype=np.float64
        )


@dataclass(frozen=True)
class Scan:
    """One laser scan: ``ranges_m`` (REP-117 encoded, float32) taken at ``stamp_s``."""

    ranges_m: NDArray[np.float32]
    stamp_s: float = 0.0


@dataclass(frozen=True)
class Odometry:
    """Wheel odometry: the robot's pose in the ``odom`` frame (it drifts), at ``stamp_s``."""

    pose: FloatArray
    stamp_s: float = 0.0


@dataclass(frozen=True)
class Prior:
    """Prior knowledge a scenario grants the agent at the start of a run.

    ``initial_pose`` is the pose in the map frame the robot is told it starts from (``None``
    for global localization); ``initial_pose_cov`` its covariance. ``walls`` are the known
    wall segments ``(N, 4)`` as ``x0, y0, x1, y1`` in metres (``None`` when no map is
    granted). ``bounds`` is ``(xmin, ymin, xmax, ymax)`` of the mapped area in metres, used
    for uniform initialization. ``day`` and ``run`` index the calendar (a real robot knows
    the date); ``first_run`` is True on the very first run of an experiment, when a static
    map is to be built. ``route`` is the desired route ``(K, 2)`` [m, map frame] in the
    direction of travel, prior knowledge as in H&W Fig. 4 (None when not granted); a run's
    goal is its end.
    """

    initial_pose: FloatArray | None
    initial_pose_cov: FloatArray | None = None
    walls: FloatArray | None = None
    bounds: tuple[float, float, float, float] | None = None
    day: int = 0
    run: int = 0
    first_run: bool = False
    route: FloatArray | None = None


@dataclass
class PoseEstimate:
    """A localizer's answer: pose ``mean`` in the map frame and its 3x3 covariance.

    ``extras`` carries optional per-scan values a localizer may report, with these keys
    (all optional): ``scan_loglik`` (average per-reading log-likelihood), ``lambda_min``
    (smallest eigenvalue of the inverse covariance, B&D §5.2), ``timescale`` (index of the
    chosen timescale, 0..4, or -1), ``timescales`` (every timescale selected for this scan,
    B&D §4.3; counted per run for Fig. 12), ``safe_mode`` (bool), ``point_classes`` (int
    array per beam: 0 unknown, 1 dynamic, 2 semi-static, 3 static, H&W §4.4).
    """

    mean: FloatArray
    cov: FloatArray
    extras: dict[str, Any] = field(default_factory=dict)


#: When a localizer reports a :class:`Diagnostic`: with every scan, or once per run.
DIAGNOSTIC_PER: tuple[str, ...] = ("scan", "run")


@dataclass(frozen=True)
class Diagnostic:
    """A value a localizer reports besides its pose, declared so that the results store keeps
    it (``Localizer.diagnostics``; what a localizer does not declare is not stored).

    ``name``: lower case, digits and ``_`` (it names a column); ``dtype``: a numpy dtype name
    (``"float64"``, ``"int64"``, ``"bool"``, ...); ``shape``: of one value (``()``: a scalar);
    ``doc``: what it is, with its unit.

    * ``per="scan"``: ``PoseEstimate.extras[name]`` of every scan; a scan without it stores
      nothing (NULL).
    * ``per="run"``: one value per run: with ``counts_of``, counted from the per-scan extra of
      that name (an integer or a sequence of integers per scan; value ``v`` counts in bin
      ``v`` of ``shape[0]`` bins, others are ignored), else ``Localizer.run_diagnostics()``
      after ``end_run``.
    """

    name: str
    dtype: str
    shape: tuple[int, ...] = ()
    per: str = "scan"
    doc: str = ""
    counts_of: str | None = None

    def __post_init__(self) -> None:
        if not re.fullmatch(r"[a-z][a-z0-9_]*", self.name or ""):
            raise ValueError(f"diagnostic name {self.name!r}: lower case letters, digits and _")
        try:
            kind = np.dtype(self.dtype).kind
        except TypeError:
            kind = ""
        if kind not in "biuf" or not kind:
            raise ValueError(f"diagnostic {self.name!r}: dtype {self.dtype!r} is not numeric")
        object.__setattr__(self, "dtype", np.dtype(self.dtype).name)
        object.__setattr__(self, "shape", tuple(int(s) for s in self.shape))
        if any(s < 1 for s in self.shape):
            raise ValueError(f"diagnostic {self.name!r}: shape {self.shape} has an empty axis")
        if self.per not in DIAGNOSTIC_PER:
            raise ValueError(f"diagnostic {self.name!r}: per must be one of {DIAGNOSTIC_PER}")
        if self.counts_of is not None and (
            self.per != "run" or len(self.shape) != 1 or kind not in "iu"
        ):
            raise ValueError(
                f"diagnostic {self.name!r}: counts_of needs per='run', one axis and an "
                "integer dtype"
            )
