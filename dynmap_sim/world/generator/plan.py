"""Floor plans: rooms, corridors, doorways and walls of each kind of building.

A plan is axis-aligned: an outer wall round ``[0, width] x [0, depth]`` and inner walls on the
centre lines between rooms, cut where a doorway is. A doorway's ``width`` is its clear opening
[m] (the wall pieces' caps included), drawn in ``door_min_m .. door_max_m``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dynmap_sim.world.generator.params import KINDS

Box = tuple[float, float, float, float]
#: Thickness of the outer wall [m].
OUTER_M = 0.2


@dataclass
class Room:
    """A room (or corridor, or open floor) ``box`` on the walls' centre lines [m]."""

    id: str
    box: Box
    use: str
    doorways: list[str] = field(default_factory=list)

    @property
    def area_m2(self) -> float:
        """Floor area [m2] inside the centre lines."""
        return (self.box[2] - self.box[0]) * (self.box[3] - self.box[1])


@dataclass(frozen=True)
class Doorway:
    """An opening of clear ``width`` [m] centred at ``(x, y)`` in a wall along x (``along_x``)
    or along y, between ``rooms``; ``door`` says whether a door leaf hangs in it, which swings
    into the room on side ``swing`` (+1: towards larger y or x)."""

    id: str
    x: float
    y: float
    along_x: bool
    width: float
    rooms: tuple[str, str]
    door: bool
    swing: int = 1


@dataclass
class Plan:
    """A floor plan: its size [m], wall pieces (world-file dicts), rooms and doorways."""

    kind: str
    width: float
    depth: float
    thickness: float
    walls: list[dict[str, Any]] = field(default_factory=list)
    rooms: list[Room] = field(default_factory=list)
    doorways: list[Doorway] = field(default_factory=list)

    def room(self, rid: str) -> Room:
        """The room with id ``rid``."""
        return next(r for r in self.rooms if r.id == rid)

    @property
    def bounds(self) -> Box:
        """World bounds: the outer wall and half a metre round it."""
        return (-0.5, -0.5, round(self.width + 0.5, 3), round(self.depth + 0.5, 3))


class _Builder:
    """Collects walls, rooms and doorways while a plan is drawn."""

    def __init__(self, kind: str, width: float, depth: float, p: dict, rng) -> None:
        self.plan = Plan(kind, round(width, 2), round(depth, 2), float(p["wall_thickness_m"]))
        self.rng = rng
        self.p = p
        w, d = self.plan.width, self.plan.depth
        self.plan.walls.append(
            {
                "id": "outer",
                "points": [[0.0, 0.0], [w, 0.0], [w, d], [0.0, d], [0.0, 0.0]],
                "thickness_m": OUTER_M,
            }
        )

    def door_width(self) -> float:
        """A doorway's clear opening [m], drawn in the parameter range."""
        return round(float(self.rng.uniform(self.p["door_min_m"], self.p["door_max_m"])), 2)

    def room(self, rid: str, box: Box, use: str) -> Room:
        r = Room(rid, tuple(round(v, 3) for v in box), use)  # type: ignore[arg-type]
        self.plan.rooms.append(r)
        return r

    def doorway(self, a: str, b: str, x: float, y: float, along_x: bool, door: bool) -> Doorway:
        """A doorway between rooms ``a`` and ``b``; its leaf swings into ``b``."""
        rb = self.plan.room(b).box
        centre_b = (0.5 * (rb[0] + rb[2]), 0.5 * (rb[1] + rb[3]))
        swing = int(np.sign((centre_b[1] - y) if along_x else (centre_b[0] - x))) or 1
        dw = Doorway(
            f"door_{len(self.plan.doorways)}",
            round(x, 3),
            round(y, 3),
            along_x,
            self.door_width(),
            (a, b),
            door,
            swing,
        )
        self.plan.doorways.append(dw)
        self.plan.room(a).doorways.append(dw.id)
        self.plan.room(b).doorways.append(dw.id)
        return dw

    def gap_centre(self, lo: float, hi: float) -> float:
        """A doorway position on a wall from ``lo`` to ``hi``, away from its ends."""
        margin = 0.5 * self.p["door_max_m"] + 0.5
        if hi - lo < 2 * margin:
            return round(0.5 * (lo + hi), 2)
        return round(float(self.rng.uniform(lo + margin, hi - margin)), 2)

    def walls(self, lines) -> None:
        """Inner walls ``(id, a, b)``, each cut at its doorways."""
        for wid, a, b in lines:
            self.wall(wid, a, b)

    def wall(self, wid: str, a: tuple[float, float], b: tuple[float, float]) -> None:
        """An inner wall from ``a`` to ``b`` (axis-aligned), cut at the doorways on it."""
        t = self.plan.thickness
        along_x = a[1] == b[1]
        k = 0 if along_x else 1
        fixed = a[1 - k]
        lo, hi = sorted((a[k], b[k]))
        cuts = []
        for dw in self.plan.doorways:
            pos = (dw.x, dw.y)
            if dw.along_x == along_x and abs(pos[1 - k] - fixed) < 1e-6 and lo < pos[k] < hi:
                half = 0.5 * (dw.width + t)
                cuts.append((pos[k] - half, pos[k] + half))
        pieces, start = [], lo
        for c0, c1 in sorted(cuts):
            pieces.append((start, c0))
            start = c1
        pieces.append((start, hi))
        pieces = [(s, e) for s, e in pieces if e - s > 0.05]
        for i, (s, e) in enumerate(pieces):
            p0 = [round(s, 3), round(fixed, 3)] if along_x else [round(fixed, 3), round(s, 3)]
            p1 = [round(e, 3), round(fixed, 3)] if along_x else [round(fixed, 3), round(e, 3)]
            pid = wid if len(pieces) == 1 else f"{wid}_{i}"
            self.plan.walls.append({"id": pid, "points": [p0, p1], "thickness_m": t})


def _splits(rng, lo: float, hi: float, lo_w: float, hi_w: float) -> list[float]:
    """Cut ``lo .. hi`` into pieces of ``lo_w .. hi_w`` [m]; returns the cut positions."""
    n = max(1, int((hi - lo) // (0.5 * (lo_w + hi_w))))
    w = rng.uniform(0.8, 1.2, n)
    edges = lo + np.cumsum(w / w.sum()) * (hi - lo)
    return [round(float(e), 2) for e in edges[:-1]]


def _apartment(b: _Builder) -> None:
    rng, w, d = b.rng, b.plan.width, b.plan.depth
    cw = round(float(rng.uniform(1.4, 1.8)), 2)
    y0 = round(float(rng.uniform(0.4, 0.48)) * d, 2)
    y1 = round(y0 + cw, 2)
    b.room("hallway", (0, y0, w, y1), "corridor")
    kitchen_w = round(float(rng.uniform(3.0, 3.8)), 2)
    k = round(w - kitchen_w, 2)
    b.room("living", (0, y1, k, d), "living")
    b.room("kitchen", (k, y1, w, d), "kitchen")
    bath_w = round(float(rng.uniform(2.2, 2.8)), 2)
    south = ["bedroom", "bath", "study"] if w >= 9.5 else ["bedroom", "bath"]
    xs = [0.0]
    rest = (w - bath_w) / (len(south) - 1)
    for use in south[:-1]:
        xs.append(round(xs[-1] + (bath_w if use == "bath" else rest), 2))
    xs.append(w)
    for i, use in enumerate(south):
        b.room(use, (xs[i], 0, xs[i + 1], y0), use)
        b.doorway("hallway", use, b.gap_centre(xs[i], xs[i + 1]), y0, True, True)
    b.doorway("hallway", "living", b.gap_centre(0, k), y1, True, False)
    b.doorway("hallway", "kitchen", b.gap_centre(k, w), y1, True, bool(rng.random() < 0.5))
    b.doorway("living", "kitchen", k, b.gap_centre(y1, d), False, False)
    b.walls(
        [("hall_s", (0, y0), (w, y0)), ("hall_n", (0, y1), (w, y1))]
        + [("living_kitchen", (k, y1), (k, d))]
        + [(f"south_{i}", (x, 0), (x, y0)) for i, x in enumerate(xs[1:-1])]
    )


def _office(b: _Builder) -> None:
    rng, w, d = b.rng, b.plan.width, b.plan.depth
    hall_w = round(float(rng.uniform(4.5, 6.5)), 2)
    L = round(w - hall_w, 2)
    ds = round(float(rng.uniform(4.0, 5.2)), 2)
    cw = round(float(rng.uniform(1.8, 2.4)), 2)
    yc = round(ds + cw, 2)
    b.room("corridor", (0, ds, L, yc), "corridor")
    b.room("lobby", (L, 0, w, d), "lobby")
    xs = [0.0, *_splits(rng, 0.0, L, 3.4, 4.8), L]
    for i in range(len(xs) - 1):
        rid = f"office_{i}"
        b.room(rid, (xs[i], 0, xs[i + 1], ds), "office")
        b.doorway("corridor", rid, b.gap_centre(xs[i], xs[i + 1]), ds, True, True)
    if len(xs) > 3:  # a connecting door between two offices: a loop off the corridor
        i = int(rng.integers(1, len(xs) - 2))
        b.doorway(f"office_{i - 1}", f"office_{i}", xs[i], b.gap_centre(0, ds), False, True)
    m = round(float(rng.uniform(4.0, 5.5)), 2)
    b.room("meeting", (0, yc, m, d), "meeting")
    b.room("openplan", (m, yc, L, d), "openplan")
    b.doorway("corridor", "meeting", b.gap_centre(0, m), yc, True, True)
    b.doorway("corridor", "openplan", b.gap_centre(m, m + 0.4 * (L - m)), yc, True, False)
    b.doorway("corridor", "openplan", b.gap_centre(L - 0.4 * (L - m), L), yc, True, False)
    b.doorway("openplan", "lobby", L, b.gap_centre(yc, d), False, False)
    b.walls(
        [("corridor_s", (0, ds), (L, ds)), ("corridor_n", (0, yc), (L, yc))]
        + [("lobby_s", (L, 0), (L, ds)), ("lobby_n", (L, yc), (L, d))]
        + [("meeting_e", (m, yc), (m, d))]
        + [(f"office_wall_{i}", (x, 0), (x, ds)) for i, x in enumerate(xs[1:-1])]
    )


def _lab(b: _Builder) -> None:
    rng, w, d = b.rng, b.plan.width, b.plan.depth
    dn = round(float(rng.uniform(3.6, 4.6)), 2)
    yr = round(d - dn, 2)
    b.room("lab", (0, 0, w, yr), "lab")
    xs = [0.0, *_splits(rng, 0.0, w, 3.6, 5.2), w]
    uses = ["office", "store", "office", "kitchen", "office", "workshop"]
    for i in range(len(xs) - 1):
        rid = f"room_{i}"
        b.room(rid, (xs[i], yr, xs[i + 1], d), uses[i % len(uses)])
        b.doorway("lab", rid, b.gap_centre(xs[i], xs[i + 1]), yr, True, True)
    b.wall("rooms_s", (0, yr), (w, yr))
    for i, x in enumerate(xs[1:-1]):
        b.wall(f"rooms_wall_{i}", (x, yr), (x, d))


def _hall(b: _Builder) -> None:
    rng, w, d = b.rng, b.plan.width, b.plan.depth
    ow = round(float(rng.uniform(4.5, 6.0)), 2)
    od = round(float(rng.uniform(3.5, 4.5)), 2)
    b.room("floor", (0, 0, w, d), "warehouse")
    b.room("office", (0, d - od, ow, d), "office")
    b.doorway("floor", "office", b.gap_centre(0, ow), d - od, True, True)
    b.wall("office_s", (0, d - od), (ow, d - od))
    b.wall("office_e", (ow, d - od), (ow, d))


_SIZES = {  # kind -> (width range, depth range) [m] before ``scale``; minimum (w, d)
    "apartment": ((8.5, 11.5), (7.5, 10.0), (7.5, 7.2)),
    "office": ((20.0, 28.0), (11.0, 13.5), (14.0, 10.5)),
    "lab": ((20.0, 28.0), (13.0, 17.0), (12.0, 10.0)),
    "hall": ((24.0, 34.0), (16.0, 22.0), (14.0, 11.0)),
}
_DRAW = {"apartment": _apartment, "office": _office, "lab": _lab, "hall": _hall}


def draw_plan(kind: str, rng, p: dict) -> Plan:
    """The floor plan of a building of ``kind`` (one of :data:`KINDS`)."""
    assert kind in KINDS
    (w0, w1), (d0, d1), (wmin, dmin) = _SIZES[kind]
    s = float(p["scale"])
    w = max(wmin, float(rng.uniform(w0, w1)) * s)
    d = max(dmin, float(rng.uniform(d0, d1)) * s)
    if kind == "office":  # the corridor side stays an office's depth, the plan grows long
        d = max(dmin, min(d, 14.0))
    b = _Builder(kind, w, d, p, rng)
    _DRAW[kind](b)
    return b.plan
