"""``corridor-follower`` (H&W 2011 §6.3) on synthetic corridors with a unicycle robot: tracking,
passing a box by a lateral offset inside the corridor, stopping and reporting ``blocked``, the
speed law."""

import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from synthetic_scans import box

sys.path.insert(0, str(Path(__file__).parent))
from control_world import HARD_M, SPEED_MPS, corridor, drive, grid_of, seg_distance  # noqa: E402

from dynmap_sim.agent.control.controller import CONTROLLERS  # noqa: E402
from dynmap_sim.agent.control.corridor_follower import (  # noqa: E402
    CorridorFollower,
    CorridorFollowerParams,
    speed_for_clearance,
)

STRAIGHT = np.array([[0.0, 0.0], [8.0, 0.0]])
START = np.array([0.0, 0.0, 0.0])


def follower(**params) -> CorridorFollower:
    return CorridorFollower(SPEED_MPS, HARD_M, **params)


def test_registered_under_its_name():
    assert CONTROLLERS.get("corridor-follower") is CorridorFollower
    assert CorridorFollower.name == "corridor-follower"


def test_tracks_a_straight_path_in_a_free_corridor():
    c = follower()
    c.set_path(STRAIGHT)
    poses, cmds = drive(c, grid_of(corridor()), START)
    assert c.done and not c.blocked
    assert np.abs(poses[:, 1]).max() < 0.01  # on the path
    assert np.linalg.norm(poses[-1, :2] - STRAIGHT[-1]) < c.params.goal_tolerance_m
    assert cmds[:, 0].max() == pytest.approx(SPEED_MPS)  # 1 m from the walls: full speed
    assert len(cmds) * 0.1 < 1.2 * 8.0 / SPEED_MPS + 3.0  # hardly slower than cruising


def test_follows_corners_of_a_polyline():
    path = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, 3.0], [0.0, 3.0]])
    c = follower()
    c.set_path(path)
    poses, _ = drive(c, grid_of(box(-1.5, -1.5, 4.5, 4.5)), START)
    assert c.done
    # every vertex is passed close by (corners are not cut)
    for v in path:
        assert np.hypot(*(poses[:, :2] - v).T).min() < 0.15


@pytest.mark.parametrize("side", [+1.0, -1.0])
def test_passes_a_box_in_the_corridor_by_a_lateral_offset(side):
    # a box covering 0.35 m of the corridor's centre line on one side; walls 1 m away
    blocker = box(3.5, min(0.0, side * 0.35), 4.0, max(0.0, side * 0.35))
    segs = corridor(blocker)
    c = follower(default_half_width_m=0.6)
    c.set_path(STRAIGHT)
    poses, cmds = drive(c, grid_of(segs), START)
    assert c.done and not c.blocked
    lateral = poses[:, 1]
    beside = (poses[:, 0] > 3.4) & (poses[:, 0] < 4.1)
    # it passes on the free side, inside the corridor, and returns to the path afterwards
    assert np.all(-side * lateral[beside] > 0.2)
    assert np.abs(lateral).max() <= 0.6 + 0.05
    assert abs(lateral[-1]) < 0.05
    clearance = [seg_distance(p[:2], segs) for p in poses]
    assert min(clearance) >= HARD_M
    # slower beside the box than in the open
    assert cmds[beside[:-1], 0].max() < 0.6 * SPEED_MPS


def test_blocked_corridor_stops_and_reports_blocked():
    segs = corridor(box(3.5, -1.0, 4.0, 1.0))  # wall to wall
    c = follower(default_half_width_m=0.6)
    c.set_path(STRAIGHT)
    poses, cmds = drive(c, grid_of(segs), START, steps=400)
    assert not c.done and c.blocked
    assert np.all(cmds[-5:] == 0.0)
    assert min(seg_distance(p[:2], segs) for p in poses) >= HARD_M
    # stopped short of the block, then stays put
    assert poses[-1, 0] < 3.5 - HARD_M
    assert np.allclose(poses[-1], poses[-5])
    # the block is gone (a fresh grid): not blocked any more, it drives on
    cmd = c.command(poses[-1], grid_of(corridor()))
    assert not c.blocked and cmd[0] > 0.0


def test_corridor_half_widths_bound_the_offset():
    segs = corridor(box(3.5, -0.05, 4.0, 0.35))  # passable at about -0.4 m
    wide, narrow = follower(), follower()
    wide.set_path(STRAIGHT, half_widths=np.array([0.6, 0.6]))
    narrow.set_path(STRAIGHT, half_widths=np.array([0.6, 0.2]))  # segment gets min: 0.2 m
    drive(wide, grid_of(segs), START)
    assert wide.done and not wide.blocked
    drive(narrow, grid_of(segs), START, steps=400)
    assert narrow.blocked and not narrow.done
    with pytest.raises(ValueError, match="half_widths"):
        narrow.set_path(STRAIGHT, half_widths=np.array([0.3]))


def test_speed_law_is_monotone_in_clearance():
    p = CorridorFollowerParams()
    d = np.linspace(0.0, 2.0, 401)
    v = np.array([speed_for_clearance(float(x), p) for x in d])
    assert np.all(np.diff(v) >= 0.0)
    assert np.all(v[d < p.min_clearance_m] == 0.0)
    assert np.all(v[d >= p.full_speed_clearance_m] == pytest.approx(p.speed_mps))
    assert np.all(v[d >= p.min_clearance_m] >= p.min_speed_mps)  # a free offset is driven
    slow = replace(p, min_speed_mps=0.0)  # the plain L13 law: linear in between
    assert speed_for_clearance(0.525, slow) == pytest.approx(0.5 * p.speed_mps)


def test_commanded_speed_grows_with_the_distance_to_an_obstacle_beside_the_path():
    speeds = []
    for gap in (0.3, 0.4, 0.5, 0.7, 0.9):
        c = follower(default_half_width_m=0.0)  # no offset: the speed law alone
        c.set_path(STRAIGHT)
        grid = grid_of(corridor(box(0.0, gap, 3.0, gap + 0.2), half_m=2.0))
        speeds.append(float(c.command(START, grid)[0]))
    assert np.all(np.diff(speeds) >= 0.0) and speeds[-1] > speeds[0]


def test_rotates_to_heading_for_a_large_heading_error():
    c = follower()
    c.set_path(STRAIGHT)
    v, w = c.command(np.array([0.0, 0.0, math.pi * 0.75]), grid_of(corridor()))
    assert v == 0.0 and abs(w) == pytest.approx(c.params.max_omega_radps)
    assert w < 0.0  # the short way round


def test_no_path_or_end_reached_gives_zero_and_done():
    c = follower()
    grid = grid_of(corridor())
    assert c.done and np.all(c.command(START, grid) == 0.0)
    c.set_path(STRAIGHT)
    assert not c.done
    assert np.all(c.command(np.array([8.0, 0.0, 0.0]), grid) == 0.0) and c.done
    c.set_path(None)
    assert c.done


def test_bad_params_are_refused():
    with pytest.raises(ValueError, match="n_offsets"):
        follower(n_offsets=4)
    with pytest.raises(TypeError):
        follower(no_such_param=1.0)
    with pytest.raises(ValueError, match="corridor-follower: regulated_min_radius_m must be"):
        follower(regulated_min_radius_m=-0.5)
    with pytest.raises(TypeError, match="corridor-follower: full_speed_clearance_m must be a"):
        follower(full_speed_clearance_m="far")


def test_curvature_regulation_slows_tight_turns_unless_its_radius_is_zero():
    """RPP's curvature regulation (``v R / R_min`` on turns tighter than R_min) is the only
    thing between the two commands of a robot 0.2 m beside a straight path in open space (its
    carrot 0.35 m ahead: a turn of radius ~0.4 m); at R_min = 0 it is off (H&W §6.3's
    controller slows for obstacles only)."""
    grid = grid_of(box(-1.5, -1.5, 4.5, 4.5))
    pose = np.array([0.0, -0.2, 0.0])
    speeds = {}
    for radius in (0.9, 0.0):
        c = follower(regulated_min_radius_m=radius)
        c.set_path(np.array([[0.0, 0.0], [3.0, 0.0]]))
        v, w = c.command(pose, grid)
        speeds[radius] = v
        assert w > 0.0  # back towards the path
    assert speeds[0.0] == pytest.approx(SPEED_MPS)
    assert speeds[0.9] < 0.6 * SPEED_MPS


def choice_by_definition(c: CorridorFollower, xy, s_robot, carrot, s_carrot, grid):
    """:meth:`CorridorFollower._choose_offset` from the module doc, point by point: each
    offset shifts the path (narrowing to the end) and the way to the carrot; free when every
    point keeps the hard clearance (the way: what the robot has, if less); the free one of
    the best saturated clearance less the offset and switch costs wins (the first of equal
    scores)."""
    p = c.params
    path, cum, end = c._path, c._cum, float(c._cum[-1])
    seg = c._seg
    offsets = c._unit_offsets * c._seg_hw[seg]
    here = float(grid.clearance_at(xy))
    need_way = min(p.min_clearance_m, here)
    best, best_score, near_all = None, -np.inf, []
    for d0 in offsets.tolist():
        free, least, near = True, np.inf, np.inf
        for step in c._probe_steps_m.tolist():
            s = min(s_robot + step, end)
            k = min(max(int(np.searchsorted(cum, s, side="right")) - 1, 0), c._n_seg - 1)
            hw = min(c._seg_hw[k], max(end - s, 0.0))
            q = path[k] + (s - cum[k]) * c._tangent[k] + min(max(d0, -hw), hw) * c._normal[k]
            cl = float(grid.clearance_at(q))
            least = min(least, cl)
            free &= cl >= p.min_clearance_m
            if s - s_robot <= p.speed_probe_m:
                near = min(near, cl)
        hw_c = min(c._seg_hw[seg], max(end - s_carrot, 0.0))
        target = carrot + min(max(d0, -hw_c), hw_c) * c._normal[seg]
        way = [float(grid.clearance_at(xy + f * (target - xy))) for f in c._way_fractions]
        free &= min(way) >= need_way
        if here >= p.min_clearance_m:
            near = min(near, min(way))
        near_all.append(near)
        score = (
            min(least, p.clearance_enough_m)
            - p.offset_cost_per_m * abs(d0)
            - p.switch_cost_per_m * abs(d0 - c._offset_m)
        )
        if free and (best is None or score > best_score):
            best, best_score = len(near_all) - 1, score
    return best, offsets, np.array(near_all), here


def test_the_offset_kernel_chooses_as_its_definition() -> None:
    """Random paths (zero-length segments and narrowing ends included), poses, grids and
    current offsets: the same best offset, offsets, clearances ahead and clearance here."""
    rng = np.random.default_rng(5)
    n_free = 0
    for _ in range(25):
        segs = [box(-1.0, -2.0, 7.0, 4.0)]
        for _ in range(int(rng.integers(0, 8))):
            x, y, s = rng.uniform(0.0, 6.0), rng.uniform(-1.5, 3.5), rng.uniform(0.05, 0.5)
            segs.append(box(x, y, x + s, y + s))
        grid = grid_of(np.concatenate(segs))
        k = int(rng.integers(2, 7))
        path = np.cumsum(rng.uniform(-1.0, 1.5, (k, 2)), axis=0) + [0.5, 0.5]
        if rng.random() < 0.3:
            path = np.insert(path, 1, path[1], axis=0)  # a zero-length segment
        c = follower()
        c.set_path(path, rng.uniform(0.0, 0.5, len(path)))
        for _ in range(6):
            c._seg = int(rng.integers(0, len(path) - 1))
            c._offset_m = float(rng.uniform(-0.5, 0.5))
            xy = path[c._seg] + rng.uniform(-0.6, 0.6, 2)
            s_robot, _ = c._along(*xy)
            a, b = path[c._seg], path[c._seg + 1]
            carrot = a + rng.uniform(0.0, 1.0) * (b - a)
            s_carrot = float(c._cum[c._seg]) + float(np.hypot(*(carrot - a)))
            got = c._choose_offset(xy, s_robot, carrot, s_carrot, grid)
            want = choice_by_definition(c, xy, s_robot, carrot, s_carrot, grid)
            assert got[0] == want[0] and got[3] == want[3]
            np.testing.assert_allclose(got[1], want[1], atol=1e-12)
            np.testing.assert_allclose(got[2], want[2], atol=1e-12)
            n_free += got[0] is not None
    assert n_free > 10  # free offsets were chosen, not only blocked cases
