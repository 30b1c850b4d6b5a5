"""Load and check world files: structure (pydantic) then meaning (ids, dates, geometry).

All errors of a file are reported at once as :class:`WorldFileError` with dotted field paths.
Semantic checks run once the structure is valid (they need typed values): duplicate ids,
unknown targets and groups, event times outside the calendar, objects inside walls, a route
or start pose through a wall, people areas outside the bounds.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from pydantic import ValidationError

from dynmap_sim.errors import FileError, pydantic_errors, read_toml
from dynmap_sim.world.calendar import Calendar
from dynmap_sim.world.polygons import edge_normals, sat_separation, transform
from dynmap_sim.world.schedule import wall_pieces
from dynmap_sim.world.spec import (
    ACTIONS,
    AddEvent,
    DoorEvent,
    GrowEvent,
    InstallEvent,
    MoveEvent,
    ObjectSpec,
    PeriodicEvent,
    PresentEvent,
    RemoveEvent,
    ShuffleEvent,
    WorldSpec,
)

#: Objects may touch walls; they must not go into them deeper than this [m].
WALL_TOLERANCE_M = 0.01
WORLDS_DIR = Path(__file__).resolve().parents[2] / "worlds"


class WorldFileError(FileError):
    """All errors of one world file, each ``(dotted.field.path, message)``."""


def resolve_world_path(name_or_path: str | Path) -> Path:
    """``"lab"``/``"apartment"`` -> ``worlds/<name>.toml``; an existing path passes through."""
    p = Path(name_or_path)
    if p.suffix == "" and not p.exists():
        for folder in (WORLDS_DIR, Path.cwd() / "worlds"):  # source tree, then working dir
            cand = folder / f"{p.name}.toml"
            if cand.exists():
                return cand
    return p


def world_json_schema() -> dict[str, Any]:
    """JSON schema of world files (for editors); shipped as ``worlds/world.schema.json``."""
    schema = WorldSpec.model_json_schema(by_alias=True)
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "dynmap_sim world file"
    return schema


def _drop_action_tag(loc: str) -> str:
    """``schedule.1.shuffle.region`` -> ``schedule.1.region`` (pydantic adds the union tag)."""
    parts = loc.split(".")
    if len(parts) >= 3 and parts[0] == "schedule" and parts[2] in ACTIONS:
        del parts[2]
    return ".".join(parts)


def parse_world(data: dict[str, Any], path: str | Path = "<world>") -> WorldSpec:
    """Validate a world already read into a dict; raises :class:`WorldFileError`."""
    try:
        spec = WorldSpec.model_validate(data)
    except ValidationError as exc:
        errors = [(_drop_action_tag(loc), msg) for loc, msg in pydantic_errors(exc)]
        raise WorldFileError(path, errors) from None
    errors = check_world(spec)
    if errors:
        raise WorldFileError(path, errors)
    return spec


def load_world(path: str | Path) -> WorldSpec:
    """Read, validate and check a world file (or a shipped world's name)."""
    p = resolve_world_path(path)
    return parse_world(read_toml(p, WorldFileError), p)


def _segment_poly(a, b) -> np.ndarray:
    """The segment ``a``-``b`` as a two-vertex polygon (for :func:`sat_separation`)."""
    return np.array([a, b], dtype=np.float64)


_Errors = list[tuple[str, str]]
#: Events that happen at one moment (``at``, ``run``); the others span ``start`` .. ``end``.
_AT_EVENTS = AddEvent | RemoveEvent | InstallEvent | MoveEvent | DoorEvent


def check_world(spec: WorldSpec) -> list[tuple[str, str]]:
    """Semantic errors of a structurally valid world, as ``(dotted path, message)``."""
    cal = Calendar(spec.calendar)
    errs, objects = _check_ids(spec)
    errs += _check_schedule(spec, cal, objects)
    walls = wall_pieces(spec)
    errs += _check_object_poses(spec, objects, walls)
    errs += _check_wall_points(spec)
    errs += _check_route(spec, walls)
    errs += _check_start(spec, walls)
    errs += _check_people(spec, cal)
    return errs


class _WallIndex:
    """Wall pieces in a uniform grid of their bounding boxes, with their SAT axes: a query
    tests only the pieces whose cells a polygon's box touches, so checking N objects against
    W walls costs about N times the walls nearby, not N x W."""

    def __init__(self, walls: list[tuple[str, np.ndarray]], cell: float = 2.0) -> None:
        self.walls = walls
        self.axes = [edge_normals(p) for _, p in walls]
        self.cell = cell
        self.cells: dict[tuple[int, int], list[int]] = {}
        for k, (_, p) in enumerate(walls):
            for key in self._keys(p.min(axis=0), p.max(axis=0)):
                self.cells.setdefault(key, []).append(k)

    def _keys(self, lo: np.ndarray, hi: np.ndarray):
        c = self.cell
        i0, j0 = int(np.floor(lo[0] / c)), int(np.floor(lo[1] / c))
        i1, j1 = int(np.floor(hi[0] / c)), int(np.floor(hi[1] / c))
        if (i1 - i0 + 1) * (j1 - j0 + 1) > 4096:  # a huge box: every wall is a candidate
            yield None
            return
        for i in range(i0, i1 + 1):
            for j in range(j0, j1 + 1):
                yield (i, j)

    def near(self, poly: np.ndarray, margin: float = 0.0) -> list[int]:
        """Indices (in file order) of the wall pieces whose cells ``poly``'s box touches."""
        lo, hi = poly.min(axis=0) - margin, poly.max(axis=0) + margin
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            return list(range(len(self.walls)))
        out: set[int] = set()
        for key in self._keys(lo, hi):
            if key is None:
                return list(range(len(self.walls)))
            out.update(self.cells.get(key, ()))
        return sorted(out)


def _in_bounds(x: float, y: float, bounds: tuple[float, float, float, float]) -> bool:
    """True where the point ``(x, y)`` lies in ``bounds`` (a NaN coordinate does not)."""
    bx0, by0, bx1, by1 = bounds
    return bx0 <= x <= bx1 and by0 <= y <= by1


def _box_outside(box, bounds: tuple[float, float, float, float]) -> bool:
    """True where the box ``(xmin, ymin, xmax, ymax)`` reaches out of ``bounds``."""
    x0, y0, x1, y1 = box
    bx0, by0, bx1, by1 = bounds
    return x0 < bx0 or y0 < by0 or x1 > bx1 or y1 > by1


def _first_wall_crossed(
    poly: np.ndarray, walls: list[tuple[str, np.ndarray]], index: _WallIndex | None = None
) -> str | None:
    """Id of the first wall piece (in file order) that ``poly`` overlaps, or None."""
    near = range(len(walls)) if index is None else index.near(poly)
    for k in near:
        pid, wp = walls[k]
        if sat_separation(poly, wp) < 0:
            return pid
    return None


def _check_ids(spec: WorldSpec) -> tuple[_Errors, dict[str, ObjectSpec]]:
    """Duplicate ids of walls and objects (one namespace) and of people; objects by id."""
    errs: _Errors = []
    seen: dict[str, str] = {}
    for i, w in enumerate(spec.walls):
        if w.id in seen:
            errs.append((f"walls.{i}.id", f"duplicate id {w.id!r} (also {seen[w.id]})"))
        else:
            seen[w.id] = f"walls.{i}"
    objects = {}
    for i, o in enumerate(spec.objects):
        if o.id in seen:
            errs.append((f"objects.{i}.id", f"duplicate id {o.id!r} (also {seen[o.id]})"))
        else:
            seen[o.id] = f"objects.{i}"
            objects[o.id] = o
    pids: set[str] = set()
    for i, p in enumerate(spec.people):
        if p.id in pids:
            errs.append((f"people.{i}.id", f"duplicate id {p.id!r}"))
        pids.add(p.id)
    return errs, objects


def _check_schedule(spec: WorldSpec, cal: Calendar, objects: dict[str, ObjectSpec]) -> _Errors:
    """Each event in turn: its references, times, installations and shuffle region."""
    errs: _Errors = []
    groups: dict[str, list[ObjectSpec]] = {}
    for o in spec.objects:
        if o.group is not None:
            groups.setdefault(o.group, []).append(o)
    installed: dict[str, int] = {}  # permanently installed object -> day of installation
    for i, ev in enumerate(spec.schedule):
        loc = f"schedule.{i}"
        errs += _event_references(ev, loc, objects, groups)
        time_errs, days = _event_times(ev, loc, cal)
        errs += time_errs
        errs += _event_installations(groups, ev, loc, days, installed)
        if isinstance(ev, ShuffleEvent):
            errs += _shuffle_region(spec, ev, loc, groups.get(ev.group, []))
        if isinstance(ev, PeriodicEvent):
            errs += _periodic_rule(spec, ev, loc, objects, groups)
    return errs


def _periodic_rule(
    spec: WorldSpec,
    ev: PeriodicEvent,
    loc: str,
    objects: dict[str, ObjectSpec],
    groups: dict[str, list[ObjectSpec]],
) -> _Errors:
    """A periodic open/closed acts on doors only; its weekdays are working days."""
    errs: _Errors = []
    if ev.state in ("open", "closed"):
        if ev.target is not None and ev.target in objects and objects[ev.target].kind != "door":
            errs.append((f"{loc}.target", f"{ev.target!r} is not a door (state {ev.state!r})"))
        for o in groups.get(ev.group or "", []) if ev.group is not None else []:
            if o.kind != "door":
                errs.append((f"{loc}.group", f"{o.id!r} of group {ev.group!r} is not a door"))
                break
    for k, day in enumerate(ev.weekdays or ()):
        if day not in spec.calendar.weekdays:
            errs.append(
                (
                    f"{loc}.weekdays.{k}",
                    f"{day!r} is not a working day of the calendar "
                    f"({', '.join(spec.calendar.weekdays)})",
                )
            )
    return errs


def _event_references(
    ev: Any, loc: str, objects: dict[str, ObjectSpec], groups: dict[str, list[ObjectSpec]]
) -> _Errors:
    """An event's target is a known object (a door for door events), its group a known one."""
    errs: _Errors = []
    target = getattr(ev, "target", None)
    group = getattr(ev, "group", None)
    if target is not None and target not in objects:
        errs.append((f"{loc}.target", f"unknown object id {target!r}"))
    if group is not None and group not in groups:
        errs.append((f"{loc}.group", f"unknown group {group!r}"))
    if isinstance(ev, DoorEvent) and target in objects and objects[target].kind != "door":
        errs.append((f"{loc}.target", f"{target!r} is not a door"))
    return errs


def _event_times(ev: Any, loc: str, cal: Calendar) -> tuple[_Errors, dict[str, int | None]]:
    """An event's run and days inside the calendar, its end not before its start; the days."""
    errs: _Errors = []
    rpd = cal.runs_per_day
    times: list[tuple[str, Any]] = []
    if isinstance(ev, _AT_EVENTS):
        times.append(("at", ev.at))
        if ev.run > rpd:
            errs.append((f"{loc}.run", f"run {ev.run} but the calendar has {rpd} per day"))
    else:
        times.append(("start", ev.start))
        if getattr(ev, "end", None) is not None:
            times.append(("end", ev.end))
    days = {}
    for key, when in times:
        d = cal.day_of(when)
        if d is None:
            errs.append(
                (
                    f"{loc}.{key}",
                    f"{when} is outside the calendar "
                    f"({cal.dates[0]} .. {cal.dates[-1]}, days 1..{cal.n_days})",
                )
            )
        days[key] = d
    if days.get("start") and days.get("end") and days["end"] < days["start"]:
        errs.append((f"{loc}.end", "end is before start"))
    return errs, days


def _event_installations(
    groups: dict[str, list[ObjectSpec]],
    ev: Any,
    loc: str,
    days: dict[str, int | None],
    installed: dict[str, int],
) -> _Errors:
    """Record installations in ``installed``; a later removal or presence of one is an error."""
    errs: _Errors = []
    if isinstance(ev, InstallEvent):
        for oid in _event_object_ids(groups, ev):
            installed[oid] = days.get("at") or 0
    if isinstance(ev, RemoveEvent | PresentEvent) or (
        isinstance(ev, PeriodicEvent) and ev.state in ("present", "absent")
    ):
        for oid in _event_object_ids(groups, ev):
            if oid in installed and (days.get("at") or days.get("start") or 0) >= installed[oid]:
                errs.append((loc, f"{oid!r} is a permanent installation and cannot be removed"))
    return errs


def _event_object_ids(groups: dict[str, list[ObjectSpec]], ev: Any) -> list[str]:
    """Ids an event applies to: its target, else every object of its group."""
    target = getattr(ev, "target", None)
    group = getattr(ev, "group", None)
    return [target] if target else [o.id for o in groups.get(group, [])]


def _shuffle_region(
    spec: WorldSpec, ev: ShuffleEvent, loc: str, members: list[ObjectSpec]
) -> _Errors:
    """A shuffle region lies in the bounds and fits each object of its group (turned if it may)."""
    errs: _Errors = []
    x0, y0, x1, y1 = ev.region
    if _box_outside(ev.region, spec.bounds):
        errs.append((f"{loc}.region", "region is outside the world bounds"))
    for o in members:
        theta = 0.0 if ev.rotate else o.pose[2]
        v = transform(o.local_vertices(), (0.0, 0.0, theta))
        w, h = v.max(axis=0) - v.min(axis=0)
        fits = (w <= x1 - x0 and h <= y1 - y0) or (ev.rotate and h <= x1 - x0 and w <= y1 - y0)
        if not fits:
            errs.append((f"{loc}.region", f"{o.id!r} does not fit in the region"))
    return errs


def _object_poses(spec: WorldSpec, objects: dict[str, ObjectSpec]) -> list[tuple[str, str, tuple]]:
    """Every pose an object takes ``(location, id, pose)``: initial, open, then moved to."""
    poses: list[tuple[str, str, tuple]] = [
        (f"objects.{i}", o.id, o.pose) for i, o in enumerate(spec.objects)
    ]
    for i, o in enumerate(spec.objects):
        if o.open_pose is not None:
            poses.append((f"objects.{i}.open_pose", o.id, o.open_pose))
    for i, ev in enumerate(spec.schedule):
        if isinstance(ev, MoveEvent) and ev.target in objects:
            poses.append((f"schedule.{i}.pose", ev.target, ev.pose))
    return poses


def _max_scales(spec: WorldSpec, objects: dict[str, ObjectSpec]) -> dict[str, float]:
    """The largest scale each object grows to (1 without a grow event)."""
    scale = {oid: 1.0 for oid in objects}
    for ev in spec.schedule:
        if isinstance(ev, GrowEvent) and ev.target in scale:
            scale[ev.target] = max(scale[ev.target], ev.scale_start, ev.scale_end)
    return scale


def _check_object_poses(
    spec: WorldSpec, objects: dict[str, ObjectSpec], walls: list[tuple[str, np.ndarray]]
) -> _Errors:
    """At each of its poses, fully grown, an object is in the bounds and not inside a wall."""
    errs: _Errors = []
    scale = _max_scales(spec, objects)
    index = _WallIndex(walls)
    local = {oid: o.local_vertices() for oid, o in objects.items()}
    for loc, oid, pose in _object_poses(spec, objects):
        o = objects.get(oid)
        if o is None:
            continue
        if not _pose_in_bounds(pose, spec.bounds):
            errs.append((loc, _pose_message("object", oid, pose, spec.bounds)))
            continue
        poly = transform(local[oid], pose, scale[oid])
        if o.kind != "wall":
            axes = edge_normals(poly)
            for k in index.near(poly):
                depth = -sat_separation(poly, walls[k][1], axes, index.axes[k])
                if depth > WALL_TOLERANCE_M:
                    pid = walls[k][0]
                    errs.append((loc, f"object {oid!r} is inside wall {pid!r} by {depth:.2f} m"))
                    break
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        if _box_outside((lo[0], lo[1], hi[0], hi[1]), spec.bounds):
            errs.append((loc, f"object {oid!r} is outside the world bounds"))
    return errs


#: Largest heading [rad] a pose may give (a few turns either way).
MAX_HEADING_RAD = 100.0


def _pose_in_bounds(pose, bounds) -> bool:
    """True where a pose's position lies in ``bounds`` and its heading is a few turns."""
    return _in_bounds(pose[0], pose[1], bounds) and abs(pose[2]) <= MAX_HEADING_RAD


def _pose_message(what: str, oid: str | None, pose, bounds) -> str:
    name = f"{what} {oid!r}" if oid else what
    if abs(pose[2]) > MAX_HEADING_RAD:
        return f"{name}: heading {pose[2]:g} rad is not within +-{MAX_HEADING_RAD:g}"
    return (
        f"{name} at ({pose[0]:g}, {pose[1]:g}) is outside the world bounds "
        f"[{', '.join(f'{b:g}' for b in bounds)}]"
    )


def _check_wall_points(spec: WorldSpec) -> _Errors:
    """Every wall point lies in the bounds."""
    errs: _Errors = []
    for i, w in enumerate(spec.walls):
        for k, (x, y) in enumerate(w.points):
            if not _in_bounds(x, y, spec.bounds):
                errs.append((f"walls.{i}.points.{k}", "point outside the world bounds"))
    return errs


def _check_route(spec: WorldSpec, walls: list[tuple[str, np.ndarray]]) -> _Errors:
    """No leg of the robot's route goes through a wall; its waypoints lie in the bounds."""
    errs: _Errors = []
    route = np.array(spec.robot.waypoints, dtype=np.float64)
    inside = [_in_bounds(x, y, spec.bounds) for x, y in route]
    bx0, by0, bx1, by1 = spec.bounds
    w, h = bx1 - bx0, by1 - by0
    near = [_in_bounds(x, y, (bx0 - w, by0 - h, bx1 + w, by1 + h)) for x, y in route]
    index = _WallIndex(walls)
    for k in range(len(route) - 1):
        if not (near[k] and near[k + 1]):
            continue  # far out of the world (reported below): no wall to go through
        pid = _first_wall_crossed(_segment_poly(route[k], route[k + 1]), walls, index)
        if pid is not None:
            errs.append((f"robot.route.{k}", f"route leg {k}->{k + 1} goes through wall {pid!r}"))
    for k, (x, y) in enumerate(route):
        if not inside[k]:
            errs.append(
                (f"robot.route.{k}", f"waypoint ({x:g}, {y:g}) is outside the world bounds")
            )
    return errs


def _check_start(spec: WorldSpec, walls: list[tuple[str, np.ndarray]]) -> _Errors:
    """The robot's start is in the bounds and (a 0.4 m square) not inside a wall."""
    sx, sy, _ = spec.robot.start
    if not _pose_in_bounds(spec.robot.start, spec.bounds):
        return [("robot.start", _pose_message("start pose", None, spec.robot.start, spec.bounds))]
    start = np.array(
        [[sx - 0.2, sy - 0.2], [sx + 0.2, sy - 0.2], [sx + 0.2, sy + 0.2], [sx - 0.2, sy + 0.2]]
    )
    pid = _first_wall_crossed(start, walls)
    if pid is not None:
        return [("robot.start", f"start pose is inside wall {pid!r}")]
    return []


def _check_people(spec: WorldSpec, cal: Calendar) -> _Errors:
    """People's areas, goals and routes lie in the bounds; their start and end in the calendar;
    their weekday profiles are for working days."""
    errs: _Errors = []
    for i, p in enumerate(spec.people):
        for k, area in enumerate(p.areas):
            if _box_outside(area, spec.bounds):
                errs.append((f"people.{i}.areas.{k}", "area is outside the world bounds"))
        for key in ("goals", "route"):
            for k, (x, y) in enumerate(getattr(p, key)):
                if not _in_bounds(x, y, spec.bounds):
                    errs.append((f"people.{i}.{key}.{k}", "point outside the world bounds"))
        for key in ("start", "end"):
            when = getattr(p, key)
            if when is not None and cal.day_of(when) is None:
                errs.append((f"people.{i}.{key}", f"{when} is outside the calendar"))
        for day in type(p.weekday_profiles).model_fields:
            if getattr(p.weekday_profiles, day) is not None and day not in spec.calendar.weekdays:
                errs.append(
                    (
                        f"people.{i}.weekday_profiles.{day}",
                        f"{day!r} is not a working day of the calendar",
                    )
                )
    return errs
