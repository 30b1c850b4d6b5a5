"""The differential-drive body: limits, kinematics, bumper events, no tunnelling."""

import math

import numpy as np
import pymunk
import pytest

from dynmap_sim.robot.diff_drive import DiffDriveRobot, RobotParams
from dynmap_sim.sensors.odometry import EncoderNoise, WheelGeometry, WheelOdometry


def space_with_wall(x_m=2.0, thickness_m=0.01):
    space = pymunk.Space()
    wall = pymunk.Poly(
        space.static_body,
        [(x_m, -5.0), (x_m + thickness_m, -5.0), (x_m + thickness_m, 5.0), (x_m, 5.0)],
    )
    wall.collision_type = 1
    space.add(wall)
    return space


def test_straight_drive_reaches_expected_distance():
    robot = DiffDriveRobot(pymunk.Space(), RobotParams(slip_sigma=0.0))
    for _ in range(30):
        res = robot.step(0.5, 0.0, 0.1, None)
    # accelerates at 1 m/s^2 for 0.5 s (steps of 0.1, 0.2, ... 0.5 m/s), then 0.5 m/s
    expected = 0.1 * (0.1 + 0.2 + 0.3 + 0.4) + 0.5 * 0.1 * 26
    assert robot.pose[0] == pytest.approx(expected, abs=1e-9)
    assert abs(robot.pose[1]) < 1e-12 and not res.collision


def test_turn_in_place_and_limits():
    robot = DiffDriveRobot(pymunk.Space(), RobotParams(slip_sigma=0.0))
    for _ in range(20):
        robot.step(0.0, 10.0, 0.1, None)  # clipped to max_omega 1.5 rad/s
    assert robot.twist == (0.0, 1.5)
    # alpha 3 rad/s^2: 0.3, 0.6, ... 1.5 (5 steps), then 15 steps at 1.5
    turned = 0.1 * (0.3 + 0.6 + 0.9 + 1.2) + 0.1 * 1.5 * 16
    assert robot.pose[2] == pytest.approx(math.remainder(turned, 2 * math.pi), abs=1e-9)
    np.testing.assert_allclose(robot.pose[:2], 0.0, atol=1e-12)


@pytest.mark.parametrize("thickness", [0.005, 0.05])
def test_never_tunnels_through_a_wall(thickness):
    params = RobotParams(max_v_mps=2.0, max_accel_mps2=100.0, slip_sigma=0.0)
    robot = DiffDriveRobot(space_with_wall(2.0, thickness), params)
    bumps = []
    for _ in range(100):
        bumps.append(robot.step(2.0, 0.0, 0.1, None).collision)
        assert robot.pose[0] <= 2.0 - 0.2 + 0.01
    assert robot.pose[0] > 2.0 - 0.2 - 0.05  # it got to the wall
    assert any(bumps) and bumps[-1] and not bumps[0]


def test_slides_along_a_wall_at_an_angle():
    params = RobotParams(slip_sigma=0.0)
    robot = DiffDriveRobot(space_with_wall(1.0), params, pose=(0.0, 0.0, math.radians(30)))
    for _ in range(60):
        robot.step(1.0, 0.0, 0.1, None)
        assert robot.pose[0] <= 1.0 - 0.2 + 0.01
    assert robot.pose[1] > 1.0  # kept moving along the wall


def test_systematic_error_bends_the_true_path_and_odometry_does_not_see_it():
    wheels = WheelGeometry(e_d=1.02)
    robot = DiffDriveRobot(pymunk.Space(), RobotParams(wheels=wheels, slip_sigma=0.0))
    odo = WheelOdometry(wheels, EncoderNoise(ticks_per_rev=0, sigma_sqrt_m=0.0))
    for _ in range(50):
        r = robot.step(0.5, 0.0, 0.1, None)
        odo.update(r.dphi_left_rad, r.dphi_right_rad, None)
    assert abs(odo.pose[1]) < 1e-12 and abs(odo.pose[2]) < 1e-12  # odometry: straight
    assert robot.pose[2] > 0.05 and robot.pose[1] > 0.05  # truth: curves left (bigger right)


def test_slip_is_seeded():
    def run(seed):
        robot = DiffDriveRobot(pymunk.Space(), RobotParams(slip_sigma=0.05))
        rng = np.random.default_rng(seed)
        for _ in range(20):
            robot.step(0.8, 0.3, 0.1, rng)
        return robot.pose

    np.testing.assert_array_equal(run(1), run(1))
    assert not np.allclose(run(1), run(2))


def test_rejects_non_finite_commands():
    robot = DiffDriveRobot(pymunk.Space())
    with pytest.raises(ValueError, match="finite"):
        robot.step(float("nan"), 0.0, 0.1, None)


def test_person_stepping_into_the_robot_is_a_bump_and_blocks_only_that_way():
    space = pymunk.Space()
    person = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
    person.position = (0.35, 0.0)  # overlaps the robot's disc (0.2 + 0.2 > 0.35)
    space.add(person, pymunk.Circle(person, 0.2))
    robot = DiffDriveRobot(space, RobotParams(slip_sigma=0.0))
    res = robot.step(0.5, 0.0, 0.1, None)
    assert res.collision and robot.pose[0] <= 1e-12  # cannot push into the person
    robot.set_pose((0.0, 0.0, math.pi))
    res = robot.step(0.5, 0.0, 0.1, None)
    assert res.collision and robot.pose[0] == pytest.approx(-0.01)  # backing away is allowed


def test_deep_overlap_escapes_outwards():
    space = pymunk.Space()
    person = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
    person.position = (0.1, 0.0)  # the robot's centre is inside the person's disc
    space.add(person, pymunk.Circle(person, 0.25))
    robot = DiffDriveRobot(space, RobotParams(slip_sigma=0.0), pose=(0.0, 0.0, 0.0))
    robot.step(0.5, 0.0, 0.1, None)
    assert robot.pose[0] == 0.0  # towards the person's centre: blocked
    robot.set_pose((0.0, 0.0, math.pi))
    robot.step(0.5, 0.0, 0.1, None)
    assert robot.pose[0] == pytest.approx(-0.01)  # away: allowed
