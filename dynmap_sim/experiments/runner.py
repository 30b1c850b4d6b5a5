"""The calendar loop: run a scenario's days and runs, localizers side by side (DESIGN.md §6).

For every run of the chosen days: ``env.reset(seed, day, run)``, build the :class:`Prior`, let
the driver drive (it follows the true pose) and record the run's (odometry, scan) stream; then
the *same* stream feeds every localizer: ``begin_run``, ``update`` per scan, ``end_run``, and
``end_day`` after the day's last run (:mod:`.workers`). With ``workers > 1`` the localizers
work in worker processes on run ``i`` while this process simulates run ``i + 1``; the numbers
are the same as with ``workers=1`` (all in this process).

Each run's rows, summaries and a checkpoint (localizers, driver, RNG states, next run) are
committed to the results store in one transaction, so an experiment killed at any moment
resumes (``resume=True``) from its last finished run and ends with exactly the numbers of an
unbroken one: each run's sensor noise derives from (seed, day, run) in the env, and everything
else that carries over between runs is in the checkpoint.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
import pickle
import time
from pathlib import Path
from typing import Any

import numpy as np

from dynmap_sim.agent.localizer import Localizer, make_localizer
from dynmap_sim.errors import InputError
from dynmap_sim.experiments.bench import (
    InProcessLocalizers,
    LocalizerOutput,
    LocalizerPool,
    RunStream,
    pickle_localizer,
)
from dynmap_sim.experiments.drivers import TourDriver, TourParams, clip_route
from dynmap_sim.experiments.results import Checkpoint, ResultsDB, RunRecord
from dynmap_sim.experiments.scenario import Scenario, env_kwargs
from dynmap_sim.metrics import RunSummary, run_summary
from dynmap_sim.types import Prior


def default_out_dir(scenario: Scenario) -> Path:
    """``results/<scenario name>`` under the current directory."""
    return Path("results") / scenario.name


def make_env(scenario: Scenario) -> Any:
    """The env a scenario describes (world file, sensor and robot presets, people)."""
    from dynmap_sim.env import DynMapEnv

    try:
        return DynMapEnv(**env_kwargs(scenario))
    except (TypeError, ValueError, KeyError) as exc:
        where = scenario.source_path or scenario.name
        raise InputError(f"{where}: cannot build the env: {exc}") from None


def experiment_hash(scenario: Scenario, seed: int, days: tuple[int, int]) -> str:
    """Identity of an experiment: scenario content, world file, seed and day range."""
    h = hashlib.sha256(scenario.content_hash().encode())
    h.update(f"|seed={seed}|days={days[0]}-{days[1]}".encode())
    return h.hexdigest()


def localizer_seeds(seed: int, n: int) -> list[np.random.Generator]:
    """One SeedSequence tree per experiment: child 0 is the runner's, 1.. the localizers'."""
    children = np.random.SeedSequence(seed).spawn(n + 1)
    return [np.random.Generator(np.random.PCG64(c)) for c in children]


#: Experiments with at most this much robot time [s] (known from ``driver.max_run_s``) run
#: their localizers in-process: starting worker processes (about 0.7 s) costs more than it
#: saves (ci-apartment-mcl, 2 runs of 20 s: 1.8 s in-process, 2.5 s with 2 workers).
SMALL_EXPERIMENT_S = 120.0


def default_workers(n_localizers: int, robot_time_s: float | None = None) -> int:
    """The automatic worker count: one process per core, at most 2 (the simulation runs in
    the main process besides) and at most one per localizer; in-process (1) for a single
    localizer or at most :data:`SMALL_EXPERIMENT_S` of robot time (``robot_time_s``, None:
    unknown), where worker processes would mostly add their start-up time."""
    if n_localizers < 2 or (robot_time_s is not None and robot_time_s <= SMALL_EXPERIMENT_S):
        return 1
    return max(1, min(2, os.cpu_count() or 1, n_localizers))


@dataclasses.dataclass
class _Kidnap:
    step: int
    pose: np.ndarray | None  # None: random (drawn at the kidnapping from the runner's RNG)


@dataclasses.dataclass
class _SimRun:
    """A simulated run waiting for its localizers' outputs."""

    index: int
    stream: RunStream
    truth: np.ndarray
    collision: np.ndarray
    events: list[tuple[int, float, str, str]]
    terminated: bool
    route_progress: float
    skipped_waypoints: int
    segments: np.ndarray
    segment_class: np.ndarray
    state_after: dict[str, Any]


class ExperimentRunner:
    """Holds an experiment's env, localizers, driver and results store (see module doc)."""

    def __init__(
        self,
        scenario: Scenario,
        out_dir: Path,
        days: tuple[int, int],
        seed: int,
        resume: bool,
        overwrite: bool = False,
        env: Any = None,
        workers: int | None = 1,
    ) -> None:
        if workers is not None and workers < 1:
            raise InputError(f"workers must be at least 1, not {workers}")
        self.scenario = scenario
        self.out_dir = out_dir
        self.seed = int(seed)
        self.days = days
        self.env = env if env is not None else make_env(scenario)
        self.u = self.env.unwrapped
        self.laser = self.u.laser_spec
        self.spec = self.world.spec
        self.slots = [s for s in self.world.calendar.slots if days[0] <= s.day <= days[1]]
        if not self.slots:
            raise InputError(
                f"days {days[0]}-{days[1]}: the world's calendar has days "
                f"1-{self.world.calendar.n_days}"
            )
        if workers is None:
            run_s = scenario.driver.max_run_s
            robot_s = None if run_s is None else len(self.slots) * float(run_s)
            workers = default_workers(len(scenario.localizers), robot_s)
        self.workers = int(workers)
        self.hash = experiment_hash(scenario, self.seed, days)
        self.start_index = 0
        state: dict[str, Any] | None = None
        #: the localizers pickled after the last stored run (None: fresh, in _fresh_locs)
        self._loc_states: list[bytes] | None = None
        self._fresh_locs: list[Localizer] = []
        self._live_locs: list[Localizer] | None = None  # the in-process engine's objects
        db_file = out_dir / "results.db"
        if resume and db_file.exists():
            self.db = ResultsDB.open(out_dir)
            meta = self.db.meta()
            if meta.get("experiment_hash") != self.hash:
                self.db.close()
                if meta.get("seed") != self.seed or meta.get("days") != list(days):
                    why = (
                        f"seed {meta.get('seed')} and days {meta.get('days')}, not seed "
                        f"{self.seed} and days {list(days)}"
                    )
                else:
                    why = "another version of the scenario or its world file (they changed)"
                raise InputError(
                    f"{db_file}: these results were made with {why}; resume with the same "
                    "inputs or start a new experiment with another --out"
                )
            cp = self.db.load_checkpoint(self.hash, self.seed)
            if cp is not None:
                self.start_index = cp.next_index
                state = cp.state
                self._loc_states = list(cp.localizers)
                if len(self._loc_states) != len(scenario.localizers):
                    raise InputError(f"{db_file}: the checkpoint has no localizer states")
        else:
            self.db = ResultsDB.create(out_dir, overwrite=overwrite)
            self._write_meta()
        self.state = state if state is not None else self._fresh_state()

    @property
    def world(self) -> Any:
        """The env's current world: the env builds a new one when ``reset`` gets another
        seed, so a reference kept from before would show another seed's objects."""
        return self.u.world

    # ------------------------------------------------------------------ setup
    def _write_meta(self) -> None:
        sc = self.scenario
        self.db.set_meta(
            scenario=sc.model_dump(mode="json"),
            scenario_path=str(sc.source_path) if sc.source_path else None,
            scenario_name=sc.name,
            world=self.spec.name,
            world_path=str(sc.world_path),
            seed=self.seed,
            days=list(self.days),
            experiment_hash=self.hash,
            laser=dataclasses.asdict(self.laser),
            route=np.asarray(self.spec.robot.route, float).tolist(),
            bounds=list(self.spec.bounds),
            slots=[[s.day, s.run, s.date.isoformat(), s.start_s] for s in self.slots],
            first_date=self.slots[0].date.isoformat(),
            complete=False,
        )
        self.db.set_localizers([(loc.display, loc.name, dict(loc.params)) for loc in sc.localizers])

    def _fresh_state(self) -> dict[str, Any]:
        sc = self.scenario
        rngs = localizer_seeds(self.seed, len(sc.localizers))
        self._fresh_locs = [
            make_localizer(c.name, laser=self.laser, rng=rngs[k + 1], **c.params)
            for k, c in enumerate(sc.localizers)
        ]
        robot_params = getattr(self.u, "robot_params", None)
        robot_radius = float(getattr(robot_params, "radius_m", 0.2))
        d = sc.driver
        params = TourParams(
            speed_mps=d.speed_mps,
            robot_radius_m=robot_radius,
            clearance_m=d.clearance_m,
            wait_for_people=d.wait_for_people,
            dt_s=float(self.laser.scan_period_s),
        )
        route = clip_route(np.asarray(self.spec.robot.route, float), d.route_fraction)
        return {"driver": TourDriver(route, params), "rng": rngs[0]}

    # ------------------------------------------------------------------ running
    def localizers(self) -> list[Localizer]:
        """The localizers as of the last stored run (copies when they ran in workers)."""
        if self._live_locs is not None:
            return self._live_locs
        if self._loc_states is None:
            return self._fresh_locs
        return [pickle.loads(b) for b in self._loc_states]  # noqa: S301 - our own state

    def _start_localizers(self) -> InProcessLocalizers | LocalizerPool:
        labels = self.scenario.labels
        if self.workers == 1:
            locs = (
                self._fresh_locs
                if self._loc_states is None
                else [pickle.loads(b) for b in self._loc_states]  # noqa: S301
            )
            self._live_locs = locs
            return InProcessLocalizers(labels, locs)
        states = self._loc_states
        if states is None:
            states = [
                pickle_localizer(lab, loc)
                for lab, loc in zip(labels, self._fresh_locs, strict=True)
            ]
        self._live_locs = None
        return LocalizerPool(labels, states, self.workers)

    def run(self, progress: bool = True, stop_after: int | None = None) -> Path:
        """Run the remaining slots; return the results folder.

        With ``workers > 1`` the localizers of run ``i`` work in worker processes while this
        process simulates run ``i + 1``. ``stop_after`` (for tests) stops after that many
        slots as if the process were killed: the experiment is left incomplete.
        """
        from tqdm.auto import tqdm

        n = len(self.slots)
        last = n if stop_after is None else min(n, stop_after)
        bar = tqdm(
            total=n,
            initial=self.start_index,
            disable=not progress,
            desc=self.scenario.name,
            unit="run",
        )
        engine = None
        try:
            engine = self._start_localizers()
            pending: _SimRun | None = None
            done_at = time.perf_counter()  # when storing the previous run began
            for i in range(self.start_index, last):
                slot = self.slots[i]
                bar.set_postfix_str(f"day {slot.day} run {slot.run}")
                sim = self._simulate(i)
                # pipelined: collect the previous run, start this one, then store the previous
                outs = engine.result() if pending is not None else None
                engine.submit(sim.stream)
                if pending is not None and outs is not None:
                    done_at = self._write(pending, outs, done_at)
                    bar.update(1)
                pending = sim
                if not engine.pipelined:
                    done_at = self._write(pending, engine.result(), done_at)
                    bar.update(1)
                    pending = None
            if pending is not None:
                self._write(pending, engine.result(), done_at)
                bar.update(1)
        finally:
            if engine is not None:
                engine.close()
            bar.close()
        if last == n:
            self.db.set_meta(complete=True)
        self.db.close()
        self.env.close()
        return self.out_dir

    def _prior(self, i: int) -> Prior:
        sc, slot = self.scenario, self.slots[i]
        known = sc.prior.initial_pose == "known"
        sxy, sth = sc.prior.initial_pose_sigma_xy_m, sc.prior.initial_pose_sigma_theta_rad
        return Prior(
            initial_pose=np.asarray(self.spec.robot.start, float).copy() if known else None,
            initial_pose_cov=np.diag([sxy**2, sxy**2, sth**2]) if known else None,
            walls=np.asarray(self.world.wall_segments(), float).copy()
            if sc.prior.map == "walls"
            else None,
            bounds=tuple(float(b) for b in self.spec.bounds),  # type: ignore[arg-type]
            day=slot.day,
            run=slot.run,
            first_run=i == 0,
        )

    def _kidnaps(self, day: int, run: int, rng: np.random.Generator) -> list[_Kidnap]:
        dt_s = float(self.laser.scan_period_s)
        out = []
        driver: TourDriver = self.state["driver"]
        route_len = float(np.sum(np.hypot(*np.diff(driver.route, axis=0).T)))
        expected_s = route_len / self.scenario.driver.speed_mps
        if self.scenario.driver.max_run_s is not None:
            expected_s = min(expected_s, self.scenario.driver.max_run_s)
        for k in self.scenario.kidnappings:
            if (k.day, k.run) != (day, run):
                continue
            t = rng.uniform(0.2, 0.6) * expected_s if k.time_s == "random" else float(k.time_s)
            pose = None if k.pose == "random" else np.asarray(k.pose, dtype=np.float64)
            out.append(_Kidnap(max(1, int(round(t / dt_s))), pose))
        return sorted(out, key=lambda kp: kp.step)

    def _random_route_pose(self, rng: np.random.Generator) -> np.ndarray:
        route = np.asarray(self.state["driver"].route, float)
        seg = np.hypot(*np.diff(route, axis=0).T)
        s = rng.uniform(0.0, seg.sum())
        k = int(min(np.searchsorted(np.cumsum(seg), s), len(seg) - 1))
        u = (s - (np.cumsum(seg)[k] - seg[k])) / max(seg[k], 1e-12)
        xy = route[k] + u * (route[k + 1] - route[k])
        return np.array([xy[0], xy[1], rng.uniform(-math.pi, math.pi)])

    def _simulate(self, i: int) -> _SimRun:
        """Drive run ``i`` through the env and record its sensor stream (no localizers: the
        driver follows the true pose and kidnappings use the runner's RNG)."""
        slot = self.slots[i]
        sc = self.scenario
        driver: TourDriver = self.state["driver"]
        rng: np.random.Generator = self.state["rng"]
        obs, info = self.env.reset(seed=self.seed, options={"day": slot.day, "run": slot.run})
        geom = self.world.geometry
        prior = self._prior(i)
        start = np.asarray(info["truth"]["pose"], dtype=np.float64)
        driver.begin_run(geom, start)
        kidnaps = self._kidnaps(slot.day, slot.run, rng)
        events: list[tuple[int, float, str, str]] = []
        max_steps = (
            int(round(sc.driver.max_run_s / self.laser.scan_period_s))
            if sc.driver.max_run_s is not None
            else None
        )
        t_l: list[float] = []
        odom_l: list[np.ndarray] = []
        scan_l: list[np.ndarray] = []
        class_l: list[np.ndarray] = []
        truth_l: list[np.ndarray] = []
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
            truth_l.append(pose)
            coll_l.append(collision)
            progress_frac = float(info.get("route_progress", progress_frac))
            if terminated or truncated or driver.done:
                break
            if max_steps is not None and step >= max_steps:
                events.append((step, t_s, "time_limit", f"stopped after {sc.driver.max_run_s} s"))
                break
            if kidnaps and kidnaps[0].step <= step:
                kp = kidnaps.pop(0)
                target = kp.pose if kp.pose is not None else self._random_route_pose(rng)
                free = driver.free_place_near(target[:2], 1.0)
                if free is None:
                    events.append((step, t_s, "kidnap_skipped", "no free place near the target"))
                else:
                    new_pose = np.array([free[0], free[1], target[2]])
                    self.u.teleport(new_pose)
                    driver.notify_teleport(new_pose, t_s)
                    events.append((step, t_s, "kidnap", f"to {np.round(new_pose, 3).tolist()}"))
                    pose = new_pose
            action = driver.act(pose, truth["people"], t_s, bumped=collision)
            obs, _, terminated, truncated, info = self.env.step(action)
            collision = bool(info.get("collision", False))
            step += 1
        events += [
            (step, t_s, "kidnap_not_reached", f"planned at step {kp.step}") for kp in kidnaps
        ]
        driver_events, skipped = list(driver.events), driver.skipped_waypoints
        finished = driver.done
        driver.end_run()
        last_of_day = i + 1 == len(self.slots) or self.slots[i + 1].day != slot.day
        stream = RunStream(
            index=i,
            prior=prior,
            stamps_s=np.asarray(t_l, dtype=np.float64),
            odom=np.asarray(odom_l, dtype=np.float64).reshape(-1, 3),
            scans=np.asarray(scan_l, dtype=np.float32).reshape(len(t_l), -1),
            beam_class=np.asarray(class_l, dtype=np.int8).reshape(len(t_l), -1),
            last_of_day=last_of_day,
        )
        return _SimRun(
            index=i,
            stream=stream,
            truth=np.asarray(truth_l, dtype=np.float64).reshape(-1, 3),
            collision=np.asarray(coll_l, dtype=bool),
            events=sorted(events + driver_events, key=lambda e: e[0]),
            terminated=bool(terminated or finished),
            route_progress=progress_frac,
            skipped_waypoints=skipped,
            segments=np.asarray(geom.segments, dtype=np.float64).copy(),
            segment_class=np.asarray(geom.segment_class, dtype=np.int8).copy(),
            # what the checkpoint after this run holds besides the localizers (copied now:
            # the next run is simulated before this one is written)
            state_after=pickle.loads(pickle.dumps(self.state, pickle.HIGHEST_PROTOCOL)),
        )

    def _write(self, sim: _SimRun, outs: list[LocalizerOutput], since: float) -> float:
        """Store a localized run with the checkpoint after it (one transaction); return when
        that began. The run's ``wall_s`` is the time since the previous run's store began
        (so the runs' wall times add up to the experiment's, also when pipelined)."""
        now = time.perf_counter()
        wall_s = now - since
        i, slot, stream = sim.index, self.slots[sim.index], sim.stream
        rec = RunRecord(
            day=slot.day,
            run=slot.run,
            date=slot.date.isoformat(),
            start_s=float(slot.start_s),
            t_s=stream.stamps_s,
            truth=sim.truth,
            collision=sim.collision,
            estimates=np.stack([o.estimates for o in outs]).reshape(len(outs), -1, 3),
            cov_diag=np.stack([o.cov_diag for o in outs]).reshape(len(outs), -1, 3),
            extras=np.stack([o.extras for o in outs]).reshape(len(outs), -1, 4),
            confusion=np.stack([o.confusion for o in outs]).reshape(len(outs), 4, 4),
            terminated=sim.terminated,
            route_progress=sim.route_progress,
            skipped_waypoints=sim.skipped_waypoints,
            wall_s=wall_s,
            events=sim.events,
            segments=sim.segments,
            segment_class=sim.segment_class,
            update_s=np.array([o.update_s for o in outs], dtype=np.float64),
            timescale_counts=np.stack([o.timescale_counts for o in outs]),
        )
        run_sum = [self._run_summary(k, rec) for k in range(len(outs))]
        self._loc_states = [o.state for o in outs]
        nxt = self.slots[i + 1] if i + 1 < len(self.slots) else None
        cp = Checkpoint(
            next_index=i + 1,
            next_day=nxt.day if nxt else -1,
            next_run=nxt.run if nxt else -1,
            state=sim.state_after,
            localizers=tuple(self._loc_states),
        )
        self.db.write_run(rec, run_sum, stream.last_of_day, cp, self.hash, self.seed)
        return now

    @staticmethod
    def _run_summary(k: int, rec: RunRecord) -> RunSummary:
        """The run summary of localizer ``k`` (:func:`dynmap_sim.metrics.run_summary`)."""
        return run_summary(
            rec.truth,
            rec.estimates[k],
            rec.t_s,
            scan_loglik=rec.extras[k, :, 0],
            lambda_min=rec.extras[k, :, 1],
            update_s=None if rec.update_s is None else float(rec.update_s[k]),
        )


def run_experiment(
    scenario: Scenario,
    out_dir: str | Path | None = None,
    days: tuple[int, int] | None = None,
    seed: int | None = None,
    resume: bool = False,
    progress: bool = True,
    overwrite: bool = False,
    workers: int | None = None,
) -> Path:
    """Run ``scenario`` (optionally only ``days``, with ``seed``) into ``out_dir``; return it.

    ``resume=True`` continues from the last checkpoint in ``out_dir`` (or starts when there is
    none). ``overwrite=True`` replaces earlier results in ``out_dir``. ``workers``: localizer
    worker processes (1: all in this process, sequentially; None: :func:`default_workers`
    for the experiment's localizers and robot time);
    the results are the same whatever the number.
    """
    out = Path(out_dir) if out_dir is not None else default_out_dir(scenario)
    days = tuple(days) if days is not None else scenario.days  # type: ignore[assignment]
    if days[0] < 1 or days[1] < days[0]:
        raise InputError(f"bad day range {days}")
    seed = scenario.seeds[0] if seed is None else int(seed)
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be at least 1, not {workers}")
    runner = ExperimentRunner(
        scenario, out, days, seed, resume=resume, overwrite=overwrite, workers=workers
    )
    return runner.run(progress=progress)
