"""Periodic schedules: a state inside a daily clock window, the other outside it, on given
weekdays and days, with a seeded chance per day; their validation; the generator's periodic
parameters."""

import copy
import datetime as dt
import hashlib

import pytest

from dynmap_sim.world import World, WorldFileError, load_world, parse_world
from dynmap_sim.world.calendar import Calendar
from dynmap_sim.world.generator import generate, route_problems
from dynmap_sim.world.schedule import Schedule

# A Monday start, seven weekdays worked, runs across the day.
CAL = {
    "start": dt.date(2024, 1, 1),
    "n_days": 14,
    "weekdays": ["mon", "tue", "wed", "thu", "fri", "sat", "sun"],
    "runs": ["07:00", "08:00", "12:30", "17:59", "18:00"],
}


def world(base: dict, *events: dict, calendar: dict | None = None) -> dict:
    """The small test room with the door open at first, ``events`` appended."""
    data = copy.deepcopy(base)
    data["calendar"] = calendar or CAL
    data["objects"][4]["open"] = True  # the door
    data["schedule"] = [e for e in data["schedule"] if e["action"] != "open"] + list(events)
    return data


def door_open(w: World, day: int, run: int) -> bool:
    """Whether the door leaves its doorway free (it has no open pose)."""
    return "door" not in w.snapshot(day, run).by_id()


def chairs(w: World, day: int, run: int) -> int:
    return sum(o.group == "chairs" for o in w.snapshot(day, run).objects)


OFFICE = {"action": "periodic", "target": "door", "state": "open", "from": "08:00", "to": "18:00"}
LUNCH = {"action": "periodic", "group": "chairs", "state": "absent", "from": "12:00", "to": "13:30"}


def test_door_is_open_inside_the_window_only(base_world):
    w = World(parse_world(world(base_world, OFFICE)), seed=0)
    for day in (1, 6, 14):
        assert [door_open(w, day, r) for r in range(1, 6)] == [False, True, True, True, False]


def test_chairs_are_out_at_lunch_only(base_world):
    w = World(parse_world(world(base_world, LUNCH)), seed=0)
    assert [chairs(w, 2, r) for r in range(1, 6)] == [2, 2, 0, 2, 2]


def test_weekdays_and_start_end_bound_the_window(base_world):
    ev = {**OFFICE, "weekdays": ["mon", "wed"], "start": 2, "end": 10}
    w = World(parse_world(world(base_world, ev)), seed=0)
    noon = 3  # run 3 is 12:30, inside the window
    for day in range(1, 15):
        date = w.calendar.slot(day, noon).date
        if not 2 <= day <= 10:
            expected = True  # outside start..end the event does nothing: open as in the file
        else:
            expected = date.strftime("%a").lower()[:3] in ("mon", "wed")
        assert door_open(w, day, noon) == expected, (day, date)


def test_dates_as_start_and_end(base_world):
    ev = {**LUNCH, "start": dt.date(2024, 1, 3), "end": dt.date(2024, 1, 4)}
    w = World(parse_world(world(base_world, ev)), seed=0)
    assert [chairs(w, d, 3) for d in range(1, 7)] == [2, 2, 0, 0, 2, 2]


def test_p_zero_never_and_p_one_always(base_world):
    never = World(parse_world(world(base_world, {**OFFICE, "p": 0.0})), seed=0)
    always = World(parse_world(world(base_world, {**OFFICE, "p": 1.0})), seed=0)
    for day in range(1, 15):
        assert not door_open(never, day, 3)  # the window never applies: closed all day
        assert door_open(always, day, 3)


def window_days(spec, seed: int) -> list[bool]:
    sched = Schedule(spec, Calendar(spec.calendar))
    i, ev = next((i, e) for i, e in enumerate(spec.schedule) if e.action == "periodic")
    noon = 2  # 0-based run of 12:30
    rpd = sched.calendar.runs_per_day
    return [
        sched.periodic_state(ev, i, seed, d * rpd + noon) == "open"
        for d in range(sched.calendar.n_days)
    ]


def test_p_is_drawn_per_day_and_seed_bit_for_bit(base_world):
    cal = {**CAL, "n_days": 200}
    spec = parse_world(world(base_world, {**OFFICE, "p": 0.5}, calendar=cal))
    a, b, c = window_days(spec, 7), window_days(spec, 7), window_days(spec, 8)
    assert a == b
    assert a != c
    assert 80 <= sum(a) <= 120  # about half of 200 days
    # the same as the snapshots say, visited in any order
    w = World(spec, seed=7)
    for day in (150, 3, 77, 3):
        assert door_open(w, day, 3) == a[day - 1]


def test_a_removed_object_stays_removed_and_a_closed_door_stays_closed(base_world):
    remove = {"action": "remove", "target": "chair_1", "at": 3}
    close = {"action": "close", "target": "door", "at": 4}
    chair_in = {**LUNCH, "state": "present"}  # present only at lunch
    data = world(base_world, remove, close, chair_in, OFFICE)
    data["schedule"] = [e for e in data["schedule"] if e["action"] != "shuffle"]
    w = World(parse_world(data), seed=0)
    assert [chairs(w, 2, r) for r in range(1, 6)] == [0, 0, 2, 0, 0]
    assert chairs(w, 3, 3) == 1  # chair_1 removed on day 3, chair_2 still comes at lunch
    assert door_open(w, 3, 3) and not door_open(w, 4, 3)
    assert "chair_2" in w.snapshot(3, 3).by_id() and "chair_1" not in w.snapshot(3, 3).by_id()


def test_route_problems_see_every_run_of_a_periodic_world(base_world):
    """The door beside the route, closed at the 18:00 run only, is seen there (not run 1)."""
    spec = parse_world(world(base_world, {**OFFICE, "from": "07:00"}))
    runs = {(p.day, p.run) for p in route_problems(spec) if "door" in p.message}
    assert (1, 5) in runs and (1, 1) not in runs


def test_shipped_periodic_lab():
    spec = load_world("lab-periodic")
    lab = load_world("lab")
    assert spec.objects == lab.objects and spec.robot == lab.robot
    assert spec.calendar.runs == ("09:00", "12:30", "17:00")
    w = World(spec, seed=0)
    hall = [chairs_in(w, 1, r, "hall_chairs") for r in (1, 2, 3)]
    assert hall[1] == 0 and hall[0] > 0 and hall[2] > 0


def chairs_in(w: World, day: int, run: int, group: str) -> int:
    return sum(o.group == group for o in w.snapshot(day, run).objects)


def test_weekday_profile_replaces_the_profile_on_its_weekday(base_world):
    data = world(base_world, calendar={**CAL, "runs": ["09:00"]})
    data["schedule"] = []
    data["people"][0].pop("end")
    data["people"][0]["start"] = 1
    data["people"][0]["weekday_profiles"] = {"sat": [[0.0, 0.0], [24.0, 0.0]]}
    w = World(parse_world(data), seed=0)
    counts = [len(w.snapshot(day, 1).people) for day in range(1, 8)]  # Mon 2024-01-01 ..
    assert counts == [3, 3, 3, 3, 3, 0, 3]


@pytest.mark.parametrize(
    ("profiles", "field", "msg"),
    [
        ({"funday": [[0.0, 0.0]]}, "people.0.weekday_profiles.funday", "Extra inputs"),
        ({"sat": [[5.0, 0.0], [2.0, 1.0]]}, "people.0.weekday_profiles.sat", "increasing"),
        ({"sat": [[5.0, 2.0]]}, "people.0.weekday_profiles.sat", "fractions in [0, 1]"),
        ({"sun": [[5.0, 0.5]]}, "people.0.weekday_profiles.sun", "not a working day"),
    ],
)
def test_bad_weekday_profiles(base_world, profiles, field, msg):
    data = world(base_world, calendar={**CAL, "weekdays": ["mon", "tue", "sat"]})
    data["people"][0]["weekday_profiles"] = profiles
    with pytest.raises(WorldFileError) as info:
        parse_world(data, "bad.toml")
    assert any(loc == field and msg in text for loc, text in info.value.errors), info.value.errors


# -- validation -----------------------------------------------------------------------------

BAD = [
    ("to before from", {"from": "18:00", "to": "08:00"}, "schedule.3.to", "must end after"),
    ("empty window", {"from": "08:00", "to": "08:00"}, "schedule.3.to", "must end after"),
    ("bad from", {"from": "8 am"}, "schedule.3.from", "HH:MM"),
    ("bad to", {"to": "25:00"}, "schedule.3.to", "HH:MM"),
    ("p above 1", {"p": 1.5}, "schedule.3.p", "less than or equal to 1"),
    ("p below 0", {"p": -0.1}, "schedule.3.p", "greater than or equal to 0"),
    ("unknown weekday", {"weekdays": ["mon", "funday"]}, "schedule.3.weekdays.1", "Input should"),
    ("unknown state", {"state": "ajar"}, "schedule.3.state", "Input should"),
    ("unknown target", {"target": "gate"}, "schedule.3.target", "unknown object id 'gate'"),
    ("not a door", {"target": "table"}, "schedule.3.target", "'table' is not a door"),
    ("no target", {"target": None}, "schedule.3", "exactly one of 'target' or 'group'"),
    ("end outside", {"end": 40}, "schedule.3.end", "outside the calendar"),
    ("end before start", {"start": 5, "end": 2}, "schedule.3.end", "end is before start"),
]


@pytest.mark.parametrize(("case", "edit", "field", "msg"), BAD, ids=[c[0] for c in BAD])
def test_bad_periodic_event(base_world, case, edit, field, msg):
    ev = {k: v for k, v in {**OFFICE, **edit}.items() if v is not None}
    with pytest.raises(WorldFileError) as info:
        parse_world(world(base_world, ev, calendar={**CAL, "n_days": 10}), "bad.toml")
    assert "bad.toml" in str(info.value)
    assert any(loc == field and msg in text for loc, text in info.value.errors), info.value.errors


def test_weekday_off_the_calendar_is_named(base_world):
    cal = {**CAL, "weekdays": ["mon", "tue", "wed", "thu", "fri"]}
    with pytest.raises(WorldFileError) as info:
        parse_world(world(base_world, {**OFFICE, "weekdays": ["fri", "sat"]}, calendar=cal))
    assert info.value.errors == [
        (
            "schedule.3.weekdays.1",
            "'sat' is not a working day of the calendar (mon, tue, wed, thu, fri)",
        )
    ]


def test_a_group_with_a_non_door_cannot_open(base_world):
    ev = {**LUNCH, "state": "closed"}
    with pytest.raises(WorldFileError) as info:
        parse_world(world(base_world, ev))
    assert ("schedule.3.group", "'chair_1' of group 'chairs' is not a door") in info.value.errors


def test_a_periodic_installation_is_refused(base_world):
    install = {"action": "install", "target": "table", "at": 1}
    ev = {**LUNCH, "group": None, "target": "table"}
    ev = {k: v for k, v in ev.items() if v is not None}
    with pytest.raises(WorldFileError, match="permanent installation"):
        parse_world(world(base_world, install, ev))


# -- generator ------------------------------------------------------------------------------

#: sha256 of ``generate(kind, 0, {"days": 6}).toml()`` as before periodic change existed.
BEFORE = {
    "apartment": "0522758f6b9818e07899d67726ab773574e45e76db3b12a60fa90e0b514f4a7b",
    "office": "bee3b05a3ba3d743e25022fc957d8ce09cd7df918661f3b2e5e5d8b917b01583",
}


@pytest.mark.parametrize("kind", sorted(BEFORE))
def test_generator_off_writes_the_same_bytes(kind):
    text = generate(kind, 0, {"days": 6}).toml()
    assert hashlib.sha256(text.encode()).hexdigest() == BEFORE[kind]
    assert "periodic" not in text


@pytest.mark.parametrize("kind", ["lab", "office"])
def test_generator_on_writes_valid_periodic_events(kind, tmp_path):
    params = {
        "days": 4,
        "periodic_doors": 2,
        "periodic_groups": 1,
        "runs_per_day": 3,
        "runs_through_day": 1,
    }
    g = generate(kind, 1, params)
    periodic = [ev for ev in g.spec.schedule if ev.action == "periodic"]
    assert periodic and g.counts["periodic_group"] == 1
    assert g.spec.calendar.runs == ("09:00", "12:30", "19:30")  # the third after hours
    doors = {o.id for o in g.spec.objects if o.kind == "door"}
    for ev in periodic:
        if ev.state == "open":
            assert ev.target in doors and (ev.from_, ev.to, ev.p) == ("08:00", "18:00", 0.9)
        else:
            assert ev.state == "absent" and ev.group is not None
    out = tmp_path / "w.toml"
    out.write_text(g.toml(), encoding="utf-8")
    assert load_world(out) == g.spec
    # periodic doors are off the route and chairs only go: no route problem comes with them
    data = {**g.data, "schedule": [e for e in g.data["schedule"] if e["action"] != "periodic"]}
    slots = [(d, r) for d in range(1, 5) for r in range(1, 4)]
    without = route_problems(parse_world(data), 1, 0.2, slots)
    assert route_problems(g.spec, 1, 0.2, slots) == without
    w = World(g.spec, seed=1)
    group = next(ev.group for ev in periodic if ev.group)
    assert chairs_in(w, 1, 2, group) == 0 and chairs_in(w, 1, 1, group) > 0
    assert generate(kind, 1, params).toml() == g.toml()


def test_a_shuffle_places_its_group_around_a_door_the_periodic_rule_closes(base_world):
    from dynmap_sim.world.polygons import sat_separation

    shuffle = {"action": "shuffle", "group": "chairs", "region": [4.0, 0.9, 5.85, 3.0]}
    data = world(base_world, shuffle, OFFICE)
    data["schedule"] = [e for i, e in enumerate(data["schedule"]) if i != 1]  # the old shuffle
    w = World(parse_world(data), seed=0)
    gaps = []
    for day in range(1, 15):
        snap = w.snapshot(day, 1)  # 07:00: the door is closed
        objs = snap.by_id()
        assert "door" in objs
        gaps += [
            sat_separation(objs[c].polygon, objs["door"].polygon)
            for c in ("chair_1", "chair_2")
            if c in objs
        ]
    assert gaps and min(gaps) >= 0.1 - 1e-9
