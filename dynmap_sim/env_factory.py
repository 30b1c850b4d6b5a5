"""Build the simulator from a typed description (:class:`SimSpec`).

The experiment engine describes the simulation it wants — a world file, people on or off,
robot and sensor presets with overrides — and this module turns that into a
:class:`dynmap_sim.env.DynMapEnv`, with every simulator class (``RobotParams``,
``WheelGeometry``, ``EncoderNoise``, ``make_lidar``, world files and calendars) behind it. So
the engine imports no ``world``, ``robot`` or ``sensors`` module (an import contract), and a
scenario file stays a schema.

Every problem is reported as ``(dotted field path, message)`` so scenario validation can name
the file and field: :func:`sim_spec_errors` collects them all at once.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dynmap_sim.env import DynMapEnv
from dynmap_sim.robot.diff_drive import RobotParams
from dynmap_sim.sensors.lidar import make_lidar
from dynmap_sim.sensors.odometry import EncoderNoise, WheelGeometry
from dynmap_sim.world import Calendar, WorldFileError, load_world, resolve_world_path

#: Robot presets: overrides of :class:`dynmap_sim.robot.diff_drive.RobotParams` defaults.
ROBOT_PRESETS: dict[str, dict[str, Any]] = {"default": {}}

#: The sensor when a scenario names none.
DEFAULT_SENSOR = "urg-04lx"

#: Shortest scan period a scenario may ask for [s]: it is the simulation step, and real
#: scanners turn at 10-75 Hz (a microsecond period would simulate for days).
MIN_SCAN_PERIOD_S = 0.005


@dataclass(frozen=True)
class SimSpec:
    """The simulation an experiment asks for.

    ``world``: a world file; ``people``: False removes all people; ``robot_preset`` (None:
    ``default``) and ``robot_overrides``: any ``RobotParams`` field (``radius_m``,
    ``max_v_mps``, ...) plus ``wheels`` (``WheelGeometry``: UMBmark ``e_d``, ``e_b``, ...) and
    ``encoder`` (``EncoderNoise``); ``sensor_preset`` (None: ``urg-04lx``) and
    ``sensor_overrides``: ``make_lidar`` overrides (``LaserSpec`` fields, ``beams``, ``mode``,
    ``mount_pose``) and
    ``noise`` (``LidarNoise`` fields).
    """

    world: Path
    people: bool = True
    robot_preset: str | None = None
    robot_overrides: Mapping[str, Any] = field(default_factory=dict)
    sensor_preset: str | None = None
    sensor_overrides: Mapping[str, Any] = field(default_factory=dict)


class SimSpecError(ValueError):
    """A bad :class:`SimSpec`; ``field`` is the dotted path of the culprit."""

    def __init__(self, field_path: str, message: str) -> None:
        super().__init__(f"{field_path}: {message}")
        self.field = field_path
        self.message = message


def resolve_world(ref: str, base_dir: str | Path | None = None) -> Path:
    """A world reference -> its file: a path (relative to ``base_dir`` first) or a shipped
    world's name (``"lab"``, ``"apartment"``). ValueError when there is none."""
    cand = Path(ref)
    if base_dir is not None and not cand.is_absolute():
        rel = Path(base_dir) / cand
        if rel.is_file():
            return rel.resolve()
    if cand.is_file():
        return cand.resolve()
    if cand.suffix == "" and "/" not in ref:
        path = Path(resolve_world_path(ref))
        if path.is_file():
            return path.resolve()
    raise ValueError(f"world file {ref!r} not found")


def _robot_kwargs(spec: SimSpec) -> dict[str, Any]:
    preset = spec.robot_preset or "default"
    if preset not in ROBOT_PRESETS:
        raise SimSpecError(
            "robot.preset", f"unknown robot {preset!r}; known: {sorted(ROBOT_PRESETS)}"
        )
    rob = {**ROBOT_PRESETS[preset], **spec.robot_overrides}
    try:
        wheels = WheelGeometry(**dict(rob.pop("wheels", {})))
        encoder = EncoderNoise(**dict(rob.pop("encoder", {})))
        robot = RobotParams(wheels=wheels, **rob)
    except (TypeError, ValueError) as exc:
        raise SimSpecError("robot.overrides", str(exc)) from None
    return {"robot": robot, "encoder": encoder}


def _finite_number(v: Any) -> bool:
    """True for an int or float (not a bool) that is finite."""
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def _sensor_kwargs(spec: SimSpec) -> dict[str, Any]:
    sensor = spec.sensor_preset or DEFAULT_SENSOR
    opts = dict(spec.sensor_overrides)
    noise = opts.pop("noise", None)
    if noise is not None and not isinstance(noise, Mapping):
        raise SimSpecError(
            "sensor.overrides.noise",
            f"must be a table of LidarNoise fields (e.g. {{ sigma_m = 0.02 }}), got {noise!r}",
        )
    for key, v in opts.items():
        if isinstance(v, float) and not math.isfinite(v):
            raise SimSpecError(f"sensor.overrides.{key}", f"must be a finite number, got {v!r}")
    if "mount_pose" in opts:
        pose = opts["mount_pose"]
        if not (
            isinstance(pose, list | tuple)
            and len(pose) == 3
            and all(_finite_number(v) for v in pose)
        ):
            raise SimSpecError(
                "sensor.overrides.mount_pose",
                f"must be 3 finite numbers [x_m, y_m, theta_rad], got {pose!r}",
            )
        opts["mount_pose"] = tuple(pose)
    try:
        period = make_lidar(sensor, noise=noise, **opts).spec.scan_period_s
    except (TypeError, ValueError) as exc:
        raise SimSpecError("sensor", str(exc)) from None
    if not (_finite_number(period) and period >= MIN_SCAN_PERIOD_S):
        raise SimSpecError(
            "sensor.overrides.scan_period_s",
            f"must be >= {MIN_SCAN_PERIOD_S} s (the scan period is the simulation step: at "
            f"most {round(1 / MIN_SCAN_PERIOD_S)} steps per second), got {period!r}",
        )
    return {"sensor": sensor, "sensor_options": opts, "lidar_noise": noise}


def make_env(spec: SimSpec) -> DynMapEnv:
    """The env ``spec`` describes; :class:`SimSpecError` naming the field on bad values."""
    kwargs = {**_robot_kwargs(spec), **_sensor_kwargs(spec)}
    return DynMapEnv(world=str(spec.world), people=spec.people, **kwargs)


def kidnapping_errors(
    spec: SimSpec, kidnappings: Sequence[tuple[int, int, Any]]
) -> list[tuple[str, str]]:
    """Problems of kidnappings ``(day, run, pose or "random")`` in ``spec``'s world, as
    ``("kidnappings.<i>.<field>", message)``: a run the calendar does not have, a pose outside
    the world's bounds. (A pose inside furniture, which depends on the day and the seed, is
    moved to free space within 1 m when the kidnapping happens, else recorded as skipped.)
    Nothing when the world file itself is invalid (:func:`sim_spec_errors` says so)."""
    try:
        world = load_world(spec.world)
        cal = Calendar(world.calendar)
    except (WorldFileError, ValueError):
        return []
    x0, y0, x1, y1 = (float(b) for b in world.bounds)
    errors: list[tuple[str, str]] = []
    for i, (day, run, pose) in enumerate(kidnappings):
        if 1 <= day <= cal.n_days and not 1 <= run <= cal.runs_per_day:
            errors.append(
                (
                    f"kidnappings.{i}.run",
                    f"day {day} has runs 1-{cal.runs_per_day} in the world's calendar, not {run}",
                )
            )
        if isinstance(pose, str):
            continue
        x, y = float(pose[0]), float(pose[1])
        if not (x0 <= x <= x1 and y0 <= y <= y1):
            errors.append(
                (
                    f"kidnappings.{i}.pose",
                    f"({x:g}, {y:g}) is outside the world's bounds [{x0:g}, {y0:g}, {x1:g}, "
                    f"{y1:g}] (x_min, y_min, x_max, y_max)",
                )
            )
    return errors


def sim_spec_errors(spec: SimSpec, days: tuple[int, int] | None = None) -> list[tuple[str, str]]:
    """All problems of ``spec`` as ``(field, message)``: robot and sensor overrides, the world
    file, and (with ``days``) a day range beyond the world's calendar."""
    errors: list[tuple[str, str]] = []
    for check in (_robot_kwargs, _sensor_kwargs):
        try:
            check(spec)
        except SimSpecError as exc:
            errors.append((exc.field, exc.message))
    try:
        world = load_world(spec.world)
    except WorldFileError as exc:
        first = exc.errors[0] if exc.errors else ("", "")
        more = f" (+{len(exc.errors) - 1} more)" if len(exc.errors) > 1 else ""
        errors.append(("world", f"world file {exc.path} is invalid: {first[0]}: {first[1]}{more}"))
        return errors
    if days is not None:
        try:
            n_days = Calendar(world.calendar).n_days
        except ValueError:  # a calendar that cannot be laid out: the run reports it
            return errors
        if days[1] > n_days:
            errors.append(
                ("days", f"the world's calendar has {n_days} days; days {list(days)} ask more")
            )
    return errors


def generated_world_toml(kind: str, seed: int, params: Mapping[str, Any]) -> str:
    """The world file text the generator makes of ``kind``, ``seed`` and ``params``
    (:mod:`dynmap_sim.world.generator`): how the benchmark makes its worlds without the
    engine importing the world package."""
    from dynmap_sim.world.generator import generate

    return generate(kind, seed, dict(params)).toml()


def generator_kinds() -> tuple[str, ...]:
    """The world generator's kinds (``apartment``, ``office``, ...)."""
    from dynmap_sim.world.generator import KINDS

    return tuple(KINDS)
