"""The calendar loop: a scenario's days and runs, localizers side by side (docs/architecture.md §6).

For every run of the chosen days: ``env.reset(seed, day, run)``, build the :class:`Prior`, let
the driver drive (it follows the true pose) and record the run's (odometry, scan) stream; the
*same* stream feeds every localizer, in chunks as it is recorded: ``begin_run``, ``update``
per scan, ``end_run``, and ``end_day`` after the day's last run (:mod:`.localizer_pool`). With
``workers > 1`` the localizers work in worker processes on run ``i`` as this process
simulates it (and may still be on runs ``i - 2`` and ``i - 1``); the numbers are the same as
with ``workers=1`` (all in this process).

Each run's rows, summaries and a checkpoint (localizers, driver, RNG states, next run) are
committed to the results store in one transaction, so an experiment killed at any moment
resumes (``resume=True``) from its last finished run and ends with exactly the numbers of an
unbroken one: each run's sensor noise derives from (seed, day, run) in the env, and everything
else that carries over between runs is in the checkpoint.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import pickle
import sys
import time
from collections import deque
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dynmap_sim.agent.localization.localizer import Localizer, make_localizer
from dynmap_sim.env_factory import SimSpecError
from dynmap_sim.env_factory import make_env as build_env
from dynmap_sim.errors import InputError
from dynmap_sim.experiments.drivers import DriverContext, clip_route, make_driver
from dynmap_sim.experiments.episode import EngineState, Episode, EpisodeLoop, LoopConfig
from dynmap_sim.experiments.localizer_pool import (
    InProcessLocalizers,
    LocalizerOutput,
    LocalizerPool,
    pickle_localizer,
)
from dynmap_sim.experiments.results import Checkpoint, ResultsDB, RunRecord
from dynmap_sim.experiments.results.checkpoints import load_state
from dynmap_sim.experiments.scenario import Scenario
from dynmap_sim.metrics import NavRunSummary, RunSummary, nav_run_summary, run_summary
from dynmap_sim.truth import RunSlot

#: The layout of what the runner checkpoints (format 1: a dict of the tour driver and the RNG,
#: before the episode loop; 2: an :class:`EngineState` with a registered Driver; 3: and the
#: places each object was seen at, the truth of H&W's point classes). Resuming needs the same
#: format; it is stored in the results' ``meta``.
CHECKPOINT_FORMAT = 3


def default_out_dir(scenario: Scenario) -> Path:
    """``results/<scenario name>`` under the current directory."""
    return Path("results") / scenario.name


def make_env(scenario: Scenario) -> Any:
    """The env a scenario describes (world file, sensor and robot presets, people)."""
    try:
        return build_env(scenario.sim_spec())
    except (SimSpecError, TypeError, ValueError, KeyError) as exc:
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
#: their localizers in-process: starting worker processes costs more than it saves
#: (docs/tuning/store.md).
SMALL_EXPERIMENT_S = 120.0


def default_workers(
    n_localizers: int, robot_time_s: float | None = None, n_steered: int = 0
) -> int:
    """The automatic worker count: one process per core, at most 2 (the simulation runs in
    the main process besides) and at most one per localizer; in-process (1) for a single
    localizer or at most :data:`SMALL_EXPERIMENT_S` of robot time (``robot_time_s``, None:
    unknown), where worker processes would mostly add their start-up time.

    When the localizers the workers get (``n_localizers`` less the ``n_steered`` one the
    driver runs in lock-step in the main process) are exactly one more than that count, each
    gets its own worker: sharing would make the pool move localizers between workers after
    the first runs' timings, which waits for every run in flight (the simulation stalls).
    Not beyond one extra: each worker's start-up and its copy of the stream then cost more
    than sharing (docs/tuning/store.md)."""
    if n_localizers < 2 or (robot_time_s is not None and robot_time_s <= SMALL_EXPERIMENT_S):
        return 1
    base = max(1, min(2, os.cpu_count() or 1, n_localizers))
    n_bench = n_localizers - n_steered
    return n_bench if base >= 2 and n_bench == base + 1 else base  # one worker: no moves


#: What the size estimate takes a scan to cost [ms of CPU] on a 2-core machine: the
#: simulation, and each localizer but dead reckoning (docs/tuning/store.md says where the
#: figures come from). Rough: the estimate says what to expect within a factor of two or
#: so, not a timing.
SIM_MS_PER_SCAN = 2.5
LOCALIZER_MS_PER_SCAN = 1.5
#: Localizers whose update costs next to nothing.
CHEAP_LOCALIZERS = ("odometry",)


@dataclasses.dataclass(frozen=True)
class ExperimentSize:
    """How big an experiment is: ``runs``, ``robot_s`` of robot time [s] (each run until its
    route ends at the driver's speed, or ``max_run_s``) and an estimated ``wall_s`` [s]."""

    runs: int
    robot_s: float
    wall_s: float

    def describe(self) -> str:
        return (
            f"{self.runs} run{'s' * (self.runs != 1)}, {_duration(self.robot_s)} of robot "
            f"time, roughly {_duration(self.wall_s)} of wall time"
        )


def experiment_size(
    scenario: Scenario, n_runs: int, route: np.ndarray, scan_period_s: float
) -> ExperimentSize:
    """The size of ``n_runs`` runs of ``scenario`` along ``route`` ``(N, 2)`` [m] (the driven
    part), scanned every ``scan_period_s`` [s]."""
    d = scenario.driver
    run_s = float(np.sum(np.hypot(*np.diff(route, axis=0).T))) / d.speed_mps
    if d.max_run_s is not None:
        run_s = min(run_s, float(d.max_run_s))
    robot_s = n_runs * run_s
    heavy = sum(1 for loc in scenario.localizers if loc.name not in CHEAP_LOCALIZERS)
    ms = SIM_MS_PER_SCAN + LOCALIZER_MS_PER_SCAN * heavy
    return ExperimentSize(n_runs, robot_s, robot_s / scan_period_s * ms / 1e3)


def scenario_size(scenario: Scenario, days: tuple[int, int] | None = None) -> ExperimentSize:
    """:func:`experiment_size` of ``scenario`` (its days, or ``days``), from its env."""
    env = make_env(scenario)
    try:
        u = env.unwrapped
        facts = u.world_facts()
        lo, hi = days if days is not None else scenario.days
        n = sum(1 for s in facts.slots if lo <= s.day <= hi)
        route = clip_route(np.asarray(facts.route, float), scenario.driver.route_fraction)
        return experiment_size(scenario, n, route, float(u.laser_spec.scan_period_s))
    finally:
        env.close()


def _duration(s: float) -> str:
    if s < 120:
        return f"{s:.0f} s"
    if s < 7200:
        return f"{s / 60:.0f} min"
    return f"{s / 3600:.1f} h"


def _slots_of_days(slots: Sequence[RunSlot], days: tuple[int, int]) -> list[RunSlot]:
    """The world's runs (calendar slots) on days ``days`` ``(first, last)``; an InputError
    when there are none."""
    chosen = [s for s in slots if days[0] <= s.day <= days[1]]
    if not chosen:
        raise InputError(
            f"days {days[0]}-{days[1]}: the world's calendar has days 1-{max(s.day for s in slots)}"
        )
    return chosen


def _worker_count(scenario: Scenario, n_runs: int, workers: int | None) -> int:
    """``workers``, or (None) the default for the scenario's localizers over ``n_runs`` runs
    (:func:`default_workers`)."""
    if workers is None:
        run_s = scenario.driver.max_run_s
        robot_s = None if run_s is None else n_runs * float(run_s)
        steered = int(scenario.driver.localizer is not None)
        workers = default_workers(len(scenario.localizers), robot_s, steered)
    return int(workers)


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
        keep_scans: bool = False,
    ) -> None:
        if workers is not None and workers < 1:
            raise InputError(f"workers must be at least 1, not {workers}")
        self.scenario = scenario
        #: store every scan's ranges (``run --keep-scans``; a resumed experiment keeps on
        #: doing what it began with)
        self.keep_scans = bool(keep_scans)
        self.out_dir = out_dir
        self.seed = int(seed)
        self.days = days
        self.env = env if env is not None else make_env(scenario)
        self.u = self.env.unwrapped
        self.laser = self.u.laser_spec
        self.facts = self.u.world_facts()
        self.slots = _slots_of_days(self.facts.slots, days)
        self.route = clip_route(np.asarray(self.facts.route, float), scenario.driver.route_fraction)
        self.loop = self._episode_loop()
        self.workers = _worker_count(scenario, len(self.slots), workers)
        self.hash = experiment_hash(scenario, self.seed, days)
        #: the experiment's size (the runs still to do are from :attr:`start_index` on)
        self.size = experiment_size(
            scenario, len(self.slots), self.route, float(self.laser.scan_period_s)
        )
        self.start_index = 0
        #: the localizers pickled after the last stored run (None: fresh, in _fresh_locs)
        self._loc_states: list[bytes] | None = None
        self._fresh_locs: list[Localizer] = []
        self._live_locs: list[Localizer] | None = None  # the in-process engine's objects
        #: the driver's localizer, run in lock-step by the episode loop: (label, object)
        self._steer: tuple[str, Localizer] | None = None
        steer = scenario.driver.localizer
        self.steer_index = scenario.labels.index(steer) if steer is not None else None
        state = self._open_store(resume, overwrite)
        self.loop.keep_people = self.keep_scans  # the people's tracks go with the ranges
        try:
            self.state = state if state is not None else self._fresh_state()
        except BaseException:
            self.db.close()
            raise

    def _episode_loop(self) -> EpisodeLoop:
        """The loop that drives the robot through the chosen runs (:attr:`slots`)."""
        d = self.scenario.driver
        config = LoopConfig(
            seed=self.seed,
            route=self.route,
            speed_mps=d.speed_mps,
            max_run_s=d.max_run_s,
            prior=self.scenario.prior,
            kidnappings=tuple(self.scenario.kidnappings),
        )
        return EpisodeLoop(self.env, config, self.slots)

    def _open_store(self, resume: bool, overwrite: bool) -> EngineState | None:
        """Open the results store (the folder locked: one writer): with ``resume`` the one
        there, checked and its checkpoint loaded (the engine state it holds; None: none),
        else a new one (``overwrite``: replacing what is there)."""
        db_file = self.out_dir / "results.db"
        if not (resume and db_file.exists()):
            self.db = ResultsDB.create(
                self.out_dir,
                overwrite=overwrite,
                meta=self._meta(),
                localizers=[
                    (loc.display, loc.name, dict(loc.params)) for loc in self.scenario.localizers
                ],
            )
            return None
        self.db = ResultsDB.open(self.out_dir, lock=True)
        try:
            self.keep_scans |= bool(self.db.meta().get("keep_scans", False))
            return self._resume_state(db_file, self.days)
        except BaseException:
            self.db.close()
            raise

    def _resume_state(self, db_file: Path, days: tuple[int, int]) -> EngineState | None:
        """Check the stored results are this experiment's and load their checkpoint (sets
        :attr:`start_index` and the localizer states); the engine state, None when none."""
        scenario = self.scenario
        state = None
        meta = self.db.meta()
        made_with = meta.get("checkpoint_format", 1)
        if made_with != CHECKPOINT_FORMAT:
            raise InputError(
                f"{db_file}: these results were written by another version of dynmap_sim "
                f"(checkpoint format {made_with}, this version writes {CHECKPOINT_FORMAT}"
                f"{'' if made_with != 1 else ': before the episode loop and the Driver role'}"
                "); --resume needs the version that wrote them. Their finished runs still "
                "load in `dynmap-sim report`; to continue, rerun into another --out"
            )
        if meta.get("experiment_hash") != self.hash:
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
            self._check_position(db_file, cp)
            self.start_index = cp.next_index
            state = cp.state
            self._loc_states = list(cp.localizers)
            if len(self._loc_states) != len(scenario.localizers):
                raise InputError(f"{db_file}: the checkpoint has no localizer states")
        return state

    def _check_position(self, db_file: Path, cp: Checkpoint) -> None:
        """The checkpoint's next run must be one of this experiment's, after a stored run
        (an edited or stale checkpoint would rerun or skip runs)."""
        n = len(self.slots)
        nxt = self.slots[cp.next_index] if 0 < cp.next_index < n else None
        want = (nxt.day, nxt.run) if nxt is not None else (-1, -1)
        done = self.db.query("SELECT count(*) FROM runs")[0][0]
        if not (0 < cp.next_index <= n and (cp.next_day, cp.next_run) == want and done >= 1):
            raise InputError(
                f"{db_file}: the checkpoint is corrupt (next run {cp.next_index} = day "
                f"{cp.next_day} run {cp.next_run} is not one of this experiment's {n} runs "
                "after a stored one); it cannot be resumed: start a new experiment with "
                "another --out"
            )

    # ------------------------------------------------------------------ setup
    def _meta(self) -> dict[str, Any]:
        """The experiment's metadata (``meta`` of its results store)."""
        sc = self.scenario
        return dict(
            scenario=sc.model_dump(mode="json"),
            scenario_path=str(sc.source_path) if sc.source_path else None,
            scenario_name=sc.name,
            world=self.facts.name,
            world_path=str(sc.world_path),
            seed=self.seed,
            days=list(self.days),
            experiment_hash=self.hash,
            checkpoint_format=CHECKPOINT_FORMAT,
            laser=dataclasses.asdict(self.laser),
            route=np.asarray(self.facts.route, float).tolist(),
            bounds=list(self.facts.bounds),
            slots=[[s.day, s.run, s.date.isoformat(), s.start_s] for s in self.slots],
            first_date=self.slots[0].date.isoformat(),
            keep_scans=self.keep_scans,
            complete=False,
        )

    def _fresh_state(self) -> EngineState:
        sc = self.scenario
        rngs = localizer_seeds(self.seed, len(sc.localizers))
        self._fresh_locs = [
            make_localizer(c.name, laser=self.laser, rng=rngs[k + 1], **c.params)
            for k, c in enumerate(sc.localizers)
        ]
        context = DriverContext(
            route=self.route,
            speed_mps=sc.driver.speed_mps,
            robot_radius_m=float(self.u.robot_radius_m),
            dt_s=float(self.laser.scan_period_s),
            laser=self.laser,
        )
        try:
            driver = make_driver(sc.driver.kind, context, dict(sc.driver.params))
        except (TypeError, ValueError) as exc:
            raise InputError(f"driver {sc.driver.kind!r}: {exc}") from None
        return EngineState(driver=driver, rng=rngs[0])

    # ------------------------------------------------------------------ running
    def localizers(self) -> list[Localizer]:
        """The localizers as of the last stored run (copies when they ran in workers)."""
        if self._live_locs is not None:
            return self._live_locs
        if self._loc_states is None:
            return self._fresh_locs
        return [load_state(b) for b in self._loc_states]

    def _start_localizers(self) -> InProcessLocalizers | LocalizerPool:
        """The localizer bench for every localizer but the one the driver steers on, which
        stays in this process and runs in lock-step with the simulation (:attr:`_steer`)."""
        labels = self.scenario.labels
        k = self.steer_index
        rest = [j for j in range(len(labels)) if j != k]
        if self.workers == 1:
            locs = (
                self._fresh_locs
                if self._loc_states is None
                else [load_state(b) for b in self._loc_states]
            )
            self._live_locs = locs
            self._steer = None if k is None else (labels[k], locs[k])
            return InProcessLocalizers([labels[j] for j in rest], [locs[j] for j in rest])
        states = self._loc_states
        if states is None:
            states = [
                pickle_localizer(lab, loc)
                for lab, loc in zip(labels, self._fresh_locs, strict=True)
            ]
        self._live_locs = None
        self._steer = None if k is None else (labels[k], load_state(states[k]))
        return LocalizerPool([labels[j] for j in rest], [states[j] for j in rest], self.workers)

    def _with_steered(self, episode: Episode, outs: list[LocalizerOutput]) -> list[LocalizerOutput]:
        """All localizers' outputs in scenario order: the bench's and the lock-stepped one's."""
        if self.steer_index is None:
            return outs
        assert episode.steered is not None
        return [*outs[: self.steer_index], episode.steered, *outs[self.steer_index :]]

    def run(self, progress: bool = True, stop_after: int | None = None) -> Path:
        """Run the remaining slots; return the results folder.

        With ``workers > 1`` the localizers work in worker processes on each run as this
        process simulates it (and on the two before, if not done). ``stop_after`` (for tests)
        stops after that many slots as if the process were killed: the experiment is left
        incomplete.
        """
        from tqdm.auto import tqdm

        class Bar(tqdm):  # type: ignore[misc, valid-type]
            """The progress bar without tqdm's monitor thread (it would outlive the bar): a
            bar updated once a run does not need it, and the report forks after the run
            (:func:`dynmap_sim.analysis.report.write_report`) where no other thread runs."""

            monitor_interval = 0

        n = len(self.slots)
        last = n if stop_after is None else min(n, stop_after)
        if progress:  # the size first: a calendar of many runs can take hours
            todo = f" ({n - self.start_index} to do)" if self.start_index else ""
            print(f"{self.scenario.name}: {self.size.describe()}{todo}", file=sys.stderr)
        bar = Bar(
            total=n,
            initial=self.start_index,
            disable=not progress,
            desc=self.scenario.name,
            unit="run",
        )
        engine = None
        try:
            engine = self._start_localizers()
            pending: deque[tuple[Episode, EngineState]] = deque()  # submitted, not stored
            done_at = time.perf_counter()  # when storing the previous run began
            for i in range(self.start_index, last):
                slot = self.slots[i]
                bar.set_postfix_str(f"day {slot.day} run {slot.run}")
                sim = self._simulate(i, engine)  # the bench takes the scans as they come
                pending.append(sim)
                # store the oldest run when as many are in flight as the bench holds (the
                # workers may still be on the ones before this)
                if len(pending) >= engine.depth:
                    done_at = self._store(pending.popleft(), engine.result(), done_at)
                    bar.update(1)
            while pending:
                done_at = self._store(pending.popleft(), engine.result(), done_at)
                bar.update(1)
        except BaseException:
            self.db.close()  # releases the folder's lock (the stored runs stay)
            raise
        finally:
            if engine is not None:
                engine.close()
            bar.close()
        if last == n:
            self.db.set_meta(complete=True)
        self.db.close()
        self.env.close()
        return self.out_dir

    def _store(
        self, sim: tuple[Episode, EngineState], outs: list[LocalizerOutput], since: float
    ) -> float:
        """:meth:`_write` a simulated run with its bench outputs (and the steered one's)."""
        return self._write(*sim, self._with_steered(sim[0], outs), since)

    def _simulate(
        self, i: int, bench: InProcessLocalizers | LocalizerPool | None = None
    ) -> tuple[Episode, EngineState]:
        """Drive run ``i`` through the episode loop (``bench``: the localizers it streams the
        scans to as they are recorded); the state to checkpoint after it (copied now: the
        next run is simulated before this one is written)."""
        episode = self.loop.run(i, self.state, self._steer, bench)
        return episode, pickle.loads(pickle.dumps(self.state, pickle.HIGHEST_PROTOCOL))

    def _write(
        self, sim: Episode, state_after: EngineState, outs: list[LocalizerOutput], since: float
    ) -> float:
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
            confusion=np.stack([o.confusion for o in outs]).reshape(len(outs), 4, 4),
            terminated=sim.terminated,
            route_progress=sim.route_progress,
            skipped_waypoints=sim.skipped_waypoints,
            wall_s=wall_s,
            events=sim.events,
            segments=sim.segments,
            segment_class=sim.segment_class,
            update_s=np.array([o.update_s for o in outs], dtype=np.float64),
            diagnostics=[o.diagnostics for o in outs],
            point_tallies=[o.point_tally for o in outs],
            nav=self._nav_summary(sim),
            driver_artifacts=dict(sim.driver_artifacts or {}),
            ranges=stream.scans if self.keep_scans else None,
            people=sim.people if self.keep_scans else None,
        )
        run_sum = [self._run_summary(k, rec) for k in range(len(outs))]
        self._loc_states = [o.state for o in outs]
        nxt = self.slots[i + 1] if i + 1 < len(self.slots) else None
        cp = Checkpoint(
            next_index=i + 1,
            next_day=nxt.day if nxt else -1,
            next_run=nxt.run if nxt else -1,
            state=state_after,
            localizers=tuple(self._loc_states),
        )
        self.db.write_run(rec, run_sum, stream.last_of_day, cp, self.hash, self.seed)
        return now

    @staticmethod
    def _nav_summary(sim: Episode) -> NavRunSummary | None:
        """The run's navigation measures (:func:`dynmap_sim.metrics.nav_run_summary`)."""
        if sim.clearance_m is None or sim.person_clearance_m is None:
            return None
        return nav_run_summary(
            sim.truth,
            sim.stream.stamps_s,
            sim.collision,
            sim.clearance_m,
            sim.person_clearance_m,
            sim.goal_reached,
            sim.shortest_path_m,
            sim.driver_stats,
        )

    @staticmethod
    def _run_summary(k: int, rec: RunRecord) -> RunSummary:
        """The run summary of localizer ``k`` (:func:`dynmap_sim.metrics.run_summary`)."""
        return run_summary(
            rec.truth,
            rec.estimates[k],
            rec.t_s,
            scan_loglik=rec.scan_diagnostic(k, "scan_loglik"),
            lambda_min=rec.scan_diagnostic(k, "lambda_min"),
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
    keep_scans: bool = False,
) -> Path:
    """Run ``scenario`` (optionally only ``days``, with ``seed``) into ``out_dir``; return it.

    ``resume=True`` continues from the last checkpoint in ``out_dir`` (or starts when there is
    none). ``overwrite=True`` replaces earlier results in ``out_dir``. ``workers``: localizer
    worker processes (1: all in this process, sequentially; None: :func:`default_workers`
    for the experiment's localizers and robot time);
    the results are the same whatever the number. ``keep_scans``: store every scan's ranges
    too (for ``export --mcap``'s ``/scan`` and the video; ≈ 2.3 kB a scan of 683 beams).
    """
    out = Path(out_dir) if out_dir is not None else default_out_dir(scenario)
    days = tuple(days) if days is not None else scenario.days  # type: ignore[assignment]
    if days[0] < 1 or days[1] < days[0]:
        raise InputError(f"bad day range {days}")
    seed = scenario.seeds[0] if seed is None else int(seed)
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be at least 1, not {workers}")
    runner = ExperimentRunner(
        scenario,
        out,
        days,
        seed,
        resume=resume,
        overwrite=overwrite,
        workers=workers,
        keep_scans=keep_scans,
    )
    return runner.run(progress=progress)
