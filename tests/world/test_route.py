"""The shipped routes keep clear of every wall and object at every run (unless marked)."""

import pytest

from dynmap_sim.world import World, load_world
from dynmap_sim.world.route import (
    ROUTE_CLEARANCE_M,
    route_blocked,
    route_clearance_m,
    route_clearances,
)


@pytest.mark.parametrize(
    "name,seeds",
    [
        ("lab", (0,)),
        ("apartment", (0, 1)),
        ("apartment-hw", (0, 1)),
        ("office", (0, 1)),
        ("corridor", (0, 1)),
        ("hall", (0, 1)),
    ],
)
def test_route_clearance_over_the_whole_calendar(name, seeds):
    spec = load_world(name)
    for seed in seeds:
        w = World(spec, seed=seed)
        for slot in w.calendar.slots:
            snap = w.snapshot(slot.day, slot.run)
            c = route_clearance_m(snap, spec.robot.route)
            assert c >= ROUTE_CLEARANCE_M, (name, seed, slot.day, slot.run, c)


@pytest.mark.parametrize("name", ["apartment", "apartment-hw"])
def test_apartment_route_blocked_from_day_22_on_purpose(name):
    spec = load_world(name)
    w = World(spec, seed=0)
    for day in range(1, 29):
        snap = w.snapshot(day, 1)
        assert route_blocked(snap) == (day >= 22), day
        w.reset(day, 1)
        assert w.route_blocked() == (day >= 22)
        if day >= 22:
            assert route_clearances(snap, spec.robot.route)["route_blocker"] == 0.0


def test_office_corridor_blocked_on_purpose_day_5_run_2_to_6_and_day_9_run_2_to_10():
    spec = load_world("office")
    w = World(spec, seed=0)
    blocked = {(5, 2), (6, 1), (6, 2), (9, 2), (10, 1), (10, 2)}
    for slot in w.calendar.slots:
        snap = w.snapshot(slot.day, slot.run)
        assert route_blocked(snap) == ((slot.day, slot.run) in blocked), (slot.day, slot.run)
    c = route_clearances(w.snapshot(6, 1), spec.robot.route)
    assert c["delivery_pallet"] == 0.0
    assert route_clearances(w.snapshot(10, 1), spec.robot.route)["old_cabinets"] == 0.0


@pytest.mark.parametrize(
    "name,blocker,blocked",
    [
        ("corridor", "corridor_bed", {(5, 2), (6, 1), (6, 2)}),
        ("hall", "book_pallet_1", {(6, 2), (7, 1), (7, 2)}),
    ],
)
def test_corridor_and_hall_blocked_on_purpose_only_when_said(name, blocker, blocked):
    spec = load_world(name)
    w = World(spec, seed=0)
    for slot in w.calendar.slots:
        snap = w.snapshot(slot.day, slot.run)
        assert route_blocked(snap) == ((slot.day, slot.run) in blocked), (slot.day, slot.run)
        if (slot.day, slot.run) in blocked:
            assert route_clearances(snap, spec.robot.route)[blocker] < ROUTE_CLEARANCE_M


def test_start_pose_is_on_the_route():
    for name in ("lab", "apartment", "office", "corridor", "hall"):
        spec = load_world(name)
        assert tuple(spec.robot.route[0]) == pytest.approx(spec.robot.start[:2])


def test_apartment_hw_hides_the_walls_near_the_route_on_days_8_to_11_only():
    """H&W §7.3: static MCL got no pose on days 8-11, the obstacles hid most known walls."""
    w = World(load_world("apartment-hw"), seed=0)
    panels = {"large_board", "panel_south", "panel_east"}
    poses = set()
    for day in range(1, 29):
        present = {o.id for o in w.snapshot(day, 1).objects} & panels
        assert present == (panels if 8 <= day <= 11 else set()), day
        if present:
            poses.add(
                tuple(
                    round(float(v), 2)
                    for o in w.snapshot(day, 1).objects
                    if o.id in panels
                    for v in o.polygon.ravel()
                )
            )
    assert len(poses) == 4  # another configuration each day
