"""People's pymunk bodies: near the robot always current, all of them on ``World.space``."""

import numpy as np

from dynmap_sim.world import World, load_world
from dynmap_sim.world.world import _near_m


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
    near_m = _near_m(0.1, 0.2, float(w.crowd.radius.max()))
    steps_with_near = 0
    for _ in range(30):
        w.step(0.1, robot_pose=pose, robot_radius_m=0.2)
        bodies = _body_positions(raw, n)
        near = np.hypot(*(w.crowd.pos - robot).T) < near_m
        steps_with_near += bool(near.any())
        np.testing.assert_array_equal(bodies[near], w.crowd.pos[near])
    assert steps_with_near >= 3
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


def test_robot_among_people_drives_as_with_every_body_current(monkeypatch):
    """Only the bodies the robot's next collision query can reach are kept current: its
    contacts with people are those of a space whose bodies all move at every step."""
    from dynmap_sim.env import DynMapEnv
    from dynmap_sim.world.world import World as W

    t = np.arange(400) * 0.1
    acts = np.stack([0.6 + 0.4 * np.sin(0.2 * t), 1.2 * np.sin(0.5 * t)], axis=1)

    def drive():
        env = DynMapEnv(world="lab")
        env.reset(seed=1, options={"day": 1, "run": 2})
        out = []
        for a in acts:
            obs, _, _, _, info = env.step(a)
            out.append((info["truth"]["pose"], info["collision"], obs["scan"]))
        return out

    lazy = drive()
    monkeypatch.setattr(W, "_sync_near", lambda self, dt_s, rxy, rr: self._sync_bodies(None))
    every = drive()
    assert any(c for _, c, _ in lazy)
    for (p, c, s), (q, d, u) in zip(lazy, every, strict=True):
        np.testing.assert_array_equal(p, q)
        assert c == d
        np.testing.assert_array_equal(s, u)
