"""Typed, frozen models of a world file (docs/architecture.md §3), validated by pydantic v2.

A world file is TOML with these sections: ``name``, ``bounds``, ``[calendar]``, ``[robot]``,
``[[walls]]``, ``[[objects]]``, ``[[schedule]]`` and ``[[people]]``. Units are SI (metres,
radians, seconds); times of day are ``"HH:MM"``; a calendar moment (``at``, ``start``,
``end``) is either a 1-based working-day number or a TOML date (``2007-10-23``), which maps
to the first working day on or after it. Structural checks live here; cross-references and
geometry (objects inside walls, routes through walls, dates outside the calendar) are checked
by :mod:`dynmap_sim.world.loader`. A minimal file::

    name = "room"
    bounds = [-0.5, -0.5, 6.5, 4.5]            # xmin, ymin, xmax, ymax [m]

    [calendar]
    start = 2024-01-01                         # first working day (or earlier)
    n_days = 10                                # working days
    weekdays = ["mon", "tue", "wed", "thu", "fri"]
    runs = ["09:00", "14:00"]                  # runs per day and their clock times

    [robot]
    start = [1.0, 1.0, 0.0]                    # x_m, y_m, theta_rad
    route = [[1.0, 1.0], [5.0, 1.0], [5.0, 3.0]]

    [[walls]]                                  # a polyline with thickness -> closed outlines
    id = "outer"
    points = [[0, 0], [6, 0], [6, 4], [0, 4], [0, 0]]
    thickness_m = 0.2

    [[objects]]                                # box | polygon (convex) | circle, with a pose
    id = "poster"
    kind = "exhibit"                           # furniture | exhibit | door | robot | wall
    group = "expo"
    size = [0.6, 0.1]
    pose = [4.0, 2.0, 0.0]

    [[schedule]]                               # add | remove | install | move | open | close
    action = "present"                         # | present | shuffle | grow | periodic
    group = "expo"
    start = 3
    end = 5

    [[people]]
    id = "walkers"
    count = 3
    areas = [[0.5, 0.5, 5.5, 2.2]]
    profile = [[8.0, 0.2], [12.5, 1.0], [18.0, 0.2]]   # [hour, fraction of count]

Set ``blocks_route = true`` on an ``add``/``install``/``move`` that puts an object on the
route on purpose (H&W day 22); the route clearance check and the driver then know it.
"""

from __future__ import annotations

import datetime as dt
import re
from typing import Annotated, Literal, get_args

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    PlainValidator,
    ValidationInfo,
    WithJsonSchema,
    field_validator,
    model_validator,
)

from dynmap_sim.world.polygons import FloatArray

Point = tuple[float, float]
Pose = tuple[float, float, float]
Box = tuple[float, float, float, float]


def _when(v: object) -> int | dt.date:
    """A calendar moment: a 1-based working-day number or a date."""
    if isinstance(v, dt.datetime):
        return v.date()
    if isinstance(v, dt.date):
        return v
    if isinstance(v, int) and not isinstance(v, bool):
        if v < 1:
            raise ValueError("day numbers start at 1")
        return v
    if isinstance(v, str):
        try:
            return dt.date.fromisoformat(v)
        except ValueError:
            pass
    raise ValueError("expected a working-day number (1, 2, ...) or a date like 2007-10-23")


When = Annotated[
    int | dt.date,
    PlainValidator(_when),
    WithJsonSchema(
        {
            "anyOf": [{"type": "integer", "minimum": 1}, {"type": "string", "format": "date"}],
            "description": "working day (1-based) or date",
        }
    ),
]
Weekday = Literal["mon", "tue", "wed", "thu", "fri", "sat", "sun"]
WEEKDAYS: tuple[str, ...] = ("mon", "tue", "wed", "thu", "fri", "sat", "sun")
MAX_EXTENT_M = 1000.0
#: Largest coordinate [m] of the bounds: far from the origin float64 loses the millimetres.
MAX_COORD_M = 1e6
_HHMM = re.compile(r"^([01]?\d|2[0-3]):([0-5]\d)$")


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


def _check_box(v: Box) -> Box:
    if not (v[2] > v[0] and v[3] > v[1]):
        raise ValueError("a box is [xmin, ymin, xmax, ymax] with xmax > xmin and ymax > ymin")
    return v


class CalendarSpec(_Model):
    """Start date, working days and run times (docs/architecture.md §2)."""

    start: dt.date = Field(description="date of the first working day (or earlier)")
    n_days: int = Field(gt=0, le=1000, description="number of working days in the experiment")
    weekdays: tuple[Weekday, ...] = Field(
        default=("mon", "tue", "wed", "thu", "fri"), description="weekdays that are working days"
    )
    holidays: tuple[dt.date, ...] = Field(default=(), description="dates that are not worked")
    runs: tuple[str, ...] = Field(min_length=1, description='clock times of the runs, "HH:MM"')

    @field_validator("weekdays")
    @classmethod
    def _weekdays(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        if not v:
            raise ValueError("at least one weekday must be a working day")
        if len(set(v)) != len(v):
            raise ValueError("weekdays must not repeat")
        return v

    @field_validator("runs")
    @classmethod
    def _runs(cls, v: tuple[str, ...]) -> tuple[str, ...]:
        secs = []
        for t in v:
            m = _HHMM.match(t)
            if not m:
                raise ValueError(f'run time {t!r} must look like "HH:MM"')
            secs.append(int(m.group(1)) * 60 + int(m.group(2)))
        if any(b <= a for a, b in zip(secs, secs[1:], strict=False)):
            raise ValueError("run times must be strictly increasing")
        return v

    @model_validator(mode="after")
    def _fits_before_year_10000(self) -> CalendarSpec:
        """The working days can be laid out before ``date.max``: every week has a working
        day, and each holiday costs at most a week more."""
        span = 7 * (self.n_days + len(self.holidays) + 1)
        if (dt.date.max - self.start).days < span:
            raise ValueError(
                f"a calendar of {self.n_days} working days from {self.start} may run past "
                f"{dt.date.max}; start it earlier"
            )
        return self


class RobotSpec(_Model):
    """Start pose and the route the operator drives, both in the map frame [m, rad]."""

    model_config = ConfigDict(
        extra="forbid", frozen=True, allow_inf_nan=False, populate_by_name=True
    )

    start: Pose = Field(description="start pose [x_m, y_m, theta_rad]")
    waypoints: tuple[Point, ...] = Field(
        alias="route", min_length=2, description="route waypoints [[x_m, y_m], ...]"
    )

    @property
    def route(self) -> FloatArray:
        """Route waypoints as a read-only ``(K, 2)`` float64 array [m]."""
        a = np.array(self.waypoints, dtype=np.float64).reshape(-1, 2)
        a.setflags(write=False)
        return a

    @property
    def route_length_m(self) -> float:
        """Length of the route polyline [m]."""
        return float(np.sum(np.hypot(*np.diff(self.route, axis=0).T)))


class WallSpec(_Model):
    """A static wall: a polyline of ``points`` with ``thickness_m`` (becomes closed outlines)."""

    id: str = Field(min_length=1)
    points: tuple[Point, ...] = Field(min_length=2, description="polyline vertices [[x, y], ...]")
    thickness_m: float = Field(default=0.1, gt=0.0)

    @field_validator("points")
    @classmethod
    def _distinct(cls, v: tuple[Point, ...]) -> tuple[Point, ...]:
        for a, b in zip(v, v[1:], strict=False):
            if a == b:
                raise ValueError("consecutive wall points must differ")
        return v


class ObjectSpec(_Model):
    """A furniture item, exhibit, door, robot or movable wall with a pose in the map frame.

    ``shape`` is ``box`` (needs ``size = [width_m, depth_m]``), ``polygon`` (needs convex
    ``vertices`` in the object frame) or ``circle`` (needs ``radius_m``). ``present`` says
    whether it stands there at the start of the calendar. A door with ``open = true`` is
    open; an open door swings to ``open_pose`` if given, or leaves the doorway free.
    """

    id: str = Field(min_length=1)
    kind: Literal["furniture", "exhibit", "door", "robot", "wall"]
    group: str | None = None
    shape: Literal["box", "polygon", "circle"] = "box"
    size: Point | None = Field(default=None, description="box [width_m, depth_m]")
    vertices: tuple[Point, ...] | None = Field(default=None, description="convex polygon")
    radius_m: float | None = Field(default=None, description="circle radius [m]")
    pose: Pose = Field(description="[x_m, y_m, theta_rad] of the object frame")
    present: bool = True
    open: bool = False
    open_pose: Pose | None = None

    @field_validator("size")
    @classmethod
    def _size(cls, v: Point | None) -> Point | None:
        if v is not None and not (v[0] > 0 and v[1] > 0):
            raise ValueError("sizes must be > 0")
        return v

    @field_validator("radius_m")
    @classmethod
    def _radius(cls, v: float | None) -> float | None:
        if v is not None and not v > 0:
            raise ValueError("radius must be > 0")
        return v

    @field_validator("vertices")
    @classmethod
    def _vertices(cls, v: tuple[Point, ...] | None) -> tuple[Point, ...] | None:
        from dynmap_sim.world.polygons import is_convex

        if v is not None and (len(v) < 3 or not is_convex(np.array(v, dtype=np.float64))):
            raise ValueError("a polygon needs at least 3 vertices and must be convex")
        return v

    @model_validator(mode="after")
    def _shape_params(self) -> ObjectSpec:
        need = {"box": "size", "polygon": "vertices", "circle": "radius_m"}[self.shape]
        if getattr(self, need) is None:
            raise ValueError(f"shape {self.shape!r} needs {need!r}")
        extra = [k for k in ("size", "vertices", "radius_m") if k != need and getattr(self, k)]
        if extra:
            raise ValueError(f"shape {self.shape!r} does not take {', '.join(extra)}")
        if self.kind != "door" and (self.open or self.open_pose is not None):
            raise ValueError("only doors can be open")
        return self

    def local_vertices(self) -> FloatArray:
        """Outline in the object frame, ``(K, 2)`` CCW [m] (circles as circumscribed 16-gons)."""
        from dynmap_sim.world.polygons import box_vertices, ccw, circle_vertices

        if self.shape == "box":
            assert self.size is not None
            return box_vertices(*self.size)
        if self.shape == "circle":
            assert self.radius_m is not None
            return circle_vertices(self.radius_m)
        return ccw(np.array(self.vertices, dtype=np.float64))


class _Event(_Model):
    pass


class _Targeted(_Event):
    target: str | None = Field(default=None, description="object id")
    group: str | None = Field(default=None, description="group name")
    at: When = Field(description="working day (1-based) or date the change is made")
    run: int = Field(default=1, ge=1, description="the change is seen from this run of the day")

    @model_validator(mode="after")
    def _one_target(self):
        if (self.target is None) == (self.group is None):
            raise ValueError("give exactly one of 'target' or 'group'")
        return self


class AddEvent(_Targeted):
    """Put an object (or a group) in place; ``blocks_route`` marks an intended route block."""

    action: Literal["add"]
    blocks_route: bool = False


class RemoveEvent(_Targeted):
    """Take an object (or a group) away."""

    action: Literal["remove"]


class InstallEvent(_Targeted):
    """A permanent installation (e.g. radiators): added and never removed afterwards."""

    action: Literal["install"]
    blocks_route: bool = False


class MoveEvent(_Event):
    """Move one object to ``pose`` [x_m, y_m, theta_rad]."""

    action: Literal["move"]
    target: str
    at: When
    run: int = Field(default=1, ge=1)
    pose: Pose
    blocks_route: bool = False


class DoorEvent(_Event):
    """Open or close a door."""

    action: Literal["open", "close"]
    target: str
    at: When
    run: int = Field(default=1, ge=1)


class PresentEvent(_Event):
    """A group stands between two days (inclusive) and is absent outside them (exhibitions)."""

    action: Literal["present"]
    group: str
    start: When
    end: When


class ShuffleEvent(_Event):
    """Re-place a group at random within ``region`` every ``every_runs`` runs (seeded).

    Each occurrence draws poses from a ``SeedSequence`` keyed by (seed, event, day, run), so
    the state at any run is a pure function of the file, the seed and the time.
    """

    action: Literal["shuffle"]
    group: str
    region: Box = Field(description="[xmin, ymin, xmax, ymax] the members stay inside")
    start: When = 1
    end: When | None = Field(default=None, description="last day (default: calendar end)")
    every_runs: int = Field(default=1, ge=1)
    rotate: bool = Field(default=True, description="draw a random heading too")
    min_gap_m: float = Field(default=0.1, ge=0.0, description="clearance to other objects")

    @field_validator("region")
    @classmethod
    def _region(cls, v: Box) -> Box:
        return _check_box(v)


class GrowEvent(_Event):
    """Gradual change: an object's size scales linearly from ``scale_start`` to ``scale_end``."""

    action: Literal["grow"]
    target: str
    start: When
    end: When
    scale_start: float = Field(gt=0.0)
    scale_end: float = Field(gt=0.0)


def _hhmm_minutes(t: str, allow_24: bool = False) -> int:
    """Minutes after midnight of a clock time ``"HH:MM"`` (``"24:00"`` too with ``allow_24``)."""
    if allow_24 and t == "24:00":
        return 24 * 60
    m = _HHMM.match(t)
    if not m:
        raise ValueError(f'clock time {t!r} must look like "HH:MM" (00:00 .. 23:59)')
    return int(m.group(1)) * 60 + int(m.group(2))


def _clock_time(v: str) -> str:
    """``v`` if it is a clock time ``"HH:MM"``, else ``ValueError``."""
    _hhmm_minutes(v)
    return v


ClockTime = Annotated[str, AfterValidator(_clock_time)]


class PeriodicEvent(_Event):
    """An object, a group or a door in ``state`` inside a daily clock window, the other state
    outside it (a door open in office hours, chairs taken away at lunch).

    On each working day from ``start`` to ``end`` whose weekday is in ``weekdays``, the window
    applies with probability ``p``, drawn from a ``SeedSequence`` keyed by (seed, event, date);
    a run is inside the window when its start time is in ``[from, to)``. Inside ``start`` ..
    ``end`` the target is in the window's state at the runs inside an applying window and in
    the other state at every other run (on a day the window does not apply, all day); outside
    ``start`` .. ``end`` the event does nothing. It acts on top of the other events: it can
    only take away, making the target absent (or a door closed) where its rule says so, and
    elsewhere the target keeps the state the rest of the schedule gives it. An object removed
    by a ``remove`` stays removed, a door shut by a ``close`` stays shut, and a door opened by
    the window must be open in the file (``open = true``) or by an ``open`` event.
    """

    model_config = ConfigDict(
        extra="forbid", frozen=True, allow_inf_nan=False, populate_by_name=True
    )

    action: Literal["periodic"]
    target: str | None = Field(default=None, description="object id (a door for open/closed)")
    group: str | None = Field(default=None, description="group name")
    state: Literal["present", "absent", "open", "closed"] = Field(
        description="state inside the window (the other one outside): present/absent for "
        "objects and groups, open/closed for doors"
    )
    from_: ClockTime = Field(alias="from", description='window start, clock time "HH:MM"')
    to: str = Field(description='window end, clock time "HH:MM" after `from` (or "24:00")')
    weekdays: tuple[Weekday, ...] | None = Field(
        default=None, description="weekdays the window applies on (default: every working day)"
    )
    start: When = Field(default=1, description="first day the event acts")
    end: When | None = Field(default=None, description="last day it acts (default: calendar end)")
    p: float = Field(
        default=1.0, ge=0.0, le=1.0, description="probability that the window applies on a day"
    )

    @field_validator("to")
    @classmethod
    def _to(cls, v: str, info: ValidationInfo) -> str:
        end = _hhmm_minutes(v, allow_24=True)
        start = info.data.get("from_")
        if start is not None and end <= _hhmm_minutes(start):
            raise ValueError(f"the window must end after it starts: to {v!r} <= from {start!r}")
        return v

    @field_validator("weekdays")
    @classmethod
    def _weekdays(cls, v: tuple[str, ...] | None) -> tuple[str, ...] | None:
        if v is not None and not v:
            raise ValueError("give at least one weekday, or leave weekdays out for every day")
        if v is not None and len(set(v)) != len(v):
            raise ValueError("weekdays must not repeat")
        return v

    @model_validator(mode="after")
    def _check(self) -> PeriodicEvent:
        if (self.target is None) == (self.group is None):
            raise ValueError("give exactly one of 'target' or 'group'")
        return self

    @property
    def from_minutes(self) -> int:
        """Window start [min after midnight]."""
        return _hhmm_minutes(self.from_)

    @property
    def to_minutes(self) -> int:
        """Window end [min after midnight], exclusive."""
        return _hhmm_minutes(self.to, allow_24=True)


Event = Annotated[
    AddEvent
    | RemoveEvent
    | InstallEvent
    | MoveEvent
    | DoorEvent
    | PresentEvent
    | ShuffleEvent
    | GrowEvent
    | PeriodicEvent,
    Field(discriminator="action"),
]
#: Every ``action`` a schedule entry may have, in the order of :data:`Event`.
ACTIONS: tuple[str, ...] = tuple(
    a
    for cls in get_args(get_args(Event)[0])
    for a in get_args(cls.model_fields["action"].annotation)
)


Profile = tuple[Point, ...]


def _check_profile(v: Profile) -> Profile:
    """``v`` if it is a profile ``[[hour, fraction], ...]`` (hours increasing in [0, 24],
    fractions in [0, 1]), else ``ValueError``."""
    if not v:
        raise ValueError("profile needs at least one [hour, fraction] point")
    hours = [h for h, _ in v]
    if any(b <= a for a, b in zip(hours, hours[1:], strict=False)):
        raise ValueError("profile hours must be strictly increasing")
    if any(not (0 <= h <= 24) for h in hours) or any(not (0 <= f <= 1) for _, f in v):
        raise ValueError("profile hours must be in [0, 24] and fractions in [0, 1]")
    return v


CheckedProfile = Annotated[Profile, AfterValidator(_check_profile)]


class WeekdayProfiles(_Model):
    """Profiles ``[[hour, fraction], ...]`` for some weekdays, instead of ``profile`` on them
    (nobody on Saturdays, a busy Friday afternoon)."""

    mon: CheckedProfile | None = None
    tue: CheckedProfile | None = None
    wed: CheckedProfile | None = None
    thu: CheckedProfile | None = None
    fri: CheckedProfile | None = None
    sat: CheckedProfile | None = None
    sun: CheckedProfile | None = None


class PeopleSpec(_Model):
    """A population of pedestrians (Helbing & Molnár social force, see the ``people`` package).

    Up to ``count`` people walk inside ``areas`` between ``goals`` (attraction points; random
    points of the areas if empty), or along a ``route`` of waypoints (a closed loop, each
    person starting somewhere on it). ``profile`` gives, as ``[[hour, fraction], ...]`` linearly
    interpolated, the fraction of ``count`` present at a time of day, and ``weekday_profiles``
    another profile for some weekdays (``{ sat = [[0, 0], [24, 0]] }``: nobody on Saturdays);
    ``start``/``end`` restrict the days they come. The number present in a run is fixed at
    the run's start time (runs last minutes; the profile changes over hours).
    """

    id: str = Field(min_length=1)
    count: int = Field(ge=0, le=40)
    areas: tuple[Box, ...] = Field(min_length=1)
    goals: tuple[Point, ...] = ()
    route: tuple[Point, ...] = Field(
        default=(), description="waypoints walked in order as a closed loop (instead of goals)"
    )
    speed_mps: Point = (0.6, 1.3)
    radius_m: float = Field(default=0.22, gt=0.0, le=0.5)
    profile: CheckedProfile = ((0.0, 1.0), (24.0, 1.0))
    weekday_profiles: WeekdayProfiles = Field(
        default_factory=WeekdayProfiles,
        description="profiles for some weekdays instead of `profile`: { sat = [[0, 0], [24, 0]] }",
    )
    start: When | None = None
    end: When | None = None

    @field_validator("areas")
    @classmethod
    def _areas(cls, v: tuple[Box, ...]) -> tuple[Box, ...]:
        for b in v:
            _check_box(b)
        return v

    @model_validator(mode="after")
    def _goals_or_route(self) -> PeopleSpec:
        if self.goals and self.route:
            raise ValueError("give either 'goals' or 'route', not both")
        if len(self.route) == 1:
            raise ValueError("a route needs at least 2 waypoints")
        return self

    @field_validator("speed_mps")
    @classmethod
    def _speed(cls, v: Point) -> Point:
        if not (0 < v[0] <= v[1] <= 3.0):
            raise ValueError("speed range must satisfy 0 < min <= max <= 3 m/s")
        return v

    def profile_on(self, weekday: int) -> Profile:
        """The profile of a day with ``weekday`` (0 Monday .. 6 Sunday)."""
        own = getattr(self.weekday_profiles, WEEKDAYS[weekday])
        return self.profile if own is None else own


class WorldSpec(_Model):
    """A whole world file."""

    name: str = Field(min_length=1)
    description: str = ""
    bounds: Box = Field(description="[xmin, ymin, xmax, ymax] of the world [m]")
    calendar: CalendarSpec
    robot: RobotSpec
    walls: tuple[WallSpec, ...] = ()
    objects: tuple[ObjectSpec, ...] = ()
    schedule: tuple[Event, ...] = ()
    people: tuple[PeopleSpec, ...] = ()

    @field_validator("bounds")
    @classmethod
    def _bounds(cls, v: Box) -> Box:
        _check_box(v)
        if v[2] - v[0] > MAX_EXTENT_M or v[3] - v[1] > MAX_EXTENT_M:
            raise ValueError(f"a world is at most {MAX_EXTENT_M:.0f} m across")
        if max(abs(c) for c in v) > MAX_COORD_M:
            raise ValueError(f"bounds must lie within {MAX_COORD_M:g} m of the origin")
        return v
