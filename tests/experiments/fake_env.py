"""A tiny stand-in for DynMapEnv (same API, unicycle kinematics, a drifting odometry and a
constant scan) so the runner's bookkeeping can be tested fast and in isolation."""

from __future__ import annotations

import numpy as np

from dynmap_sim import se2
from dynmap_sim.truth import ObstacleSnapshot, RunSlot, WorldFacts
from dynmap_sim.types import LaserSpec
from dynmap_sim.world import World, load_world, resolve_world_path


class FakeEnv:
    def __init__(self, world: str = "apartment", scale_error: float = 0.02) -> None:
        self.world = World(load_world(resolve_world_path(world)), seed=0)
        self.laser_spec = LaserSpec("fake", 8, -1.0, 0.25, 0.02, 5.6, 0.1, 0.0)
        self.robot_radius_m = 0.2
        self.scale_error = scale_error
        self.unwrapped = self
        self.resets: list[tuple[int, int, int]] = []

    def _obs(self):
        return {"scan": np.full(8, 2.0, np.float32), "odom": self.odom.copy()}, {
            "truth": {
                "pose": self.pose.copy(),
                "beam_class": np.ones(8, np.int8),
                "beam_object": np.zeros(8, np.int32),
                "people": self.world.people_poses(),
                "time": (self.day, self.run, self.world.time_s),
            },
            "collision": False,
            "route_progress": 0.0,
        }

    def reset(self, seed=None, options=None):
        self.day, self.run = options["day"], options["run"]
        self.resets.append((seed, self.day, self.run))
        self.world.reset(self.day, self.run)
        self.pose = np.asarray(self.world.spec.robot.start, float).copy()
        self.odom = np.zeros(3)
        self.rng = np.random.default_rng([seed, self.day, self.run])
        return self._obs()

    def step(self, action):
        v, w = float(action[0]), float(action[1])
        dt = 0.1
        delta = np.array([v * dt, 0.0, w * dt])
        self.pose = se2.compose(self.pose, delta)
        noisy = delta * [1.0 + self.scale_error, 1.0, 1.0] + self.rng.normal(0, 1e-4, 3)
        self.odom = se2.compose(self.odom, noisy)
        self.world.step(dt, robot_pose=tuple(self.pose))
        obs, info = self._obs()
        return obs, 0.0, False, False, info

    def world_facts(self):
        spec = self.world.spec
        return WorldFacts(
            name=spec.name,
            bounds=tuple(float(b) for b in spec.bounds),
            start_pose=np.asarray(spec.robot.start, float),
            route=np.asarray(spec.robot.route, float),
            wall_segments=self.world.wall_segments(),
            slots=tuple(
                RunSlot(s.day, s.run, s.date, s.start_s) for s in self.world.calendar.slots
            ),
        )

    def obstacles(self):
        g = self.world.geometry
        return ObstacleSnapshot(g.segments, g.segment_class, g.circles, g.circle_class)

    def teleport(self, pose):
        self.pose = np.asarray(pose, float).copy()

    def close(self):
        pass


from dynmap_sim.agent.localization.localizer import Localizer  # noqa: E402
from dynmap_sim.types import Diagnostic, PoseEstimate  # noqa: E402


class RecordingLocalizer(Localizer):
    """Dead reckoning that logs the calls it gets and reports (and declares) every extra."""

    diagnostics = (
        Diagnostic("scan_loglik", "float64"),
        Diagnostic("lambda_min", "float64"),
        Diagnostic("timescale", "int64"),
        Diagnostic("safe_mode", "bool"),
    )

    def __init__(self, laser, rng, **params):
        super().__init__(laser, rng, **params)
        self.calls: list[tuple] = []
        self.origin = np.zeros(3)
        self.odom0 = None

    def begin_run(self, prior):
        self.calls.append(("begin_run", prior.day, prior.run, prior.first_run))
        self.origin = np.zeros(3) if prior.initial_pose is None else prior.initial_pose
        self.odom0 = None

    def update(self, odom, scan):
        if self.odom0 is None:
            self.odom0 = odom.pose.copy()
        mean = se2.compose(self.origin, se2.between(self.odom0, odom.pose))
        noise = float(self.rng.normal())  # consumes the localizer's own stream
        return PoseEstimate(
            mean=mean,
            cov=np.eye(3) * 0.01,
            extras={
                "scan_loglik": -1.5 + 0.0 * noise,
                "lambda_min": 100.0,
                "timescale": 2,
                "safe_mode": False,
                "point_classes": np.full(len(scan.ranges_m), 3, np.int64),
            },
        )

    def end_run(self):
        self.calls.append(("end_run",))

    def end_day(self):
        self.calls.append(("end_day",))


class UnpicklableLocalizer(RecordingLocalizer):
    """Holds a lambda: cannot be checkpointed."""

    def __init__(self, laser, rng, **params):
        super().__init__(laser, rng, **params)
        self.hook = lambda x: x


class DeclaringLocalizer(RecordingLocalizer):
    """Declares diagnostics of its own, like Hentschel & Wagner's would: point-class counts
    and the chosen map slot per scan, slot usage counted per run, the distance driven per run
    from its hook, and a day artifact."""

    diagnostics = (
        Diagnostic("point_class_counts", "int64", (4,)),
        Diagnostic("map_slot", "int64"),
        Diagnostic("slot_counts", "int64", (3,), per="run", counts_of="map_slot"),
        Diagnostic("path_m", "float64", per="run"),
    )

    def begin_run(self, prior):
        super().begin_run(prior)
        self.n_updates = 0

    def update(self, odom, scan):
        est = super().update(odom, scan)
        self.n_updates += 1
        est.extras = {
            "point_class_counts": [0, 1, 2, self.n_updates],
            "map_slot": self.n_updates % 3,
        }
        return est

    def run_diagnostics(self):
        return {"path_m": 0.1 * self.n_updates}

    def day_artifacts(self):
        return {"day_note": {"updates": np.array([self.n_updates])}}
