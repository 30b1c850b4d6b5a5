"""What blocks a route (H&W §6.3): an obstacle that stays in the corridor blocks the route's
edges and is driven round; one that passes by (a person crossing) is waited for and blocks
nothing (``StackParams.block_persist_s``); one that closes the way ends the run saying that
no way exists."""

from __future__ import annotations

import math

import numpy as np
import pytest
from synthetic_scans import box, raycast

from dynmap_sim import se2
from dynmap_sim.agent.navigation.stack import NO_WAY, NavigationStack, StackParams
from dynmap_sim.types import LaserSpec, Odometry, PoseEstimate, Prior, Scan

LASER = LaserSpec("test", 241, -2.0944, 2.0944 / 120, 0.02, 5.6, 0.1, 0.0)
ROOM = box(0.0, 0.0, 8.0, 2.4)
#: a 0.4 m square on the route's centre line, 1.6 m ahead of where it appears
OBSTACLE = box(3.6, 1.0, 4.0, 1.4)
#: a wall across the room there
CLOSURE = np.array([[3.8, 0.0, 3.8, 2.4]])
PRIOR = Prior(
    np.array([0.5, 1.2, 0.0]), walls=ROOM, bounds=(0, 0, 8, 2.4), route=[[0.5, 1.2], [7.0, 1.2]]
)


def drive(
    stack: NavigationStack, stays_s: float, obstacle: np.ndarray = OBSTACLE, steps: int = 1500
) -> None:
    """Drive a unicycle on ``stack``'s commands with exact scans; the ``obstacle`` appears
    when the robot passes x = 2 m and is there for ``stays_s`` [s]."""
    pose = np.array([0.5, 1.2, 0.0])
    appeared = math.inf
    for k in range(steps):
        t = 0.1 * k
        if pose[0] >= 2.0 and not math.isfinite(appeared):
            appeared = t
        walls = ROOM if not appeared <= t < appeared + stays_s else np.vstack([ROOM, obstacle])
        lp = se2.compose(pose, np.asarray(LASER.mount_pose))
        scan = Scan(raycast(lp, LASER.angles(), walls, LASER.range_max_m).astype(np.float32), t)
        est = PoseEstimate(pose.copy(), np.diag([1e-4, 1e-4, 1e-4]))
        cmd = stack.step(t, Odometry(pose.copy(), t), scan, est)
        pose = pose + 0.1 * cmd[0] * np.array([np.cos(pose[2]), np.sin(pose[2]), 0.0])
        pose[2] += 0.1 * cmd[1]
        if stack.done or stack.gave_up:
            break


@pytest.mark.parametrize("stays_s, blocks", [(1.5, False), (math.inf, True)])
def test_only_an_obstacle_that_stays_blocks_the_route(stays_s: float, blocks: bool):
    stack = NavigationStack(LASER, 0.17)
    stack.begin_run(PRIOR)
    drive(stack, stays_s)
    kinds = [kind for _, kind, _ in stack.events]
    assert stack.done and not stack.gave_up
    assert ("block" in kinds) is blocks
    assert ("detour" in kinds) is blocks


def test_a_closure_with_no_way_round_ends_the_run_saying_so():
    quick = {"idle_time_s": 1.0, "wait_s": 0.5, "max_attempts": 2, "movement_time_s": 2.0}
    stack = NavigationStack(LASER, 0.17, StackParams(recovery=quick))
    stack.begin_run(PRIOR)
    drive(stack, math.inf, CLOSURE)
    assert stack.gave_up and not stack.done
    assert stack.unreachable_cause == NO_WAY
    why = [detail for _, kind, detail in stack.events if kind == "unreachable"]
    assert len(why) == 1 and why[0].startswith("no way to the goal exists")
