"""Scenario files: what to run (world, days, seeds, robot, sensor, driver, localizers, prior,
kidnappings) and what to expect (docs/architecture.md §6).

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
import sys
import tomllib
from collections.abc import Callable, Sequence
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

from dynmap_sim.agent.localization.localizer import LOCALIZERS, make_localizer
from dynmap_sim.env_factory import SimSpec, kidnapping_errors, resolve_world, sim_spec_errors
from dynmap_sim.errors import FileError, pydantic_errors, read_toml
from dynmap_sim.experiments.drivers import DRIVERS, DriverContext, make_driver
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


#: Longest run a scenario may ask for [s] (a day; a robot-time limit, not a wall-time one).
MAX_RUN_S = 86400.0
#: Largest initial pose uncertainty [m], [rad] (beyond: ``initial_pose = "unknown"``).
MAX_SIGMA_XY_M = 100.0
MAX_SIGMA_THETA_RAD = 2.0 * math.pi
#: Seeds are numpy SeedSequence entropy and SQLite integers: 0 .. 2**63 - 1.
MAX_SEED = 2**63 - 1


class DriverConfig(_Strict):
    """Who drives the robot: a driver by registry name (``tour``: a scripted operator
    steering along the world's route) or ``"package.module:ClassName"``, with its ``params``.
    ``speed_mps``, ``max_run_s`` and ``route_fraction`` hold for every driver."""

    kind: str = Field("tour", description="driver registry name or 'package.module:Class'")
    speed_mps: float = Field(0.35, gt=0.0, le=2.0, description="cruise speed [m/s]")
    max_run_s: float | None = Field(
        None,
        gt=0.0,
        le=MAX_RUN_S,
        allow_inf_nan=False,
        description="robot-time limit per run [s] (None: until the route ends)",
    )
    route_fraction: float = Field(
        1.0, gt=0.0, le=1.0, description="drive only this leading fraction of the route"
    )
    params: dict[str, ParamValue] = Field(
        default_factory=dict,
        description="the driver's own parameters (tour: wait_for_people, clearance_m, "
        "planner, controller, ...)",
    )
    localizer: str | None = Field(
        None,
        description="label of the localizer whose estimate the driver steers on, in lock-step "
        "with the simulation (drivers that steer on an estimate need one; tour sees the truth)",
    )

    @model_validator(mode="before")
    @classmethod
    def _tour_shorthand(cls, data: Any) -> Any:
        """``wait_for_people`` and ``clearance_m`` at the top level (the first file format)
        are the tour's parameters."""
        if isinstance(data, dict) and ({"wait_for_people", "clearance_m"} & set(data)):
            data = dict(data)
            params = dict(data.get("params") or {})
            for key in ("wait_for_people", "clearance_m"):
                if key in data:
                    params.setdefault(key, data.pop(key))
            data["params"] = params
        return data

    @field_validator("kind")
    @classmethod
    def _known_driver(cls, v: str) -> str:
        DRIVERS.get(v)  # raises ValueError with the known names
        return v


class PriorConfig(_Strict):
    """Prior knowledge granted to the agent at the start of every run."""

    map: Literal["none", "walls"] = "none"
    initial_pose: Literal["known", "unknown"] = "known"
    initial_pose_sigma_xy_m: float = Field(
        0.05, ge=0.0, le=MAX_SIGMA_XY_M, allow_inf_nan=False, description="[m]"
    )
    initial_pose_sigma_theta_rad: float = Field(
        0.05, ge=0.0, le=MAX_SIGMA_THETA_RAD, allow_inf_nan=False, description="[rad]"
    )


class LocalizerConfig(_Strict):
    """One localizer to evaluate: its class, parameters and a unique display label."""

    name: str = Field(description="registry name (e.g. 'odometry') or 'package.module:Class'")
    label: str | None = Field(None, description="display label (default: the name)")
    params: dict[str, ParamValue] = Field(default_factory=dict)

    @field_validator("name")
    @classmethod
    def _known(cls, v: str) -> str:
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

#: What a driver is built with when only its parameters are validated.
_DUMMY_DRIVER_CONTEXT = DriverContext(
    route=np.array([[0.0, 0.0], [1.0, 0.0]]),
    speed_mps=0.35,
    robot_radius_m=0.2,
    dt_s=0.1,
    laser=_DUMMY_LASER,
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
        if not isinstance(v, str) and not (math.isfinite(v) and 0 <= v <= MAX_RUN_S):
            raise ValueError(f"time_s must be 'random' or in 0..{MAX_RUN_S:g} s, not {v!r}")
        return v

    @field_validator("pose")
    @classmethod
    def _finite_pose(cls, v: Any) -> Any:
        if isinstance(v, str):
            return v
        if not all(math.isfinite(c) for c in v):
            raise ValueError(f"pose must be 3 finite numbers (x_m, y_m, theta_rad), not {v!r}")
        if abs(v[2]) > 2.0 * math.pi:
            raise ValueError(f"pose theta_rad must be in [-2π, 2π], not {v[2]!r}")
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


class NavigationExpectation(_Strict):
    """Navigation thresholds over every run, measured against the truth (all optional)."""

    goal_reached_fraction: float | None = Field(
        None, ge=0, le=1, description="at least this share of runs reach the route's end"
    )
    max_collisions: int | None = Field(None, ge=0, description="bumper onsets in all runs")
    max_near_misses: int | None = Field(
        None, ge=0, description="people closer than 0.3 m to the robot, in all runs"
    )
    min_clearance_m: float | None = Field(
        None, description="the robot's disc keeps at least this from every obstacle [m]"
    )
    max_gave_up: int | None = Field(None, ge=0, description="runs in which the driver gave up")


class Expectations(_Strict):
    """What a regression check asserts (``dynmap-sim check``)."""

    no_collisions: bool = False
    max_skipped_waypoints: int | None = Field(None, ge=0)
    localizers: dict[str, LocalizerExpectation] = Field(default_factory=dict)
    navigation: NavigationExpectation | None = None
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


#: A scenario name names its results folder: this many characters at most, so that every
#: file under ``results/<name>/`` stays well within the usual 255-byte file-name limit.
MAX_NAME_CHARS = 100


class Scenario(_Strict):
    """A validated scenario. ``world_path`` is resolved against the scenario file's folder."""

    name: str = Field(
        min_length=1,
        description="the scenario's name, also its default results folder results/<name>: "
        "no path separators, at most 100 characters so that every file name under it stays "
        "within the file system's limits",
    )
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

    @field_validator("name")
    @classmethod
    def _name_is_a_file_name(cls, v: str) -> str:
        """The name is the default results folder's name (``results/<name>``)."""
        if len(v) > MAX_NAME_CHARS:
            raise ValueError(
                f"the name is a file name (results go to results/<name>): at most "
                f"{MAX_NAME_CHARS} characters, not {len(v)}"
            )
        bad = [c for c in ("/", "\\", "\0") if c in v]
        if bad or v.strip() in (".", "..") or v != v.strip() or any(ord(c) < 32 for c in v):
            raise ValueError(
                f"the name is a file name (results go to results/<name>): no path "
                f"separators, '..', control characters or surrounding spaces, not {v!r}"
            )
        return v

    @field_validator("seeds")
    @classmethod
    def _seeds_ok(cls, v: list[int]) -> list[int]:
        if any(s < 0 or s > MAX_SEED for s in v):
            raise ValueError(
                f"seeds must be in 0..2**63-1, not {[s for s in v if s < 0 or s > MAX_SEED]}"
            )
        if len(set(v)) != len(v):
            raise ValueError("seeds must be distinct")
        return v

    @field_validator("world")
    @classmethod
    def _world_ok(cls, v: str, info: ValidationInfo) -> str:
        base = (info.context or {}).get("base_dir")
        resolve_world(v, base)  # raises ValueError with a readable message
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
            self._world_path = resolve_world(self.world, base)
        return self._world_path

    @property
    def labels(self) -> list[str]:
        """Display labels of the localizers, in file order."""
        return [loc.display for loc in self.localizers]

    def sim_spec(self) -> SimSpec:
        """The simulation this scenario asks for (world, people, robot, sensor)."""
        return SimSpec(
            world=self.world_path,
            people=self.people,
            robot_preset=self.robot.preset,
            robot_overrides=dict(self.robot.overrides),
            sensor_preset=self.sensor.preset,
            sensor_overrides=dict(self.sensor.overrides),
        )

    def content_hash(self) -> str:
        """SHA-256 of the scenario's content and its world file (keys checkpoints)."""
        h = hashlib.sha256()
        h.update(json.dumps(self.model_dump(mode="json"), sort_keys=True).encode())
        h.update(self.world_path.read_bytes())
        return h.hexdigest()


def _semantic_errors(scn: Scenario) -> list[tuple[str, str]]:
    """Checks across fields and files: labels, expectation keys, kidnapping days, localizer
    and driver parameters, robot and sensor overrides, the world file and its calendar."""
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
    for i, k in enumerate(scn.kidnappings):
        if not scn.days[0] <= k.day <= scn.days[1]:
            errors.append((f"kidnappings.{i}.day", f"day {k.day} is outside days {list(scn.days)}"))
    for i, loc in enumerate(scn.localizers):
        try:
            rng = np.random.default_rng(0)
            made = make_localizer(loc.name, laser=_DUMMY_LASER, rng=rng, **loc.params)
        except (TypeError, ValueError) as exc:
            errors.append((f"localizers.{i}.params", f"rejected by {loc.name!r}: {exc}"))
            continue
        if getattr(made, "needs_prior_walls", False) and scn.prior.map != "walls":
            errors.append(
                (
                    f"localizers.{i}.params",
                    f"{loc.name!r} makes its map from the prior's walls, but prior.map is "
                    f'{scn.prior.map!r}: set [prior] map = "walls" (or another map_source)',
                )
            )
    try:
        make_driver(scn.driver.kind, _DUMMY_DRIVER_CONTEXT, scn.driver.params)
    except (TypeError, ValueError) as exc:
        errors.append(("driver.params", f"rejected by {scn.driver.kind!r}: {exc}"))
    needs = DRIVERS.get(scn.driver.kind).needs_estimate
    steer = scn.driver.localizer
    if needs and steer is None:
        errors.append(
            (
                "driver.localizer",
                f"driver {scn.driver.kind!r} steers on a localizer's estimate: "
                f"name one of the labels ({', '.join(labels)})",
            )
        )
    elif steer is not None and not needs:
        errors.append(
            (
                "driver.localizer",
                f"driver {scn.driver.kind!r} does not steer on an estimate "
                "(it sees the truth or only the sensors); remove 'localizer'",
            )
        )
    elif steer is not None and steer not in labels:
        errors.append(
            ("driver.localizer", f"no localizer has label {steer!r} (labels: {', '.join(labels)})")
        )
    errors += sim_spec_errors(scn.sim_spec(), scn.days)
    errors += kidnapping_errors(scn.sim_spec(), [(k.day, k.run, k.pose) for k in scn.kidnappings])
    return errors


def _importable_from(folder: Path) -> None:
    """Put a scenario file's folder on the import path (once), so its ``module:Class`` roles
    are found next to it, as a user expects; worker processes inherit the path."""
    if folder.is_dir():
        entry = str(folder.resolve())
        if entry not in sys.path:
            sys.path.append(entry)


#: An extra check of a valid scenario: ``(dotted field, message)`` pairs, [] when fine.
ScenarioCheck = Callable[[Scenario], list[tuple[str, str]]]


def parse_scenario(
    data: dict[str, Any], path: str | Path = "<scenario>", checks: Sequence[ScenarioCheck] = ()
) -> Scenario:
    """Validate scenario data (a parsed TOML table); ``path`` is used for messages and for
    resolving relative world paths. ``checks`` add checks of layers above the engine (the
    analysis checks that required findings exist); their errors are reported with the rest."""
    p = Path(path)
    _importable_from(p.parent)
    try:
        scn = Scenario.model_validate(data, context={"base_dir": p.parent})
    except ValidationError as exc:
        raise ScenarioFileError(p, pydantic_errors(exc)) from None
    scn._source = p.resolve() if p.exists() else None
    if scn._source is None:
        scn._world_path = resolve_world(scn.world, p.parent)
    errors = _semantic_errors(scn)
    for check in checks:
        errors += check(scn)
    if errors:
        raise ScenarioFileError(p, errors)
    return scn


def load_scenario(path: str | Path, checks: Sequence[ScenarioCheck] = ()) -> Scenario:
    """Load and validate a scenario file; raise :class:`ScenarioFileError` listing all errors
    (``checks``: see :func:`parse_scenario`)."""
    data = read_toml(path, ScenarioFileError)
    return parse_scenario(data, path, checks)


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
