"""Scenario files: what to run (world, days, seeds, robot, sensor, driver, localizers, prior,
kidnappings) and what to expect (DESIGN.md §6).

A scenario is TOML validated by pydantic v2 with ``extra="forbid"``. Problems are reported as
:class:`ScenarioFileError`, each with the file and the dotted field path: all field errors at
once, then (when the fields are valid) all checks across fields and files at once (labels,
expectation keys, kidnapping days, localizer parameters, robot and sensor overrides, the
world file and its calendar)::

    name = "ci-apartment"
    world = "apartment"              # a shipped world name or a path relative to this file
    days = [1, 3]                    # inclusive day range (1-based working days), or "1-3"
    seeds = [0]

    [driver]
    kind = "tour"
    max_run_s = 20.0                 # robot-time limit per run (optional)

    [prior]
    map = "walls"                    # "none" | "walls"
    initial_pose = "known"           # "known" | "unknown"

    [[localizers]]
    name = "odometry"                # registry name or "package.module:ClassName"
    label = "odom"                   # display label (unique); defaults to the name
    params = {}

    [expectations]
    no_collisions = true
    [expectations.localizers.odom]
    mean_error_m = 0.3               # every day's mean position error <= 0.3 m
    # with a dynamic-map: B&D findings that must hold (keys of findings.md)
    # findings = ["likelihood_above_static", "ltm_usage_rises"]
"""

from __future__ import annotations

import hashlib
import json
import math
import tomllib
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    ValidationError,
    ValidationInfo,
    field_validator,
    model_validator,
)

from dynmap_sim.errors import FileError, pydantic_errors, read_toml
from dynmap_sim.types import LaserSpec

#: Keys only a scenario file has at its top level (world files have none of them).
_SCENARIO_KEYS = frozenset({"localizers", "driver", "expectations", "kidnappings", "prior"})


class ScenarioFileError(FileError):
    """All the problems of one scenario file (file + dotted field path + message)."""


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


Scalar = float | int | str | bool
ParamValue = Scalar | list[Scalar] | dict[str, Scalar]


class PresetConfig(_Strict):
    """A robot or sensor preset by name, with individual values overridden."""

    preset: str | None = None
    overrides: dict[str, ParamValue] = Field(default_factory=dict)


class DriverConfig(_Strict):
    """Who drives the robot. ``tour``: a scripted operator steering along the world's route."""

    kind: Literal["tour", "autonomous"] = "tour"
    speed_mps: float = Field(0.35, gt=0.0, le=2.0, description="cruise speed [m/s]")
    max_run_s: float | None = Field(
        None, gt=0.0, description="robot-time limit per run [s] (None: until the route ends)"
    )
    route_fraction: float = Field(
        1.0, gt=0.0, le=1.0, description="drive only this leading fraction of the route"
    )
    wait_for_people: bool = True
    clearance_m: float = Field(
        0.12, ge=0.0, le=1.0, description="extra clearance kept from obstacles [m]"
    )

    @model_validator(mode="after")
    def _autonomous_not_yet(self) -> DriverConfig:
        if self.kind == "autonomous":
            raise ValueError("driver 'autonomous' is not available yet; use 'tour'")
        return self


class PriorConfig(_Strict):
    """Prior knowledge granted to the agent at the start of every run."""

    map: Literal["none", "walls"] = "none"
    initial_pose: Literal["known", "unknown"] = "known"
    initial_pose_sigma_xy_m: float = Field(0.05, ge=0.0)
    initial_pose_sigma_theta_rad: float = Field(0.05, ge=0.0)


class LocalizerConfig(_Strict):
    """One localizer to evaluate: its class, parameters and a unique display label."""

    name: str = Field(description="registry name (e.g. 'odometry') or 'package.module:Class'")
    label: str | None = Field(None, description="display label (default: the name)")
    params: dict[str, ParamValue] = Field(default_factory=dict)

    @field_validator("name")
    @classmethod
    def _known(cls, v: str) -> str:
        from dynmap_sim.agent.localizer import LOCALIZERS

        LOCALIZERS.get(v)  # raises ValueError with the known names
        return v

    @field_validator("label")
    @classmethod
    def _label_ok(cls, v: str | None) -> str | None:
        if v is not None and (not v or any(c in v for c in "/\\\n\t")):
            raise ValueError("a label must be non-empty without slashes, tabs or newlines")
        return v

    @property
    def display(self) -> str:
        """The label used in results, reports and expectations."""
        return self.label or self.name


_DUMMY_LASER = LaserSpec(
    name="validation",
    n_beams=181,
    angle_min_rad=-math.pi / 2,
    angle_increment_rad=math.pi / 180,
    range_min_m=0.02,
    range_max_m=8.0,
    scan_period_s=0.1,
    time_increment_s=0.0,
)


class Kidnapping(_Strict):
    """Teleport the true robot during a run; odometry does not notice (global localization)."""

    day: int = Field(ge=1)
    run: int = Field(1, ge=1)
    time_s: float | Literal["random"] = Field(
        "random", description="seconds after the run's start, or 'random'"
    )
    pose: tuple[float, float, float] | Literal["random"] = Field(
        "random", description="(x_m, y_m, theta_rad) in the map frame, or 'random' (on the route)"
    )

    @field_validator("time_s")
    @classmethod
    def _nonneg(cls, v: float | str) -> float | str:
        if not isinstance(v, str) and v < 0:
            raise ValueError("time_s must be >= 0")
        return v


class LocalizerExpectation(_Strict):
    """Thresholds for one localizer (all optional; each given one is checked)."""

    mean_error_m: float | None = Field(None, gt=0, description="each day's mean position error")
    max_error_m: float | None = Field(None, gt=0, description="largest position error overall")
    rmse_m: float | None = Field(None, gt=0, description="each day's RMSE of position error")
    lost_fraction: float | None = Field(
        None, ge=0, le=1, description="fraction of scans with error > 0.5 m, overall"
    )
    mean_heading_error_rad: float | None = Field(None, gt=0)
    max_time_to_recover_s: float | None = Field(
        None, gt=0, description="every lost episode recovers within this time [s]"
    )


class Expectations(_Strict):
    """What a regression check asserts (``dynmap-sim check``)."""

    no_collisions: bool = False
    max_skipped_waypoints: int | None = Field(None, ge=0)
    localizers: dict[str, LocalizerExpectation] = Field(default_factory=dict)
    findings: list[str] = Field(
        default_factory=list,
        description="Biber & Duckett findings (findings.md keys) that must hold; needs a "
        "dynamic-map localizer",
    )


def _parse_days(v: Any) -> Any:
    if isinstance(v, int) and not isinstance(v, bool):
        return (v, v)
    if isinstance(v, str):
        a, _, b = v.partition("-")
        try:
            return (int(a), int(b or a))
        except ValueError:
            raise ValueError(f"days must look like '1-7' or [1, 7], not {v!r}") from None
    return v


class Scenario(_Strict):
    """A validated scenario. ``world_path`` is resolved against the scenario file's folder."""

    name: str = Field(min_length=1)
    description: str = ""
    world: str = Field(description="shipped world name ('lab', 'apartment') or a path")
    days: tuple[int, int] = Field(description="inclusive 1-based day range")
    seeds: list[int] = Field(default_factory=lambda: [0], min_length=1)
    people: bool = True
    robot: PresetConfig = Field(default_factory=PresetConfig)
    sensor: PresetConfig = Field(default_factory=lambda: PresetConfig(preset="urg-04lx"))
    driver: DriverConfig = Field(default_factory=DriverConfig)
    prior: PriorConfig = Field(default_factory=PriorConfig)
    localizers: list[LocalizerConfig] = Field(min_length=1)
    kidnappings: list[Kidnapping] = Field(default_factory=list)
    expectations: Expectations = Field(default_factory=Expectations)

    _source: Path | None = PrivateAttr(default=None)
    _world_path: Path | None = PrivateAttr(default=None)

    @field_validator("days", mode="before")
    @classmethod
    def _days_before(cls, v: Any) -> Any:
        return _parse_days(v)

    @field_validator("days")
    @classmethod
    def _days_ok(cls, v: tuple[int, int]) -> tuple[int, int]:
        if v[0] < 1 or v[1] < v[0]:
            raise ValueError(f"days must be 1 <= first <= last, got {list(v)}")
        return v

    @field_validator("seeds")
    @classmethod
    def _seeds_ok(cls, v: list[int]) -> list[int]:
        if any(s < 0 for s in v):
            raise ValueError("seeds must be >= 0")
        if len(set(v)) != len(v):
            raise ValueError("seeds must be distinct")
        return v

    @field_validator("world")
    @classmethod
    def _world_ok(cls, v: str, info: ValidationInfo) -> str:
        base = (info.context or {}).get("base_dir")
        _resolve_world(v, base)  # raises ValueError with a readable message
        return v

    # ----------------------------------------------------------------- helpers
    @property
    def source_path(self) -> Path | None:
        """The scenario file this was loaded from (None when built in code)."""
        return self._source

    @property
    def world_path(self) -> Path:
        """The world file (resolved against the scenario file's folder)."""
        if self._world_path is None:
            base = self._source.parent if self._source else None
            self._world_path = _resolve_world(self.world, base)
        return self._world_path

    @property
    def labels(self) -> list[str]:
        """Display labels of the localizers, in file order."""
        return [loc.display for loc in self.localizers]

    def content_hash(self) -> str:
        """SHA-256 of the scenario's content and its world file (keys checkpoints)."""
        h = hashlib.sha256()
        h.update(json.dumps(self.model_dump(mode="json"), sort_keys=True).encode())
        h.update(self.world_path.read_bytes())
        return h.hexdigest()


def _resolve_world(world: str, base_dir: str | Path | None) -> Path:
    """Resolve a world reference: a path (relative to ``base_dir``) or a shipped name."""
    cand = Path(world)
    if base_dir is not None and not cand.is_absolute():
        rel = Path(base_dir) / cand
        if rel.is_file():
            return rel.resolve()
    if cand.is_file():
        return cand.resolve()
    if cand.suffix == "" and "/" not in world:
        try:
            from dynmap_sim.world import resolve_world_path
        except ImportError as exc:  # the world package is missing
            raise ValueError(f"cannot resolve world {world!r}: {exc}") from None
        try:
            path = Path(resolve_world_path(world))
        except Exception as exc:  # noqa: BLE001 - any failure is a bad reference
            raise ValueError(f"unknown world {world!r}: {exc}") from None
        if path.is_file():
            return path.resolve()
    raise ValueError(f"world file {world!r} not found")


def _semantic_errors(scn: Scenario) -> list[tuple[str, str]]:
    """Checks across fields and files: labels, expectation keys, kidnapping days, localizer
    parameters, the world file and the day range against its calendar."""
    from dynmap_sim.agent.localizer import make_localizer
    from dynmap_sim.world import WorldFileError, load_world

    errors: list[tuple[str, str]] = []
    labels = scn.labels
    for i, lab in enumerate(labels):
        if labels.index(lab) != i:
            errors.append(
                (
                    f"localizers.{i}.label",
                    f"label {lab!r} is used twice; give each a distinct label",
                )
            )
    for key in scn.expectations.localizers:
        if key not in labels:
            errors.append(
                (
                    f"expectations.localizers.{key}",
                    f"no localizer has label {key!r} (labels: {', '.join(labels)})",
                )
            )
    from dynmap_sim.studies.biber_duckett.findings import FINDING_KEYS

    for i, key in enumerate(scn.expectations.findings):
        if key not in FINDING_KEYS:
            errors.append(
                (
                    f"expectations.findings.{i}",
                    f"unknown finding {key!r}; known: {', '.join(FINDING_KEYS)}",
                )
            )
    if scn.expectations.findings and "dynamic-map" not in [loc.name for loc in scn.localizers]:
        errors.append(
            ("expectations.findings", "the findings need a localizer named 'dynamic-map'")
        )
    for i, k in enumerate(scn.kidnappings):
        if not scn.days[0] <= k.day <= scn.days[1]:
            errors.append((f"kidnappings.{i}.day", f"day {k.day} is outside days {list(scn.days)}"))
    for i, loc in enumerate(scn.localizers):
        try:
            rng = np.random.default_rng(0)
            make_localizer(loc.name, laser=_DUMMY_LASER, rng=rng, **loc.params)
        except (TypeError, ValueError) as exc:
            errors.append((f"localizers.{i}.params", f"rejected by {loc.name!r}: {exc}"))
    for check in (robot_kwargs, sensor_kwargs):
        try:
            check(scn)
        except (TypeError, ValueError) as exc:
            where, _, msg = str(exc).partition(": ")
            errors.append((where, msg))
    try:
        spec = load_world(scn.world_path)
    except WorldFileError as exc:
        first = exc.errors[0] if exc.errors else ("", "")
        more = f" (+{len(exc.errors) - 1} more)" if len(exc.errors) > 1 else ""
        errors.append(("world", f"world file {exc.path} is invalid: {first[0]}: {first[1]}{more}"))
        return errors
    n_days = _calendar_days(spec)
    if n_days is not None and scn.days[1] > n_days:
        errors.append(
            ("days", f"the world's calendar has {n_days} days; days {list(scn.days)} ask more")
        )
    return errors


#: Robot presets: overrides of :class:`dynmap_sim.robot.diff_drive.RobotParams` defaults.
ROBOT_PRESETS: dict[str, dict[str, Any]] = {"default": {}}


def robot_kwargs(scn: Scenario) -> dict[str, Any]:
    """``robot`` and ``encoder`` arguments of ``DynMapEnv`` (ValueError on bad values).

    ``[robot] overrides``: any ``RobotParams`` field (``radius_m``, ``max_v_mps``, ...), plus
    ``wheels`` (``WheelGeometry``: ``e_d``, ``e_b``, ...) and ``encoder`` (``EncoderNoise``).
    """
    from dynmap_sim.robot.diff_drive import RobotParams
    from dynmap_sim.sensors.odometry import EncoderNoise, WheelGeometry

    preset = scn.robot.preset or "default"
    if preset not in ROBOT_PRESETS:
        raise ValueError(f"robot.preset: unknown robot {preset!r}; known: {sorted(ROBOT_PRESETS)}")
    rob = {**ROBOT_PRESETS[preset], **scn.robot.overrides}
    try:
        wheels = WheelGeometry(**dict(rob.pop("wheels", {})))  # type: ignore[arg-type]
        encoder = EncoderNoise(**dict(rob.pop("encoder", {})))  # type: ignore[arg-type]
        robot = RobotParams(wheels=wheels, **rob)  # type: ignore[arg-type]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"robot.overrides: {exc}") from None
    return {"robot": robot, "encoder": encoder}


def sensor_kwargs(scn: Scenario) -> dict[str, Any]:
    """``sensor``, ``sensor_options`` and ``lidar_noise`` arguments of ``DynMapEnv``.

    ``[sensor] overrides``: ``make_lidar`` overrides (``LaserSpec`` fields, ``beams``,
    ``mode``, ``mount_pose``) and ``noise`` (``LidarNoise`` fields). ValueError on bad values.
    """
    from dynmap_sim.sensors.lidar import make_lidar

    sensor = scn.sensor.preset or "urg-04lx"
    opts = dict(scn.sensor.overrides)
    noise = opts.pop("noise", None)
    if "mount_pose" in opts:
        opts["mount_pose"] = tuple(opts["mount_pose"])  # type: ignore[arg-type]
    try:
        make_lidar(sensor, noise=noise, **opts)  # type: ignore[arg-type]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"sensor: {exc}") from None
    return {"sensor": sensor, "sensor_options": opts, "lidar_noise": noise}


def env_kwargs(scn: Scenario) -> dict[str, Any]:
    """Keyword arguments of ``DynMapEnv`` for a scenario's world, robot, sensor and people."""
    return {
        "world": str(scn.world_path),
        "people": scn.people,
        **robot_kwargs(scn),
        **sensor_kwargs(scn),
    }


def _calendar_days(spec: Any) -> int | None:
    """Number of working days of a world spec's calendar, or None when it cannot be told."""
    try:
        from dynmap_sim.world.calendar import Calendar

        return int(Calendar(spec.calendar).n_days)
    except Exception:  # noqa: BLE001 - the run itself will report a real problem
        return None


def parse_scenario(data: dict[str, Any], path: str | Path = "<scenario>") -> Scenario:
    """Validate scenario data (a parsed TOML table); ``path`` is used for messages and for
    resolving relative world paths."""
    p = Path(path)
    try:
        scn = Scenario.model_validate(data, context={"base_dir": p.parent})
    except ValidationError as exc:
        raise ScenarioFileError(p, pydantic_errors(exc)) from None
    scn._source = p.resolve() if p.exists() else None
    if scn._source is None:
        scn._world_path = _resolve_world(scn.world, p.parent)
    errors = _semantic_errors(scn)
    if errors:
        raise ScenarioFileError(p, errors)
    return scn


def load_scenario(path: str | Path) -> Scenario:
    """Load and validate a scenario file; raise :class:`ScenarioFileError` listing all errors."""
    data = read_toml(path, ScenarioFileError)
    return parse_scenario(data, path)


def is_scenario_file(path: str | Path) -> bool:
    """True when ``path`` looks like a scenario (not a world): it has scenario-only keys, or
    it lives in a ``scenarios`` folder."""
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return "scenarios" in p.parts
    return bool(_SCENARIO_KEYS & set(data)) or isinstance(data.get("world"), str)


def scenario_json_schema() -> dict[str, Any]:
    """JSON schema of scenario files (for editors)."""
    schema = Scenario.model_json_schema()
    schema["title"] = "dynmap_sim scenario"
    return schema
