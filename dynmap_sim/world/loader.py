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
from dynmap_sim.world.polygons import sat_separation, transform
from dynmap_sim.world.schedule import wall_pieces
from dynmap_sim.world.spec import (
    AddEvent,
    DoorEvent,
    GrowEvent,
    InstallEvent,
    MoveEvent,
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


_ACTIONS = ("add", "remove", "install", "move", "open", "close", "present", "shuffle", "grow")


def _drop_action_tag(loc: str) -> str:
    """``schedule.1.shuffle.region`` -> ``schedule.1.region`` (pydantic adds the union tag)."""
    parts = loc.split(".")
    if len(parts) >= 3 and parts[0] == "schedule" and parts[2] in _ACTIONS:
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
    return np.array([a, b], dtype=np.float64)


def check_world(spec: WorldSpec) -> list[tuple[str, str]]:
    """Semantic errors of a structurally valid world, as ``(dotted path, message)``."""
    errs: list[tuple[str, str]] = []
    cal = Calendar(spec.calendar)
    rpd = cal.runs_per_day

    # ids
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
    groups = {o.group for o in spec.objects if o.group is not None}

    # schedule references and times
    installed: dict[str, int] = {}
    for i, ev in enumerate(spec.schedule):
        loc = f"schedule.{i}"
        target = getattr(ev, "target", None)
        group = getattr(ev, "group", None)
        if target is not None and target not in objects:
            errs.append((f"{loc}.target", f"unknown object id {target!r}"))
        if group is not None and group not in groups:
            errs.append((f"{loc}.group", f"unknown group {group!r}"))
        if isinstance(ev, DoorEvent) and target in objects and objects[target].kind != "door":
            errs.append((f"{loc}.target", f"{target!r} is not a door"))
        times: list[tuple[str, Any]] = []
        if isinstance(ev, AddEvent | RemoveEvent | InstallEvent | MoveEvent | DoorEvent):
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
        if isinstance(ev, InstallEvent):
            for oid in [target] if target else [o.id for o in spec.objects if o.group == group]:
                installed[oid] = days.get("at") or 0
        if isinstance(ev, RemoveEvent) or (isinstance(ev, PresentEvent)):
            for oid in [target] if target else [o.id for o in spec.objects if o.group == group]:
                if (
                    oid in installed
                    and (days.get("at") or days.get("start") or 0) >= installed[oid]
                ):
                    errs.append((loc, f"{oid!r} is a permanent installation and cannot be removed"))
        if isinstance(ev, ShuffleEvent):
            x0, y0, x1, y1 = ev.region
            bx0, by0, bx1, by1 = spec.bounds
            if x0 < bx0 or y0 < by0 or x1 > bx1 or y1 > by1:
                errs.append((f"{loc}.region", "region is outside the world bounds"))
            for o in spec.objects:
                if o.group == group:
                    theta = 0.0 if ev.rotate else o.pose[2]
                    v = transform(o.local_vertices(), (0.0, 0.0, theta))
                    w, h = v.max(axis=0) - v.min(axis=0)
                    fits = (w <= x1 - x0 and h <= y1 - y0) or (
                        ev.rotate and h <= x1 - x0 and w <= y1 - y0
                    )
                    if not fits:
                        errs.append((f"{loc}.region", f"{o.id!r} does not fit in the region"))

    # geometry: objects inside walls, route/start through walls
    walls = wall_pieces(spec)
    poses: list[tuple[str, str, tuple]] = [
        (f"objects.{i}", o.id, o.pose) for i, o in enumerate(spec.objects)
    ]
    for i, o in enumerate(spec.objects):
        if o.open_pose is not None:
            poses.append((f"objects.{i}.open_pose", o.id, o.open_pose))
    for i, ev in enumerate(spec.schedule):
        if isinstance(ev, MoveEvent) and ev.target in objects:
            poses.append((f"schedule.{i}.pose", ev.target, ev.pose))
    bx0, by0, bx1, by1 = spec.bounds
    scale = {oid: 1.0 for oid in objects}
    for ev in spec.schedule:
        if isinstance(ev, GrowEvent) and ev.target in scale:
            scale[ev.target] = max(scale[ev.target], ev.scale_start, ev.scale_end)
    for loc, oid, pose in poses:
        o = objects.get(oid)
        if o is None:
            continue
        poly = transform(o.local_vertices(), pose, scale[oid])
        if o.kind != "wall":
            for pid, wp in walls:
                depth = -sat_separation(poly, wp)
                if depth > WALL_TOLERANCE_M:
                    errs.append((loc, f"object {oid!r} is inside wall {pid!r} by {depth:.2f} m"))
                    break
        lo, hi = poly.min(axis=0), poly.max(axis=0)
        if lo[0] < bx0 or lo[1] < by0 or hi[0] > bx1 or hi[1] > by1:
            errs.append((loc, f"object {oid!r} is outside the world bounds"))
    for i, w in enumerate(spec.walls):
        for k, (x, y) in enumerate(w.points):
            if not (bx0 <= x <= bx1 and by0 <= y <= by1):
                errs.append((f"walls.{i}.points.{k}", "point outside the world bounds"))
    route = np.array(spec.robot.waypoints, dtype=np.float64)
    for k in range(len(route) - 1):
        seg = _segment_poly(route[k], route[k + 1])
        for pid, wp in walls:
            if sat_separation(seg, wp) < 0:
                errs.append(
                    (f"robot.route.{k}", f"route leg {k}->{k + 1} goes through wall {pid!r}")
                )
                break
    for k, (x, y) in enumerate(route):
        if not (bx0 <= x <= bx1 and by0 <= y <= by1):
            errs.append((f"robot.route.{k}", "waypoint outside the world bounds"))
    sx, sy, _ = spec.robot.start
    start = np.array(
        [[sx - 0.2, sy - 0.2], [sx + 0.2, sy - 0.2], [sx + 0.2, sy + 0.2], [sx - 0.2, sy + 0.2]]
    )
    for pid, wp in walls:
        if sat_separation(start, wp) < 0:
            errs.append(("robot.start", f"start pose is inside wall {pid!r}"))
            break
    for i, p in enumerate(spec.people):
        for k, (x0, y0, x1, y1) in enumerate(p.areas):
            if x0 < bx0 or y0 < by0 or x1 > bx1 or y1 > by1:
                errs.append((f"people.{i}.areas.{k}", "area is outside the world bounds"))
        for key in ("goals", "route"):
            for k, (x, y) in enumerate(getattr(p, key)):
                if not (bx0 <= x <= bx1 and by0 <= y <= by1):
                    errs.append((f"people.{i}.{key}.{k}", "point outside the world bounds"))
        for key in ("start", "end"):
            when = getattr(p, key)
            if when is not None and cal.day_of(when) is None:
                errs.append((f"people.{i}.{key}", f"{when} is outside the calendar"))
    return errs
