"""The tour driver on synthetic geometry, with a unicycle standing in for the robot."""

import numpy as np
import pytest

from dynmap_sim.agent.planning.clearance_grid import build_clearance_grid
from dynmap_sim.agent.planning.grid_dijkstra import GridDijkstra
from dynmap_sim.experiments.drivers import (
    DriverContext,
    RunStart,
    StepInput,
    TourDriver,
    TourParams,
    clip_route,
)
from dynmap_sim.truth import ObstacleSnapshot
from dynmap_sim.types import BeamClass, LaserSpec, Odometry, Prior, Scan

RADIUS_M = 0.2
LASER = LaserSpec("test", 4, -1.0, 0.5, 0.02, 5.6, 0.1, 0.0)


def tour(route, **params):
    ctx = DriverContext(
        np.asarray(route, float), speed_mps=0.35, robot_radius_m=RADIUS_M, dt_s=0.1, laser=LASER
    )
    return TourDriver(ctx, **params)


def start(driver, geom, pose):
    driver.begin_run(RunStart(Prior(initial_pose=None), np.asarray(pose, float), geom))


def box(x0, y0, x1, y1):
    return np.array(
        [[x0, y0, x1, y0], [x1, y0, x1, y1], [x1, y1, x0, y1], [x0, y1, x0, y0]], dtype=float
    )


def room(extra=()):
    """A 10 m x 4 m room with optional obstacle boxes."""
    segs = [box(0, 0, 10, 4)] + [box(*b) for b in extra]
    seg = np.concatenate(segs)
    cls = np.full(len(seg), BeamClass.WALL, dtype=np.int8)
    cls[4:] = BeamClass.FURNITURE
    return ObstacleSnapshot(
        segments=seg,
        segment_class=cls,
        circles=np.zeros((0, 3)),
        circle_class=np.zeros(0, dtype=np.int8),
    )


def seg_point_dist(p, seg):
    a, b = seg[:, :2], seg[:, 2:]
    ab = b - a
    u = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab), 0, 1)
    q = a + u[:, None] * ab
    return np.hypot(*(p - q).T).min()


def drive(driver, geom, start_pose, people=lambda t: np.zeros((0, 3)), dt=0.1, max_steps=3000):
    pose = np.array(start_pose, dtype=float)
    driver.begin_run(RunStart(Prior(initial_pose=pose), pose.copy(), geom))
    poses = [pose.copy()]
    odom, scan = Odometry(np.zeros(3)), Scan(np.zeros(4, np.float32))
    for k in range(max_steps):
        if driver.done:
            break
        v, w = driver.act(StepInput(k * dt, odom, scan, pose=pose, people=people(k * dt)))
        pose = pose + dt * np.array([v * np.cos(pose[2]), v * np.sin(pose[2]), w])
        poses.append(pose.copy())
    return np.array(poses)


def test_clip_route():
    r = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    np.testing.assert_allclose(clip_route(r, 0.75), [[0, 0], [2, 0], [2, 1]])
    np.testing.assert_allclose(clip_route(r, 0.25), [[0, 0], [1, 0]])
    assert clip_route(r, 1.0) is r or np.array_equal(clip_route(r, 1.0), r)


def test_straight_route_is_followed_closely():
    geom = room()
    route = np.array([[1.0, 2.0], [9.0, 2.0]])
    d = tour(route)
    poses = drive(d, geom, (1.0, 2.0, 0.0))
    assert d.done
    assert np.hypot(*(poses[-1, :2] - route[-1])) < 0.15
    assert np.abs(poses[:, 1] - 2.0).max() < 0.05
    assert d.skipped_waypoints == 0 and not [e for e in d.events if e[2] == "detour"]
    # cruise speed ~0.35 m/s: 8 m in roughly 23 s
    assert 20.0 < len(poses) * 0.1 < 35.0


def test_detours_around_a_blocking_obstacle_without_touching_it():
    geom = room(extra=[(4.0, 1.0, 5.0, 3.0)])
    route = np.array([[1.0, 2.0], [9.0, 2.0]])
    d = tour(route)
    poses = drive(d, geom, (1.0, 2.0, 0.0))
    assert d.done and np.hypot(*(poses[-1, :2] - route[-1])) < 0.15
    assert any(e[2] == "detour" for e in d.events)
    clearance = min(seg_point_dist(p[None], geom.segments) for p in poses[:, :2])
    assert clearance > RADIUS_M


def test_waypoint_inside_an_obstacle_is_skipped_and_recorded():
    geom = room(extra=[(4.0, 1.0, 6.0, 3.0)])
    route = np.array([[1.0, 2.0], [5.0, 2.0], [9.0, 2.0]])
    d = tour(route)
    poses = drive(d, geom, (1.0, 2.0, 0.0))
    assert d.skipped_waypoints == 1
    assert [e[2] for e in d.events].count("skip_waypoint") == 1
    assert np.hypot(*(poses[-1, :2] - route[-1])) < 0.15


def test_unreachable_waypoint_is_skipped():
    # a wall across the room cuts it in two
    geom = room(extra=[(5.0, -0.5, 5.1, 4.5)])
    route = np.array([[1.0, 2.0], [9.0, 2.0]])
    d = tour(route)
    drive(d, geom, (1.0, 2.0, 0.0), max_steps=50)
    assert d.skipped_waypoints == 1
    assert "unreachable" in d.events[0][3]


def test_waits_for_a_person_in_the_way():
    geom = room()
    route = np.array([[1.0, 2.0], [9.0, 2.0]])
    d = tour(route)
    # a person stands at x=4 for the first 30 s, then leaves
    person = lambda t: np.array([[4.0, 2.0, 0.0]]) if t < 30 else np.zeros((0, 3))  # noqa: E731
    poses = drive(d, geom, (1.0, 2.0, 0.0), people=person)
    assert any(e[2] == "wait_for_person" for e in d.events)
    assert np.max(poses[:, 0][:300]) < 4.0 - TourParams().person_stop_m + 0.05
    assert d.done


def test_teleport_replans_to_the_remaining_route():
    geom = room()
    route = np.array([[1.0, 1.0], [5.0, 1.0], [9.0, 1.0], [9.0, 3.0]])
    d = tour(route)
    start(d, geom, [1.0, 1.0, 0.0])
    d.teleported(np.array([2.0, 3.0, 0.0]), 1.0)
    v = d.path()
    np.testing.assert_allclose(v[0], [2.0, 3.0], atol=0.05)
    np.testing.assert_allclose(v[-1], [9.0, 3.0], atol=0.05)


def test_planner_nearest_free_and_clearance():
    geom = room()
    grid = build_clearance_grid(geom.segments, geom.circles, resolution_m=0.05)
    assert grid.clearance_at(np.array([5.0, 2.0])) == pytest.approx(2.0, abs=0.05)
    q = grid.nearest_free(np.array([5.0, 0.1]), 0.25, 0.5)
    assert q is not None and q[1] == pytest.approx(0.25, abs=0.06)
    assert grid.nearest_free(np.array([5.0, 0.1]), 0.25, 0.05) is None
    path = GridDijkstra(0.25, 0.3).plan(np.array([1.0, 2.0]), np.array([9.0, 2.0]), grid)
    np.testing.assert_allclose(path, [[1.0, 2.0], [9.0, 2.0]])  # a free straight line


def test_padding_rows_of_absent_people_are_ignored():
    geom = room()
    route = np.array([[1.0, 2.0], [9.0, 2.0]])
    d = tour(route)
    pad = np.array([[np.inf, np.inf, 0.0], [np.inf, np.inf, 0.0]])
    poses = drive(d, geom, (1.0, 2.0, 0.0), people=lambda t: pad)
    assert d.done and not any(e[2] == "wait_for_person" for e in d.events)
    assert np.hypot(*(poses[-1, :2] - route[-1])) < 0.15
