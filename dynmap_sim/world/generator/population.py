"""People and the calendar of a generated world: who walks where, at what hours, on which
days, and when the robot runs."""

from __future__ import annotations

import datetime as dt
from typing import Any

from dynmap_sim.world.generator.furnish import inner_box
from dynmap_sim.world.generator.plan import Plan, Room

#: Clock times a run may start at, as in the papers (morning, after lunch, early evening).
RUN_TIMES = (
    "08:30",
    "09:00",
    "09:30",
    "10:30",
    "11:30",
    "13:15",
    "14:00",
    "15:00",
    "16:30",
    "17:30",
)
#: Run times by runs a day with ``runs_through_day``, chosen so that the runs of a day meet
#: different states of the periodic rules (doors open 08:00-18:00, chairs out 12:00-13:30):
#: lunch and after hours (chairs out, door open; chairs in, door shut), then the morning
#: (chairs in, door open), then the late afternoon.
DAY_RUN_TIMES = {
    1: ("12:30",),
    2: ("12:30", "19:30"),
    3: ("09:00", "12:30", "19:30"),
    4: ("09:00", "12:30", "17:00", "19:30"),
}

_PROFILES = {  # [hour, fraction of the group present]
    "residents": [[0.0, 1.0], [7.5, 1.0], [8.5, 0.4], [17.0, 0.4], [18.5, 1.0], [24.0, 1.0]],
    "staff": [
        [0.0, 0.0],
        [8.0, 0.2],
        [9.5, 0.5],
        [12.0, 1.0],
        [13.5, 1.0],
        [15.0, 0.6],
        [17.5, 0.3],
        [19.0, 0.0],
    ],
    "visitors": [[0.0, 0.0], [9.0, 0.1], [11.0, 0.4], [14.0, 1.0], [16.0, 1.0], [18.0, 0.0]],
    "workers": [
        [0.0, 0.0],
        [6.0, 0.6],
        [8.0, 1.0],
        [12.0, 0.5],
        [13.0, 1.0],
        [17.0, 0.8],
        [18.0, 0.0],
    ],
}
_GROUPS = {  # kind -> (group id, profile, share, room uses, speed range)
    "apartment": [("residents", "residents", 1.0, None, (0.5, 1.1))],
    "office": [
        ("staff", "staff", 0.6, ("corridor", "lobby", "openplan"), (0.8, 1.4)),
        ("visitors", "visitors", 0.4, ("lobby",), (0.6, 1.2)),
    ],
    "lab": [
        ("students", "staff", 0.7, ("lab",), (0.7, 1.3)),
        ("researchers", "staff", 0.3, ("lab", "office", "kitchen"), (0.6, 1.2)),
    ],
    "hall": [("workers", "workers", 1.0, ("warehouse",), (0.8, 1.5))],
}


def _room_area(plan: Plan, room: Room) -> list[float]:
    return [round(v, 2) for v in inner_box(plan, room, 0.3)]


def draw_people(plan: Plan, rng, p: dict, places: list[tuple], on_route: set[str]):
    """People groups (world-file dicts) sharing ``p["people"]`` between the kind's groups."""
    total = int(p["people"])
    out: list[dict[str, Any]] = []
    for gid, prof, share, uses, speed in _GROUPS[plan.kind]:
        count = min(40, int(round(total * share)))
        if count == 0:
            continue
        rooms = [r for r in plan.rooms if r.id in on_route and (uses is None or r.use in uses)]
        if not rooms:
            continue
        areas = [_room_area(plan, r) for r in rooms]
        goals = [
            [float(x), float(y)]
            for x, y in places
            if any(a[0] <= x <= a[2] and a[1] <= y <= a[3] for a in areas)
        ]
        group: dict[str, Any] = {"id": gid, "count": count, "areas": areas}
        if len(goals) >= 2:
            group["goals"] = goals
        group["speed_mps"] = list(speed)
        group["profile"] = _PROFILES[prof]
        out.append(group)
    return out


def draw_calendar(rng, p: dict) -> dict[str, Any]:
    """A Monday start in 2024-2026, Mon-Fri, perhaps a holiday, runs at drawn times (or at
    :data:`DAY_RUN_TIMES` with ``runs_through_day``)."""
    start = dt.date(2024, 1, 1) + dt.timedelta(weeks=int(rng.integers(0, 150)))
    runs = sorted(rng.choice(len(RUN_TIMES), size=int(p["runs_per_day"]), replace=False))
    cal: dict[str, Any] = {
        "start": start,
        "n_days": int(p["days"]),
        "weekdays": ["mon", "tue", "wed", "thu", "fri"],
    }
    if int(p["days"]) >= 8 and rng.random() < 0.5:
        cal["holidays"] = [start + dt.timedelta(days=int(rng.integers(1, 5)) + 7)]
    cal["runs"] = [RUN_TIMES[int(k)] for k in runs]
    if p["runs_through_day"]:  # drawn all the same, so the stream stays where it was
        cal["runs"] = list(DAY_RUN_TIMES[int(p["runs_per_day"])])
    return cal
