"""A safety stop between any controller and the robot (nav2's Collision Monitor).

nav2's Collision Monitor filters ``cmd_vel`` *after* the controller, straight from the sensor
data and bypassing costmaps and planners, so that a controller bug (or a map in the wrong
place) cannot drive the robot into an obstacle: zones around the robot each trigger an action
when at least ``min_points`` sensor points lie inside them, and the most restrictive triggered
zone wins. This module does the same for the one laser of this robot, entirely in the robot
frame: it never uses the map or the pose estimate, so it keeps working when localization is
wrong.

Zones (all in ``base_link``; the robot is a disc of radius ``r``; "ahead" is the direction of
the commanded forward speed, so a reversing command is checked behind):

* **footprint**: a disc of radius ``r + footprint_margin_m``. Points in it stop everything,
  turning included (something touches the robot).
* **stop**: a box from the robot's centre to ``r + stop_margin_m + |v| stop_time_s`` ahead,
  ``r + lateral_margin_m`` to each side (nav2's example stop box is 0.3-0.4 m ahead of a
  similar robot; here it grows with the commanded speed, like a braking distance). Points in
  it zero the forward speed but **keep the turn rate**: a disc turning on the spot sweeps no
  new space, and turning is how the controller gets away from what is ahead.
* **slowdown**: the same box to ``r + slowdown_margin_m + |v| slowdown_time_s`` ahead and
  ``r + slowdown_lateral_margin_m`` to the sides: both ``v`` and ``omega`` are scaled by
  ``slowdown_ratio`` (nav2's ``slowdown_ratio``; scaling both keeps the commanded curvature).

A beam that returns ``-inf`` (REP-117: something closer than ``range_min``) is a point at
``range_min`` on that beam; ``+inf`` (no return) and ``NaN`` are no points. The zones are
checked in one compiled loop over the beams (:func:`monitor_action`). What the monitor did is
counted (:attr:`CollisionMonitor.counts`) and its transitions recorded
(:attr:`CollisionMonitor.events`) so a run can report them.

Blind sector: the URG-04LX sees 240 degrees, so a reversing command is checked only against the
part of the box behind the robot that the laser covers. Reversing is the recovery's business,
which decides separately whether backing up is safe (:mod:`.recovery`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.params import Int, params_dataclass
from dynmap_sim.jit import compiled
from dynmap_sim.types import LaserSpec, Scan

FloatArray = NDArray[np.float64]

#: The monitor's actions, least to most restrictive.
PASS, SLOWDOWN, STOP, FOOTPRINT_STOP = "pass", "slowdown", "stop", "footprint_stop"


@params_dataclass("collision-monitor")
class CollisionMonitorParams:
    """Tunables (SI units) of :class:`CollisionMonitor`."""

    #: the robot's radius r [m]
    robot_radius_m: float = 0.2
    #: points within ``r + this`` stop the robot, turning included [m]
    footprint_margin_m: float = 0.02
    #: the stop box reaches ``r + stop_margin_m + |v| * stop_time_s`` ahead [m] ...
    stop_margin_m: float = 0.05
    #: ... [s]: at 0.35 m/s the box reaches 0.2 + 0.05 + 0.175 = 0.425 m (nav2's example 0.4 m)
    stop_time_s: float = 0.5
    #: the stop box's half-width beyond r [m]: less than the controllers' safety margin
    #: (hard clearance 0.25 = r + 0.05), so a wall the controller passes at its hard clearance
    #: does not trip the stop with range noise
    lateral_margin_m: float = 0.03
    #: the slowdown box reaches ``r + slowdown_margin_m + |v| * slowdown_time_s`` ahead [m] ...
    slowdown_margin_m: float = 0.25
    #: ... [s] (nav2's ``time_before_collision`` 2 s; 1.5 s here, the robot is slow)
    slowdown_time_s: float = 1.5
    #: the slowdown box's half-width beyond r [m]
    slowdown_lateral_margin_m: float = 0.15
    #: factor on (v, omega) in the slowdown zone (nav2's default ``slowdown_ratio`` 0.5)
    slowdown_ratio: float = 0.5
    #: points a zone needs to trigger (nav2: 4 on 360-beam scans; the URG has 683 beams, a
    #: 2 cm table leg at 0.3 m gives ~10, and a lone spurious short return gives 1)
    min_points: Int = 3


def scan_points(laser: LaserSpec, ranges_m: ArrayLike) -> FloatArray:
    """The scan's returns as points ``(N, 2)`` in the robot frame [m] (``-inf``: a point at
    ``range_min``; ``+inf``/``NaN``: none). Vectorized over beams."""
    r = np.asarray(ranges_m, dtype=np.float64).reshape(-1)
    if r.shape != (laser.n_beams,):
        raise ValueError(f"a scan of {laser.n_beams} beams expected, got {r.shape}")
    r = np.where(r == -np.inf, laser.range_min_m, r)
    ok = np.isfinite(r)
    mx, my, myaw = laser.mount_pose
    ang = laser.angles()[ok] + myaw
    rr = r[ok]
    return np.stack([mx + rr * np.cos(ang), my + rr * np.sin(ang)], axis=1)


def count_in_box(points: FloatArray, x_min_m: float, x_max_m: float, half_width_m: float) -> int:
    """How many ``(N, 2)`` points lie in the box ``x_min <= x <= x_max``, ``|y| <= half_width``."""
    x, y = points[:, 0], points[:, 1]
    return int(np.count_nonzero((x >= x_min_m) & (x <= x_max_m) & (np.abs(y) <= half_width_m)))


#: :func:`monitor_action`'s codes, least to most restrictive
PASS_CODE, SLOWDOWN_CODE, STOP_CODE, FOOTPRINT_STOP_CODE = 0, 1, 2, 3
#: the monitor's actions by :func:`monitor_action`'s codes
_ACTIONS = (PASS, SLOWDOWN, STOP, FOOTPRINT_STOP)


class Zones(NamedTuple):
    """The monitor's zones for one command [m]: the footprint's radius, the stop box's and
    the slowdown box's reach ahead and half-width (:meth:`CollisionMonitor.zones`)."""

    footprint_r_m: float
    stop_x_max_m: float
    stop_half_width_m: float
    slow_x_max_m: float
    slow_half_width_m: float


@compiled
def monitor_action(ranges_m, cos_a, sin_a, mount_xy, range_min_m, v_mps, zones, min_points):  # type: ignore[no-untyped-def]
    """The action's code (``*_CODE``) for forward speed ``v_mps`` [m/s] given one scan's
    ranges [m], its beams' directions in the robot frame and the laser's mount position
    ``mount_xy`` [m]: the most restrictive :class:`Zones` zone holding ``min_points``."""
    mount_x_m, mount_y_m = mount_xy
    footprint_r_m, stop_x_max_m, stop_half_width_m, slow_x_max_m, slow_half_width_m = zones
    sign = math.copysign(1.0, v_mps)
    n_foot = 0
    n_stop = 0
    n_slow = 0
    for b in range(ranges_m.shape[0]):
        r = ranges_m[b]
        if r == -math.inf:
            r = range_min_m
        if not math.isfinite(r):
            continue
        x = mount_x_m + r * cos_a[b]
        y = mount_y_m + r * sin_a[b]
        if np.hypot(x, y) <= footprint_r_m:
            n_foot += 1
        ax = x * sign
        ay = abs(y)
        if ax >= 0.0 and ax <= stop_x_max_m and ay <= stop_half_width_m:
            n_stop += 1
        if ax >= 0.0 and ax <= slow_x_max_m and ay <= slow_half_width_m:
            n_slow += 1
    if n_foot >= min_points:
        return FOOTPRINT_STOP_CODE
    if v_mps == 0.0:
        return PASS_CODE
    if n_stop >= min_points:
        return STOP_CODE
    if n_slow >= min_points:
        return SLOWDOWN_CODE
    return PASS_CODE


class CollisionMonitor:
    """Filters ``(v, omega)`` commands by the raw scan (module doc); ``params``:
    :class:`CollisionMonitorParams` fields.
    """

    def __init__(self, laser: LaserSpec, robot_radius_m: float, **params: float) -> None:
        self.laser = laser
        self.params = CollisionMonitorParams(robot_radius_m=robot_radius_m, **params)
        #: steps filtered and how many of them triggered each action
        self.counts: dict[str, int] = {PASS: 0, SLOWDOWN: 0, STOP: 0, FOOTPRINT_STOP: 0}
        #: ``(t_s, kind, detail)`` each time the action changes to a non-``pass`` one
        self.events: list[tuple[float, str, str]] = []
        #: the action of the last :meth:`filter`
        self.last_action = PASS
        self._beam_trig: tuple[FloatArray, FloatArray] | None = None

    def _action(self, v_mps: float, ranges_m: ArrayLike) -> str:
        """The action for forward speed ``v_mps`` [m/s] given the scan's ranges (module
        doc)."""
        r = np.asarray(ranges_m, dtype=np.float64).reshape(-1)
        if r.shape != (self.laser.n_beams,):
            raise ValueError(f"a scan of {self.laser.n_beams} beams expected, got {r.shape}")
        if self._beam_trig is None:  # numpy's cos / sin of the beams in the robot frame
            ang = self.laser.angles() + self.laser.mount_pose[2]
            self._beam_trig = (np.cos(ang), np.sin(ang))
        p = self.params
        zones = self.zones(v_mps)
        code = monitor_action(
            r,
            *self._beam_trig,
            (float(self.laser.mount_pose[0]), float(self.laser.mount_pose[1])),
            float(self.laser.range_min_m),
            float(v_mps),
            Zones(p.robot_radius_m + p.footprint_margin_m, *zones[STOP][1:], *zones[SLOWDOWN][1:]),
            int(p.min_points),
        )
        return _ACTIONS[code]

    @property
    def stop_count(self) -> int:
        """Steps at which the monitor stopped the robot (footprint stops included)."""
        return self.counts[STOP] + self.counts[FOOTPRINT_STOP]

    @property
    def slowdown_count(self) -> int:
        """Steps at which the monitor slowed the robot down."""
        return self.counts[SLOWDOWN]

    def zones(self, v_mps: float) -> dict[str, tuple[float, float, float]]:
        """The stop and slowdown boxes for a forward speed ``|v_mps|`` as ``(x_min, x_max,
        half_width)`` [m] in the direction of travel."""
        p = self.params
        r, av = p.robot_radius_m, abs(float(v_mps))
        return {
            STOP: (0.0, r + p.stop_margin_m + av * p.stop_time_s, r + p.lateral_margin_m),
            SLOWDOWN: (
                0.0,
                r + p.slowdown_margin_m + av * p.slowdown_time_s,
                r + p.slowdown_lateral_margin_m,
            ),
        }

    def filter(
        self, command: ArrayLike, scan: Scan | ArrayLike, t_s: float | None = None
    ) -> NDArray[np.float32]:
        """The safe command ``[v_mps, omega_radps]`` for the controller's ``command`` given the
        latest ``scan`` (a :class:`~dynmap_sim.types.Scan` or its ranges); counts and records
        what it did (``t_s`` defaults to the scan's stamp)."""
        cmd = np.asarray(command, dtype=np.float64).reshape(2)
        ranges = scan.ranges_m if isinstance(scan, Scan) else scan
        if t_s is None:
            t_s = scan.stamp_s if isinstance(scan, Scan) else 0.0
        v, omega = float(cmd[0]), float(cmd[1])
        action = self._action(v, ranges)
        if action == FOOTPRINT_STOP:
            v, omega = 0.0, 0.0
        elif action == STOP:
            v = 0.0
        elif action == SLOWDOWN:
            v, omega = v * self.params.slowdown_ratio, omega * self.params.slowdown_ratio
        self.counts[action] += 1
        if action != PASS and action != self.last_action:
            detail = f"commanded v={cmd[0]:.2f} m/s, omega={cmd[1]:.2f} rad/s"
            self.events.append((float(t_s), action, detail))
        self.last_action = action
        return np.array([v, omega], dtype=np.float32)
