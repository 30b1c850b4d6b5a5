"""Wheel odometry: an empty-world square closes with the error E_d and E_b predict."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dynmap_sim.se2 import compose
from dynmap_sim.sensors.odometry import (
    EncoderNoise,
    WheelGeometry,
    WheelOdometry,
    body_twist_from_wheels,
    wheel_rates_for_twist,
)

EXACT = EncoderNoise(ticks_per_rev=0, sigma_sqrt_m=0.0)


def drive_true_square(odo, geom, side_m=4.0, direction=1, steps=50, rng=None):
    """Drive a *true* square (leg, turn 90 deg in place) and feed the wheel angles to ``odo``."""
    rl, rr = 0.5 * geom.diameter_left_m, 0.5 * geom.diameter_right_m
    half_b = 0.5 * geom.wheelbase_actual_m
    for _ in range(4):
        for _ in range(steps):
            odo.update(side_m / steps / rl, side_m / steps / rr, rng)
        arc = direction * (math.pi / 2) * half_b / steps
        for _ in range(steps):
            odo.update(-arc / rl, arc / rr, rng)
    return odo.pose


def arc_pose(ds, dth):
    if abs(dth) < 1e-12:
        return np.array([ds, 0.0, 0.0])
    rad = ds / dth
    return np.array([rad * math.sin(dth), rad * (1 - math.cos(dth)), dth])


def expected_square(geom, side_m, direction):
    """Closed form: each leg and each turn is one circular arc in the odometry's estimate."""
    kd_l = geom.wheel_diameter_m / geom.diameter_left_m  # = (E_d + 1) / 2
    kd_r = geom.wheel_diameter_m / geom.diameter_right_m  # = (E_d + 1) / (2 E_d)
    b = geom.wheelbase_m
    leg = arc_pose(0.5 * side_m * (kd_l + kd_r), side_m * (kd_r - kd_l) / b)
    turn_wheel = direction * (math.pi / 2) * 0.5 * geom.wheelbase_actual_m
    turn = arc_pose(0.5 * turn_wheel * (kd_r - kd_l), turn_wheel * (kd_r + kd_l) / b)
    pose = np.zeros(3)
    for _ in range(4):
        pose = compose(compose(pose, leg), turn)
    return pose


def test_perfect_wheels_close_the_square():
    geom = WheelGeometry()
    pose = drive_true_square(WheelOdometry(geom, EXACT), geom)
    np.testing.assert_allclose(pose, 0.0, atol=1e-9)


@settings(max_examples=25, deadline=None)
@given(e_d=st.floats(0.98, 1.02), e_b=st.floats(0.95, 1.05), direction=st.sampled_from([1, -1]))
def test_square_closes_with_predicted_error(e_d, e_b, direction):
    geom = WheelGeometry(e_d=e_d, e_b=e_b)
    pose = drive_true_square(WheelOdometry(geom, EXACT), geom, direction=direction)
    np.testing.assert_allclose(pose, expected_square(geom, 4.0, direction), atol=1e-9)


def test_wheelbase_error_heading_after_square():
    """With E_d = 1 every estimated 90 deg turn is E_b * 90 deg: 4 turns -> 2 pi (E_b - 1)."""
    geom = WheelGeometry(e_b=1.02)
    pose = drive_true_square(WheelOdometry(geom, EXACT), geom)
    assert pose[2] == pytest.approx(2 * math.pi * 0.02, abs=1e-9)


def test_kinematics_round_trip_and_systematic_error():
    nominal = WheelGeometry()
    wl, wr = wheel_rates_for_twist(nominal, 0.4, 0.3)
    assert body_twist_from_wheels(nominal, wl, wr) == pytest.approx((0.4, 0.3))
    bad = WheelGeometry(e_d=1.01, e_b=1.0)
    v, w = body_twist_from_wheels(bad, *wheel_rates_for_twist(bad, 0.5, 0.0))
    assert v == pytest.approx(0.5) and w > 0.0  # bigger right wheel: drifts left
    assert bad.diameter_right_m / bad.diameter_left_m == pytest.approx(1.01)
    assert 0.5 * (bad.diameter_right_m + bad.diameter_left_m) == pytest.approx(0.15)


def test_random_noise_drifts_and_grows_with_distance():
    geom = WheelGeometry()
    ends_short, ends_long = [], []
    for seed in range(40):
        rng = np.random.default_rng(seed)
        odo = WheelOdometry(geom, EncoderNoise(ticks_per_rev=4096, sigma_sqrt_m=0.005))
        r = 0.5 * geom.wheel_diameter_m
        for i in range(400):
            odo.update(0.05 / r, 0.05 / r, rng)
            if i == 99:
                ends_short.append(odo.pose)
        ends_long.append(odo.pose)
    s, lo = np.array(ends_short), np.array(ends_long)
    assert np.std(s[:, 2]) > 0 and np.std(lo[:, 1]) > 2 * np.std(s[:, 1])
    assert abs(np.mean(lo[:, 0]) - 20.0) < 0.05


def test_quantization_loses_no_ticks():
    geom = WheelGeometry()
    odo = WheelOdometry(geom, EncoderNoise(ticks_per_rev=100, sigma_sqrt_m=0.0))
    r = 0.5 * geom.wheel_diameter_m
    for _ in range(1000):
        odo.update(0.00123 / r, 0.00123 / r, None)
    assert odo.pose[0] == pytest.approx(1.23, abs=2 * math.pi * r / 100)
