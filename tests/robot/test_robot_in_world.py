"""Driving wildly at full speed in a shipped world never puts the robot inside an obstacle."""

import numpy as np

from dynmap_sim.robot.diff_drive import DiffDriveRobot, RobotParams
from dynmap_sim.world import World, load_world, resolve_world_path


def point_segment_distance(p, seg):
    a, d = seg[:, :2], seg[:, 2:] - seg[:, :2]
    t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.einsum("ij,ij->i", d, d), 0.0, 1.0)
    return np.hypot(*(a + t[:, None] * d - p).T)


def test_full_speed_random_driving_never_enters_walls():
    spec = load_world(resolve_world_path("lab")).model_copy(update={"people": ()})
    world = World(spec, seed=0)
    params = RobotParams(max_v_mps=1.5, max_accel_mps2=5.0, slip_sigma=0.05)
    robot = DiffDriveRobot(world.space, params, tuple(spec.robot.start))
    rng = np.random.default_rng(0)
    g = world.geometry
    bumps = 0
    for i in range(1500):
        if i % 20 == 0:
            cmd = (1.5, rng.uniform(-1.5, 1.5))
        res = robot.step(*cmd, 0.1, rng)
        bumps += res.collision
        p = robot.pose[:2]
        assert point_segment_distance(p, g.segments).min() >= params.radius_m - 1e-6
        if g.circles.shape[0]:
            gap = np.hypot(*(g.circles[:, :2] - p).T) - g.circles[:, 2]
            assert gap.min() >= params.radius_m - 1e-6
    assert bumps > 10  # it did hit things, and stayed outside them
