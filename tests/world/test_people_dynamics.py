"""The social force kernel against the closed forms of Helbing & Molnár (1995)."""

import numpy as np
import pytest

from dynmap_sim.world.people import SegmentGrid, StepConstants
from dynmap_sim.world.people.dynamics import move, social_force
from dynmap_sim.world.people.params import A_PEOPLE, A_WALL, B_PEOPLE, B_WALL

NO_WALLS = SegmentGrid(np.zeros((0, 4)))


def at_goal_velocity(z, goal, v0):
    """Velocities ``v0 e`` toward the goals: the driving term is zero."""
    e = (goal - z) / np.abs(goal - z)
    return v0 * e


def test_a_lone_person_at_its_goal_velocity_feels_no_force():
    z, goal, v0 = np.array([1.0 + 2.0j]), np.array([5.0 + 4.0j]), np.array([1.1])
    k = StepConstants.build(np.array([0.22]), v0, 0.2)
    force, pair_gap, _, robot_gap = social_force(
        z, at_goal_velocity(z, goal, v0), goal, NO_WALLS.rows(z), None, k
    )
    assert abs(force[0]) < 1e-12
    assert pair_gap == robot_gap == np.inf


def test_the_driving_force_relaxes_toward_the_desired_velocity():
    z, goal, v0 = np.array([0j]), np.array([3.0 + 0j]), np.array([1.2])
    k = StepConstants.build(np.array([0.22]), v0, 0.2)
    force, *_ = social_force(z, np.array([0j]), goal, NO_WALLS.rows(z), None, k)
    assert force[0] == pytest.approx(1.2 / 0.5, rel=1e-12)  # v0 / tau along +x


@pytest.mark.parametrize("d", [0.5, 1.0, 2.5])
def test_repulsion_between_two_people_is_equal_opposite_and_exponential(d):
    r = 0.25
    z = np.array([0j, d * np.exp(0.7j)])
    goal = z + np.array([10j, 10j])  # both walk the same way, side by side
    v0 = np.array([1.0, 1.0])
    k = StepConstants.build(np.array([r, r]), v0, 0.2)
    force, pair_gap, _, _ = social_force(
        z, at_goal_velocity(z, goal, v0), goal, NO_WALLS.rows(z), None, k
    )
    assert force[0] == pytest.approx(-force[1], abs=1e-12)
    want = A_PEOPLE * np.exp((2 * r - d) / B_PEOPLE)
    assert force[1] == pytest.approx(want * np.exp(0.7j), rel=1e-12)
    assert pair_gap == pytest.approx(d - 2 * r, abs=1e-12)


@pytest.mark.parametrize("d", [0.4, 0.9])
def test_a_wall_pushes_along_its_normal_within_reach_only(d):
    wall = SegmentGrid(np.array([[-5.0, 0.0, 5.0, 0.0]]))
    r = 0.2
    z, goal, v0 = np.array([d * 1j]), np.array([4.0 + d * 1j]), np.array([1.0])
    k = StepConstants.build(np.array([r]), v0, 0.2)
    force, _, wall_gap, _ = social_force(
        z, at_goal_velocity(z, goal, v0), goal, wall.rows(z), None, k
    )
    assert force[0] == pytest.approx(1j * A_WALL * np.exp((r - d) / B_WALL), rel=1e-12)
    assert wall_gap[0] == pytest.approx(d - r, abs=1e-12)
    far = np.array([1.5j])
    force, *_ = social_force(
        far, at_goal_velocity(far, far + 4, v0), far + 4, wall.rows(far), None, k
    )
    assert abs(force[0]) < 1e-12  # beyond REACH_M: no force


def test_the_move_caps_the_speed():
    z, v = np.array([0j, 1 + 1j]), np.array([0j, 0j])
    k = StepConstants.build(np.array([0.2, 0.2]), np.array([1.0, 0.5]), 0.2)
    old = move(z, v, np.array([100.0 + 0j, 0.1j]), 0.1, k)
    assert list(old) == [0j, 1 + 1j]
    assert abs(v[0]) == pytest.approx(1.3) and v[1] == pytest.approx(0.01j)
    assert z[0] == pytest.approx(0.13) and z[1] == pytest.approx(1 + 1.001j)
