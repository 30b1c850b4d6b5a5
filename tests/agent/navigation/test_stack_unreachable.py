"""A goal the stack cannot reach ends the run with an event that says why: no way exists on
the routes or the costmap, the localizer is lost, or the robot is stuck on a way that exists;
and a route driven against its direction where it must go back (reverse edges)."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_scans import box, raycast

from dynmap_sim import se2
from dynmap_sim.agent.navigation.routes import RouteMemoryParams
from dynmap_sim.agent.navigation.stack import LOST, NO_WAY, NavigationStack, StackParams
from dynmap_sim.types import LaserSpec, Odometry, PoseEstimate, Prior, Scan

LASER = LaserSpec("test", 241, -2.0944, 2.0944 / 120, 0.02, 5.6, 0.1, 0.0)
#: quick recovery: idle 1 s, wait 0.5 s, two attempts
QUICK = {"idle_time_s": 1.0, "wait_s": 0.5, "max_attempts": 2, "movement_time_s": 2.0}


def drive(stack: NavigationStack, walls: np.ndarray, pose, std_m: float = 0.01, steps=2000):
    """Drive a unicycle on ``stack``'s commands with exact scans of ``walls`` and an estimate
    of position std ``std_m``; stops when the stack is done or gave up."""
    pose = np.asarray(pose, float)
    cov = np.diag([std_m**2, std_m**2, 0.01])
    for k in range(steps):
        t = 36_000.0 + 0.1 * k
        lp = se2.compose(pose, np.asarray(LASER.mount_pose))
        scan = Scan(raycast(lp, LASER.angles(), walls, LASER.range_max_m).astype(np.float32), t)
        cmd = stack.step(t, Odometry(pose.copy(), t), scan, PoseEstimate(pose.copy(), cov))
        pose = pose + 0.1 * cmd[0] * np.array([np.cos(pose[2]), np.sin(pose[2]), 0.0])
        pose[2] += 0.1 * cmd[1]
        if stack.done or stack.gave_up:
            break
    return pose


def walled_off() -> tuple[np.ndarray, Prior]:
    """A 6 m x 2 m room cut in two by a wall across it at x = 3: the route to x = 5 has no
    way through, on the routes or on the costmap."""
    walls = np.concatenate([box(0.0, 0.0, 6.0, 2.0), np.array([[3.0, 0.0, 3.0, 2.0]])])
    route = np.array([[1.0, 1.0], [5.0, 1.0]])
    prior = Prior(np.array([1.0, 1.0, 0.0]), walls=walls, bounds=(0, 0, 6, 2), route=route)
    return walls, prior


def test_no_way_to_the_goal_ends_the_run_with_an_unreachable_event():
    walls, prior = walled_off()
    stack = NavigationStack(LASER, 0.17, StackParams(recovery=QUICK))
    stack.begin_run(prior)
    drive(stack, walls, [1.0, 1.0, 0.0])
    assert stack.gave_up and not stack.done
    assert stack.unreachable_cause == NO_WAY
    why = [detail for _, kind, detail in stack.events if kind == "unreachable"]
    assert len(why) == 1 and why[0].startswith("no way to the goal exists")
    assert why[0].endswith("(no_way)")  # the cause, for the results summary


def test_a_lost_localizer_is_named_when_the_goal_is_not_reached():
    walls, prior = walled_off()
    stack = NavigationStack(LASER, 0.17, StackParams(recovery=QUICK, lost_std_m=0.5))
    stack.begin_run(prior)
    drive(stack, walls, [1.0, 1.0, 0.0], std_m=0.8)
    assert stack.gave_up and stack.unreachable_cause == LOST
    kinds = [kind for _, kind, _ in stack.events]
    assert kinds.index("lost") < kinds.index("unreachable")
    why = [detail for _, kind, detail in stack.events if kind == "unreachable"]
    assert len(why) == 1 and "localizer is lost" in why[0] and why[0].endswith("(lost)")


@pytest.mark.parametrize("std_m, lost", [(0.3, False), (1.2, True)])
def test_the_lost_event_follows_the_estimates_uncertainty(std_m: float, lost: bool):
    walls = box(0.0, 0.0, 6.0, 2.0)
    prior = Prior(np.array([1.0, 1.0, 0.0]), walls=walls, route=np.array([[1.0, 1.0], [5.0, 1.0]]))
    stack = NavigationStack(LASER, 0.17)
    stack.begin_run(prior)
    drive(stack, walls, [1.0, 1.0, 0.0], std_m=std_m, steps=20)
    assert ("lost" in [kind for _, kind, _ in stack.events]) is lost


def test_a_route_back_through_a_doorway_it_passed_is_driven_backwards():
    """A route into a room that ends there; the next run's goal lies back at the route's
    start, through the same doorway: with reverse edges the plan follows the route back."""
    walls = np.concatenate(
        [box(0.0, 0.0, 8.0, 3.0), np.array([[4.0, 0.0, 4.0, 1.0], [4.0, 2.0, 4.0, 3.0]])]
    )
    out = np.array([[1.0, 1.5], [7.0, 1.5]])
    reverse = StackParams(route_memory=RouteMemoryParams(reverse_cost_factor=1.5))
    stack = NavigationStack(LASER, 0.17, reverse)
    stack.begin_run(Prior(np.array([1.0, 1.5, 0.0]), walls=walls, route=out, day=1, run=1))
    pose = drive(stack, walls, [1.0, 1.5, 0.0])
    assert stack.done
    back = out[::-1].copy()
    stack.begin_run(Prior(pose, walls=walls, route=back, day=1, run=2))
    drive(stack, walls, pose)
    assert stack.done and not stack.gave_up
    kinds = [kind for _, kind, _ in stack.events]
    assert "grid_path" not in kinds and "bridge" not in kinds  # the route itself, backwards
