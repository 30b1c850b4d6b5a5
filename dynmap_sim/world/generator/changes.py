"""The schedule of change: every family of event the world format knows, at named rates.

Moves, additions, removals, shuffles, doors closed and opened again, exhibitions,
installations and growth are drawn here, before the route (periodic doors and chair
groups, which only take things away, by :func:`draw_periodic` from a stream of their own);
every outline an object ever takes is put into the
:class:`~dynmap_sim.world.generator.place.Placer`, so the route (drawn round all of them)
keeps clear of every change. Route blocks come after the route
(:mod:`dynmap_sim.world.generator.blocks`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from dynmap_sim.world.generator.furnish import Furnished, inner_box
from dynmap_sim.world.generator.place import (
    HALF_PI,
    Placer,
    inside,
    outline,
    rounded_pose,
)
from dynmap_sim.world.generator.plan import Plan, Room

#: Rooms large enough for an exhibition, by use.
_EXHIBITION_ROOMS = ("lobby", "lab", "warehouse", "openplan", "living", "corridor")


@dataclass
class Changes:
    """New objects and events (world-file dicts), and how many of each family were drawn."""

    objects: list[dict[str, Any]] = field(default_factory=list)
    events: list[dict[str, Any]] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)


class _Drawer:
    def __init__(self, plan: Plan, fur: Furnished, placer: Placer, rng, p: dict, n_runs: int):
        self.plan, self.fur, self.placer, self.rng, self.p = plan, fur, placer, rng, p
        self.days = int(p["days"])
        self.n_runs = n_runs
        self.out = Changes()
        self.objects = {o["id"]: o for o in fur.objects}

    def when(self, first: int = 1) -> tuple[int, int]:
        """A day in ``first .. days`` and a run of it."""
        first = min(first, self.days)
        return int(self.rng.integers(first, self.days + 1)), int(
            self.rng.integers(1, self.n_runs + 1)
        )

    def count(self, per_week: float) -> int:
        return int(self.rng.poisson(per_week * self.days / 5.0))

    def spot(self, room: Room, size, tag: str, circle: bool = False, tries: int = 40):
        """A pose for an object of ``size`` in ``room`` clear of everything ever placed:
        against a wall or somewhere on the floor; None if none is found."""
        x0, y0, x1, y1 = inner_box(self.plan, room)
        for _ in range(tries):
            th = 0.0 if self.rng.random() < 0.5 else HALF_PI
            w, d = (size, size) if circle else size
            ex, ey = (w, d) if th == 0.0 else (d, w)
            if x1 - x0 < ex or y1 - y0 < ey:
                continue
            x = self.rng.uniform(x0 + ex / 2, x1 - ex / 2)
            y = self.rng.uniform(y0 + ey / 2, y1 - ey / 2)
            if self.rng.random() < 0.6:  # against the nearest wall
                dx = min(x - x0 - ex / 2, x1 - ex / 2 - x)
                dy = min(y - y0 - ey / 2, y1 - ey / 2 - y)
                if dx < dy:
                    x = x0 + ex / 2 if x - x0 < x1 - x else x1 - ex / 2
                else:
                    y = y0 + ey / 2 if y - y0 < y1 - y else y1 - ey / 2
            obj = {"pose": rounded_pose(x, y, th)}
            if circle:
                obj.update(shape="circle", radius_m=size)
            else:
                obj["size"] = list(size)
            poly = outline(obj)
            if inside(poly, (x0, y0, x1, y1)) and self.placer.free(poly, 0.05, {tag}):
                return obj["pose"], poly
        return None

    def new_object(self, room: Room, name: str, size, kind="furniture", circle=False, **extra):
        """A new object placed in ``room`` (not present at first), or None."""
        oid = f"{name}_{len(self.out.objects)}"
        found = self.spot(room, size, oid, circle)
        if found is None:
            return None
        pose, poly = found
        obj: dict[str, Any] = {"id": oid, "kind": kind, **extra}
        if circle:
            obj.update(shape="circle", radius_m=size)
        else:
            obj["size"] = list(size)
        obj["pose"] = pose
        self.placer.add(poly, oid)
        self.out.objects.append(obj)
        return obj

    def rooms(self, uses=None) -> list[Room]:
        return [r for r in self.plan.rooms if uses is None or r.use in uses]

    def pick_room(self, uses=None) -> Room:
        rooms = self.rooms(uses) or self.rooms()
        return rooms[int(self.rng.integers(len(rooms)))]

    def ids(self, *roles: str) -> list[str]:
        return [oid for oid, r in self.fur.role.items() if r in roles]


def _moves(dr: _Drawer) -> None:
    movable = dr.ids("movable")
    n = 0
    for _ in range(dr.count(dr.p["move_per_week"]) if movable else 0):
        oid = movable[int(dr.rng.integers(len(movable)))]
        o = dr.objects[oid]
        room = dr.plan.room(dr.fur.room_of[oid])
        found = dr.spot(room, o.get("radius_m") or tuple(o["size"]), oid, "radius_m" in o)
        if found is None:
            continue
        pose, poly = found
        dr.placer.add(poly, oid)
        day, run = dr.when(2)
        dr.out.events.append({"action": "move", "target": oid, "at": day, "run": run, "pose": pose})
        n += 1
    dr.out.counts["move"] = n


def _new_pieces(dr: _Drawer, action: str, n: int, choose) -> None:
    """``n`` new pieces ``choose()`` -> ``(name, size)``, each put in place by ``action``."""
    placed = 0
    for _ in range(n):
        name, size = choose()
        obj = dr.new_object(dr.pick_room(), name, size, present=False)
        if obj is None:
            continue
        day, run = dr.when(2)
        dr.out.events.append({"action": action, "target": obj["id"], "at": day, "run": run})
        placed += 1
    dr.out.counts[action] = placed


def _adds(dr: _Drawer) -> None:
    kinds = [("new_cabinet", (1.0, 0.45)), ("boxes", (0.6, 0.4)), ("new_table", (1.2, 0.7))]
    n = dr.count(dr.p["add_per_week"])
    _new_pieces(dr, "add", n, lambda: kinds[int(dr.rng.integers(len(kinds)))])


def _removes(dr: _Drawer) -> None:
    pool = dr.ids("clutter", "chair_loose", "movable")
    n = 0
    for _ in range(min(dr.count(dr.p["remove_per_week"]), len(pool))):
        oid = pool.pop(int(dr.rng.integers(len(pool))))
        day, run = dr.when(2)
        dr.out.events.append({"action": "remove", "target": oid, "at": day, "run": run})
        if day < dr.days and dr.rng.random() < 0.5:  # brought back some days later
            back = int(dr.rng.integers(day + 1, dr.days + 1))
            dr.out.events.append({"action": "add", "target": oid, "at": back})
        n += 1
    dr.out.counts["remove"] = n


def _shuffles(dr: _Drawer) -> None:
    groups = sorted(dr.fur.regions)
    dr.rng.shuffle(groups)
    n = 0
    for g in groups[: int(dr.p["shuffle_groups"])]:
        ev: dict[str, Any] = {"action": "shuffle", "group": g, "region": list(dr.fur.regions[g])}
        if dr.rng.random() < 0.5 and dr.days > 1:
            ev["start"] = int(dr.rng.integers(2, dr.days + 1))
        ev["every_runs"] = 1 if dr.rng.random() < 0.6 else dr.n_runs
        ev["min_gap_m"] = 0.05
        dr.out.events.append(ev)
        n += 1
    dr.out.counts["shuffle"] = n


def _doors(dr: _Drawer, closable: list[str]) -> None:
    busy: dict[str, list[tuple[int, int]]] = {d: [] for d in closable}
    n = 0
    for _ in range(dr.count(dr.p["door_per_week"]) if closable else 0):
        door = closable[int(dr.rng.integers(len(closable)))]
        day, run = dr.when(1)
        back = min(dr.days + 1, day + int(dr.rng.integers(1, 4)))
        if any(a <= back and day <= b for a, b in busy[door]):
            continue
        busy[door].append((day, back))
        dr.out.events.append({"action": "close", "target": door, "at": day, "run": run})
        if back <= dr.days:
            dr.out.events.append({"action": "open", "target": door, "at": back})
        n += 1
    dr.out.counts["door"] = n


def _exhibitions(dr: _Drawer) -> None:
    n = 0
    for k in range(int(dr.p["exhibitions"])):
        room = max(dr.rooms(_EXHIBITION_ROOMS), key=lambda r: r.area_m2 * dr.rng.uniform(0.5, 1))
        group = f"exhibition_{k}"
        items = [
            ("poster", (1.0, 0.1), False),
            ("stand", 0.3, True),
            ("display", (1.2, 0.6), False),
        ]
        placed = 0
        for i in range(int(dr.rng.integers(3, 7))):
            name, size, circ = items[i % len(items)]
            placed += (
                dr.new_object(room, f"{group}_{name}", size, "exhibit", circ, group=group)
                is not None
            )
        if not placed:
            continue
        start = int(dr.rng.integers(1, dr.days + 1))
        end = min(dr.days, start + int(dr.rng.integers(1, 6)))
        dr.out.events.append({"action": "present", "group": group, "start": start, "end": end})
        n += 1
    dr.out.counts["exhibition"] = n


def _installs(dr: _Drawer) -> None:
    _new_pieces(dr, "install", int(dr.p["installs"]), lambda: ("radiator", (1.2, 0.12)))


def _growth(dr: _Drawer) -> None:
    n = 0
    for _ in range(int(dr.p["growth"])):
        end_scale = round(float(dr.rng.uniform(1.4, 2.0)), 2)
        r = round(float(dr.rng.uniform(0.15, 0.22)), 3)
        room = dr.pick_room(("living", "lobby", "openplan", "lab", "office", "warehouse"))
        obj = dr.new_object(room, "plant", round(r * end_scale, 3), circle=True)
        if obj is None:
            continue
        obj["radius_m"] = r  # reserved at its full size, written at its first
        start_scale = round(float(dr.rng.uniform(0.6, 0.9)), 2)
        dr.out.events.append(
            {
                "action": "grow",
                "target": obj["id"],
                "start": 1,
                "end": dr.days,
                "scale_start": start_scale,
                "scale_end": end_scale,
            }
        )
        n += 1
    dr.out.counts["grow"] = n


def draw_changes(
    plan: Plan, fur: Furnished, placer: Placer, rng, p: dict, n_runs: int, closable: list[str]
) -> Changes:
    """Every family of change at its parameter's rate; ``closable`` are the doors that may
    close (the route does not pass them)."""
    dr = _Drawer(plan, fur, placer, rng, p, n_runs)
    for family in (_moves, _adds, _removes, _shuffles, _exhibitions, _installs, _growth):
        family(dr)
    _doors(dr, closable)
    return dr.out


#: Office hours of a periodic door and lunch hours of a periodic chair group ("HH:MM").
OFFICE_HOURS = ("08:00", "18:00")
LUNCH_HOURS = ("12:00", "13:30")


def draw_periodic(fur: Furnished, rng, p: dict, closable: list[str]) -> Changes:
    """Periodic events: ``periodic_doors`` of the ``closable`` doors (off the route) open in
    office hours on a day with probability ``periodic_p`` and closed otherwise, and
    ``periodic_groups`` shuffled chair groups taken out at lunch. They only close doors and
    take chairs away, so the route drawn round everything stays clear."""
    out = Changes()
    doors = list(closable)
    rng.shuffle(doors)
    for door in sorted(doors[: int(p["periodic_doors"])]):
        out.events.append(
            {
                "action": "periodic",
                "target": door,
                "state": "open",
                "from": OFFICE_HOURS[0],
                "to": OFFICE_HOURS[1],
                "p": float(p["periodic_p"]),
            }
        )
    groups = sorted(fur.regions)
    rng.shuffle(groups)
    for g in sorted(groups[: int(p["periodic_groups"])]):
        out.events.append(
            {
                "action": "periodic",
                "group": g,
                "state": "absent",
                "from": LUNCH_HOURS[0],
                "to": LUNCH_HOURS[1],
            }
        )
    out.counts["periodic_door"] = min(int(p["periodic_doors"]), len(doors))
    out.counts["periodic_group"] = min(int(p["periodic_groups"]), len(groups))
    return out
