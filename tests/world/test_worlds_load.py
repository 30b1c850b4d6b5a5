"""The shipped worlds load and keep their promises (calendar, route, API shape)."""

from datetime import date
from pathlib import Path

import numpy as np
import pytest

from dynmap_sim.types import BeamClass
from dynmap_sim.world import World, load_world, resolve_world_path
from dynmap_sim.world.render import render_snapshot
from dynmap_sim.world.route import route_clearances

WORLDS = Path(__file__).resolve().parents[2] / "worlds"
SHIPPED = sorted(p.stem for p in WORLDS.glob("*.toml"))


def test_lab_calendar_has_23_working_days_and_3_runs():
    spec = load_world(resolve_world_path("lab"))
    w = World(spec, seed=0)
    assert w.calendar.n_days == 23
    assert w.calendar.runs_per_day == 3
    assert len(w.calendar.slots) == 69
    assert all(s.date.weekday() < 5 for s in w.calendar.slots)
    assert 100.0 <= spec.robot.route_length_m <= 130.0


def test_apartment_calendar_has_28_days_one_run():
    spec = load_world("apartment")
    w = World(spec, seed=0)
    assert w.calendar.n_days == 28
    assert w.calendar.runs_per_day == 1
    x0, y0, x1, y1 = spec.bounds
    assert x1 - x0 >= 8.0 and y1 - y0 >= 10.0


@pytest.mark.parametrize("name", ["lab", "apartment", "office", "corridor", "hall"])
def test_world_api_shapes(name):
    spec = load_world(name)
    w = World(spec, seed=1)
    assert spec.robot.route.shape[1] == 2
    assert len(spec.robot.start) == 3
    g = w.geometry
    assert g.segments.dtype == np.float64 and g.segments.shape[1] == 4
    assert g.segment_object.dtype == np.int32 and g.segment_class.dtype == np.int8
    assert len(g.segment_object) == len(g.segments)
    assert g.segment_object.max() < len(g.object_ids)
    assert set(np.unique(g.segment_class)) <= {int(c) for c in BeamClass}
    walls = w.wall_segments()
    assert walls.shape[1] == 4 and len(walls) > 0
    v = g.static_version
    w.reset(w.calendar.n_days, 1)
    assert w.geometry.static_version > v
    w.step(0.1, robot_pose=spec.robot.start)
    assert w.people_poses().shape[1] == 3
    assert w.time_s == pytest.approx(w.calendar.slot(w.calendar.n_days, 1).start_s + 0.1)


def test_every_shipped_world_is_tested_validates_loads_and_renders(tmp_path):
    # a new world: add it to the lists here
    assert SHIPPED == [
        "apartment",
        "apartment-hw",
        "corridor",
        "hall",
        "lab",
        "lab-periodic",
        "office",
    ]
    for name in SHIPPED:
        spec = load_world(name)  # validates: raises on any problem of the file
        w = World(spec, seed=0)
        n = w.calendar.n_days
        png = render_snapshot(spec, seed=0, day=n, run=1, out_path=tmp_path / f"{name}.png")
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_office_calendar_has_10_days_two_runs_and_a_long_corridor_route():
    spec = load_world("office")
    w = World(spec, seed=0)
    assert w.calendar.n_days == 10
    assert w.calendar.runs_per_day == 2
    assert all(s.date.weekday() < 5 for s in w.calendar.slots)
    x0, y0, x1, y1 = spec.bounds
    assert 19.0 <= x1 - x0 <= 22.0 and 11.0 <= y1 - y0 <= 14.0
    assert 40.0 <= spec.robot.route_length_m <= 70.0
    assert spec.people and max(p.count for p in spec.people) >= 5


def test_corridor_is_a_28_m_corridor_of_look_alike_rooms_driven_both_ways():
    spec = load_world("corridor")
    w = World(spec, seed=0)
    assert w.calendar.n_days == 10 and w.calendar.runs_per_day == 2
    assert {s.date.weekday() for s in w.calendar.slots} >= {5, 6}  # a ward works weekends
    walls = {wall.id: wall.points for wall in spec.walls}
    (x0, y0), (x1, _) = walls["corridor_s_0"][0], walls["corridor_s_7"][-1]
    assert x1 - x0 == pytest.approx(28.0)
    assert walls["corridor_n_0"][0][1] - y0 == pytest.approx(2.4)
    beds = [o for o in spec.objects if o.id[1:] in {f"{k}_bed" for k in range(1, 8)}]
    assert len(beds) == 11 and len({tuple(o.size) for o in beds}) == 1
    xs = spec.robot.route[:, 0]
    assert xs.max() - xs.min() >= 28.0 and 80.0 <= spec.robot.route_length_m <= 100.0
    assert sum(p.count for p in spec.people) >= 8  # nurses, visitors, a patient, a cleaner


def test_hall_is_open_in_the_middle_with_two_study_rooms_turned_by_180_degrees():
    spec = load_world("hall")
    w = World(spec, seed=0)
    assert w.calendar.n_days == 10 and w.calendar.runs_per_day == 2
    assert date(2024, 5, 9) not in {s.date for s in w.calendar.slots}  # closed on a holiday
    # from the hall's centre no wall is within the URG-04LX's 5.6 m but the pillars
    snap = w.snapshot(1, 1)
    near = route_clearances(snap, np.array([[12.0, 6.0], [12.0, 6.001]]))
    kinds = {o.id: o.kind for o in snap.objects}
    walls = {k for k, d in near.items() if kinds[k] == "wall" and d < 5.6}
    assert walls and all(k.startswith("pillar") for k in walls), walls
    # the east study room is the west one turned by 180 degrees about the centre (the south
    # piece of one is the north piece of the other)
    objs = {o.id: o.polygon for o in snap.objects if o.id.startswith(("west_", "east_"))}
    west = [k for k in objs if k.startswith("west_") and "chair" not in k]
    assert len(west) >= 8
    for k in west:
        turned = 24.0 - objs[k][:, 0] + 1j * (12.0 - objs[k][:, 1])
        twin = "east_" + k[5:-2] + {"_s": "_n", "_n": "_s"}.get(k[-2:], k[-2:])
        east = objs[twin][:, 0] + 1j * objs[twin][:, 1]
        d = np.abs(turned[:, None] - east[None, :]).min(axis=1)
        assert d.max() < 1e-3, (k, twin)
    assert 55.0 <= spec.robot.route_length_m <= 70.0


def test_static_version_changes_only_when_the_geometry_does():
    w = World(load_world("apartment"), seed=0)
    w.reset(1, 1)
    v1 = w.geometry.static_version
    w.reset(2, 1)  # week 1 is static: the lidar may keep its cached broad phase
    assert w.geometry.static_version == v1
    w.reset(8, 1)  # week 2: new obstacles
    assert w.geometry.static_version > v1
    v8 = w.geometry.static_version
    segs8 = w.geometry.segments.copy()
    w.reset(1, 1)
    assert w.geometry.static_version > v8
    w.reset(8, 1)
    np.testing.assert_array_equal(w.geometry.segments, segs8)
