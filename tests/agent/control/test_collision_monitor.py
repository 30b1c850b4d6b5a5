"""The collision monitor (nav2 Collision Monitor style) on exact synthetic scans in the robot
frame: stop, slowdown, pass, turning in place, the footprint, reversing, REP-117 values."""

from dataclasses import replace

import numpy as np
import pytest
from synthetic_scans import LASER, box, raycast

from dynmap_sim.agent.control.collision_monitor import (
    FOOTPRINT_STOP,
    PASS,
    SLOWDOWN,
    STOP,
    CollisionMonitor,
    scan_points,
)
from dynmap_sim.types import Scan

ROBOT = np.zeros(3)  # the scan is in the robot frame: the map pose never matters
FULL = replace(  # a 360-degree laser, to see behind the robot
    LASER, name="test-360", n_beams=360, angle_min_rad=-np.pi, angle_increment_rad=np.pi / 180
)


def scan_of(segments: np.ndarray, laser=LASER) -> Scan:
    segments = np.asarray(segments, float).reshape(-1, 4)
    if not len(segments):
        return Scan(np.full(laser.n_beams, np.inf, dtype=np.float32), stamp_s=1.5)
    r = raycast(ROBOT, laser.angles(), segments, laser.range_max_m)
    return Scan(r.astype(np.float32), stamp_s=1.5)


def block_ahead(x_m: float, half_width_m: float = 0.15) -> np.ndarray:
    """A board across the way ``x_m`` ahead of the robot's centre."""
    return box(x_m, -half_width_m, x_m + 0.05, half_width_m)


def monitor(laser=LASER) -> CollisionMonitor:
    return CollisionMonitor(laser, robot_radius_m=0.2)


def test_a_return_in_the_stop_box_stops_forward_motion_but_keeps_the_turn():
    m = monitor()
    # 0.35 m ahead: inside the stop box at 0.3 m/s (0.2 + 0.05 + 0.15 = 0.4 m)
    v, w = m.filter([0.3, 0.2], scan_of(block_ahead(0.35)))
    assert v == 0.0 and w == pytest.approx(0.2)
    assert m.last_action == STOP and m.stop_count == 1
    assert m.events == [(1.5, STOP, "commanded v=0.30 m/s, omega=0.20 rad/s")]


def test_a_return_in_the_slowdown_box_scales_the_command():
    m = monitor()
    # 0.7 m ahead: beyond the stop box, inside the slowdown box (0.2 + 0.25 + 0.45 = 0.9 m)
    v, w = m.filter([0.3, 0.2], scan_of(block_ahead(0.7)))
    ratio = m.params.slowdown_ratio
    assert v == pytest.approx(0.3 * ratio) and w == pytest.approx(0.2 * ratio)
    assert m.last_action == SLOWDOWN and m.slowdown_count == 1 and m.stop_count == 0


def test_the_boxes_grow_with_the_commanded_speed():
    scan = scan_of(block_ahead(0.4))
    m = monitor()
    # slow: the stop box reaches 0.2 + 0.05 + 0.025 = 0.275 m, the board is in the slowdown box
    assert m.filter([0.05, 0.0], scan)[0] == pytest.approx(0.05 * m.params.slowdown_ratio)
    # fast: the stop box reaches 0.2 + 0.05 + 0.175 = 0.425 m
    assert m.filter([0.35, 0.0], scan)[0] == 0.0
    zones = m.zones(0.35)
    assert zones[STOP][1] == pytest.approx(0.425) and zones[SLOWDOWN][1] > zones[STOP][1]


@pytest.mark.parametrize(
    "segments",
    [
        block_ahead(1.5),  # far ahead
        box(0.2, 0.45, 1.0, 0.6),  # beside the way, outside the boxes' width
        box(-0.8, -0.1, -0.5, 0.1),  # behind, driving forward
        np.zeros((0, 4)),  # nothing at all
    ],
)
def test_nothing_in_the_boxes_passes_the_command(segments):
    m = monitor(FULL)
    cmd = m.filter([0.3, -0.4], scan_of(segments, FULL))
    assert np.allclose(cmd, [0.3, -0.4]) and m.last_action == PASS
    assert m.counts[PASS] == 1 and m.events == []


def test_turning_in_place_is_allowed_next_to_an_obstacle():
    m = monitor()
    v, w = m.filter([0.0, 0.8], scan_of(block_ahead(0.3)))
    assert v == 0.0 and w == pytest.approx(0.8) and m.last_action == PASS


def test_something_inside_the_footprint_margin_stops_turning_too():
    m = monitor()
    v, w = m.filter([0.0, 0.8], scan_of(block_ahead(0.21)))
    assert v == 0.0 and w == 0.0 and m.last_action == FOOTPRINT_STOP and m.stop_count == 1


def test_reversing_is_checked_behind_and_ignores_what_is_ahead():
    m = monitor(FULL)
    assert m.filter([-0.1, 0.0], scan_of(block_ahead(-0.35), FULL))[0] == 0.0
    assert m.last_action == STOP
    assert m.filter([-0.1, 0.0], scan_of(block_ahead(0.3), FULL))[0] == pytest.approx(-0.1)


def test_a_lone_spurious_return_does_not_trigger():
    m = monitor()
    ranges = np.full(LASER.n_beams, np.inf, dtype=np.float32)
    ahead = int(np.argmin(np.abs(LASER.angles())))
    ranges[ahead] = 0.3
    assert m.filter([0.3, 0.0], ranges)[0] == pytest.approx(0.3)
    ranges[ahead - 1 : ahead + 2] = 0.3  # three beams: a real object
    assert m.filter([0.3, 0.0], ranges)[0] == 0.0


def test_rep117_too_close_counts_and_no_return_or_nan_does_not():
    ranges = np.full(LASER.n_beams, np.inf, dtype=np.float32)
    ranges[:10] = np.nan
    pts = scan_points(LASER, ranges)
    assert pts.shape == (0, 2)
    ranges[100:104] = -np.inf  # something closer than range_min: at range_min
    pts = scan_points(LASER, ranges)
    assert pts.shape == (4, 2) and np.allclose(np.hypot(*pts.T), LASER.range_min_m)
    m = monitor()
    assert np.all(m.filter([0.0, 0.5], ranges) == 0.0) and m.last_action == FOOTPRINT_STOP


def test_the_laser_mount_pose_is_applied():
    mounted = replace(LASER, mount_pose=(0.15, 0.0, 0.0))
    pts = scan_points(mounted, scan_of(block_ahead(0.2)).ranges_m)  # 0.2 m from the laser
    assert pts[:, 0].min() == pytest.approx(0.35, abs=1e-6)  # 0.35 m from the centre
    with pytest.raises(ValueError, match="beams"):
        scan_points(LASER, np.zeros(5))


def test_counts_and_events_record_what_it_did():
    m = monitor()
    stop, slow, free = (scan_of(block_ahead(x)) for x in (0.35, 0.7, 2.0))
    for s in (free, stop, stop, slow, slow, free, stop):
        m.filter([0.3, 0.0], s)
    assert m.counts == {PASS: 2, STOP: 3, SLOWDOWN: 2, FOOTPRINT_STOP: 0}
    assert [k for _, k, _ in m.events] == [STOP, SLOWDOWN, STOP]  # transitions only


def action_by_points(monitor: CollisionMonitor, v_mps: float, ranges: np.ndarray) -> str:
    """The monitor's action from its zones' definition, point by point (module doc)."""
    p = monitor.params
    pts = scan_points(monitor.laser, ranges).tolist()
    zones = monitor.zones(v_mps)
    sign = 1.0 if np.copysign(1.0, v_mps) > 0 else -1.0
    foot = sum(np.hypot(x, y) <= p.robot_radius_m + p.footprint_margin_m for x, y in pts)
    if foot >= p.min_points:
        return FOOTPRINT_STOP
    if v_mps == 0.0:
        return PASS
    for action in (STOP, SLOWDOWN):
        x0, x1, hw = zones[action]
        if sum(x0 <= x * sign <= x1 and abs(y) <= hw for x, y in pts) >= p.min_points:
            return action
    return PASS


def test_the_kernels_action_is_the_zones_definition() -> None:
    """Random boxes around the robot, REP-117 values and speeds (reversing, zero, -0.0,
    forward): the action the definition gives, every action occurring."""
    rng = np.random.default_rng(2)
    seen = set()
    for _ in range(300):
        segs = []
        for _ in range(rng.integers(0, 4)):
            x, y, s = rng.uniform(-0.8, 0.8), rng.uniform(-0.8, 0.8), rng.uniform(0.02, 0.4)
            segs.append(box(x, y, x + s, y + s))
        if segs:
            r = raycast(np.zeros(3), LASER.angles(), np.concatenate(segs), LASER.range_max_m)
        else:
            r = np.full(LASER.n_beams, np.inf)
        bad = rng.random(r.shape)
        r[bad < 0.02] = -np.inf
        r[(bad > 0.02) & (bad < 0.03)] = np.nan
        ranges = r.astype(np.float32)
        v = float(rng.choice([0.0, -0.1, 0.1, 0.35, -0.0, rng.uniform(-0.4, 0.4)]))
        mon = CollisionMonitor(LASER, 0.2)
        mon.filter(np.array([v, 0.3]), Scan(ranges), 0.0)
        assert mon.last_action == action_by_points(mon, v, ranges)
        seen.add(mon.last_action)
    assert len(seen) == 4
