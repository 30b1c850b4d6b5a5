"""People's pymunk bodies: near the robot always current, all of them on ``World.space``."""

import numpy as np

from dynmap_sim.world import World, load_world
from dynmap_sim.world.world import SYNC_MARGIN_M, SYNC_SPEED_MPS


def _body_positions(space, n):
    people = [b for b in space.bodies if b.body_type == b.KINEMATIC][:n]
    return np.array([tuple(b.position) for b in people])


def test_bodies_near_the_robot_are_current_and_space_access_syncs_all():
    w = World(load_world("lab"), seed=0)
    w.reset(1, 2)
    n = w.crowd.n
    assert n >= 10
    raw = w._space  # what a robot holding the space sees (no sync on access)
    robot = w.crowd.pos[0] + np.array([0.8, 0.0])
    pose = (float(robot[0]), float(robot[1]), 0.0)
    for _ in range(30):
        w.step(0.1, robot_pose=pose, robot_radius_m=0.2)
        bodies = _body_positions(raw, n)
        near = np.hypot(*(w.crowd.pos - robot).T) < 0.2 + SYNC_MARGIN_M + SYNC_SPEED_MPS * 0.1
        assert near.any()
        np.testing.assert_array_equal(bodies[near], w.crowd.pos[near])
    far = ~near
    assert far.any() and not np.array_equal(bodies[far], w.crowd.pos[far])  # lazily moved
    np.testing.assert_array_equal(_body_positions(w.space, n), w.crowd.pos)
    vel = np.array([tuple(b.velocity) for b in w._people_bodies])
    np.testing.assert_array_equal(vel, w.crowd.vel)


def test_without_a_robot_every_body_moves_each_step():
    w = World(load_world("lab"), seed=0)
    w.reset(1, 2)
    for _ in range(5):
        w.step(0.1)
        np.testing.assert_array_equal(_body_positions(w._space, w.crowd.n), w.crowd.pos)
