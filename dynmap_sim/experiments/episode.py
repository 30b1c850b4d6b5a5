"""The episode loop: one run of the calendar through the env, steered by a driver.

``env.reset(seed, day, run)``, the run's :class:`~dynmap_sim.types.Prior`, then every control
step: record the sensors (odometry, scan) and the truth (``info["truth"]``), carry out a
kidnapping when one is due, ask the driver for the action, ``env.step``. The result is an
:class:`Episode`: the run's sensor stream (:class:`~dynmap_sim.experiments.bench.RunStream`,
what the localizers consume) and its truth (what the metrics compare them with).

Truth reaches the loop only through ``info["truth"]`` and the env's documented read-only
views (:mod:`dynmap_sim.truth`: ``world_facts()``, ``obstacles()``); the loop acts on the
world only through ``env.step`` and ``env.teleport`` (a kidnapping). The driver sees the truth
only when it declares ``sees_truth``.

A driver that steers on a localizer's estimate gets it in lock-step: the loop feeds that
localizer each scan as it is recorded (:class:`~dynmap_sim.experiments.bench.LocalizerRun`,
the same calls the localizer bench makes on a recorded stream) and hands the estimate to the
driver before it acts.

What carries over between runs besides the localizers — the driver, the engine's random
generator (kidnapping times and places) and where the robot has seen each object (the
seen-before point-class truth, :class:`~dynmap_sim.metrics.SeenPlaces`) — is the
:class:`EngineState`, which the runner checkpoints after every run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.localizer import Localizer
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid
from dynmap_sim.agent.planning.grid_dijkstra import GridDijkstra
from dynmap_sim.experiments.bench import (
    CHUNK_SCANS,
    LocalizerOutput,
    LocalizerRun,
    RunHeader,
    RunStream,
    ScanChunk,
)
from dynmap_sim.experiments.drivers import Driver, RunStart, StepInput
from dynmap_sim.experiments.drivers.tour import plan_through_waypoints, static_clearance_grid
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
    bench: :class:`~dynmap_sim.experiments.bench.LocalizerPool`,
    :class:`~dynmap_sim.experiments.bench.InProcessLocalizers`)."""

    def begin(self, header: RunHeader, capacity: int = 1024) -> None: ...

    def feed(self, chunk: ScanChunk) -> None: ...

    def end(self) -> None: ...


def _chunk(
    t_l: list[float],
    odom_l: list[FloatArray],
    scan_l: list[NDArray[np.float32]],
    class_l: list[NDArray[np.int8]],
    point_l: list[NDArray[np.int8]],
    start: int,
) -> ScanChunk:
    """The recorded scans from ``start`` on, as the stream's arrays hold them."""
    n = len(t_l) - start
    return ScanChunk(
        np.asarray(t_l[start:], dtype=np.float64),
        np.asarray(odom_l[start:], dtype=np.float64).reshape(n, 3),
        np.asarray(scan_l[start:], dtype=np.float32).reshape(n, -1),
        np.asarray(class_l[start:], dtype=np.int8).reshape(n, -1),
        np.asarray(point_l[start:], dtype=np.int8).reshape(n, -1),
    )


@dataclass
class EngineState:
    """A driver that steers on a localizer's estimate gets it in lock-step: the loop feeds that
    localizer each scan as it is recorded (:class:`~dynmap_sim.experiments.bench.LocalizerRun`,
    the same calls the localizer bench makes on a recorded stream) and hands the estimate to the
    driver before it acts.

    What carries over between runs besides the localizers (checkpointed after each run):
        the ``driver``, the engine's ``rng`` (kidnapping times and places) and ``seen``, the
        places at which the robot has seen each object in the runs so far (the truth of
        H&W's point classes: an object not seen at its place before is semi-static)."""

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
        :data:`~dynmap_sim.experiments.bench.CHUNK_SCANS` scans as it is recorded."""
        slot = self.slots[i]
        cfg = self.config
        driver, rng = state.driver, state.rng
        obs, info = self.env.reset(seed=cfg.seed, options={"day": slot.day, "run": slot.run})
        facts = self.u.world_facts()  # after reset: another seed builds another world
        obstacles = self.u.obstacles()
        prior = self.prior(i, facts)
        start = np.asarray(info["truth"]["pose"], dtype=np.float64)
        sees = driver.sees_truth
        driver.begin_run(RunStart(prior, start if sees else None, obstacles if sees else None))
        kidnaps = self._kidnaps(slot, rng)
        static_grid = static_clearance_grid(obstacles, GRID_RESOLUTION_M)
        # the seen-before truth of H&W's point classes: each object's place now, and whether
        # the robot saw it there in an earlier run
        n_obj = len(obstacles.object_ids)
        places = object_places(
            n_obj,
            obstacles.segments,
            obstacles.segment_object,
            obstacles.circles,
            obstacles.circle_object,
        )
        seen_mask = state.seen.seen_before(obstacles.object_ids, places)
        hit_objects = np.zeros(n_obj, dtype=bool)
        radius_m = float(self.u.robot_radius_m)
        free_clearance_m = radius_m + FREE_MARGIN_M
        shortest_m = self._shortest_path_m(start, static_grid, free_clearance_m)
        person_l: list[float] = []
        people_of = getattr(self.u, "people", None) if self.keep_people else None
        crowd = people_of() if people_of is not None else None
        people_l: list[FloatArray] = []
        events: list[tuple[int, float, str, str]] = []
        max_steps = int(round(cfg.max_run_s / self.dt_s)) if cfg.max_run_s is not None else None
        lockstep = None
        limit = max_steps if max_steps is not None else getattr(self.u, "max_episode_steps", 0)
        if steer is not None:
            lockstep = LocalizerRun(steer[0], steer[1], prior, capacity=int(limit) + 1)
        last_of_day = i + 1 == len(self.slots) or self.slots[i + 1].day != slot.day
        if bench is not None:
            bench.begin(RunHeader(i, prior, last_of_day), int(limit) + 1)
        sent = 0  # scans handed to the bench
        estimate = None
        t_l: list[float] = []
        odom_l: list[FloatArray] = []
        scan_l: list[NDArray[np.float32]] = []
        class_l: list[NDArray[np.int8]] = []
        point_l: list[NDArray[np.int8]] = []
        truth_l: list[FloatArray] = []
        coll_l: list[bool] = []
        terminated = truncated = False
        collision = False
        step = 0
        progress_frac = 0.0
        while True:
            truth = info["truth"]
            pose = np.array(truth["pose"], dtype=np.float64)  # copies: the history must not
            t_s = float(truth["time"][2])  # change if a producer reuses its arrays
            t_l.append(t_s)
            odom_l.append(np.array(obs["odom"], dtype=np.float64))
            scan_l.append(np.array(obs["scan"], dtype=np.float32))
            class_l.append(np.array(truth["beam_class"], dtype=np.int8))
            beam_object = np.asarray(truth.get("beam_object", ()), dtype=np.int64)
            if beam_object.shape != class_l[-1].shape:
                beam_object = np.full(class_l[-1].shape, -1, dtype=np.int64)
            point_l.append(seen_before_point_classes(class_l[-1], beam_object, seen_mask))
            hit = beam_object[(beam_object >= 0) & (beam_object < n_obj)]
            hit_objects[hit] = True
            truth_l.append(pose)
            coll_l.append(collision)
            person_l.append(self._person_clearance_m(pose, radius_m))
            if crowd is not None:
                people_l.append(_positions(people_of(), crowd.ids))
            if lockstep is not None:
                estimate = lockstep.update(t_s, odom_l[-1], scan_l[-1], class_l[-1], point_l[-1])
            progress_frac = float(info.get("route_progress", progress_frac))
            if bench is not None and len(t_l) - sent >= CHUNK_SCANS:
                bench.feed(_chunk(t_l, odom_l, scan_l, class_l, point_l, sent))
                sent = len(t_l)
            if terminated or truncated or driver.done:
                break
            if max_steps is not None and step >= max_steps:
                events.append((step, t_s, "time_limit", f"stopped after {cfg.max_run_s} s"))
                break
            if kidnaps and kidnaps[0].step <= step:
                kp = kidnaps.pop(0)
                target = kp.pose if kp.pose is not None else self._random_route_pose(rng)
                free = static_grid.nearest_free(target[:2], free_clearance_m, KIDNAP_SEARCH_M)
                if free is None:
                    events.append((step, t_s, "kidnap_skipped", "no free place near the target"))
                else:
                    new_pose = np.array([free[0], free[1], target[2]])
                    self.u.teleport(new_pose)
                    if sees:
                        driver.teleported(new_pose, t_s)
                    events.append((step, t_s, "kidnap", f"to {np.round(new_pose, 3).tolist()}"))
                    pose = new_pose
            action = driver.act(
                StepInput(
                    t_s=t_s,
                    odom=Odometry(pose=odom_l[-1].copy(), stamp_s=t_s),
                    scan=Scan(ranges_m=scan_l[-1].copy(), stamp_s=t_s),
                    bumped=collision,
                    estimate=estimate,
                    pose=pose if sees else None,
                    people=truth["people"] if sees else None,
                )
            )
            obs, _, terminated, truncated, info = self.env.step(action)
            collision = bool(info.get("collision", False))
            step += 1
        events += [
            (step, t_s, "kidnap_not_reached", f"planned at step {kp.step}") for kp in kidnaps
        ]
        driver_events, skipped = list(driver.events), driver.skipped_waypoints
        finished = driver.done
        driver_stats = dict(driver.stats())
        driver.end_run()
        state.seen.remember(obstacles.object_ids, places, hit_objects & ~_people(obstacles))
        truth_arr = np.asarray(truth_l, dtype=np.float64).reshape(-1, 3)
        static_circles = obstacles.circles[obstacles.circle_class != BeamClass.PERSON]
        clearance = np.minimum(
            clearances(truth_arr[:, :2], radius_m, obstacles.segments, static_circles),
            np.asarray(person_l),
        )
        end_m = float(np.hypot(*(truth_arr[-1, :2] - cfg.route[-1])))
        # the env measures progress along the world's whole route; the driven route may be
        # its leading part (route_fraction)
        share = path_length_m(cfg.route) / max(path_length_m(facts.route), 1e-12)
        progress_on_route = min(1.0, progress_frac / max(share, 1e-12))
        if bench is not None:
            if len(t_l) > sent:
                bench.feed(_chunk(t_l, odom_l, scan_l, class_l, point_l, sent))
            bench.end()
        steered = lockstep.finish(last_of_day) if lockstep is not None else None
        stream = RunStream(
            index=i,
            prior=prior,
            stamps_s=np.asarray(t_l, dtype=np.float64),
            odom=np.asarray(odom_l, dtype=np.float64).reshape(-1, 3),
            scans=np.asarray(scan_l, dtype=np.float32).reshape(len(t_l), -1),
            beam_class=np.asarray(class_l, dtype=np.int8).reshape(len(t_l), -1),
            last_of_day=last_of_day,
            point_truth=np.asarray(point_l, dtype=np.int8).reshape(len(t_l), -1),
        )
        return Episode(
            index=i,
            stream=stream,
            truth=truth_arr,
            collision=np.asarray(coll_l, dtype=bool),
            events=sorted(events + driver_events, key=lambda e: e[0]),
            terminated=bool(terminated or finished),
            route_progress=progress_frac,
            skipped_waypoints=skipped,
            segments=np.array(obstacles.segments, dtype=np.float64),
            segment_class=np.array(obstacles.segment_class, dtype=np.int8),
            steered=steered,
            clearance_m=clearance,
            person_clearance_m=np.asarray(person_l, dtype=np.float64),
            goal_reached=goal_reached(
                bool(terminated), progress_on_route, end_m, truth_arr, cfg.route
            ),
            shortest_path_m=shortest_m,
            driver_stats=driver_stats,
            driver_artifacts=dict(driver.run_artifacts()),
            people=(
                PeopleTrack(
                    crowd.ids,
                    np.array(crowd.radius, dtype=np.float64),
                    np.asarray(people_l, dtype=np.float64).reshape(len(t_l), len(crowd.ids), 2),
                )
                if crowd is not None
                else None
            ),
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
