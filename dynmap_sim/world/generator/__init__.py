"""Worlds nobody drew: a generator of apartments, offices, labs and warehouse halls.

```python
from dynmap_sim.world.generator import generate_world, write_world
spec = generate_world("office", seed=3, params={"days": 5, "people": 10})
write_world("office", 3, "office-3.toml", params={"days": 5})
```

:func:`generate_world` returns the same typed :class:`~dynmap_sim.world.spec.WorldSpec` that
:func:`~dynmap_sim.world.loader.load_world` makes of the written file. The same kind, seed and
parameters give the same file byte for byte. Every world's route is checked feasible on day 1
for the robot's radius (grid A* on that day's geometry); see docs/worlds/generated.md.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dynmap_sim.world.calendar import Calendar
from dynmap_sim.world.generator.blocks import draw_blocks
from dynmap_sim.world.generator.changes import draw_changes, draw_periodic
from dynmap_sim.world.generator.feasibility import RouteProblem, route_problems
from dynmap_sim.world.generator.furnish import furnish
from dynmap_sim.world.generator.grid import rasterize
from dynmap_sim.world.generator.params import (
    KINDS,
    PARAMS,
    GeneratorError,
    check_kind,
    check_seed,
    parse_param,
    resolve_params,
)
from dynmap_sim.world.generator.place import Placer
from dynmap_sim.world.generator.plan import Plan, draw_plan
from dynmap_sim.world.generator.population import draw_calendar, draw_people
from dynmap_sim.world.generator.route import HUBS, draw_route
from dynmap_sim.world.generator.writer import (
    relative_world,
    scenario_toml,
    world_toml,
    write_atomically,
)
from dynmap_sim.world.loader import parse_world
from dynmap_sim.world.spec import WorldSpec

__all__ = [
    "KINDS",
    "PARAMS",
    "GeneratedWorld",
    "GeneratorError",
    "RouteProblem",
    "generate",
    "generate_world",
    "parse_param",
    "route_problems",
    "write_world",
]

_SKIP_ALWAYS = ("bath", "store")
#: One random stream per concern; a new one goes last so the others stay as they were.
_STREAMS = ("plan", "furnish", "calendar", "changes", "blocks", "people", "route", "periodic")


@dataclass(frozen=True)
class GeneratedWorld:
    """A generated world: its file's dict, its typed spec, the comment header, the counts of
    each family drawn."""

    data: dict[str, Any]
    spec: WorldSpec
    header: list[str]
    counts: dict[str, int]
    blocks: dict[str, str]  # route-block object id -> "a way round" | "no way round"

    def toml(self) -> str:
        """The world file's text."""
        return world_toml(self.data, self.header)


def _route_rooms(plan: Plan, rng) -> tuple[list, list[str]]:
    """Rooms the route visits (hubs always) and the doors it never passes (may close)."""
    visit, skipped = [], set()
    for room in plan.rooms:
        off = room.use in _SKIP_ALWAYS or (
            room.use not in HUBS and room.use in ("office", "meeting") and rng.random() < 0.35
        )
        (skipped.add(room.id) if off else visit.append(room))
    closable = sorted(
        f"{dw.id}_leaf" for dw in plan.doorways if dw.door and set(dw.rooms) & skipped
    )
    return visit, closable


def _header(kind: str, seed: int, p: dict, counts: dict[str, int], notes: dict[str, str]):
    changed = {k: v for k, v in p.items() if v != next(q for q in PARAMS if q.name == k).default}
    lines = [
        f"A generated {kind} (dynmap-sim generate {kind} --seed {seed}"
        + "".join(f" --param {k}={v}" for k, v in sorted(changed.items()))
        + ").",
        "Families of change drawn: " + ", ".join(f"{k} {v}" for k, v in counts.items()) + ".",
    ]
    lines += [f"{oid}: closes the route for a day or two with {how}." for oid, how in notes.items()]
    return lines


def _sort_key(ev: dict[str, Any]) -> tuple[int, int]:
    return (int(ev.get("at", ev.get("start", 1))), int(ev.get("run", 1)))


def generate(kind: str, seed: int, params: Mapping[str, Any] | None = None) -> GeneratedWorld:
    """Generate a world of ``kind`` (:data:`KINDS`) from ``seed``; GeneratorError for bad
    input. Each concern draws from its own child of ``SeedSequence([seed, kind])``."""
    kind, seed, p = check_kind(kind), check_seed(seed), resolve_params(params)
    ss = np.random.SeedSequence([seed, KINDS.index(kind)])
    rng = dict(
        zip(_STREAMS, (np.random.default_rng(s) for s in ss.spawn(len(_STREAMS))), strict=True)
    )
    plan = draw_plan(kind, rng["plan"], p)
    placer = Placer(plan.walls)
    fur = furnish(plan, rng["furnish"], placer, float(p["clutter_per_10m2"]))
    cal = draw_calendar(rng["calendar"], p)
    n_runs = len(cal["runs"])
    visit, closable = _route_rooms(plan, rng["route"])
    ch = draw_changes(plan, fur, placer, rng["changes"], p, n_runs, closable)
    periodic = draw_periodic(fur, rng["periodic"], p, closable)
    if periodic.events:  # written only when asked for: other worlds stay byte for byte
        ch.events += periodic.events
        ch.counts.update(periodic.counts)
    closed = tuple(f"door_closed:{d}" for d in closable)
    polys = placer.polygons(skip=("keepout", "lane", "door_closed:")) + placer.polygons(only=closed)
    grid = rasterize(plan.bounds, polys)
    radius = float(p["robot_radius_m"])
    route = draw_route(grid, plan, fur, visit, radius)
    blocks, block_events, block_counts, notes = draw_blocks(
        grid,
        rasterize(plan.bounds, placer.polygons(only="wall")),
        placer,
        route,
        rng["blocks"],
        p,
        int(p["days"]),
        n_runs,
    )
    heading = float(np.arctan2(route[1][1] - route[0][1], route[1][0] - route[0][0]))
    counts = {**ch.counts, **block_counts}
    data: dict[str, Any] = {
        "name": f"{kind}-{seed}",
        "description": f"Generated {kind}, seed {seed}: {plan.width:g} m x {plan.depth:g} m",
        "bounds": list(plan.bounds),
        "calendar": cal,
        "robot": {
            "start": [float(route[0][0]), float(route[0][1]), round(heading, 4)],
            "route": [[float(x), float(y)] for x, y in route],
        },
        "walls": plan.walls,
        "objects": fur.objects + ch.objects + blocks,
        "schedule": sorted(ch.events + block_events, key=_sort_key),
        "people": draw_people(
            plan, rng["people"], p, [tuple(q) for q in route], {r.id for r in visit}
        ),
    }
    header = _header(kind, seed, p, counts, notes)
    spec = parse_world(data, f"<generated {kind} seed {seed}>")
    _check_day_one(spec, seed, radius)
    return GeneratedWorld(data, spec, header, counts, notes)


def _check_day_one(spec: WorldSpec, seed: int, radius: float) -> None:
    """Every run of day 1: the route's legs keep the robot's radius clear (grid A*)."""
    cal = Calendar(spec.calendar)
    slots = [(1, r) for r in range(1, cal.runs_per_day + 1)]
    problems = route_problems(spec, seed, radius, slots)
    if problems:
        pr = problems[0]
        raise GeneratorError(
            f"generated {spec.name}: the route is not feasible on day {pr.day} run {pr.run}: "
            f"{pr.field} at ({pr.x:.2f}, {pr.y:.2f}): {pr.message}"
        )


def generate_world(kind: str, seed: int, params: Mapping[str, Any] | None = None) -> WorldSpec:
    """The typed world spec of :func:`generate` (what ``load_world`` makes of its file)."""
    return generate(kind, seed, params).spec


def write_world(
    kind: str,
    seed: int,
    out: str | Path,
    params: Mapping[str, Any] | None = None,
    scenario: str | Path | None = None,
    force: bool = False,
) -> GeneratedWorld:
    """Generate and write ``out`` (and ``scenario``): both or neither, an existing file only
    with ``force``; GeneratorError for bad input or an unwritable output."""
    g = generate(kind, seed, params)
    targets = {Path(out): None}
    if scenario is not None:
        targets[Path(scenario)] = None
    if len(targets) < (2 if scenario is not None else 1):
        raise GeneratorError("the scenario and the world must be different files")
    for path in targets:
        _check_output(path, force)
    files = {Path(out): g.toml()}
    if scenario is not None:
        sp = Path(scenario)
        head = [f"A tour of the generated world {g.spec.name} over its whole calendar."]
        files[sp] = scenario_toml(
            f"{g.spec.name}-tour", relative_world(Path(out), sp), g.spec.calendar.n_days, seed, head
        )
    try:
        write_atomically(files)
    except OSError as exc:
        raise GeneratorError(f"cannot write {exc.filename or out}: {exc.strerror or exc}") from None
    return g


def _check_output(path: Path, force: bool) -> None:
    """An output file: its folder exists and is writable, it is no folder or device, and an
    existing file is replaced only with ``force``."""
    import os

    if path.is_dir():
        raise GeneratorError(f"{path}: is a folder; give a file name")
    if path.exists() and not path.is_file():
        raise GeneratorError(f"{path}: not a regular file")
    if path.exists() and not force:
        raise GeneratorError(f"{path} already exists; pass --force to replace it")
    parent = path.parent
    if not parent.is_dir():
        raise GeneratorError(f"{path}: folder {parent} does not exist; create it first")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise GeneratorError(f"{path}: folder {parent} is not writable")
