"""The Gymnasium env: a thin shell over world, robot and sensors (docs/architecture.md §1)."""

from __future__ import annotations

import math
import operator
from collections.abc import Iterator, Sequence
from dataclasses import fields
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.error import ClosedEnvironmentError, ResetNeeded
from numpy.typing import NDArray

from dynmap_sim.errors import InputError
from dynmap_sim.raster import CLASS_RGB, Canvas, polyline
from dynmap_sim.robot.diff_drive import DiffDriveRobot, RobotParams
from dynmap_sim.robot.route import RouteProgress
from dynmap_sim.sensors.lidar import LidarNoise, make_lidar
from dynmap_sim.sensors.odometry import EncoderNoise, WheelOdometry
from dynmap_sim.truth import ObstacleSnapshot, PeopleSnapshot, RunSlot, WorldFacts, read_only
from dynmap_sim.types import LaserSpec
from dynmap_sim.world import World, WorldSpec, load_world, resolve_world_path
from dynmap_sim.world.people.crowd import Crowd

FloatArray = NDArray[np.float64]

#: Tags that make each noise stream of a run independent (SeedSequence entropy words).
_LIDAR, _ODOM, _SLIP = 0x1DA2, 0x0D0, 0x511

#: The keys ``reset(options=...)`` knows.
RESET_OPTIONS = ("day", "run")
#: Largest ``render_size_px`` (a frame of 8192 x 8192 RGB is 200 MB).
MAX_RENDER_SIZE_PX = 8192
#: Longest step period ``dt_s`` [s]. The people's explicit Euler step relaxes their
#: velocities with the time constant ``TAU_S`` = 0.5 s and is stable only below twice that,
#: the robot's bumper sweeps one step's travel, and laser scanners deliver 5-75 scans a
#: second: a longer step would not simulate the world, however long it ran.
MAX_DT_S = 1.0


def _real(v: Any) -> bool:
    """True for a finite real number (not a bool)."""
    return (
        isinstance(v, int | float | np.integer | np.floating)
        and not isinstance(v, bool | np.bool_)
        and math.isfinite(v)
    )


def _positive_int(v: Any) -> bool:
    return isinstance(v, int | np.integer) and not isinstance(v, bool) and v >= 1


def _check_args(
    render_mode: Any, max_episode_steps: Any, collision_penalty: Any, goal_tolerance_m: Any
) -> None:
    """Check :class:`DynMapEnv`'s scalar arguments; InputError naming the argument and value."""
    modes = DynMapEnv.metadata["render_modes"]
    if render_mode is not None and render_mode not in modes:
        raise InputError(
            f"render_mode {render_mode!r} is not supported; render modes: None, "
            + ", ".join(map(repr, modes))
            + " (env.render() returns an RGB image to show or save)"
        )
    if max_episode_steps is not None and not _positive_int(max_episode_steps):
        raise InputError(f"max_episode_steps must be an integer >= 1, got {max_episode_steps!r}")
    if not (_real(collision_penalty) and collision_penalty >= 0):
        raise InputError(
            f"collision_penalty must be a finite number >= 0, got {collision_penalty!r}"
        )
    if not (_real(goal_tolerance_m) and goal_tolerance_m > 0):
        raise InputError(f"goal_tolerance_m must be a finite number > 0, got {goal_tolerance_m!r}")


def _check_parts(lidar_noise: Any, robot: Any, encoder: Any) -> None:
    """Check the types of :class:`DynMapEnv`'s parts (None: the defaults; the lidar noise may
    also be a dict of :class:`LidarNoise` fields that change the preset's, as ``make_lidar``
    takes it)."""
    if isinstance(lidar_noise, dict):
        unknown = sorted(set(lidar_noise) - {f.name for f in fields(LidarNoise)})
        if unknown:
            raise InputError(f"lidar_noise: no LidarNoise field {', '.join(map(repr, unknown))}")
        lidar_noise = None
    for name, value, cls in (
        ("lidar_noise", lidar_noise, LidarNoise),
        ("robot", robot, RobotParams),
        ("encoder", encoder, EncoderNoise),
    ):
        if value is not None and not isinstance(value, cls):
            raise InputError(f"{name} must be None or a {cls.__name__}, got {value!r}")


def _check_args_more(people: Any, sensor_options: Any, dt_s: Any, render_size_px: Any) -> None:
    """Check the rest of :class:`DynMapEnv`'s arguments."""
    if not isinstance(people, bool | np.bool_):
        raise InputError(f"people must be True or False, got {people!r}")
    if sensor_options is not None and not isinstance(sensor_options, dict):
        raise InputError(f"sensor_options must be a dict, got {sensor_options!r}")
    if dt_s is not None and not (_real(dt_s) and 0 < dt_s <= MAX_DT_S):
        raise InputError(
            f"dt_s must be a finite number in (0, {MAX_DT_S:g}] (seconds), got {dt_s!r}"
        )
    if not (_positive_int(render_size_px) and render_size_px <= MAX_RENDER_SIZE_PX):
        raise InputError(
            f"render_size_px must be an integer in 1..{MAX_RENDER_SIZE_PX}, got {render_size_px!r}"
        )


class DynMapEnv(gymnasium.Env):
    """A mobile robot driving its route through an indoor world that changes over weeks.

    ## Description

    The robot (a differential-drive disc) carries a laser scanner and wheel odometry in a
    world whose furniture, doors and exhibits change on a calendar and where people walk
    around (``dynmap_sim.world``). One episode is one *run* of the world's calendar: the
    world is put into the state of that run (day, run of the day), the robot starts at the
    world's start pose with its odometry at the origin, and it is driven along the world's
    route. This class only wires the parts together: physics and bumper
    (``dynmap_sim.robot.diff_drive``), laser (``dynmap_sim.sensors.lidar``), odometry
    (``dynmap_sim.sensors.odometry``), schedule and people (``dynmap_sim.world``).

    ## Observation

    ``Dict``: ``"scan"`` — ``Box(-inf, inf, (n_beams,), float32)``, laser ranges [m] encoded
    per REP-117 (``+inf`` no return, ``-inf`` closer than the minimum range; ``NaN`` invalid,
    which the default noise model never produces); beam geometry in
    ``env.unwrapped.laser_spec``. ``"odom"`` — ``Box(-inf, inf, (3,), float64)``, the wheel
    odometry pose ``(x_m, y_m, theta_rad)`` in the odom frame (starts at 0 each run; drifts).

    ## Action

    ``Box([-v_max, -omega_max], [v_max, omega_max], (2,), float32)``: the commanded forward
    speed [m/s] and turn rate [rad/s]. Any real dtype is accepted (integers, ``uint8``,
    ``float16``, ``float32``, ``float64``, or a list) and cast to float64 before use, so
    an action's value, not its dtype, decides the step; booleans, complex numbers and
    strings raise ``ValueError``. Out-of-range actions are **clipped** to the box (and then
    rate-limited by the robot's acceleration limits); NaN or infinite actions raise a
    ``ValueError``.

    ## Reward

    ``progress_m - collision_penalty * collision``: the metres of route progress made this
    step (projection of the robot onto the route polyline, monotone, see
    ``dynmap_sim.robot.route``) minus ``collision_penalty`` (default 1.0) for every step the
    bumper is pressed.

    ## Episode end

    *Terminated* when the robot reaches the route's last waypoint (within
    ``goal_tolerance_m``) after following the whole route. *Truncated* after
    ``max_episode_steps`` steps (default: 3 x route length / 0.1 m/s / step period, i.e.
    time enough to drive the route three times at 0.1 m/s). Once an episode has ended
    (terminated or truncated), ``step`` raises ``gymnasium.error.ResetNeeded`` until the
    next ``reset`` (as before the first one); after ``close()``, ``reset`` and ``step``
    raise ``gymnasium.error.ClosedEnvironmentError``.

    ## Info

    ``info["truth"]`` (never part of the observation): ``pose`` (map frame, float64 (3,)),
    ``beam_class`` (int8 per beam, names in ``dynmap_sim.BEAM_CLASSES``), ``beam_object``
    (int32 index into ``env.unwrapped.world.geometry.object_ids``, -1 nothing hit),
    ``range_m`` (noise-free ranges), ``people`` (``(max_people, 3)`` poses of the people on
    the floor, in a fixed order within a run, padded with rows ``(inf, inf, 0)`` — nobody,
    infinitely far away — so that the shape never changes, which vector envs need; NaN is not
    used because ``check_env`` compares infos with ``==``), ``n_people`` (how many rows are
    real), ``time`` (day, run, seconds since midnight). ``info["collision"]`` (bool),
    ``info["route_progress"]`` (fraction), ``info["stamp_s"]`` (seconds since the run
    started).

    ## Arguments

    ``world``: ``"lab"``, ``"apartment"``, a path to a world TOML file, or a ``WorldSpec``.
    ``sensor``: ``"urg-04lx"`` or ``"lms200"``; ``sensor_options``: preset overrides passed to
    ``make_lidar`` (e.g. ``{"beams": 181, "mode": "cm", "mount_pose": (0.1, 0, 0)}``);
    ``lidar_noise``: a ``LidarNoise``, or a dict of its fields changing the preset's.
    ``people``: False removes all people. ``robot``:
    ``RobotParams`` (limits, wheel geometry with UMBmark errors ``E_d``/``E_b``, slip);
    ``encoder``: ``EncoderNoise``. ``dt_s``: step period [s], at most ``MAX_DT_S`` (1 s;
    default the scan period).
    ``render_mode``: None, ``"rgb_array"`` (``render()`` returns the frame) or ``"human"``
    (a matplotlib window shows it at every reset and step, in real time).
    A bad argument raises ``dynmap_sim.errors.InputError`` (a ``ValueError``) naming it and
    its value, at construction.

    ## Seeding and episodes

    ``reset(seed=s, options={"day": d, "run": r})`` starts run ``(d, r)`` (1-based) of world
    seed ``s``. A reset with a ``seed`` and no day/run starts the first run; without a seed
    it starts the next run of the calendar (wrapping to the first). Lidar, odometry and slip
    noise of a run come from ``SeedSequence([seed, day, run, tag])``, so a run is the same
    whatever ran before it. Other option keys, a non-dict ``options``, a day or run outside the
    calendar and a negative seed raise ``ValueError`` before anything changes, so a ``reset``
    that raised leaves the env as it was.

    ## Worlds

    ``dynmap_sim/Apartment-v0`` (Hentschel & Wagner 2011 §7, 28 days, 1 run a day),
    ``dynmap_sim/Lab-v0`` (Biber & Duckett 2009 §5, 23 working days, 3 runs a day) and
    ``dynmap_sim/World-v0`` (``world=PATH``, required).

    ## Version history

    * v0: first version.

    The env pickles (world, robot, odometry and noise-stream states included), so a run can
    be checkpointed and resumed bit for bit.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    def __init__(
        self,
        world: str | Path | WorldSpec = "lab",
        sensor: str = "urg-04lx",
        people: bool = True,
        render_mode: str | None = None,
        *,
        sensor_options: dict[str, Any] | None = None,
        lidar_noise: LidarNoise | None = None,
        robot: RobotParams | None = None,
        encoder: EncoderNoise | None = None,
        dt_s: float | None = None,
        max_episode_steps: int | None = None,
        collision_penalty: float = 1.0,
        goal_tolerance_m: float = 0.3,
        render_size_px: int = 640,
    ) -> None:
        _check_args(render_mode, max_episode_steps, collision_penalty, goal_tolerance_m)
        _check_args_more(people, sensor_options, dt_s, render_size_px)
        _check_parts(lidar_noise, robot, encoder)
        if not isinstance(world, str | Path | WorldSpec):
            raise InputError(
                "world must be 'lab', 'apartment', a path to a world file or a WorldSpec, "
                f"got {world!r}"
            )
        spec = world if isinstance(world, WorldSpec) else load_world(resolve_world_path(world))
        if not people:
            spec = spec.model_copy(update={"people": ()})
        self.spec_world = spec
        self.render_mode = render_mode
        self.lidar = make_lidar(sensor, noise=lidar_noise, **(sensor_options or {}))
        self.laser_spec: LaserSpec = self.lidar.spec
        self.robot_params = robot if robot is not None else RobotParams()
        self.encoder = encoder if encoder is not None else EncoderNoise()
        period = self.laser_spec.scan_period_s
        if dt_s is None and not (_real(period) and 0.0 < period <= MAX_DT_S):
            raise InputError(
                f"the sensor's scan_period_s must be in (0, {MAX_DT_S:g}] s (it is the step "
                f"period dt_s unless dt_s is given), got {period!r}"
            )
        self.dt_s = float(dt_s) if dt_s is not None else period
        self.collision_penalty = float(collision_penalty)
        self.route = RouteProgress(spec.robot.route, goal_tolerance_m=goal_tolerance_m)
        if max_episode_steps is None:
            max_episode_steps = max(100, math.ceil(3.0 * self.route.length_m / 0.1 / self.dt_s))
        self.max_episode_steps = int(max_episode_steps)
        self.render_size_px = int(render_size_px)
        # fixed-size people array (vector envs need equal info shapes): the most people the
        # world's populations can ever put on the floor at once
        self.max_people = sum(
            math.ceil(pop.count * max(1.0, *(f for _, f in pop.profile))) for pop in spec.people
        )
        self.metadata = {**self.metadata, "render_fps": max(1, round(1.0 / self.dt_s))}
        self._no_people = np.zeros((self.max_people, 3))  # padding rows (inf, inf, 0)
        self._no_people[:, :2] = np.inf

        p = self.robot_params
        n = self.laser_spec.n_beams
        self.observation_space = spaces.Dict(
            {
                "scan": spaces.Box(-np.inf, np.inf, (n,), np.float32),
                "odom": spaces.Box(-np.inf, np.inf, (3,), np.float64),
            }
        )
        high = np.array([p.max_v_mps, p.max_omega_radps], dtype=np.float32)
        self.action_space = spaces.Box(-high, high, (2,), np.float32)
        self._act_lo = (-high).astype(np.float64)
        self._act_hi = high.astype(np.float64)
        self._act_bounds = (tuple(self._act_lo.tolist()), tuple(self._act_hi.tolist()))

        self.world_seed = 0
        self.world = World(spec, seed=0)
        self.robot = DiffDriveRobot(self.world.space, p, tuple(spec.robot.start))
        self.odometry = WheelOdometry(p.wheels, self.encoder)
        self._slot = -1  # index of the current run in the calendar (-1: none yet)
        self._started = False
        self._last: dict[str, Any] | None = None
        self._window: Any = None  # render_mode="human": a HumanWindow, opened lazily
        self._ended = False  # the episode terminated or was truncated: reset before a step
        self._closed = False

    # -- Gymnasium API ----------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        # every argument is checked before any state changes: a reset that raised leaves the
        # env as it was
        if self._closed:
            raise ClosedEnvironmentError("reset() after close(): make a new env")
        asked_slot = self._check_reset_args(seed, options)
        super().reset(seed=seed)
        if seed is None and not self._started:
            seed = int(self.np_random.integers(2**31))
        if seed is not None and int(seed) != self.world_seed:
            self.world_seed = int(seed)
            self.world = World(self.spec_world, seed=self.world_seed)
            self.robot.attach(self.world.space)
        cal = self.world.calendar
        if asked_slot is not None:
            self._slot = asked_slot
        elif seed is not None or not self._started:
            self._slot = 0
        else:
            self._slot = (self._slot + 1) % cal.n_slots
        self._started = True
        slot = cal.slots[self._slot]
        self.world.reset(slot.day, slot.run)
        self._rng_lidar, self._rng_odom, self._rng_slip = (
            np.random.default_rng(np.random.SeedSequence([self.world_seed, slot.day, slot.run, t]))
            for t in (_LIDAR, _ODOM, _SLIP)
        )
        self.robot.set_pose(tuple(self.spec_world.robot.start))
        self.odometry.reset()
        self.route.reset()
        self._steps = 0
        self._ended = False
        pose = self.robot.pose
        self.route.update(float(pose[0]), float(pose[1]))
        return self._observe(pose, collision=False)

    def _check_reset_args(self, seed: Any, options: Any) -> int | None:
        """Check ``reset``'s arguments; the slot index that ``options`` ask for, or None."""
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
            raise ValueError(f"reset seed must be None or an integer >= 0, got {seed!r}")
        if options is None:
            return None
        if not isinstance(options, dict):
            raise ValueError(
                f"reset options must be a dict with keys from {list(RESET_OPTIONS)}, "
                f"got {options!r}"
            )
        unknown = [k for k in options if k not in RESET_OPTIONS]
        if unknown:
            raise ValueError(
                f"reset options: unknown key(s) {', '.join(map(repr, unknown))}; "
                f"known: {', '.join(map(repr, RESET_OPTIONS))}"
            )
        if not options:
            return None
        day = self._option_int(options, "day", 1)
        run = self._option_int(options, "run", 1)
        try:
            return self.world.calendar.slot_index(day, run)
        except ValueError as exc:
            raise ValueError(f"reset options: {exc}") from None

    @staticmethod
    def _option_int(options: dict[str, Any], key: str, default: int) -> int:
        v = options.get(key, default)
        if isinstance(v, bool) or not isinstance(v, int | np.integer):
            raise ValueError(f"reset options: {key!r} must be an integer, got {v!r}")
        return int(v)

    def step(self, action: Any) -> tuple[dict[str, np.ndarray], float, bool, bool, dict[str, Any]]:
        pose, collision, reward, terminated, truncated = self._advance(action)
        obs, info = self._observe(pose, collision)
        return obs, reward, terminated, truncated, info

    def _advance(self, action: Any) -> tuple[FloatArray, bool, float, bool, bool]:
        """Everything of :meth:`step` but the observation: the robot's new pose, the
        collision flag, reward, terminated and truncated."""
        pose, collision = self._drive(action)
        self.world.step(self.dt_s, robot_pose=pose, robot_radius_m=self.robot_params.radius_m)
        return self._score(pose, collision)

    def _drive(self, action: Any) -> tuple[FloatArray, bool]:
        """The first part of a step: check ``action``, move the robot and count the
        odometry; the robot's new pose and the collision flag (then the world steps, then
        :meth:`_score`)."""
        self._check_steppable()
        kind = np.asarray(action).dtype.kind
        if kind not in "iuf":
            raise ValueError(
                "action must be 2 real numbers (v_mps, omega_radps), got "
                f"{np.asarray(action).dtype} values {action!r}"
            )
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (2,):
            raise ValueError(f"action must have shape (2,) = (v_mps, omega_radps), got {a.shape}")
        v, w = float(a[0]), float(a[1])
        if not (math.isfinite(v) and math.isfinite(w)):
            raise ValueError(f"action must be finite (v_mps, omega_radps), got {a.tolist()}")
        return self._drive_vw(v, w)

    def _check_steppable(self) -> None:
        """Gymnasium's order of calls: no step after close, before the first reset or after
        the episode ended (until the next reset)."""
        if self._closed:
            raise ClosedEnvironmentError("step() after close(): make a new env")
        if not self._started:
            raise ResetNeeded("call reset() before step()")
        if self._ended:
            raise ResetNeeded("the episode has ended (terminated or truncated): call reset()")

    def _drive_vw(self, v: float, w: float) -> tuple[FloatArray, bool]:
        """:meth:`_drive` of a checked action: finite ``v`` [m/s], ``w`` [rad/s]."""
        lo, hi = self._act_bounds
        v = min(max(v, lo[0]), hi[0])
        w = min(max(w, lo[1]), hi[1])
        res = self.robot.step(v, w, self.dt_s, self._rng_slip)
        self.odometry.update(res.dphi_left_rad, res.dphi_right_rad, self._rng_odom)
        return self.robot.pose, res.collision

    def _score(
        self, pose: FloatArray, collision: bool
    ) -> tuple[FloatArray, bool, float, bool, bool]:
        """The last part of a step (after the world stepped): route progress, reward,
        terminated and truncated."""
        self._steps += 1
        x, y = float(pose[0]), float(pose[1])
        gained = self.route.update(x, y)
        reward = gained - (self.collision_penalty if collision else 0.0)
        terminated = self.route.done(x, y)
        truncated = self._steps >= self.max_episode_steps and not terminated
        self._ended = terminated or truncated
        return pose, collision, float(reward), terminated, truncated

    def _observe(
        self, pose: FloatArray, collision: bool
    ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Observation and info at ``pose`` (a vector env, which casts and noises all its
        envs' scans at once, writes the same values with :meth:`InfoRows.write_steps`)."""
        reading = self.lidar.scan(pose, self.world.geometry, self._rng_lidar)
        slot = self.world.slot
        people, n_people = self._people()
        obs = {"scan": reading.ranges_m, "odom": self.odometry.pose}
        info = {
            "truth": {
                "pose": pose,
                "beam_class": reading.beam_class,
                "beam_object": reading.beam_object,
                "range_m": reading.true_range_m,
                "n_people": n_people,
                "people": people,
                "time": (slot.day, slot.run, self.world.time_s),
            },
            "collision": bool(collision),
            "route_progress": self.route.fraction,
            "stamp_s": self.world.elapsed_s,
        }
        self._last = {"pose": pose, "reading": reading}
        if self.render_mode == "human":
            self._show()
        return obs, info

    def _show(self) -> None:
        """``render_mode="human"``: the frame in the window (opened at the first frame)."""
        if self._window is None:
            from dynmap_sim.human_window import HumanWindow

            self._window = HumanWindow(
                f"dynmap_sim: {self.spec_world.name}", self.metadata["render_fps"]
            )
        self._window.show(_render(self))

    def _people(self) -> tuple[FloatArray, int]:
        """People poses padded to ``max_people`` rows ``(inf, inf, 0)``, and their number."""
        out = np.empty_like(self._no_people)
        return out, self._people_into(out)

    def _people_into(self, out: FloatArray) -> int:
        """Write the people poses into ``out`` (``(max_people, 3)``, padded with rows
        ``(inf, inf, 0)``); their number."""
        out[...] = self._no_people
        crowd = self.world.crowd
        n = min(crowd.n, self.max_people)
        if n:
            out[:n, :2] = crowd.pos[:n]
            vel = crowd.vel[:n]
            out[:n, 2] = np.arctan2(vel[:, 1], vel[:, 0])  # heading of motion, as people_poses
        return n

    def people(self) -> PeopleSnapshot:
        """A read-only snapshot of the current run's people (ids, positions, radii)."""
        crowd = self.world.crowd
        return PeopleSnapshot(
            ids=tuple(crowd.ids),
            xy=read_only(np.asarray(crowd.pos, dtype=np.float64).reshape(-1, 2)),
            radius=read_only(np.asarray(crowd.radius, dtype=np.float64).ravel()),
        )

    # -- extras ---------------------------------------------------------------------------
    def teleport(self, pose: Any) -> None:
        """Kidnap the robot: move the true robot to ``pose`` (map frame); odometry is unaware."""
        p = np.asarray(pose, dtype=np.float64)
        if p.shape != (3,) or not np.isfinite(p).all():
            raise ValueError(f"teleport pose must be 3 finite numbers (x, y, theta), got {pose!r}")
        self.robot.set_pose(p)
        self.world.sync_space()  # people's bodies far from the old pose lag behind

    @property
    def robot_radius_m(self) -> float:
        """The robot's radius [m]."""
        return float(self.robot_params.radius_m)

    def world_facts(self) -> WorldFacts:
        """The current world's fixed facts (a read-only view; see :mod:`dynmap_sim.truth`)."""
        spec = self.spec_world
        return WorldFacts(
            name=spec.name,
            bounds=tuple(float(b) for b in spec.bounds),  # type: ignore[arg-type]
            start_pose=read_only(np.asarray(spec.robot.start, dtype=np.float64)),
            route=read_only(np.asarray(spec.robot.route, dtype=np.float64)),
            wall_segments=read_only(np.asarray(self.world.wall_segments(), dtype=np.float64)),
            slots=tuple(
                RunSlot(s.day, s.run, s.date, s.start_s) for s in self.world.calendar.slots
            ),
        )

    def obstacles(self) -> ObstacleSnapshot:
        """A read-only snapshot of the current world's obstacles (people's legs included)."""
        g = self.world.geometry
        return ObstacleSnapshot(
            segments=read_only(np.asarray(g.segments, dtype=np.float64)),
            segment_class=read_only(np.asarray(g.segment_class, dtype=np.int8)),
            circles=read_only(np.asarray(g.circles, dtype=np.float64).reshape(-1, 3)),
            circle_class=read_only(np.asarray(g.circle_class, dtype=np.int8).ravel()),
            segment_object=read_only(np.asarray(g.segment_object, dtype=np.int32).ravel()),
            circle_object=read_only(np.asarray(g.circle_object, dtype=np.int32).ravel()),
            object_ids=tuple(g.object_ids),
        )

    @property
    def day_run(self) -> tuple[int, int]:
        """``(day, run)`` of the current episode (1-based)."""
        slot = self.world.slot
        return slot.day, slot.run

    def render(self) -> np.ndarray | None:
        """``"rgb_array"``: the frame ``(H, W, 3)`` uint8; ``"human"``: None (the window
        already shows it, Gymnasium's convention); None without a render mode."""
        if self.render_mode != "rgb_array":
            return None
        return _render(self)

    def close(self) -> None:
        """Close the ``"human"`` window, if one is open; the env takes no more ``reset`` or
        ``step`` (closing again is a no-op)."""
        if self._window is not None:
            self._window.close()
            self._window = None
        self._closed = True
        super().close()


class InfoRows:
    """A vector env's observations and infos of ``n`` :class:`DynMapEnv` sub-envs as batch
    arrays, row ``i`` for sub-env ``i``: ``scan``, ``odom`` and the fields of ``info``
    (``truth``'s ``pose``, ``beam_class``, ``beam_object``, ``range_m``, ``n_people``,
    ``people``, ``time``; ``collision``, ``route_progress``, ``stamp_s``), written in place
    by :meth:`write_steps` (after a step of several sub-envs) or :meth:`put` (one sub-env's
    ``obs`` and ``info``)."""

    def __init__(self, n: int, n_beams: int, max_people: int) -> None:
        self.scan = np.zeros((n, n_beams), dtype=np.float32)
        self.odom = np.zeros((n, 3))
        self.pose = np.zeros((n, 3))
        self.beam_class = np.zeros((n, n_beams), dtype=np.int8)
        self.beam_object = np.zeros((n, n_beams), dtype=np.int32)
        self.range_m = np.zeros((n, n_beams))
        self.n_people = np.zeros(n, dtype=np.int64)
        self.people = np.zeros((n, max_people, 3))
        self.time: list[tuple[int, int, float] | None] = [None] * n
        self.collision = np.zeros(n, dtype=np.bool_)
        self.route_progress = np.zeros(n)
        self.stamp_s = np.zeros(n)
        self._no_people = np.zeros((n, max_people, 3))  # padding rows (inf, inf, 0)
        self._no_people[:, :, :2] = np.inf
        self._labels: _LabelRows | None = None
        # the people rows as one (n * max_people, 3) view; the flat row of each person
        # written by _people_rows, and for which (rows, counts) it was made
        self._people_flat = self.people.reshape(-1, 3)
        self._people_at: tuple[Any, Any] = (None, None)

    def put(self, i: int, obs: dict[str, np.ndarray], info: dict[str, Any]) -> None:
        """Row ``i`` from one sub-env's ``obs`` and ``info`` (of ``reset`` or ``step``)."""
        self.scan[i] = obs["scan"]
        self.odom[i] = obs["odom"]
        truth = info["truth"]
        for key in ("pose", "beam_class", "beam_object", "range_m", "n_people", "people"):
            getattr(self, key)[i] = truth[key]
        self.time[i] = truth["time"]
        for key in ("collision", "route_progress", "stamp_s"):
            getattr(self, key)[i] = info[key]

    def write_steps(
        self,
        envs: Sequence[DynMapEnv],
        at: list[int],
        poses: Sequence[FloatArray],
        collisions: Sequence[bool],
        cast: tuple[FloatArray, NDArray[np.int64]],
        ranges_m: NDArray[np.float32],
    ) -> None:
        """Rows ``at`` after a step of each of ``envs`` (at ``poses``, with ``collisions``):
        what :meth:`DynMapEnv._observe` returns, each field of all rows in one array
        operation. ``cast`` holds the scans' noise-free ranges [m] and hit indices
        ``(len(envs), n_beams)``, ``ranges_m`` their noisy readings. The sub-envs' last
        readings are not kept (a vector env's sub-envs do not render)."""
        rows: Any = slice(None) if len(at) == self.scan.shape[0] else at
        true_r, hits = cast
        self.scan[rows] = ranges_m
        self.range_m[rows] = true_r
        self.pose[rows] = poses
        odom, route, stamp, crowds, tables = [], [], [], [], []
        for i, env in zip(at, envs, strict=True):
            world = env.world
            slot = world.slot
            self.time[i] = (slot.day, slot.run, world.time_s)
            odom.append(env.odometry._pose)
            route.append(env.route.fraction)
            stamp.append(world.elapsed_s)
            crowds.append(world.crowd)
            tables.append(env.lidar._label_tables(world.geometry))
        self.odom[rows] = odom
        self.collision[rows] = collisions
        self.route_progress[rows] = route
        self.stamp_s[rows] = stamp
        labels = self._labels
        if labels is None or not labels.holds(tables):
            labels = self._labels = _LabelRows(tables)
        idx = hits + labels.first
        self.beam_object[rows] = labels.obj[idx]
        self.beam_class[rows] = labels.cls[idx]
        self._people_rows(rows, at, crowds)

    def _people_rows(self, rows: Any, at: list[int], crowds: list[Crowd]) -> None:
        """``people`` and ``n_people`` of rows ``at`` (``rows``: the same as an index) from
        their worlds' ``crowds``, as :meth:`DynMapEnv._people_into` writes each."""
        people = self.people
        max_people = people.shape[1]
        counts = [min(c.n, max_people) for c in crowds]
        self.n_people[rows] = counts
        people[rows] = self._no_people[rows]
        total = sum(counts)
        if not total:
            return
        pos = np.concatenate([c.pos[:k] for c, k in zip(crowds, counts, strict=True)])
        vel = np.concatenate([c.vel[:k] for c, k in zip(crowds, counts, strict=True)])
        key = (at, counts)
        if self._people_at[0] != key:  # (the same rows and counts from step to step)
            env = np.repeat(np.array(at), counts)
            person = np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
            self._people_at = (key, env * max_people + person)
        flat = self._people_at[1]
        self._people_flat[flat, :2] = pos
        self._people_flat[flat, 2] = np.arctan2(vel[:, 1], vel[:, 0])  # as _people_into

    def infos(self) -> dict[str, Any]:
        """The batched infos (fresh arrays), as Gymnasium's ``VectorEnv._add_info`` batches
        the sub-envs' info dicts: an array per key and a ``_key`` mask (all True)."""
        n = self.scan.shape[0]
        time = np.empty(n, dtype=object)  # (None-filled, as np.full(n, None) but cheaper)
        for i, v in enumerate(self.time):
            time[i] = v
        masks = iter(np.ones((11, n), dtype=np.bool_))  # the 11 masks: rows of one block
        truth = {
            "pose": self.pose.copy(),
            "beam_class": self.beam_class.copy(),
            "beam_object": self.beam_object.copy(),
            "range_m": self.range_m.copy(),
            "n_people": self.n_people.copy(),
            "people": self.people.copy(),
            "time": time,
        }
        out: dict[str, Any] = {
            "truth": _with_masks(truth, masks),
            "collision": self.collision.copy(),
            "route_progress": self.route_progress.copy(),
            "stamp_s": self.stamp_s.copy(),
        }
        return _with_masks(out, masks)


class _LabelRows:
    """The label tables (object index, class per hit index, from
    :meth:`Lidar._label_tables`) of several scans laid end to end after one sentinel, so
    that hit index ``h`` of scan ``i`` reads entry ``h + first[i]``: each table ends with
    its own sentinel (the entry of hit ``-1``), which is also the entry before the next
    table."""

    def __init__(self, tables: list[tuple[NDArray[np.int32], NDArray[np.int8]]]) -> None:
        self.tables = tables
        sizes = [len(obj) for obj, _ in tables]
        self.first = (1 + np.cumsum(sizes) - sizes)[:, None]
        self.obj = np.concatenate([[-1], *(obj for obj, _ in tables)]).astype(np.int32)
        self.cls = np.concatenate([[0], *(cls for _, cls in tables)]).astype(np.int8)

    def holds(self, tables: list[tuple[NDArray[np.int32], NDArray[np.int8]]]) -> bool:
        """True if these are the very tables laid out here (the same arrays, in order; a
        lidar hands out the same tuple while its tables stay, so the tuples are compared)."""
        mine = self.tables
        return len(mine) == len(tables) and all(map(operator.is_, mine, tables))


def _with_masks(d: dict[str, Any], masks: Iterator[NDArray[np.bool_]]) -> dict[str, Any]:
    """``d`` with a ``_key`` mask after each key (``VectorEnv._add_info``): the next of
    ``masks`` (all True, one per sub-env; rows of one array, each its own)."""
    out: dict[str, Any] = {}
    for key, value in d.items():
        out[key] = value
        out[f"_{key}"] = next(masks)
    return out


# -- rendering: the numpy rasterizer of dynmap_sim.raster (no matplotlib state, ~ms per frame) --
def _render(env: DynMapEnv) -> np.ndarray:
    canvas = Canvas(env.spec_world.bounds, env.render_size_px)
    lines, discs = canvas.lines, canvas.discs

    route = env.spec_world.robot.route
    lines(polyline(route), np.array([200, 200, 235], np.uint8))
    g = env.world.geometry
    lines(g.segments, CLASS_RGB[g.segment_class])
    discs(g.circles, CLASS_RGB[g.circle_class])
    if env._last is not None:
        pose = env._last["pose"]
        reading = env._last["reading"]
        discs(
            np.array([[pose[0], pose[1], env.robot_params.radius_m]]),
            np.array([60, 60, 200], np.uint8),
        )
        head = np.array(
            [
                [
                    pose[0],
                    pose[1],
                    pose[0] + 0.4 * math.cos(pose[2]),
                    pose[1] + 0.4 * math.sin(pose[2]),
                ]
            ]
        )
        lines(head, np.array([255, 255, 0], np.uint8))
        lp = env.lidar.laser_pose(pose)
        r = reading.ranges_m.astype(np.float64)
        ok = np.isfinite(r)
        ang = lp[2] + env.laser_spec.angles()[ok]
        pts = np.stack([lp[0] + r[ok] * np.cos(ang), lp[1] + r[ok] * np.sin(ang)], axis=-1)
        canvas.points(pts, np.array([0, 170, 255], np.uint8))
    return canvas.img
