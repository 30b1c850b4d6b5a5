"""Stuck detection and recovery behaviours (nav2's progress checker and behaviour-tree recovery).

nav2's controller server declares a failure when its progress checker sees the robot move less
than ``required_movement_radius`` (0.5 m) within ``movement_time_allowance`` (10 s); the
default behaviour tree (``navigate_to_pose_w_replanning_and_recovery``) then runs its recovery
behaviours round-robin, one per failure, and gives up after ``number_of_retries`` (6): clear the
costmaps, spin, wait 5 s, back up 0.3 m at 0.05 m/s, while the path is replanned at 1 Hz
anyway. H&W 2011 §6.3 leave recovery out; their robot handles a blocked path by global
replanning, which the stack does itself on :attr:`.corridor_follower.CorridorFollower.blocked`.

:class:`Recovery` is that loop as a small state machine, called once per control step with the
pose, the controller's command (before the collision monitor) and the controller's ``blocked``
flag:

* **monitor**: *stuck* when the robot moved less than ``required_movement_m`` in
  ``movement_time_s`` while commanded to move, when the controller has reported ``blocked``
  for ``blocked_time_s``, or when the command has been zero for ``idle_time_s`` (waiting behind
  a speed limit is fine for a while; the stack calls :meth:`Recovery.step` only while a path
  is being followed, i.e. not once the controller is done). Each stuck detection runs the
  next behaviour of the cycle **wait -> back up -> replan**; getting ``recovered_m`` away
  from where it was last stuck resets the cycle and the count (a back-up and a drive into the
  same block again do not); the ``max_attempts + 1``-th stuck detection without that **gives
  up** (an event and a ``give_up`` action, never an exception).
* **wait** ``wait_s`` (a person or a door may move away): zero command.
* **back up** ``backup_m`` at ``backup_mps`` (nav2's 0.3 m at 0.05 m/s), straight back, ending
  when the distance is covered, the time allowance is over, or a return appears in the box
  behind. Before it starts, the box behind the robot (``backup_m`` deep, the robot's width plus
  margin) must be free. The scan covers only part of it: the URG-04LX sees 240 degrees, so the
  120 degrees behind the robot are blind. Decision (``unknown_behind``): the visible part of
  the box must hold no return (fewer than ``min_points``), and the blind part is vouched for by
  the robot's own **trail**: the robot's recent poses (kept ``trail_s``) must cover the box's
  centre line, i.e. the robot itself drove through that space — it came from there. That is
  what a human driver trusts when reversing the way they came; the residual risk is something
  that moved in behind the robot since, in the blind sector, which the slow speed keeps small.
  If the trail does not vouch (the robot turned on the spot since), the back-up is skipped
  (an event) and the replan runs at once. ``"allow"`` trusts the blind part,
  ``"refuse"`` never backs up into it.
* **replan**: a ``replan`` action once; the stack plans a new path and hands it to the
  controller, and monitoring resumes.

The trail and the progress check use whatever pose the caller passes; pass the **odometry**
pose: it is smooth and continuous, so localization jumps can neither fake progress nor break
the trail (and recovery keeps working when localization is wrong).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.control.collision_monitor import count_in_box, scan_points
from dynmap_sim.agent.params import Int, Positive, params_dataclass
from dynmap_sim.types import LaserSpec, Scan

FloatArray = NDArray[np.float64]

#: The behaviours, in the order they are tried.
CYCLE = ("wait", "backup", "replan")


@params_dataclass("recovery")
class RecoveryParams:
    """Tunables (SI units) of :class:`Recovery`."""

    #: the robot's radius [m]
    robot_radius_m: float = 0.2
    #: progress: at least this displacement [m] ... (nav2 0.5 m; less here, so creeping past
    #: a box at the follower's 0.05 m/s floor, halved by the monitor's slowdown to 0.025 m/s,
    #: is progress with 25 % to spare)
    required_movement_m: float = 0.2
    #: ... within this time [s] (nav2's ``movement_time_allowance``)
    movement_time_s: float = 10.0
    #: the recoveries' count resets once the robot is this far from where it was last found
    #: stuck [m]: more than a back-up plus a progress window, so backing up and driving into
    #: the same block again is not progress
    recovered_m: float = 0.6
    #: a controller that reports ``blocked`` this long is stuck [s] (the stack's own 1 Hz
    #: replanning has had two chances by then)
    blocked_time_s: float = 2.0
    #: a zero command while not done and not blocked (e.g. a speed limit holding the robot
    #: behind a person who does not go away) is stuck after this long [s]: no run hangs
    idle_time_s: float = 30.0
    #: commands below these magnitudes are "not commanded to move" [m/s], [rad/s]
    moving_mps: float = 1e-3
    moving_radps: float = 1e-3
    #: the wait behaviour [s] (nav2's ``Wait 5 s``)
    wait_s: float = 5.0
    #: the back-up distance [m] and speed [m/s] (nav2's default tree: 0.3 m at 0.05 m/s)
    backup_m: Positive = 0.3
    backup_mps: Positive = 0.05
    #: the back-up ends unfinished after ``backup_m / backup_mps`` times this [-]
    backup_time_factor: float = 2.0
    #: the back-up box's half-width beyond the radius [m]
    backup_lateral_margin_m: float = 0.05
    #: returns in the box behind that forbid backing up (one spurious return is tolerated)
    min_points: Int = 2
    #: the blind part of the box behind: "trail" (vouched by the robot's own trail),
    #: "allow" (trusted), "refuse" (never back up into it)
    unknown_behind: str = "trail"
    #: trail memory [s] and its point spacing [m]
    trail_s: float = 60.0
    trail_spacing_m: float = 0.02
    #: a trail point within this of the box's centre line covers it [m]
    trail_lateral_m: float = 0.1
    #: recoveries tried before giving up (nav2's ``number_of_retries`` 6: the cycle twice)
    max_attempts: Int = 6

    def __post_init__(self) -> None:
        if self.unknown_behind not in ("trail", "allow", "refuse"):
            raise ValueError(
                f"unknown_behind must be 'trail', 'allow' or 'refuse', got {self.unknown_behind!r}"
            )


@dataclass(frozen=True)
class RecoveryAction:
    """What the stack does instead of driving the controller's command this step.

    ``kind``: ``"wait"`` / ``"backup"`` (send ``command``, through the collision monitor),
    ``"replan"`` (plan a new path and hand it to the controller; ``command`` is None: drive on
    with the controller) or ``"give_up"`` (stop for good: ``command`` is zero)."""

    kind: str
    command: NDArray[np.float32] | None
    detail: str = ""


class Recovery:
    """The stuck-detection and recovery state machine (module doc); ``params``:
    :class:`RecoveryParams` fields. ``laser`` is needed to check the space behind."""

    def __init__(self, laser: LaserSpec, robot_radius_m: float, **params: float | str) -> None:
        self.laser = laser
        self.params = RecoveryParams(robot_radius_m=robot_radius_m, **params)  # type: ignore[arg-type]
        self.events: list[tuple[float, str, str]] = []
        self._trail: deque[tuple[float, float, float]] = deque()
        self.reset()

    def reset(self) -> None:
        """Forget the run: a fresh progress window, no attempts, no trail (events stay)."""
        self._state = "monitor"
        self._attempts = 0
        self._next = 0
        self._base_xy: FloatArray | None = None
        self._base_t = 0.0
        self._blocked_since: float | None = None
        self._idle_since: float | None = None
        self._until_t = 0.0
        self._backup_start: FloatArray | None = None
        self._stuck_xy: FloatArray | None = None
        self._last_t: float | None = None
        self._trail.clear()
        self.stuck_s = 0.0
        #: recovery behaviours run in this run (waits, back-ups, replans)
        self.recoveries = 0

    @property
    def attempts(self) -> int:
        """Recoveries run since the last progress."""
        return self._attempts

    @property
    def gave_up(self) -> bool:
        return self._state == "gave_up"

    @property
    def recovering(self) -> bool:
        """True while a wait or back-up runs."""
        return self._state in ("wait", "backup")

    # ----------------------------------------------------------------- step
    def step(
        self,
        t_s: float,
        pose: ArrayLike,
        command: ArrayLike,
        blocked: bool = False,
        scan: Scan | ArrayLike | None = None,
    ) -> RecoveryAction | None:
        """One control step: ``pose`` (odometry, see module doc), the controller's ``command``
        ``[v, omega]`` and ``blocked`` flag, the latest ``scan`` (needed to back up; None:
        no back-up). None: drive the controller's command; else a :class:`RecoveryAction`."""
        p = self.params
        pose = np.asarray(pose, dtype=np.float64).reshape(3)
        xy = pose[:2]
        dt = 0.0 if self._last_t is None else max(float(t_s) - self._last_t, 0.0)
        self._last_t = float(t_s)
        self._record_trail(t_s, xy)
        if self._state == "gave_up":
            return RecoveryAction("give_up", np.zeros(2, dtype=np.float32), "gave up earlier")
        if self._base_xy is None:
            self._restart_window(t_s, xy)
        assert self._base_xy is not None
        if self._state != "monitor":
            self.stuck_s += dt
        if self._state == "wait":
            if t_s < self._until_t:
                return RecoveryAction("wait", np.zeros(2, dtype=np.float32))
            self._resume(t_s, xy)
        if self._state == "backup":
            action = self._backing_up(t_s, pose, scan)
            if action is not None:
                return action
            self._resume(t_s, xy)
        # monitor
        if self._stuck_xy is not None and float(np.hypot(*(xy - self._stuck_xy))) >= p.recovered_m:
            self.events.append((float(t_s), "progress", "away from where it was stuck; reset"))
            self._attempts = 0
            self._next = 0
            self._stuck_xy = None
        if float(np.hypot(*(xy - self._base_xy))) >= p.required_movement_m:
            self._restart_window(t_s, xy)
            return None
        cmd = np.asarray(command, dtype=np.float64).reshape(2)
        moving = abs(cmd[0]) > p.moving_mps or abs(cmd[1]) > p.moving_radps
        if blocked:
            if self._blocked_since is None:
                self._blocked_since = float(t_s)
        else:
            self._blocked_since = None
        if moving or blocked:
            self._idle_since = None
        elif self._idle_since is None:
            self._idle_since = float(t_s)
        why, since = None, float(t_s)
        if self._blocked_since is not None and t_s - self._blocked_since >= p.blocked_time_s:
            why, since = "controller blocked", self._blocked_since
        elif self._idle_since is not None:
            self._restart_window(t_s, xy)  # standing still on purpose: no progress due
            if t_s - self._idle_since >= p.idle_time_s:
                why, since = "zero command (not done, not blocked)", self._idle_since
        elif t_s - self._base_t >= p.movement_time_s:
            why, since = f"moved < {p.required_movement_m} m", self._base_t
        if why is None:
            return None
        why = f"{why} for {t_s - since:.1f} s"
        self.stuck_s += t_s - since
        self._stuck_xy = xy.copy()
        self.events.append((float(t_s), "stuck", why))
        return self._start_next(t_s, pose, scan)

    # ----------------------------------------------------------------- behaviours
    def _start_next(
        self, t_s: float, pose: FloatArray, scan: Scan | ArrayLike | None
    ) -> RecoveryAction:
        p = self.params
        if self._attempts >= p.max_attempts:
            self._state = "gave_up"
            detail = f"no progress after {self._attempts} recoveries"
            self.events.append((float(t_s), "give_up", detail))
            return RecoveryAction("give_up", np.zeros(2, dtype=np.float32), detail)
        self._attempts += 1
        self.recoveries += 1
        kind = CYCLE[self._next]
        self._next = (self._next + 1) % len(CYCLE)
        if kind == "backup":
            ok, why = self.backup_allowed(pose, scan)
            if not ok:
                self.events.append((float(t_s), "backup_skipped", why))
                kind = "replan"
                self._next = (CYCLE.index("replan") + 1) % len(CYCLE)
        attempt = f"attempt {self._attempts}/{p.max_attempts}"
        if kind == "wait":
            self._state = "wait"
            self._until_t = float(t_s) + p.wait_s
            self.events.append((float(t_s), "wait", f"{p.wait_s:.1f} s; {attempt}"))
            return RecoveryAction("wait", np.zeros(2, dtype=np.float32), attempt)
        if kind == "backup":
            self._state = "backup"
            self._backup_start = pose[:2].copy()
            self._until_t = float(t_s) + p.backup_time_factor * p.backup_m / p.backup_mps
            self.events.append((float(t_s), "backup", f"{p.backup_m:.2f} m; {attempt}"))
            return RecoveryAction("backup", self._backup_command(), attempt)
        self.events.append((float(t_s), "replan", attempt))
        self._resume(t_s, pose[:2])
        return RecoveryAction("replan", None, attempt)

    def _backup_command(self) -> NDArray[np.float32]:
        return np.array([-self.params.backup_mps, 0.0], dtype=np.float32)

    def _backing_up(
        self, t_s: float, pose: FloatArray, scan: Scan | ArrayLike | None
    ) -> RecoveryAction | None:
        """The back-up command, or None when it has ended (recorded)."""
        p = self.params
        assert self._backup_start is not None
        moved = float(np.hypot(*(pose[:2] - self._backup_start)))
        if moved >= p.backup_m:
            return None
        if t_s >= self._until_t:
            self.events.append((float(t_s), "backup_aborted", f"time out after {moved:.2f} m"))
            return None
        if scan is not None and self._returns_behind(scan, p.backup_m - moved) >= p.min_points:
            self.events.append(
                (float(t_s), "backup_aborted", f"obstacle behind after {moved:.2f} m")
            )
            return None
        return RecoveryAction("backup", self._backup_command())

    def _resume(self, t_s: float, xy: FloatArray) -> None:
        self._state = "monitor"
        self._blocked_since = None
        self._idle_since = None
        self._restart_window(t_s, xy)

    def _restart_window(self, t_s: float, xy: FloatArray) -> None:
        self._base_xy = np.array(xy, dtype=np.float64)
        self._base_t = float(t_s)

    # ----------------------------------------------------------------- the space behind
    def _box_behind(self, depth_m: float) -> tuple[float, float, float]:
        p = self.params
        r = p.robot_radius_m
        return -(r + depth_m), 0.0, r + p.backup_lateral_margin_m

    def _returns_behind(self, scan: Scan | ArrayLike, depth_m: float) -> int:
        ranges = scan.ranges_m if isinstance(scan, Scan) else scan
        return count_in_box(scan_points(self.laser, ranges), *self._box_behind(depth_m))

    def blind_behind(self) -> bool:
        """True when part of the back-up box lies outside the laser's field of view."""
        x0, x1, hw = self._box_behind(self.params.backup_m)
        xs, ys = np.meshgrid(np.linspace(x0, x1, 9), np.linspace(-hw, hw, 9))
        mx, my, myaw = self.laser.mount_pose
        bearing = np.arctan2(ys - my, xs - mx) - myaw
        bearing = (bearing + math.pi) % (2.0 * math.pi) - math.pi
        lo, hi = self.laser.angle_min_rad, self.laser.angle_max_rad
        return bool(np.any((bearing < lo) | (bearing > hi)))

    def trail_covers_behind(self, pose: FloatArray) -> bool:
        """True when the robot's trail covers the back-up box's centre line (it drove there)."""
        p = self.params
        if not self._trail:
            return False
        tr = np.array([(x, y) for _, x, y in self._trail]) - pose[:2]
        c, s = math.cos(pose[2]), math.sin(pose[2])
        bx, by = c * tr[:, 0] + s * tr[:, 1], -s * tr[:, 0] + c * tr[:, 1]
        on_line = np.abs(by) <= p.trail_lateral_m
        need = np.arange(p.trail_spacing_m, p.backup_m + 1e-9, 2.0 * p.trail_spacing_m)
        near = np.abs(bx[on_line][None, :] + need[:, None]) <= 2.0 * p.trail_spacing_m
        return bool(np.all(near.any(axis=1)))

    def backup_allowed(self, pose: FloatArray, scan: Scan | ArrayLike | None) -> tuple[bool, str]:
        """Whether backing up ``backup_m`` is safe, and why not (module doc)."""
        p = self.params
        if scan is None:
            return False, "no scan"
        n = self._returns_behind(scan, p.backup_m)
        if n >= p.min_points:
            return False, f"{n} scan returns in the space behind"
        if not self.blind_behind() or p.unknown_behind == "allow":
            return True, ""
        if p.unknown_behind == "refuse":
            return False, "the space behind is outside the laser's view"
        if self.trail_covers_behind(np.asarray(pose, dtype=np.float64)):
            return True, ""
        return False, "the space behind is unseen and the robot did not come from there"

    def _record_trail(self, t_s: float, xy: FloatArray) -> None:
        p = self.params
        tr = self._trail
        if not tr or math.hypot(xy[0] - tr[-1][1], xy[1] - tr[-1][2]) >= p.trail_spacing_m:
            tr.append((float(t_s), float(xy[0]), float(xy[1])))
        while tr and tr[0][0] < t_s - p.trail_s:
            tr.popleft()
