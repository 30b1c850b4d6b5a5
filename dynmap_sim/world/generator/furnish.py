"""Furnishing a floor plan as people do: against walls, tables with chairs round them, desks
in rows, shelves in aisles, partitions making bays, and some clutter.

Doorways keep a free zone on both sides (the door leaf swings there) and a lane of
:data:`LANE_M` joins the doorways of a room, so every room stays walkable.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dynmap_sim.world.generator.place import (
    HALF_PI,
    Placer,
    box_poly,
    inside,
    outline,
    rounded_pose,
)
from dynmap_sim.world.generator.plan import OUTER_M, Doorway, Plan, Room
from dynmap_sim.world.polygons import ccw, thick_segment

#: Width [m] of the free lane kept between a room's doorways.
LANE_M = 1.2


@dataclass
class Furnished:
    """Objects (world-file dicts) and what the schedule may do with them."""

    objects: list[dict[str, Any]] = field(default_factory=list)
    role: dict[str, str] = field(default_factory=dict)  # id -> movable|chair|clutter|...
    room_of: dict[str, str] = field(default_factory=dict)
    regions: dict[str, tuple[float, float, float, float]] = field(default_factory=dict)
    aisles: list[tuple[float, float, float]] = field(default_factory=list)  # (x west, y, x east)


def inner_box(plan: Plan, room: Room, extra: float = 0.0) -> tuple[float, float, float, float]:
    """A room's floor inside its walls (and ``extra`` [m] further in)."""
    m = 0.5 * max(OUTER_M, plan.thickness) + 0.06 + extra
    x0, y0, x1, y1 = room.box
    return (x0 + m, y0 + m, x1 - m, y1 - m)


def doorway_point(dw: Doorway, into: int, depth: float) -> tuple[float, float]:
    """A point ``depth`` [m] from doorway ``dw`` on side ``into`` (+1 / -1)."""
    if dw.along_x:
        return (dw.x, dw.y + into * depth)
    return (dw.x + into * depth, dw.y)


def side_of(dw: Doorway, room: Room) -> int:
    """+1 where ``room`` lies on the larger-coordinate side of the doorway, else -1."""
    cx, cy = 0.5 * (room.box[0] + room.box[2]), 0.5 * (room.box[1] + room.box[3])
    return 1 if ((cy - dw.y) if dw.along_x else (cx - dw.x)) > 0 else -1


class Furnisher:
    """Places furniture room by room into a :class:`Placer`."""

    def __init__(self, plan: Plan, rng, placer: Placer) -> None:
        self.plan, self.rng, self.placer = plan, rng, placer
        self.out = Furnished()
        self._n = 0
        self._keep_clear()

    def _keep_clear(self) -> None:
        for dw in self.plan.doorways:
            half = 0.5 * dw.width + 0.25
            across = dw.width + 0.2
            box = (
                (dw.x - half, dw.y - across, dw.x + half, dw.y + across)
                if dw.along_x
                else (dw.x - across, dw.y - half, dw.x + across, dw.y + half)
            )
            self.placer.add(box_poly(box), "keepout")
        for room in self.plan.rooms:
            if room.use == "warehouse":
                continue  # the shelves make the aisles
            dws = [d for d in self.plan.doorways if d.id in room.doorways]
            pts = [doorway_point(d, side_of(d, room), 0.6) for d in dws]
            if len(pts) == 1:
                x0, y0, x1, y1 = room.box
                pts.append((0.5 * (x0 + x1), 0.5 * (y0 + y1)))
            pts.sort()
            for a, b in zip(pts, pts[1:], strict=False):
                if np.hypot(b[0] - a[0], b[1] - a[1]) > 0.1:
                    self.placer.add(ccw(thick_segment(a, b, LANE_M)), "lane")

    # -- one object -----------------------------------------------------------------------
    def put(
        self,
        room: Room,
        name: str,
        size,
        pose,
        role: str = "fixed",
        kind: str = "furniture",
        group: str | None = None,
        circle: bool = False,
        gap: float = 0.05,
    ) -> dict[str, Any] | None:
        """Place one object if it fits in ``room`` without overlaps; the object dict or None."""
        obj: dict[str, Any] = {"id": f"{room.id}_{name}_{self._n}", "kind": kind}
        if group:
            obj["group"] = group
        if circle:
            obj["shape"] = "circle"
            obj["radius_m"] = round(float(size), 3)
        else:
            obj["size"] = [round(float(size[0]), 3), round(float(size[1]), 3)]
        obj["pose"] = rounded_pose(*pose)
        poly = outline(obj)
        if not inside(poly, inner_box(self.plan, room)) or not self.placer.free(poly, gap):
            return None
        self._n += 1
        self.placer.add(poly, obj["id"])
        self.out.objects.append(obj)
        self.out.role[obj["id"]] = role
        self.out.room_of[obj["id"]] = room.id
        return obj

    def against_wall(self, room: Room, name: str, size, role="fixed", tries=25, **kw):
        """Back against one of the room's walls, at a random place along it."""
        x0, y0, x1, y1 = inner_box(self.plan, room)
        w, d = size
        for _ in range(tries):
            side = int(self.rng.integers(4))
            if side < 2:  # south / north wall: width along x
                if x1 - x0 < w:
                    continue
                x = self.rng.uniform(x0 + w / 2, x1 - w / 2)
                y = y0 + d / 2 if side == 0 else y1 - d / 2
                pose = (x, y, 0.0)
            else:
                if y1 - y0 < w:
                    continue
                y = self.rng.uniform(y0 + w / 2, y1 - w / 2)
                x = x0 + d / 2 if side == 2 else x1 - d / 2
                pose = (x, y, HALF_PI)
            obj = self.put(room, name, size, pose, role, **kw)
            if obj is not None:
                return obj
        return None

    def free_spot(self, room: Room, name: str, size, role="fixed", margin=0.9, tries=25, **kw):
        """Somewhere in the room, ``margin`` [m] off its walls, axis-aligned."""
        x0, y0, x1, y1 = inner_box(self.plan, room, margin)
        for _ in range(tries):
            turn = bool(self.rng.random() < 0.5)
            if np.isscalar(size):  # a circle of radius ``size``
                w = d = 2.0 * float(size)
            else:
                w, d = (size[1], size[0]) if turn else size
            if x1 - x0 < w or y1 - y0 < d:
                continue
            pose = (
                self.rng.uniform(x0 + w / 2, x1 - w / 2),
                self.rng.uniform(y0 + d / 2, y1 - d / 2),
            )
            obj = self.put(room, name, size, (*pose, HALF_PI if turn else 0.0), role, **kw)
            if obj is not None:
                return obj
        return None

    def corner_plant(self, room: Room) -> None:
        """A potted plant (a circle) in a corner."""
        x0, y0, x1, y1 = inner_box(self.plan, room)
        r = float(self.rng.uniform(0.2, 0.3))
        for _ in range(4):
            cx = x0 + r + 0.02 if self.rng.random() < 0.5 else x1 - r - 0.02
            cy = y0 + r + 0.02 if self.rng.random() < 0.5 else y1 - r - 0.02
            if self.put(room, "plant", r, (cx, cy, 0.0), "plant", circle=True):
                return

    # -- groups ---------------------------------------------------------------------------
    def table_with_chairs(self, room: Room, size, n_chairs: int, name="table", margin=1.0):
        """A table in the room with chairs on its long sides; the chairs are one group."""
        table = self.free_spot(room, name, size, "movable", margin=margin)
        if table is None:
            return
        tx, ty, th = table["pose"]
        w, d = size
        along = np.array([np.cos(th), np.sin(th)])
        normal = np.array([-along[1], along[0]])
        group = f"{table['id']}_chairs"
        xs = np.linspace(-0.5 * w + 0.4, 0.5 * w - 0.4, max(1, (n_chairs + 1) // 2))
        placed = []
        for k in range(n_chairs):
            s = 1 if k % 2 == 0 else -1
            u = xs[(k // 2) % len(xs)]
            c = np.array([tx, ty]) + u * along + s * (0.5 * d + 0.32) * normal
            chair = self.put(room, "chair", (0.45, 0.45), (c[0], c[1], th), "chair", group=group)
            if chair is not None:
                placed.append(chair)
        if len(placed) >= 2:
            polys = [outline(o) for o in [table, *placed]]
            lo = np.min([p.min(axis=0) for p in polys], axis=0) - 0.25
            hi = np.max([p.max(axis=0) for p in polys], axis=0) + 0.25
            ib = inner_box(self.plan, room)
            region = (
                round(max(lo[0], ib[0]), 3),
                round(max(lo[1], ib[1]), 3),
                round(min(hi[0], ib[2]), 3),
                round(min(hi[1], ib[3]), 3),
            )
            self.out.regions[group] = region
            self.placer.add(box_poly(region), f"region:{group}")

    def desk_rows(self, room: Room, margin: float = 1.3) -> None:
        """Rows of desks along x, each with a chair on its south side, aisles between rows."""
        x0, y0, x1, y1 = inner_box(self.plan, room, margin)
        pitch = float(self.rng.uniform(2.4, 3.0))
        dw = float(self.rng.uniform(1.4, 1.8))
        for y in np.arange(y0 + 1.2, y1 - 0.4, pitch):
            n = int((x1 - x0) // (dw + 0.05))
            start = x0 + 0.5 * ((x1 - x0) - n * (dw + 0.05))
            for i in range(n):
                if self.rng.random() < 0.2:
                    continue  # gaps in a row, as rows are in real labs
                x = start + (i + 0.5) * (dw + 0.05)
                if self.put(room, "desk", (dw, 0.8), (x, y, 0.0), "movable"):
                    self.put(room, "chair", (0.5, 0.5), (x, y - 0.75, 0.0), "chair_loose")

    def clutter(self, room: Room, per_10m2: float) -> None:
        """Loose boxes and bins, mostly along the walls."""
        n = int(self.rng.poisson(per_10m2 * room.area_m2 / 10.0))
        for _ in range(n):
            if self.rng.random() < 0.4:
                self._bin(room)
            else:
                s = (float(self.rng.uniform(0.3, 0.6)), float(self.rng.uniform(0.3, 0.5)))
                self.against_wall(room, "box", s, "clutter", tries=3)

    def _bin(self, room: Room) -> None:
        r = float(self.rng.uniform(0.15, 0.25))
        x0, y0, x1, y1 = inner_box(self.plan, room, 0.05)
        for _ in range(3):
            pose = (self.rng.uniform(x0 + r, x1 - r), self.rng.uniform(y0 + r, y1 - r), 0.0)
            if self.put(room, "bin", r, pose, "clutter", circle=True):
                return

    def shelf_rows(self, room: Room) -> None:
        """Warehouse aisles: double shelf rows along x, cut by a cross aisle; the rows
        nearest the west wall touch it, so the aisles between them are dead ends."""
        x0, y0, x1, y1 = inner_box(self.plan, room)
        depth = float(self.rng.uniform(1.0, 1.2))
        aisle = float(self.rng.uniform(1.8, 2.6))
        cross = float(self.rng.uniform(2.6, 3.4))
        top = y1 - 5.5  # the office and the main aisle in front of it
        xa, xb = x0, x1 - 3.0  # a free aisle along the east wall
        xm = 0.5 * (xa + xb) + float(self.rng.uniform(-2.0, 2.0))
        n_dead = int(self.rng.integers(2, 4))
        y = y0 + 4.0  # the loading area along the south wall
        k = 0
        while y + depth <= top:
            west = xa if k < n_dead else xa + 2.6
            for lo, hi in ((west, xm - 0.5 * cross), (xm + 0.5 * cross, xb)):
                length = hi - lo
                n = max(1, int(length // 4.0))
                seg = length / n
                for i in range(n):
                    cx = lo + (i + 0.5) * seg
                    self.put(
                        room,
                        "shelf",
                        (seg - 0.02, depth),
                        (cx, y + 0.5 * depth, 0.0),
                        "shelf",
                        group=f"shelf_row_{k}",
                        gap=0.0,
                    )
            y += depth + aisle
            k += 1
            if y <= top:  # the aisle north of this row
                self.out.aisles.append((west + 0.6, y - 0.5 * aisle, xb + 1.5))
        ya = y0 + 3.0 if not self.out.aisles else self.out.aisles[0][1]
        lanes = [
            ((xb + 1.5, y0 + 2.0), (xb + 1.5, top + 1.5)),
            ((xm, ya), (xm, top + 1.5)),
            ((x0 + 1.0, top + 1.5), (xb + 1.5, top + 1.5)),
            ((x0 + 1.0, y0 + 3.1), (xb + 1.5, y0 + 3.1)),
        ]
        lanes += [((a, y), (b, y)) for a, y, b in self.out.aisles]
        for a, b in lanes:
            self.placer.add(ccw(thick_segment(a, b, LANE_M)), "lane")
        for _ in range(int(self.rng.integers(3, 7))):  # pallets in the loading area
            pose = (self.rng.uniform(x0 + 3, x1 - 4), self.rng.uniform(y0 + 0.5, y0 + 1.9), 0.0)
            self.put(room, "pallet", (1.2, 0.8), pose, "movable")

    def partitions(self, room: Room) -> None:
        """Movable partition walls standing out from the south wall: bays of a lab."""
        x0, y0, x1, _ = inner_box(self.plan, room)
        n = int(self.rng.integers(2, 5))
        for x in np.linspace(x0, x1, n + 2)[1:-1]:
            length = float(self.rng.uniform(2.2, 3.5))
            self.put(
                room,
                "partition",
                (length, 0.08),
                (x, y0 + 0.5 * length, HALF_PI),
                "partition",
                kind="wall",
                group="partitions",
                gap=0.0,
            )


def _living(f: Furnisher, r: Room) -> None:
    f.against_wall(r, "sofa", (2.0, 0.9), "movable")
    f.against_wall(r, "tv_stand", (1.4, 0.45), "movable")
    f.against_wall(r, "bookshelf", (0.9, 0.35))
    f.free_spot(r, "coffee_table", (1.0, 0.6), "movable", margin=1.2)
    f.against_wall(r, "armchair", (0.8, 0.8), "movable")
    if r.area_m2 > 18:
        f.table_with_chairs(r, (1.6, 0.9), 4, "dining_table")
    f.corner_plant(r)


def _kitchen(f: Furnisher, r: Room) -> None:
    f.against_wall(r, "counter", (2.4, 0.6))
    f.against_wall(r, "fridge", (0.7, 0.7))
    f.table_with_chairs(r, (1.2, 0.8), 3, margin=0.9)


def _bedroom(f: Furnisher, r: Room) -> None:
    f.against_wall(r, "bed", (1.6, 2.0))
    f.against_wall(r, "wardrobe", (1.6, 0.6))
    f.against_wall(r, "nightstand", (0.45, 0.4), "movable")


def _study(f: Furnisher, r: Room) -> None:
    desk = f.against_wall(r, "desk", (1.4, 0.7), "movable")
    if desk is not None:
        f.free_spot(r, "chair", (0.5, 0.5), "chair_loose", margin=0.8)
    f.against_wall(r, "bookshelf", (0.9, 0.35))
    f.against_wall(r, "cupboard", (1.2, 0.5), "movable")


def _bath(f: Furnisher, r: Room) -> None:
    f.against_wall(r, "cabinet", (0.8, 0.4))
    f.against_wall(r, "washer", (0.6, 0.6))


def _corridor(f: Furnisher, r: Room) -> None:
    x0, y0, x1, y1 = inner_box(f.plan, r)
    if min(x1 - x0, y1 - y0) >= 1.9:
        f.against_wall(r, "bench", (1.2, 0.4), "movable")
    f.against_wall(r, "cabinet", (0.9, 0.35))


def _office(f: Furnisher, r: Room) -> None:
    for _ in range(int(f.rng.integers(1, 3))):
        if f.against_wall(r, "desk", (1.6, 0.8), "movable") is not None:
            f.free_spot(r, "chair", (0.5, 0.5), "chair_loose", margin=0.9)
    f.against_wall(r, "cabinet", (1.2, 0.45), "movable")
    f.against_wall(r, "shelf", (1.4, 0.4))
    if r.area_m2 > 16:
        f.table_with_chairs(r, (1.2, 0.8), 2, "small_table", margin=0.9)


def _meeting(f: Furnisher, r: Room) -> None:
    f.table_with_chairs(r, (2.4, 1.1), 6, "meeting_table", margin=1.0)
    f.against_wall(r, "sideboard", (1.6, 0.45), "movable")
    f.corner_plant(r)


def _openplan(f: Furnisher, r: Room) -> None:
    for _ in range(int(f.rng.integers(2, 5))):
        f.table_with_chairs(r, (1.6, 1.6), 4, "desk_island", margin=1.1)
    f.against_wall(r, "cabinet", (1.2, 0.45), "movable")
    f.against_wall(r, "printer", (0.8, 0.6), "movable")
    f.corner_plant(r)


def _lobby(f: Furnisher, r: Room) -> None:
    f.free_spot(r, "reception", (2.2, 0.8), margin=1.3)
    f.against_wall(r, "lockers", (1.8, 0.5))
    f.against_wall(r, "sofa", (2.0, 0.9), "movable")
    f.against_wall(r, "armchair", (0.8, 0.8), "movable")
    f.corner_plant(r)
    f.corner_plant(r)


def _lab(f: Furnisher, r: Room) -> None:
    f.partitions(r)
    f.table_with_chairs(r, (2.0, 1.0), 4, "lab_table", margin=1.5)
    f.desk_rows(r)
    for _ in range(2):
        f.against_wall(r, "workbench", (2.0, 0.9), "movable")
    for _ in range(int(f.rng.integers(1, 4))):
        f.free_spot(r, "robot", 0.3, "movable", kind="robot", circle=True, margin=1.0)


def _store(f: Furnisher, r: Room) -> None:
    for _ in range(4):
        f.against_wall(r, "shelf", (1.2, 0.5))


def _workshop(f: Furnisher, r: Room) -> None:
    f.against_wall(r, "workbench", (2.0, 0.9))
    f.against_wall(r, "cabinet", (1.0, 0.5), "movable")


def _warehouse(f: Furnisher, r: Room) -> None:
    f.shelf_rows(r)
    f.table_with_chairs(r, (1.6, 0.8), 4, "break_table", margin=1.0)


_RECIPES = {
    "living": _living,
    "kitchen": _kitchen,
    "bedroom": _bedroom,
    "study": _study,
    "bath": _bath,
    "corridor": _corridor,
    "office": _office,
    "meeting": _meeting,
    "openplan": _openplan,
    "lobby": _lobby,
    "lab": _lab,
    "store": _store,
    "workshop": _workshop,
    "warehouse": _warehouse,
}


def door_leaf(plan: Plan, dw: Doorway) -> dict[str, Any]:
    """The door of doorway ``dw``: closed in the opening, open swung 90 degrees into the room
    on its ``swing`` side, hinged at one jamb."""
    leaf = round(dw.width - 0.02, 3)
    off = 0.5 * plan.thickness + 0.02 + 0.5 * leaf
    if dw.along_x:
        pose = [dw.x, dw.y, 0.0]
        open_pose = [dw.x - 0.5 * dw.width + 0.03, dw.y + dw.swing * off, HALF_PI]
    else:
        pose = [dw.x, dw.y, HALF_PI]
        open_pose = [dw.x + dw.swing * off, dw.y - 0.5 * dw.width + 0.03, 0.0]
    return {
        "id": f"{dw.id}_leaf",
        "kind": "door",
        "group": "doors",
        "size": [leaf, 0.05],
        "pose": rounded_pose(*pose),
        "open": True,
        "open_pose": rounded_pose(*open_pose),
    }


def furnish(plan: Plan, rng, placer: Placer, clutter_per_10m2: float) -> Furnished:
    """Doors and furniture for every room of ``plan``, placed into ``placer``."""
    f = Furnisher(plan, rng, placer)
    for dw in plan.doorways:
        if dw.door:
            leaf = door_leaf(plan, dw)
            placer.add(outline(leaf), f"door_closed:{leaf['id']}")
            placer.add(outline(leaf, leaf["open_pose"]), f"door_open:{leaf['id']}")
            f.out.objects.append(leaf)
            f.out.role[leaf["id"]] = "door"
            f.out.room_of[leaf["id"]] = dw.rooms[1]
    # rooms inside others (the hall's office) first, so the open floor furnishes round them
    for room in sorted(plan.rooms, key=lambda r: r.area_m2):
        _RECIPES[room.use](f, room)
    for room in plan.rooms:
        if room.use != "corridor":
            f.clutter(room, clutter_per_10m2)
    return f.out
