"""People (social force): they keep off walls and furniture, off each other and off the robot."""

import numpy as np
import pytest

from dynmap_sim.world import World, load_world, parse_world
from dynmap_sim.world.people import ROBOT_GAP_M, SocialForce, profile_fraction
from dynmap_sim.world.polygons import point_segment_distance, points_in_convex
from dynmap_sim.world.spec import PeopleSpec

TOL_M = 0.02


def _robot_along_route(route, s_m):
    """Pose at arc length ``s_m`` along the route polyline."""
    seg = np.diff(route, axis=0)
    lens = np.hypot(seg[:, 0], seg[:, 1])
    cum = np.concatenate([[0.0], np.cumsum(lens)])
    k = int(np.clip(np.searchsorted(cum, s_m) - 1, 0, len(lens) - 1))
    u = (s_m - cum[k]) / lens[k]
    p = route[k] + min(max(u, 0.0), 1.0) * seg[k]
    return (float(p[0]), float(p[1]), float(np.arctan2(seg[k, 1], seg[k, 0])))


@pytest.mark.parametrize("name,day,run,s0", [("lab", 6, 2, 57.0), ("apartment", 16, 1, 0.0)])
def test_people_keep_off_walls_furniture_and_the_robot(name, day, run, s0):
    spec = load_world(name)
    w = World(spec, seed=7)
    w.reset(day, run)
    assert w.crowd.n >= 2
    robot_r = 0.2
    polys = [o.polygon for o in w.objects]
    segs = w.geometry.segments
    closest = np.inf
    for k in range(400):
        pose = _robot_along_route(spec.robot.route, s0 + 0.05 * k)
        w.step(0.1, robot_pose=pose, robot_radius_m=robot_r)
        p = w.people_poses()[:, :2]
        r = w.people_radii()
        d_static = point_segment_distance(p, segs).min(axis=1)
        assert np.all(d_static >= r - TOL_M), (k, d_static - r)
        for poly in polys:
            assert not points_in_convex(p, poly).any()
        d_robot = np.hypot(*(p - np.array(pose[:2])).T)
        assert np.all(d_robot >= r + robot_r - TOL_M), (k, d_robot - r - robot_r)
        closest = min(closest, float((d_robot - r).min()))
        if len(p) > 1:
            d = np.hypot(*(p[:, None] - p[None]).transpose(2, 0, 1))
            np.fill_diagonal(d, np.inf)
            assert np.all(d >= (r[:, None] + r[None]) - 0.1)
    assert closest < 1.5  # the robot did meet people on its way


def test_person_walking_at_a_standing_robot_keeps_its_distance(base_world):
    base_world["people"] = [
        {
            "id": "p",
            "count": 1,
            "areas": [[0.5, 0.5, 1.0, 1.5]],
            "goals": [[5.3, 1.0]],
            "speed_mps": [1.2, 1.2],
        }
    ]
    base_world["robot"]["start"] = [5.0, 3.0, 0.0]
    w = World(parse_world(base_world), seed=0)
    robot = (3.0, 1.0, 0.0)
    closest = np.inf
    for _ in range(200):
        w.step(0.1, robot_pose=robot)
        d = np.hypot(*(w.people_poses()[0, :2] - robot[:2]))
        closest = min(closest, d)
    assert closest >= 0.22 + 0.2 + ROBOT_GAP_M - 1e-6
    assert closest < 1.0  # it did walk up to the robot and around it


def test_lone_person_reaches_its_goal_at_its_desired_speed():
    pop = PeopleSpec(
        id="p", count=1, areas=((0.0, 0.0, 1.0, 1.0),), goals=((9.0, 0.5),), speed_mps=(1.0, 1.0)
    )
    sf = SocialForce((pop,), np.zeros((0, 4)), np.random.default_rng(0))
    crowd = sf.spawn(12 * 3600.0, [True])
    start = crowd.pos[0].copy()
    goal = crowd.goal[0].copy()
    for _ in range(30):
        sf.step(crowd, 0.1)
    # relaxation toward v0 = 1 m/s with tau = 0.5 s, semi-implicit Euler with dt = 0.1 s:
    # v_k = v0 (1 - q^k) with q = 1 - dt / tau, x_n = dt * sum_{k=1..n} v_k
    q = 1.0 - 0.1 / 0.5
    assert np.hypot(*crowd.vel[0]) == pytest.approx(1.0 - q**30, abs=1e-9)
    travelled = np.hypot(*(crowd.pos[0] - start))
    expected = 0.1 * (30 - q * (1 - q**30) / (1 - q))
    assert travelled == pytest.approx(expected, abs=1e-9)
    direction = (crowd.pos[0] - start) / travelled
    np.testing.assert_allclose(direction, (goal - start) / np.hypot(*(goal - start)), atol=0.02)


def test_profile_fraction_interpolates():
    prof = ((0.0, 0.0), (12.0, 1.0), (24.0, 0.0))
    assert profile_fraction(prof, 6 * 3600.0) == pytest.approx(0.5)
    assert profile_fraction(prof, 12 * 3600.0) == pytest.approx(1.0)


def test_lunch_crowd_in_the_lab_hallway():
    spec = load_world("lab")
    w = World(spec, seed=0)
    hall = [len(w.snapshot(d, r).people) for d in (2, 10) for r in (1, 2, 3)]
    assert hall[1] > hall[0] + 5 and hall[1] > hall[2] + 5  # run 2 (after lunch) is crowded


def test_legs_are_seen_as_two_circles_per_person():
    spec = load_world("lab")
    w = World(spec, seed=0)
    w.reset(3, 2)
    w.step(0.1)
    g = w.geometry
    person = g.circle_class == 5
    assert person.sum() == 2 * w.crowd.n
    owners = np.array(g.object_ids)[g.circle_object[person]]
    assert all(o.startswith("person:") for o in owners)
    legs = g.circles[person]
    centres = np.repeat(w.people_poses()[:, :2], 2, axis=0)
    assert np.all(np.hypot(*(legs[:, :2] - centres).T) + legs[:, 2] <= 0.22 + 1e-9)


def test_step_rejects_bad_time_steps():
    w = World(load_world("apartment"), seed=0)
    for bad in (float("nan"), -0.1, float("inf")):
        with pytest.raises(ValueError, match="dt_s"):
            w.step(bad)


def test_clock_does_not_drift():
    w = World(load_world("apartment"), seed=0)
    w.reset(3, 1)
    for _ in range(36000):  # one hour of 0.1 s steps (nobody at home: cheap)
        w.step(0.1)
    assert w.elapsed_s == 3600.0
    assert w.time_s == w.calendar.slot(3, 1).start_s + 3600.0


def test_head_on_meeting_in_a_corridor_ends_with_the_person_passing(base_world):
    # a person walks exactly along the centre line at a robot standing on that line: the
    # symmetric forces alone would make it stop; the evasion term makes it pass on its right
    base_world["people"] = [
        {
            "id": "p",
            "count": 1,
            "areas": [[0.5, 2.0 - 1e-8, 0.9, 2.0 + 1e-8]],
            "goals": [[5.4, 2.0]],
            "speed_mps": [1.0, 1.0],
        }
    ]
    base_world["objects"] = []
    base_world["schedule"] = []
    w = World(parse_world(base_world), seed=0)
    robot = (3.0, 2.0, np.pi)
    lowest_y = 2.0
    for _ in range(80):
        w.step(0.1, robot_pose=robot)
        x, y = w.people_poses()[0, :2]
        lowest_y = min(lowest_y, y)
        if x > 3.5:
            break
    assert x > 3.5  # it got past the robot within 8 s
    assert lowest_y < 1.5  # on its right (the robot was dead ahead)


def test_people_on_a_route_walk_its_waypoints_in_order(base_world):
    loop = [[1.0, 0.8], [5.0, 0.8], [5.0, 3.0], [1.0, 3.0]]
    base_world["people"] = [
        {
            "id": "guard",
            "count": 1,
            "areas": [[0.5, 0.5, 5.5, 3.5]],
            "route": loop,
            "speed_mps": [1.0, 1.0],
        }
    ]
    base_world["objects"] = []
    base_world["schedule"] = []
    w = World(parse_world(base_world), seed=4)
    visits = []
    for _ in range(400):
        w.step(0.1)
        p = w.people_poses()[0, :2]
        d = np.hypot(*(np.array(loop) - p).T)
        k = int(np.argmin(d))
        if d[k] < 0.45 and (not visits or visits[-1] != k):
            visits.append(k)
    assert len(visits) >= 6  # 40 s at 1 m/s on a 12.4 m loop: more than a lap
    steps = [(b - a) % 4 for a, b in zip(visits, visits[1:], strict=False)]
    assert all(s == 1 for s in steps), visits  # always the next waypoint of the loop


def test_goals_and_route_are_exclusive(base_world):
    from dynmap_sim.world import WorldFileError

    base_world["people"][0]["goals"] = [[1.0, 1.0]]
    base_world["people"][0]["route"] = [[1.0, 1.0], [2.0, 1.0]]
    with pytest.raises(WorldFileError, match="either 'goals' or 'route'"):
        parse_world(base_world)


def test_people_area_with_no_free_spot_spawns_nobody(base_world):
    # the whole area lies inside the table: nobody can stand there, and nothing hangs
    base_world["people"] = [{"id": "p", "count": 5, "areas": [[2.8, 2.9, 3.2, 3.1]]}]
    w = World(parse_world(base_world), seed=0)
    assert w.crowd.n == 0
    w.step(0.1)


def test_inside_test_agrees_with_convex_containment():
    w = World(load_world("lab"), seed=0)
    w.reset(4, 2)
    pts = np.random.default_rng(0).uniform([-0.4, -0.4], [40.4, 16.4], (2000, 2))
    ref = np.zeros(len(pts), dtype=bool)
    for o in w.objects:
        ref |= points_in_convex(pts, o.polygon)
    assert ref.any()
    np.testing.assert_array_equal(w._forces.obstacles.inside_any(pts), ref)


def test_a_robot_standing_on_a_persons_goal_does_not_cause_a_deadlock(base_world):
    # the person wants to go where the robot stands (and the robot waits for people ahead):
    # it must give up that goal and walk elsewhere rather than stand in front of the robot
    base_world["people"] = [
        {
            "id": "p",
            "count": 1,
            "areas": [[0.5, 1.5, 1.5, 2.5]],
            "goals": [[4.5, 2.0], [1.0, 1.0]],
            "speed_mps": [1.0, 1.0],
        }
    ]
    base_world["objects"] = []
    base_world["schedule"] = []
    w = World(parse_world(base_world), seed=1)
    robot = np.array([4.5, 2.0, np.pi])
    w.crowd.goal[0] = robot[:2]
    goals = set()
    for _ in range(200):
        w.step(0.1, robot_pose=robot)
        goals.add(tuple(np.round(w.crowd.goal[0], 2)))
    assert (1.0, 1.0) in goals
    assert np.hypot(*(w.people_poses()[0, :2] - robot[:2])) > 1.5
