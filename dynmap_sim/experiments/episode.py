"""The episode loop: one run of the calendar through the env, steered by a driver.

``env.reset(seed, day, run)``, the run's :class:`~dynmap_sim.types.Prior`, then every control
step: record the sensors (odometry, scan) and the truth (``info["truth"]``), carry out a
kidnapping when one is due, ask the driver for the action, ``env.step``. The result is an
:class:`Episode`: the run's sensor stream
(:class:`~dynmap_sim.experiments.localizer_pool.RunStream`, what the localizers consume) and
its truth (what the metrics compare them with), recorded scan by scan by a
:class:`RunRecorder`.

Truth reaches the loop only through ``info["truth"]`` and the env's documented read-only
views (:mod:`dynmap_sim.truth`: ``world_facts()``, ``obstacles()``); the loop acts on the
world only through ``env.step`` and ``env.teleport`` (a kidnapping). The driver sees the truth
only when it declares ``sees_truth``.

A driver that steers on a localizer's estimate gets it in lock-step: the loop feeds that
localizer each scan as it is recorded (:class:`~dynmap_sim.experiments.localizer_pool.LocalizerRun`,
the same calls the localizer bench makes on a recorded stream) and hands the estimate to the
driver before it acts.

What carries over between runs besides the localizers — the driver, the engine's random
generator (kidnapping times and places) and where the robot has seen each object (the
seen-before point-class truth, :class:`~dynmap_sim.metrics.SeenPlaces`) — is the
:class:`EngineState`, which the runner checkpoints after every run.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.localization.localizer import Localizer
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid
from dynmap_sim.agent.planning.grid_dijkstra import GridDijkstra
from dynmap_sim.experiments.drivers import Driver, RunStart, StepInput
from dynmap_sim.experiments.drivers.tour import plan_through_waypoints, static_clearance_grid
from dynmap_sim.experiments.localizer_pool import (
    CHUNK_SCANS,
    LocalizerOutput,
    LocalizerRun,
    RunHeader,
    RunStream,
    ScanChunk,
)
from dynmap_sim.experiments.results import PeopleTrack
from dynmap_sim.experiments.scenario import Kidnapping, PriorConfig
from dynmap_sim.metrics import (
    SeenPlaces,
    clearances,
    goal_reached,
    object_places,
    path_length_m,
    seen_before_point_classes,
)
from dynmap_sim.truth import RunSlot, WorldFacts
from dynmap_sim.types import BeamClass, Odometry, Prior, Scan

FloatArray = NDArray[np.float64]

#: A kidnapped robot is put where it fits, and the shortest path keeps, the robot's radius
#: plus this margin free [m] (the tour operator's hard clearance) ...
FREE_MARGIN_M = 0.05
#: ... on a clearance grid of the run's true static obstacles of this resolution [m].
GRID_RESOLUTION_M = 0.05
#: A kidnapping target is moved to free space within this distance [m] (else skipped).
KIDNAP_SEARCH_M = 1.0
#: The shortest path prefers this much more clearance [m], like the tour operator's plan.
PREFERRED_EXTRA_M = 0.07
#: A route waypoint inside an obstacle counts if free space is this near [m] (the tour's).
SNAP_WAYPOINT_M = 0.4
#: The person beam class as a plain int (a faster comparison than with the enum member).
_PERSON = int(BeamClass.PERSON)


class StreamSink(Protocol):
    """Where :meth:`EpisodeLoop.run` hands a run's stream as it is recorded (the localizer
    bench: :class:`~dynmap_sim.experiments.localizer_pool.LocalizerPool`,
    :class:`~dynmap_sim.experiments.localizer_pool.InProcessLocalizers`)."""

    def begin(self, header: RunHeader, capacity: int = 1024) -> None: ...

    def feed(self, chunk: ScanChunk) -> None: ...

    def end(self) -> None: ...


class RunRecorder:
    """What a run records at every scan, as it is recorded: the sensor stream (stamps,
    odometry, scan, beam classes, the seen-before point classes), the truth (pose, bumper
    flag, clearance to people [m]), the people's positions (when kept) and which objects
    the laser hit. :meth:`chunk` hands the scans recorded since the last chunk to the
    localizer pool; :meth:`stream` and the ``*_array`` methods give the whole run."""

    def __init__(
        self,
        seen_mask: NDArray[np.bool_],
        person_clearance: Callable[[FloatArray], float],
        people_of: Callable[[], Any] | None = None,
    ) -> None:
        self.seen_mask = seen_mask
        self.hit_objects = np.zeros(len(seen_mask), dtype=bool)
        self._person_clearance = person_clearance
        self._people_of = people_of
        #: the run's crowd (its ids and radii are fixed; None: people not kept)
        self.crowd = people_of() if people_of is not None else None
        self.t: list[float] = []
        self.odom: list[FloatArray] = []
        self.scan: list[NDArray[np.float32]] = []
        self.beam_class: list[NDArray[np.int8]] = []
        self.point_truth: list[NDArray[np.int8]] = []
        self.truth: list[FloatArray] = []
        self.collision: list[bool] = []
        self.person_clearance_m: list[float] = []
        self.people: list[FloatArray] = []
        self.sent = 0  # scans handed to the pool

    def __len__(self) -> int:
        return len(self.t)

    def record(self, obs: Any, truth: Any, collision: bool) -> tuple[float, FloatArray]:
        """Record one scan (copies: the history must not change if a producer reuses its
        arrays); its time [s] and true pose."""
        pose = np.array(truth["pose"], dtype=np.float64)
        t_s = float(truth["time"][2])
        self.t.append(t_s)
        self.odom.append(np.array(obs["odom"], dtype=np.float64))
        self.scan.append(np.array(obs["scan"], dtype=np.float32))
        classes = np.array(truth["beam_class"], dtype=np.int8)
        self.beam_class.append(classes)
        beam_object = np.asarray(truth.get("beam_object", ()), dtype=np.int64)
        if beam_object.shape != classes.shape:
            beam_object = np.full(classes.shape, -1, dtype=np.int64)
        self.point_truth.append(seen_before_point_classes(classes, beam_object, self.seen_mask))
        n_obj = len(self.hit_objects)
        self.hit_objects[beam_object[(beam_object >= 0) & (beam_object < n_obj)]] = True
        self.truth.append(pose)
        self.collision.append(collision)
        self.person_clearance_m.append(self._person_clearance(pose))
        if self.crowd is not None and self._people_of is not None:
            self.people.append(_positions(self._people_of(), self.crowd.ids))
        return t_s, pose

    def last(self) -> tuple[FloatArray, NDArray[np.float32], NDArray[np.int8], NDArray[np.int8]]:
        """The last scan's odometry, ranges, beam classes and point classes."""
        return self.odom[-1], self.scan[-1], self.beam_class[-1], self.point_truth[-1]

    def chunk(self) -> ScanChunk:
        """The scans recorded since the last chunk, as the stream's arrays hold them."""
        start, n = self.sent, len(self.t) - self.sent
        self.sent = len(self.t)
        return ScanChunk(
            np.asarray(self.t[start:], dtype=np.float64),
            np.asarray(self.odom[start:], dtype=np.float64).reshape(n, 3),
            np.asarray(self.scan[start:], dtype=np.float32).reshape(n, -1),
            np.asarray(self.beam_class[start:], dtype=np.int8).reshape(n, -1),
            np.asarray(self.point_truth[start:], dtype=np.int8).reshape(n, -1),
        )

    def stream(self, index: int, prior: Prior, last_of_day: bool) -> RunStream:
        n = len(self.t)
        return RunStream(
            index=index,
            prior=prior,
            stamps_s=np.asarray(self.t, dtype=np.float64),
            odom=np.asarray(self.odom, dtype=np.float64).reshape(-1, 3),
            scans=np.asarray(self.scan, dtype=np.float32).reshape(n, -1),
            beam_class=np.asarray(self.beam_class, dtype=np.int8).reshape(n, -1),
            last_of_day=last_of_day,
            point_truth=np.asarray(self.point_truth, dtype=np.int8).reshape(n, -1),
        )

    def truth_array(self) -> FloatArray:
        return np.asarray(self.truth, dtype=np.float64).reshape(-1, 3)

    def people_track(self) -> PeopleTrack | None:
        """The people at every scan (None: not kept)."""
        if self.crowd is None:
            return None
        ids = self.crowd.ids
        xy = np.asarray(self.people, dtype=np.float64).reshape(len(self.t), len(ids), 2)
        return PeopleTrack(ids, np.array(self.crowd.radius, dtype=np.float64), xy)


@dataclass
class EngineState:
    """What carries over between runs besides the localizers (checkpointed after each run):
    the ``driver``, the engine's ``rng`` (kidnapping times and places) and ``seen``, the
    places at which the robot has seen each object in the runs so far (the truth of H&W's
    point classes: an object not seen at its place before is semi-static)."""

    driver: Driver
    rng: np.random.Generator
    seen: SeenPlaces = field(default_factory=SeenPlaces)


@dataclass(frozen=True)
class _Kidnap:
    step: int
    pose: FloatArray | None  # None: random (drawn at the kidnapping from the engine's RNG)


@dataclass
class Episode:
    """One simulated run: its sensor ``stream`` and its truth, waiting for the localizers.

    ``truth`` ``(T, 3)`` true poses; ``collision`` ``(T,)`` bumper pressed before the scan;
    ``events`` ``(step, t_s, kind, detail)``; ``terminated`` the route was finished;
    ``route_progress`` fraction of the route; ``segments`` ``(N, 4)`` / ``segment_class`` the
    run's obstacles (for figures).
    """

    index: int
    stream: RunStream
    truth: FloatArray
    collision: NDArray[np.bool_]
    events: list[tuple[int, float, str, str]]
    terminated: bool
    route_progress: float
    skipped_waypoints: int
    segments: FloatArray
    segment_class: NDArray[np.int8]
    #: the output of the localizer the driver steered on, run in lock-step (None: none)
    steered: LocalizerOutput | None = None
    #: true clearance of the robot's disc [m] per scan: to any obstacle, and to people
    clearance_m: FloatArray | None = None
    person_clearance_m: FloatArray | None = None
    #: the goal (the route's end) reached, by the truth (:func:`metrics.goal_reached`)
    goal_reached: bool = False
    #: the shortest path through the route's waypoints around the true obstacles [m]
    shortest_path_m: float = math.nan
    #: the driver's counts (:meth:`Driver.stats`) and what it handed over after the run
    driver_stats: dict[str, float] | None = None
    driver_artifacts: dict[str, bytes] | None = None
    #: the run's people at each scan (only with :attr:`EpisodeLoop.keep_people`; None: not
    #: kept)
    people: PeopleTrack | None = None


@dataclass(frozen=True)
class LoopConfig:
    """The scenario's settings the loop needs: the world ``seed``, the ``route`` the driver
    drives (for random kidnapping places), ``speed_mps`` and ``max_run_s`` (robot-time limit
    per run, None: none), the ``prior`` granted and the ``kidnappings``."""

    seed: int
    route: FloatArray
    speed_mps: float
    max_run_s: float | None
    prior: PriorConfig
    kidnappings: tuple[Kidnapping, ...]


@dataclass
class _Run:
    """One run as :meth:`EpisodeLoop.run` drives it: what it set up before the first step."""

    index: int
    facts: WorldFacts
    obstacles: Any
    prior: Prior
    kidnaps: list[_Kidnap]
    static_grid: ClearanceGrid
    places: Any
    radius_m: float
    shortest_m: float
    recorder: RunRecorder
    lockstep: LocalizerRun | None
    max_steps: int | None
    last_of_day: bool


@dataclass
class _Drive:
    """How the control loop ended: the last step and time [s], the env's flags, the route
    progress (fraction of the world's route) and the loop's events."""

    step: int = 0
    t_s: float = 0.0
    terminated: bool = False
    truncated: bool = False
    progress: float = 0.0
    events: list[tuple[int, float, str, str]] = field(default_factory=list)


class EpisodeLoop:
    """Runs episodes of ``env`` (see the module doc)."""

    def __init__(self, env: Any, config: LoopConfig, slots: list[RunSlot]) -> None:
        self.env = env
        self.u = env.unwrapped
        self.config = config
        self.slots = slots
        self.dt_s = float(self.u.laser_spec.scan_period_s)
        #: record the people's positions at every scan (``run --keep-scans``; an env
        #: without a ``people()`` truth view records none)
        self.keep_people = False

    def prior(self, i: int, facts: WorldFacts) -> Prior:
        """The prior of run ``i`` (of :attr:`slots`): what the scenario grants the agent."""
        pc, slot = self.config.prior, self.slots[i]
        return facts.prior(
            slot.day,
            slot.run,
            first_run=i == 0,
            sigma_xy_m=pc.initial_pose_sigma_xy_m,
            sigma_theta_rad=pc.initial_pose_sigma_theta_rad,
            walls=pc.map == "walls",
            known_pose=pc.initial_pose == "known",
            route=self.config.route,
        )

    def _kidnaps(self, slot: RunSlot, rng: np.random.Generator) -> list[_Kidnap]:
        route = self.config.route
        route_len = float(np.sum(np.hypot(*np.diff(route, axis=0).T)))
        expected_s = route_len / self.config.speed_mps
        if self.config.max_run_s is not None:
            expected_s = min(expected_s, self.config.max_run_s)
        out = []
        for k in self.config.kidnappings:
            if (k.day, k.run) != (slot.day, slot.run):
                continue
            t = rng.uniform(0.2, 0.6) * expected_s if k.time_s == "random" else float(k.time_s)
            pose = None if k.pose == "random" else np.asarray(k.pose, dtype=np.float64)
            out.append(_Kidnap(max(1, int(round(t / self.dt_s))), pose))
        return sorted(out, key=lambda kp: kp.step)

    def _random_route_pose(self, rng: np.random.Generator) -> FloatArray:
        route = self.config.route
        seg = np.hypot(*np.diff(route, axis=0).T)
        s = rng.uniform(0.0, seg.sum())
        k = int(min(np.searchsorted(np.cumsum(seg), s), len(seg) - 1))
        u = (s - (np.cumsum(seg)[k] - seg[k])) / max(seg[k], 1e-12)
        xy = route[k] + u * (route[k + 1] - route[k])
        return np.array([xy[0], xy[1], rng.uniform(-math.pi, math.pi)])

    def run(
        self,
        i: int,
        state: EngineState,
        steer: tuple[str, Localizer] | None = None,
        bench: StreamSink | None = None,
    ) -> Episode:
        """Drive run ``i`` of :attr:`slots` and record it; ``state`` carries on. ``steer``:
        the (label, localizer) the driver steers on, updated here scan by scan in lock-step
        (its estimate goes to the driver; its output to :attr:`Episode.steered`). ``bench``:
        the other localizers, handed the stream in chunks of
        :data:`~dynmap_sim.experiments.localizer_pool.CHUNK_SCANS` scans as it is recorded."""
        slot = self.slots[i]
        obs, info = self.env.reset(
            seed=self.config.seed, options={"day": slot.day, "run": slot.run}
        )
        run = self._begin(i, state, info, steer, bench)
        drive = self._drive(run, state, obs, info, bench)
        return self._finish(run, state, drive, bench)

    def _begin(
        self,
        i: int,
        state: EngineState,
        info: dict[str, Any],
        steer: tuple[str, Localizer] | None,
        bench: StreamSink | None,
    ) -> _Run:
        """After ``env.reset``: the run's prior, truth views and recorder; the driver and the
        localizers begin the run."""
        slot = self.slots[i]
        facts = self.u.world_facts()  # after reset: another seed builds another world
        obstacles = self.u.obstacles()
        prior = self.prior(i, facts)
        start = np.asarray(info["truth"]["pose"], dtype=np.float64)
        sees = state.driver.sees_truth
        state.driver.begin_run(
            RunStart(prior, start if sees else None, obstacles if sees else None)
        )
        kidnaps = self._kidnaps(slot, state.rng)
        static_grid = static_clearance_grid(obstacles, GRID_RESOLUTION_M)
        # the seen-before truth of H&W's point classes: each object's place now, and whether
        # the robot saw it there in an earlier run
        places = object_places(
            len(obstacles.object_ids),
            obstacles.segments,
            obstacles.segment_object,
            obstacles.circles,
            obstacles.circle_object,
        )
        radius_m = float(self.u.robot_radius_m)
        people_of = getattr(self.u, "people", None) if self.keep_people else None
        recorder = RunRecorder(
            state.seen.seen_before(obstacles.object_ids, places),
            lambda pose: self._person_clearance_m(pose, radius_m),
            people_of,
        )
        cfg = self.config
        max_steps = int(round(cfg.max_run_s / self.dt_s)) if cfg.max_run_s is not None else None
        limit = max_steps if max_steps is not None else getattr(self.u, "max_episode_steps", 0)
        last_of_day = i + 1 == len(self.slots) or self.slots[i + 1].day != slot.day
        lockstep = None
        if steer is not None:
            lockstep = LocalizerRun(steer[0], steer[1], prior, capacity=int(limit) + 1)
        if bench is not None:
            bench.begin(RunHeader(i, prior, last_of_day), int(limit) + 1)
        return _Run(
            index=i,
            facts=facts,
            obstacles=obstacles,
            prior=prior,
            kidnaps=kidnaps,
            static_grid=static_grid,
            places=places,
            radius_m=radius_m,
            shortest_m=self._shortest_path_m(start, static_grid, radius_m + FREE_MARGIN_M),
            recorder=recorder,
            lockstep=lockstep,
            max_steps=max_steps,
            last_of_day=last_of_day,
        )

    def _drive(
        self,
        run: _Run,
        state: EngineState,
        obs: Any,
        info: dict[str, Any],
        bench: StreamSink | None,
    ) -> _Drive:
        """The control loop: record each scan, feed the lock-stepped localizer and the pool,
        carry out a due kidnapping, let the driver act, step the env."""
        driver, rec, sees = state.driver, run.recorder, state.driver.sees_truth
        out = _Drive()
        collision = False
        estimate = None
        while True:
            truth = info["truth"]
            t_s, pose = rec.record(obs, truth, collision)
            out.t_s = t_s
            odom, scan, classes, points = rec.last()
            if run.lockstep is not None:
                estimate = run.lockstep.update(t_s, odom, scan, classes, points)
            out.progress = float(info.get("route_progress", out.progress))
            if bench is not None and len(rec) - rec.sent >= CHUNK_SCANS:
                bench.feed(rec.chunk())
            if out.terminated or out.truncated or driver.done:
                break
            if run.max_steps is not None and out.step >= run.max_steps:
                stop = f"stopped after {self.config.max_run_s} s"
                out.events.append((out.step, t_s, "time_limit", stop))
                break
            if run.kidnaps and run.kidnaps[0].step <= out.step:
                pose = self._kidnap(run, state, out, pose)
            action = driver.act(
                StepInput(
                    t_s=t_s,
                    odom=Odometry(pose=odom.copy(), stamp_s=t_s),
                    scan=Scan(ranges_m=scan.copy(), stamp_s=t_s),
                    bumped=collision,
                    estimate=estimate,
                    pose=pose if sees else None,
                    people=truth["people"] if sees else None,
                )
            )
            obs, _, out.terminated, out.truncated, info = self.env.step(action)
            collision = bool(info.get("collision", False))
            out.step += 1
        return out

    def _kidnap(self, run: _Run, state: EngineState, out: _Drive, pose: FloatArray) -> FloatArray:
        """Carry out the next kidnapping (to free space near its target); the pose after."""
        kp = run.kidnaps.pop(0)
        target = kp.pose if kp.pose is not None else self._random_route_pose(state.rng)
        free_m = run.radius_m + FREE_MARGIN_M
        free = run.static_grid.nearest_free(target[:2], free_m, KIDNAP_SEARCH_M)
        step, t_s = out.step, out.t_s
        if free is None:
            out.events.append((step, t_s, "kidnap_skipped", "no free place near the target"))
            return pose
        new_pose = np.array([free[0], free[1], target[2]])
        self.u.teleport(new_pose)
        if state.driver.sees_truth:
            state.driver.teleported(new_pose, t_s)
        out.events.append((step, t_s, "kidnap", f"to {np.round(new_pose, 3).tolist()}"))
        return new_pose

    def _finish(
        self, run: _Run, state: EngineState, drive: _Drive, bench: StreamSink | None
    ) -> Episode:
        """End the run (driver, pool, lock-stepped localizer, seen places) and measure it."""
        cfg, driver, rec, obstacles = self.config, state.driver, run.recorder, run.obstacles
        events = drive.events + [
            (drive.step, drive.t_s, "kidnap_not_reached", f"planned at step {kp.step}")
            for kp in run.kidnaps
        ]
        driver_events, skipped = list(driver.events), driver.skipped_waypoints
        finished = driver.done
        driver_stats = dict(driver.stats())
        driver.end_run()
        hit = rec.hit_objects & ~_people(obstacles)
        state.seen.remember(obstacles.object_ids, run.places, hit)
        truth = rec.truth_array()
        static_circles = obstacles.circles[obstacles.circle_class != BeamClass.PERSON]
        person = np.asarray(rec.person_clearance_m, dtype=np.float64)
        clearance = np.minimum(
            clearances(truth[:, :2], run.radius_m, obstacles.segments, static_circles), person
        )
        end_m = float(np.hypot(*(truth[-1, :2] - cfg.route[-1])))
        # the env measures progress along the world's whole route; the driven route may be
        # its leading part (route_fraction)
        share = path_length_m(cfg.route) / max(path_length_m(run.facts.route), 1e-12)
        progress_on_route = min(1.0, drive.progress / max(share, 1e-12))
        if bench is not None:
            if len(rec) > rec.sent:
                bench.feed(rec.chunk())
            bench.end()
        steered = run.lockstep.finish(run.last_of_day) if run.lockstep is not None else None
        return Episode(
            index=run.index,
            stream=rec.stream(run.index, run.prior, run.last_of_day),
            truth=truth,
            collision=np.asarray(rec.collision, dtype=bool),
            events=sorted(events + driver_events, key=lambda e: e[0]),
            terminated=bool(drive.terminated or finished),
            route_progress=drive.progress,
            skipped_waypoints=skipped,
            segments=np.array(obstacles.segments, dtype=np.float64),
            segment_class=np.array(obstacles.segment_class, dtype=np.int8),
            steered=steered,
            clearance_m=clearance,
            person_clearance_m=person,
            goal_reached=goal_reached(
                bool(drive.terminated), progress_on_route, end_m, truth, cfg.route
            ),
            shortest_path_m=run.shortest_m,
            driver_stats=driver_stats,
            driver_artifacts=dict(driver.run_artifacts()),
            people=rec.people_track(),
        )

    def _shortest_path_m(self, start: FloatArray, grid: ClearanceGrid, clearance_m: float) -> float:
        """Length [m] of the shortest collision-free path from the true start through the
        route's waypoints on the run's true obstacles (the SPL reference; NaN when a
        waypoint cannot be reached)."""
        planner = GridDijkstra(clearance_m, clearance_m + PREFERRED_EXTRA_M)
        plan = plan_through_waypoints(
            self.config.route, 0, start[:2], grid, planner, clearance_m, SNAP_WAYPOINT_M
        )
        return (
            math.nan
            if plan.notes and any(k == "skip_waypoint" for k, _ in plan.notes)
            else plan.length_m
        )

    def _person_clearance_m(self, pose: FloatArray, radius_m: float) -> float:
        """True clearance [m] of the robot's disc to the nearest person's legs now: what
        :func:`~dynmap_sim.metrics.clearances` gives for the legs alone (the same operations,
        bit for bit), in a few numpy calls (it runs every step)."""
        obs = self.u.obstacles()
        legs = obs.circles[obs.circle_class == _PERSON]
        if not len(legs):
            return math.inf
        d = np.hypot(pose[0] - legs[:, 0], pose[1] - legs[:, 1]) - legs[:, 2]
        return float(d.min()) - float(radius_m)


def _people(obstacles: Any) -> NDArray[np.bool_]:
    """Per object index of ``obstacles``: a person (people are never remembered as seen)."""
    n = len(obstacles.object_ids)
    out = np.zeros(n, dtype=bool)
    obj = np.asarray(obstacles.circle_object, dtype=np.int64)
    cls = np.asarray(obstacles.circle_class)
    if obj.shape == cls.shape:
        legs = obj[cls == BeamClass.PERSON]
        out[legs[(legs >= 0) & (legs < n)]] = True
    return out


def _positions(now: Any, ids: tuple[str, ...]) -> FloatArray:
    """``(len(ids), 2)`` positions of the people ``ids`` in the snapshot ``now`` (NaN for
    one not in it: the crowd of a run is fixed, so this is a guard)."""
    if now.ids == ids:
        return np.array(now.xy, dtype=np.float64).reshape(-1, 2)
    where = {k: i for i, k in enumerate(now.ids)}
    out = np.full((len(ids), 2), np.nan)
    for j, k in enumerate(ids):
        if k in where:
            out[j] = now.xy[where[k]]
    return out
