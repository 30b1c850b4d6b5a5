"""Localizers in worker processes, pipelined with the simulation (docs/architecture.md §6).

A run's sensor stream does not depend on the localizers: the tour driver follows the *true*
pose and kidnappings come from the runner's RNG. So the runner records a run's stream
(:class:`RunStream`: odometry, scans, time stamps and the true beam classes) and hands it to
the localizers as it is recorded, in chunks of scans (:meth:`~LocalizerPool.begin`,
:meth:`~LocalizerPool.feed`, :meth:`~LocalizerPool.end`; or a whole recorded run at once,
:meth:`~LocalizerPool.submit`), either in-process (:class:`InProcessLocalizers`,
``workers=1``) or spread over persistent worker processes (:class:`LocalizerPool`), which
localize a run while the main process is still simulating it and the next ones. Both run
every localizer through :class:`LocalizerRun`, which makes the calls the sequential runner
always made (``begin_run(prior)``, ``update(odom, scan)`` per scan in order, ``end_run()``,
``end_day()`` after the day's last run) on copies of the same arrays, so the numbers are
bit-identical whichever way (and in whatever chunks) they were computed.

After each run every localizer is pickled (:attr:`LocalizerOutput.state`): that is the
checkpoint's copy, and the pool moves a localizer to another worker by sending it that
state (it balances the workers by the busy time each localizer took in the last run).
Up to :attr:`LocalizerPool.depth` runs are in flight at once: a worker takes the chunks as
they arrive (a reader thread) and works on them in order as soon as it is done with the ones
before, so the simulation and the localizers never wait for each other within a run, and the
workers neither idle while the first run is simulated nor have whole runs left when the last
one is. Nor does the pool wait for its workers to start (their imports take seconds of CPU:
the H&W replica's three took 4.4 s): the first run is simulated meanwhile, and a worker that
cannot take its localizers is reported at the first result.
Worker processes use the ``spawn`` start method, ignore SIGINT (the main process stops them),
exit when the main process goes away, and report a failing localizer by its label; a dead
worker is noticed through its process sentinel, so the main process never hangs on it.
"""

from __future__ import annotations

import math
import multiprocessing as mp
import os
import pickle
import queue
import signal
import threading
import time
import traceback
from collections import deque
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, wait
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.localization.localizer import Localizer
from dynmap_sim.errors import InputError
from dynmap_sim.experiments.results import LocalizerDiagnostics
from dynmap_sim.experiments.results.checkpoints import load_state
from dynmap_sim.metrics import PointClassTally, confusion_matrix
from dynmap_sim.types import Diagnostic, Odometry, PoseEstimate, Prior, Scan

#: A rebalanced assignment must shorten the slowest worker's busy time by this fraction.
REBALANCE_GAIN = 0.15

#: A worker of a pool with one localizer per worker whose last run took less than this
#: share of the busiest worker's busy time gets :data:`LIGHT_WORKER_NICE` (once; see
#: :meth:`LocalizerPool._yield_light_workers`).
LIGHT_WORKER_SHARE = 0.5
#: The niceness given to such a light worker (Unix ``nice``: 0 normal, 19 lowest).
LIGHT_WORKER_NICE = 10

#: Native thread pools in a worker: one thread each, unless the environment says otherwise.
#: The worker processes are the parallelism; OpenBLAS's own threads in every worker would
#: oversubscribe the cores (the lab localizers ran slower that way: docs/tuning/store.md).
WORKER_THREAD_ENV = {
    "OPENBLAS_NUM_THREADS": "1",
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}


class LocalizerError(RuntimeError):
    """A localizer raised (in-process or in a worker); the message names it and the run."""


@dataclass
class RunStream:
    """One run's sensor stream as the localizers consume it (``T`` scans).

    ``stamps_s`` ``(T,)`` seconds since midnight; ``odom`` ``(T, 3)`` odometry poses;
    ``scans`` ``(T, n_beams)`` float32 ranges [m] (REP-117 encoded); ``beam_class``
    ``(T, n_beams)`` int8 true beam classes (only for scoring ``point_classes``, never shown
    to a localizer); ``last_of_day``: ``end_day()`` follows ``end_run()``; ``point_truth``
    ``(T, n_beams)`` int8 true point classes seen-before (H&W §4.4,
    :func:`dynmap_sim.metrics.seen_before_point_classes`; None: not known), also only for
    scoring.
    """

    index: int
    prior: Prior
    stamps_s: NDArray[np.float64]
    odom: NDArray[np.float64]
    scans: NDArray[np.float32]
    beam_class: NDArray[np.int8]
    last_of_day: bool
    point_truth: NDArray[np.int8] | None = None

    def chunks(self, size: int) -> Iterator[ScanChunk]:
        """The stream's scans in chunks of at most ``size`` (views)."""
        n = len(self.stamps_s)
        for a in range(0, n, max(1, int(size))):
            b = min(n, a + size)
            truth = None if self.point_truth is None else self.point_truth[a:b]
            yield ScanChunk(self.stamps_s[a:b], self.odom[a:b], self.scans[a:b],
                            self.beam_class[a:b], truth)  # fmt: skip


@dataclass
class ScanChunk:
    """Consecutive scans of a run's stream (the fields of :class:`RunStream`, ``K`` rows)."""

    stamps_s: NDArray[np.float64]
    odom: NDArray[np.float64]
    scans: NDArray[np.float32]
    beam_class: NDArray[np.int8]
    point_truth: NDArray[np.int8] | None = None


@dataclass(frozen=True)
class RunHeader:
    """What the localizers need before a run's first scan: its index in the experiment, its
    prior and whether ``end_day()`` follows its ``end_run()``."""

    index: int
    prior: Prior
    last_of_day: bool


#: Scans whose reported point classes a :class:`LocalizerRun` scores at once.
SCORE_BATCH = 256

#: Scans a chunk of a run's stream holds on its way to the localizers (10 s of robot time at
#: the URG-04LX's 10 Hz): small enough that the workers follow the simulation closely,
#: large enough that a message costs little beside the localizers' work on it.
CHUNK_SCANS = 100


@dataclass
class LocalizerOutput:
    """What one localizer produced for one run.

    ``estimates`` ``(T, 3)``; ``cov_diag`` ``(T, 3)``; ``confusion`` ``(4, 4)`` point-class
    counts; ``update_s`` CPU time of ``update()`` [s] (its thread's, :func:`time.thread_time`:
    not the time it waited for a core it shares with other processes); ``busy_s`` wall time
    of the whole run including the hooks and pickling [s]; ``state`` the pickled localizer
    after ``end_run`` (and ``end_day``); ``diagnostics`` what it declared and reported
    (:class:`DiagnosticsRecorder`); ``point_tally`` its reported point classes against the
    seen-before truth and their shares of the valid readings
    (:class:`~dynmap_sim.metrics.PointClassTally`).
    """

    estimates: NDArray[np.float64]
    cov_diag: NDArray[np.float64]
    confusion: NDArray[np.int64]
    update_s: float
    busy_s: float
    state: bytes
    diagnostics: LocalizerDiagnostics = field(default_factory=LocalizerDiagnostics)
    point_tally: PointClassTally = field(default_factory=PointClassTally)


def declared_diagnostics(loc: Localizer) -> tuple[Diagnostic, ...]:
    """``loc.diagnostics``, checked: :class:`Diagnostic` each, no name twice."""
    declared = tuple(getattr(loc, "diagnostics", ()) or ())
    names = [d.name for d in declared if isinstance(d, Diagnostic)]
    if len(names) != len(declared) or len(set(names)) != len(names):
        raise InputError(
            f"{type(loc).__module__}.{type(loc).__qualname__}.diagnostics: Diagnostic "
            f"declarations with distinct names, not {declared!r}"
        )
    return declared


class DiagnosticsRecorder:
    """Collects one localizer's declared diagnostics over one run of ``n`` scans.

    Per-scan ones from each scan's ``PoseEstimate.extras`` (:meth:`scan`); per-run ones
    counted from them (``counts_of``) or asked for after ``end_run`` (:meth:`end_run`);
    day artifacts after ``end_day`` (:meth:`end_day`). The result is :attr:`out`.
    """

    def __init__(self, loc: Localizer, n: int) -> None:
        declared = declared_diagnostics(loc)
        self._scan = [d for d in declared if d.per == "scan"]
        self._counted = [d for d in declared if d.per == "run" and d.counts_of]
        self.out = LocalizerDiagnostics(
            declared,
            {d.name: np.full((n, *d.shape), math.nan) for d in self._scan},
            {d.name: np.zeros(d.shape, dtype=d.dtype) for d in self._counted},
        )

    def resize(self, n: int) -> None:
        """Make room for ``n`` scans (new rows NaN; rows beyond ``n`` dropped)."""
        for d in self._scan:
            old = self.out.per_scan[d.name]
            new = np.full((n, *d.shape), math.nan)
            k = min(n, len(old))
            new[:k] = old[:k]
            self.out.per_scan[d.name] = new

    def scan(self, step: int, extras: dict[str, Any]) -> None:
        """Record the declared values among a scan's ``extras``."""
        for d in self._scan:
            v = extras.get(d.name)
            if v is not None:
                self.out.per_scan[d.name][step] = v
        for d in self._counted:
            n_bins = d.shape[0]
            sel = [int(v) for v in np.ravel(extras.get(d.counts_of, ())) if 0 <= int(v) < n_bins]
            if sel:
                self.out.per_run[d.name] += np.bincount(sel, minlength=n_bins)

    def end_run(self, loc: Localizer) -> None:
        """Ask for the per-run values after ``end_run`` (declared ones only)."""
        declared = {d.name: d for d in self.out.declared if d.per == "run" and not d.counts_of}
        for name, value in loc.run_diagnostics().items():
            d = declared.get(name)
            if d is None:
                raise ValueError(f"run_diagnostics(): {name!r} is not a declared per-run value")
            self.out.per_run[name] = np.asarray(value, dtype=d.dtype).reshape(d.shape)

    def end_day(self, loc: Localizer) -> None:
        """Take the day's artifacts after ``end_day``."""
        self.out.artifacts = dict(loc.day_artifacts())


def _day_run(stream: RunStream | RunHeader) -> str:
    return f"day {stream.prior.day} run {stream.prior.run}"


def unpicklable_error(label: str, loc: Localizer, err: Exception) -> InputError:
    """The error for a localizer that cannot be pickled for the checkpoint."""
    return InputError(
        f"localizer {label!r} ({type(loc).__module__}.{type(loc).__qualname__}) "
        f"cannot be pickled for the checkpoint after each run: {err}. Localizers "
        "must be picklable (no lambdas, open files or threads in their state)."
    )


def pickle_localizer(label: str, loc: Localizer) -> bytes:
    """``loc`` pickled (highest protocol); :class:`InputError` naming it when it cannot be."""
    try:
        return pickle.dumps(loc, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception as err:  # noqa: BLE001 - any failure is the answer
        raise unpicklable_error(label, loc, err) from err


class LocalizerContractError(InputError):
    """A localizer broke the :class:`~dynmap_sim.agent.localization.localizer.Localizer`
    contract: the message names it, the rule and the run and scan (one line, no traceback:
    the fault is in what it returned, not in the testbed's frames)."""


class LocalizerRun:
    """One localizer through one run, scan by scan: ``begin_run(prior)`` when made,
    :meth:`update` per scan, :meth:`finish` at the end (``end_run``, ``end_day`` after the
    day's last run, then the localizer is pickled).

    :func:`localize_run` is this over a recorded stream; a driver that steers on a localizer's
    estimate runs it in lock-step with the simulation, and the output is the same either way.
    ``capacity`` is a first guess of the run's scans (the arrays grow as needed). A failing
    localizer raises :class:`LocalizerError` naming it, the run and the scan.
    """

    def __init__(self, label: str, loc: Localizer, prior: Prior, capacity: int = 1024) -> None:
        busy0 = time.perf_counter()
        #: wall time spent in this run's calls so far (not waiting for scans) [s]
        self.busy_s = 0.0
        self.label = label
        self.loc = loc
        self.prior = prior
        cap = max(1, int(capacity))
        self.est = np.empty((cap, 3))
        self.cov_diag = np.empty((cap, 3))
        self.diagnostics = DiagnosticsRecorder(loc, cap)
        self.confusion = np.zeros((4, 4), dtype=np.int64)
        self.point_tally = PointClassTally()
        #: reported point classes not scored yet: (beam classes, classes, ranges, truth)
        self._unscored: list[tuple[Any, NDArray[np.int64], Any, Any]] = []
        self.update_s = 0.0
        self.n = 0
        with self._blame(None):
            loc.begin_run(prior)
        self.busy_s += time.perf_counter() - busy0

    @contextmanager
    def _blame(self, step: int | None) -> Iterator[None]:
        try:
            yield
        except Exception as exc:
            where = f"at scan {step}" if step is not None else "in a run/day hook"
            raise LocalizerError(
                f"localizer {self.label!r} failed on day {self.prior.day} run {self.prior.run} "
                f"{where}: {type(exc).__name__}: {exc}"
            ) from exc

    def update(
        self,
        t_s: float,
        odom_pose: NDArray[np.float64],
        ranges_m: NDArray[np.float32],
        beam_class: NDArray[np.int8],
        point_truth: NDArray[np.int8] | None = None,
    ) -> PoseEstimate:
        """Feed one scan (fresh copies of the odometry pose and ranges go to the localizer);
        ``beam_class`` and ``point_truth`` (the truth: beam labels, seen-before point
        classes) only score reported point classes."""
        step = self.n
        if step == len(self.est):
            grown = 2 * len(self.est)
            self.est = np.concatenate([self.est, np.empty_like(self.est)])
            self.cov_diag = np.concatenate([self.cov_diag, np.empty_like(self.cov_diag)])
            self.diagnostics.resize(grown)
        odom = Odometry(pose=np.array(odom_pose, dtype=np.float64), stamp_s=t_s)
        scan = Scan(ranges_m=np.array(ranges_m, dtype=np.float32), stamp_s=t_s)
        with self._blame(step):
            t_up = time.thread_time()
            e = self.loc.update(odom, scan)
            self.update_s += time.thread_time() - t_up
        where = f"on day {self.prior.day} run {self.prior.run} at scan {step}"
        mean, cov = self.checked_estimate(self.label, self.loc, e, where)
        self.est[step] = mean
        self.cov_diag[step] = np.diagonal(cov)
        with self._blame(step):
            ex = e.extras
            if ex:
                self.diagnostics.scan(step, ex)
                pc = ex.get("point_classes")
                if pc is not None:
                    self._score(beam_class, pc, ranges_m, point_truth)
        self.n += 1
        return e

    def _score(
        self,
        beam_class: NDArray[np.int8],
        classes: Any,
        ranges_m: NDArray[np.float32],
        point_truth: NDArray[np.int8] | None,
    ) -> None:
        """Score one scan's reported point classes against the truth (beam labels and the
        seen-before classes): a scan like the last ones waits to be scored with them
        (:meth:`_score_held`, the same sums), any other one is scored now."""
        p = np.asarray(classes)
        shape = np.shape(beam_class)
        held = self._unscored
        if (
            p.ndim == 1
            and p.shape == shape == np.shape(ranges_m)
            and (point_truth is None or np.shape(point_truth) == shape)
            and (not held or (held[-1][3] is None) == (point_truth is None))
        ):
            held.append((beam_class, p.astype(np.int64), ranges_m, point_truth))
            if len(held) >= SCORE_BATCH:
                self._score_held()
            return
        self._score_held()
        self.confusion += confusion_matrix(beam_class, classes)
        self.point_tally.add(classes, ranges_m, point_truth)

    def _score_held(self) -> None:
        """Score the held scans at once (:meth:`PointClassTally.add_scans`)."""
        held, self._unscored = self._unscored, []
        if not held:
            return
        p = np.stack([h[1] for h in held])
        self.confusion += confusion_matrix(np.stack([h[0] for h in held]), p)
        truth = None if held[0][3] is None else np.stack([h[3] for h in held])
        self.point_tally.add_scans(p, np.stack([h[2] for h in held]), truth)

    @staticmethod
    def checked_estimate(
        label: str, loc: Localizer, e: Any, where: str
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """The mean ``(3,)`` and covariance ``(3, 3)`` of what ``update()`` returned, as
        float64; :class:`LocalizerContractError` naming the localizer, the rule it broke and
        ``where`` (the run and scan) when it is not a PoseEstimate of finite numbers."""
        who = f"localizer {label!r} ({type(loc).__module__}.{type(loc).__qualname__})"

        def broke(rule: str, got: str) -> LocalizerContractError:
            return LocalizerContractError(
                f"{who} broke the Localizer contract {where}: update() must return {rule}, "
                f"got {got}"
            )

        if not isinstance(e, PoseEstimate):
            got = "None" if e is None else f"a {type(e).__name__}"
            raise broke("a PoseEstimate", got)
        try:
            mean = np.asarray(e.mean, dtype=np.float64)
            cov = np.asarray(e.cov, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise broke("a PoseEstimate of numbers", f"{exc}") from None
        if mean.shape != (3,) or not np.isfinite(mean).all():
            got = f"shape {mean.shape}" if mean.shape != (3,) else f"{mean.tolist()}"
            raise broke("a PoseEstimate with a (3,) mean of finite numbers (x, y, theta)", got)
        if cov.shape != (3, 3) or not np.isfinite(cov).all():
            got = f"shape {cov.shape}" if cov.shape != (3, 3) else "non-finite values"
            raise broke("a PoseEstimate with a finite (3, 3) covariance", got)
        return mean, cov

    def feed(self, chunk: ScanChunk) -> None:
        """:meth:`update` with each scan of ``chunk`` in order."""
        t0 = time.perf_counter()
        truth = chunk.point_truth
        for j in range(len(chunk.stamps_s)):
            self.update(
                float(chunk.stamps_s[j]),
                chunk.odom[j],
                chunk.scans[j],
                chunk.beam_class[j],
                None if truth is None else truth[j],
            )
        self.busy_s += time.perf_counter() - t0

    def finish(self, last_of_day: bool) -> LocalizerOutput:
        """End the run (and the day), pickle the localizer; the run's output."""
        t0 = time.perf_counter()
        n = self.n
        if n != len(self.est):
            self.diagnostics.resize(n)
        with self._blame(n - 1):
            self._score_held()
        with self._blame(None):
            self.loc.end_run()
            self.diagnostics.end_run(self.loc)
            if last_of_day:
                self.loc.end_day()
                self.diagnostics.end_day(self.loc)
        state = pickle_localizer(self.label, self.loc)
        return LocalizerOutput(
            self.est[:n].copy(),
            self.cov_diag[:n].copy(),
            self.confusion,
            self.update_s,
            self.busy_s + time.perf_counter() - t0,
            state,
            diagnostics=self.diagnostics.out,
            point_tally=self.point_tally,
        )


def localize_run(label: str, loc: Localizer, stream: RunStream) -> LocalizerOutput:
    """Feed one run's recorded stream to one localizer (:class:`LocalizerRun`)."""
    run = LocalizerRun(label, loc, stream.prior, capacity=len(stream.stamps_s))
    run.feed(ScanChunk(stream.stamps_s, stream.odom, stream.scans, stream.beam_class,
                       stream.point_truth))  # fmt: skip
    return run.finish(stream.last_of_day)


class StreamedRuns:
    """Some localizers through runs streamed in chunks: :meth:`begin` a run (``begin_run``
    of each), :meth:`feed` chunks (each localizer takes the chunk's scans in order),
    :meth:`end` (their outputs). A localizer that failed is reported at :meth:`end`, after
    the run's remaining chunks were skipped (the caller reads one answer per run)."""

    def __init__(self) -> None:
        self._runs: list[tuple[int, LocalizerRun]] = []
        self._header: RunHeader | None = None
        self._error: Exception | None = None

    def begin(self, header: RunHeader, locs: dict[int, tuple[str, Localizer]], n: int) -> None:
        self._header, self._error, self._runs = header, None, []
        try:
            for k, (label, loc) in locs.items():
                self._runs.append((k, LocalizerRun(label, loc, header.prior, capacity=n)))
        except Exception as exc:  # noqa: BLE001 - reported at end()
            self._error = exc

    def feed(self, chunk: ScanChunk) -> None:
        if self._error is not None:
            return
        try:
            for _, run in self._runs:
                run.feed(chunk)
        except Exception as exc:  # noqa: BLE001 - reported at end()
            self._error = exc

    def end(self) -> dict[int, LocalizerOutput]:
        header, error, runs = self._header, self._error, self._runs
        self._header, self._error, self._runs = None, None, []
        if header is None:
            raise RuntimeError("end() without begin()")
        if error is not None:
            raise error
        return {k: run.finish(header.last_of_day) for k, run in runs}


class InProcessLocalizers:
    """All localizers in the calling process (``workers=1``): :meth:`feed` does the work as
    the chunks come (:meth:`submit`: a whole recorded run)."""

    #: Runs in flight at most (the runner stores each as soon as it is simulated).
    depth = 1

    def __init__(self, labels: Sequence[str], localizers: Sequence[Localizer]) -> None:
        self.labels = list(labels)
        self.locs = list(localizers)
        self._runs = StreamedRuns()
        self._out: list[LocalizerOutput] | None = None

    def begin(self, header: RunHeader, capacity: int = 1024) -> None:
        if self._out is not None:
            raise RuntimeError(f"begin() with {self.depth} runs not collected")
        locs = dict(enumerate(zip(self.labels, self.locs, strict=True)))
        self._runs.begin(header, locs, capacity)

    def feed(self, chunk: ScanChunk) -> None:
        self._runs.feed(chunk)

    def end(self) -> None:
        out = self._runs.end()
        self._out = [out[k] for k in range(len(self.labels))]

    def submit(self, stream: RunStream) -> None:
        """:meth:`begin`, :meth:`feed` and :meth:`end` with a whole recorded run."""
        submit_stream(self, stream)

    def result(self) -> list[LocalizerOutput]:
        out, self._out = self._out, None
        if out is None:
            raise RuntimeError("result() without a submitted run")
        return out

    def close(self) -> None:
        pass


def submit_stream(engine: InProcessLocalizers | LocalizerPool, stream: RunStream) -> None:
    """A whole recorded run into ``engine``: begin, its scans in chunks, end."""
    engine.begin(RunHeader(stream.index, stream.prior, stream.last_of_day), len(stream.stamps_s))
    for chunk in stream.chunks(CHUNK_SCANS):
        engine.feed(chunk)
    engine.end()


# ---------------------------------------------------------------------- worker processes
def _exit_with_parent(parent_pid: int) -> None:
    """Watchdog thread of a worker: leave at once when the main process is gone."""
    while True:
        time.sleep(0.5)
        if os.getppid() != parent_pid:
            os._exit(1)


def _receive(conn: Connection, inbox: queue.SimpleQueue) -> None:
    """Reader thread of a worker: each message into ``inbox`` as it arrives (the main process
    hands over the next run while this one is localized); None once the main process left
    (or broke off a message), after ``("stop",)``."""
    while True:
        try:
            msg = conn.recv()
        except Exception:  # noqa: BLE001 - the main process left (or broke off a message)
            inbox.put(None)
            return
        inbox.put(msg)
        if msg[0] == "stop":
            return


def _worker_main(conn: Connection, parent_pid: int) -> None:
    """A worker's loop: hold some localizers, run each submitted stream through them.

    Messages: ``("adopt", {k: (label, pickled)})``, ``("drop", [k, ...])``,
    ``("begin", RunHeader, n_scans)``, ``("scans", ScanChunk)``, ``("end",)``, ``("stop",)``,
    handled in order (:func:`_receive` reads them as they come). ``adopt``, ``drop`` and
    ``end`` get one reply each: ``("ok", payload)`` (after ``end``: the run's outputs) or
    ``("error", kind, message, traceback)``; ``begin`` and ``scans`` none.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the main process's business
    threading.Thread(target=_exit_with_parent, args=(parent_pid,), daemon=True).start()
    inbox: queue.SimpleQueue = queue.SimpleQueue()
    threading.Thread(target=_receive, args=(conn, inbox), daemon=True).start()
    locs: dict[int, tuple[str, Localizer]] = {}
    runs = StreamedRuns()
    while True:
        msg = inbox.get()
        if msg is None:
            return
        kind = msg[0]
        if kind == "stop":
            return
        if kind == "begin":
            runs.begin(msg[1], locs, msg[2])
            continue
        if kind == "scans":
            runs.feed(msg[1])
            continue
        try:
            if kind == "adopt":
                for k, (label, blob) in msg[1].items():
                    locs[k] = (label, load_state(blob))
                reply: tuple[Any, ...] = ("ok", None)
            elif kind == "drop":
                for k in msg[1]:
                    locs.pop(k, None)
                reply = ("ok", None)
            elif kind == "end":
                reply = ("ok", runs.end())
            else:
                reply = ("error", "protocol", f"unknown message {kind!r}", "")
        except InputError as exc:
            reply = ("error", "input", str(exc), traceback.format_exc())
        except Exception as exc:  # noqa: BLE001 - reported to the main process
            reply = ("error", "localizer", str(exc), traceback.format_exc())
        try:
            conn.send(reply)
        except (BrokenPipeError, OSError):
            return


@dataclass
class _Worker:
    proc: Any  # multiprocessing.Process of the spawn context
    conn: Connection
    locs: list[int]
    niced: bool = False  # given LIGHT_WORKER_NICE (never undone: only root may)
    owed: int = 0  # replies to messages sent without waiting (the first adopt), not yet read


class LocalizerPool:
    """Localizers spread over ``n_workers`` persistent worker processes (see module doc).

    ``states`` are the pickled localizers (fresh or from a checkpoint), index-aligned with
    ``labels``. Use as: per run ``begin(header)``, ``feed(chunk)`` per chunk of its scans and
    ``end()`` (or ``submit(stream)`` with a whole recorded run), and ``result()`` per run, in
    order, with at most :attr:`depth` runs begun and not yet collected; ``close()`` at the
    end (also on errors: it terminates the workers).
    """

    #: Runs in flight at most: the workers localize the run being simulated as it comes and
    #: may still be on the two before it (one would leave a core idle whenever one side
    #: waits).
    depth = 3

    def __init__(self, labels: Sequence[str], states: Sequence[bytes], n_workers: int) -> None:
        if n_workers < 1:
            raise ValueError("n_workers must be >= 1")
        self.labels = list(labels)
        self.states = list(states)
        self.busy_s = [0.0] * len(self.labels)  # per localizer, last run
        self._in_flight: deque[RunHeader] = deque()  # begun, not collected, oldest first
        self._collected: deque[list[LocalizerOutput]] = deque()  # collected, not returned
        n_workers = min(n_workers, max(1, len(self.labels)))
        ctx = mp.get_context("spawn")
        self.workers: list[_Worker] = []
        saved = {k: os.environ.get(k) for k in WORKER_THREAD_ENV}
        try:
            for k, v in WORKER_THREAD_ENV.items():  # inherited by the spawned workers
                os.environ.setdefault(k, v)
            for w in range(n_workers):
                ours, theirs = ctx.Pipe(duplex=True)
                proc = ctx.Process(
                    target=_worker_main,
                    args=(theirs, os.getpid()),
                    name=f"dynmap-localizers-{w + 1}",
                    daemon=True,
                )
                proc.start()
                theirs.close()
                self.workers.append(_Worker(proc, ours, []))
            # first assignment: round robin (no costs measured yet); not waited for: the
            # workers start (imports, about 3 s of CPU each) while the first run is simulated,
            # and their replies are read before the next ones (:meth:`_recv`)
            for k in range(len(self.labels)):
                self.workers[k % n_workers].locs.append(k)
            for w in self.workers:
                self._send(w, ("adopt", {k: (self.labels[k], self.states[k]) for k in w.locs}))
        except BaseException:
            self.close()
            raise
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v

    # ------------------------------------------------------------------ messaging
    def _who(self, w: _Worker) -> str:
        names = ", ".join(repr(self.labels[k]) for k in w.locs) or "no localizers"
        return f"worker process {w.proc.name} (pid {w.proc.pid}; {names})"

    def _recv(self, w: _Worker) -> Any:
        """The worker's reply to the last message that asks one, after those owed to
        messages sent without waiting (:meth:`_send`); raises when it reports an error or
        dies (never hangs)."""
        while w.owed:
            w.owed -= 1
            self._recv_one(w)
        return self._recv_one(w)

    def _recv_one(self, w: _Worker) -> Any:
        """The worker's next reply (see :meth:`_recv`)."""
        while True:
            ready = wait([w.conn, w.proc.sentinel])
            if w.conn in ready:
                try:
                    reply = w.conn.recv()
                except (EOFError, OSError):
                    reply = None
                break
            if w.proc.sentinel in ready and not w.conn.poll():
                reply = None
                break
        if reply is None:
            w.proc.join(timeout=1.0)
            what = f" on {_day_run(self._in_flight[0])}" if self._in_flight else ""
            raise LocalizerError(
                f"{self._who(w)} died{what} (exit code {w.proc.exitcode}); "
                "out of memory or a crash in native code?"
            )
        if reply[0] == "ok":
            return reply[1]
        _, kind, message, tb = reply
        if kind == "input":
            raise InputError(message)
        raise LocalizerError(f"{message}\n--- traceback in {self._who(w)} ---\n{tb}")

    @staticmethod
    def _post(w: _Worker, msg: tuple[Any, ...]) -> None:
        """Send ``msg`` to the worker, ignoring a broken pipe: a dead worker is reported
        where its reply is read (:meth:`_recv`), and :meth:`close` joins it either way."""
        try:
            w.conn.send(msg)
        except (BrokenPipeError, OSError):
            pass

    def _send(self, w: _Worker, msg: tuple[Any, ...]) -> None:
        """Send a message that gets a reply without waiting for it (read by :meth:`_recv`
        before the next reply)."""
        self._post(w, msg)
        w.owed += 1

    def _call(self, w: _Worker, msg: tuple[Any, ...]) -> Any:
        self._post(w, msg)
        return self._recv(w)

    # ------------------------------------------------------------------ balancing
    def _rebalance(self) -> None:
        """Move localizers between workers when the last run's busy times call for it
        (longest first onto the least loaded worker; only for a gain of REBALANCE_GAIN)."""
        if len(self.workers) < 2 or not any(self.busy_s):
            return
        load_now = [sum(self.busy_s[k] for k in w.locs) for w in self.workers]
        new: list[list[int]] = [[] for _ in self.workers]
        load = [0.0] * len(self.workers)
        for k in sorted(range(len(self.labels)), key=lambda k: -self.busy_s[k]):
            j = int(np.argmin(load))
            new[j].append(k)
            load[j] += self.busy_s[k]
        if max(load) > (1.0 - REBALANCE_GAIN) * max(load_now):
            return
        while self._in_flight:  # the localizers' states after the runs in flight first
            self._collected.append(self._collect())
        # keep as many localizers in place as possible: match new groups to workers
        order = sorted(
            range(len(new)),
            key=lambda j: -max(len(set(new[j]) & set(w.locs)) for w in self.workers),
        )
        free = list(range(len(self.workers)))
        target: dict[int, list[int]] = {}
        for j in order:
            best = max(free, key=lambda i: len(set(new[j]) & set(self.workers[i].locs)))
            free.remove(best)
            target[best] = sorted(new[j])
        for i, w in enumerate(self.workers):
            gone = [k for k in w.locs if k not in target[i]]
            if gone:
                self._call(w, ("drop", gone))
        for i, w in enumerate(self.workers):
            came = [k for k in target[i] if k not in w.locs]
            if came:
                self._call(w, ("adopt", {k: (self.labels[k], self.states[k]) for k in came}))
            w.locs = target[i]

    # ------------------------------------------------------------------ runs
    def _send_all(self, msg: tuple[Any, ...]) -> None:
        for w in self.workers:
            if w.locs:
                self._post(w, msg)

    def begin(self, header: RunHeader, capacity: int = 1024) -> None:
        """Start a run in the workers (returns at once; a worker busy with an earlier run
        starts on it when done); ``capacity``: a first guess of its scans."""
        if len(self._in_flight) + len(self._collected) >= self.depth:
            raise RuntimeError(f"begin() with {self.depth} runs not collected")
        self._rebalance()
        self._in_flight.append(header)
        self._send_all(("begin", header, int(capacity)))

    def feed(self, chunk: ScanChunk) -> None:
        """The next scans of the run begun last."""
        self._send_all(("scans", chunk))

    def end(self) -> None:
        """The run begun last has no more scans: the workers finish it."""
        self._send_all(("end",))

    def submit(self, stream: RunStream) -> None:
        """:meth:`begin`, :meth:`feed` and :meth:`end` with a whole recorded run."""
        submit_stream(self, stream)

    def result(self) -> list[LocalizerOutput]:
        """Wait for the oldest submitted run's outputs (index-aligned with the labels)."""
        if self._collected:
            return self._collected.popleft()
        if not self._in_flight:
            raise RuntimeError("result() without a submitted run")
        return self._collect()

    def _collect(self) -> list[LocalizerOutput]:
        """The oldest run in flight's outputs, from the workers that have localizers (the
        same that had them when it was submitted: a rebalance collects the runs in flight
        first)."""
        out: dict[int, LocalizerOutput] = {}
        for w in self.workers:
            if w.locs:
                out.update(self._recv(w))
        self._in_flight.popleft()
        for k, o in out.items():
            self.states[k] = o.state
            self.busy_s[k] = o.busy_s
        self._yield_light_workers()
        return [out[k] for k in range(len(self.labels))]

    def _yield_light_workers(self) -> None:
        """Lower the CPU priority of workers that take less than :data:`LIGHT_WORKER_SHARE`
        of the busiest one's time (to :data:`LIGHT_WORKER_NICE`), when every worker holds one
        localizer (no rebalance can then give a light worker a heavy localizer).

        Why: with more processes than cores the scheduler shares the cores equally, so the
        heaviest localizer (the experiment's critical path) falls behind while light ones
        finish early and leave a core idle at the end. Niced, the light ones take what the
        simulation and the heavy worker leave (the simulation waits for runs in flight, the
        worker for scans), and the pool's depth bounds how far they lag
        (docs/tuning/store.md). Only the schedule changes, never a number; ignored where the
        platform has no ``setpriority`` or refuses it."""
        setpriority = getattr(os, "setpriority", None)
        if setpriority is None or len(self.workers) < 2:
            return
        if any(len(w.locs) != 1 for w in self.workers):
            return
        load = [self.busy_s[w.locs[0]] for w in self.workers]
        top = max(load)
        for w, busy in zip(self.workers, load, strict=True):
            if not w.niced and top > 0 and busy < LIGHT_WORKER_SHARE * top:
                try:
                    setpriority(os.PRIO_PROCESS, w.proc.pid, LIGHT_WORKER_NICE)
                except OSError:
                    return
                w.niced = True

    def close(self) -> None:
        """Stop the workers (politely, then by force); safe to call more than once."""
        for w in self.workers:
            self._post(w, ("stop",))
        deadline = time.monotonic() + 2.0
        for w in self.workers:
            w.proc.join(timeout=max(0.0, deadline - time.monotonic()))
            if w.proc.is_alive():
                w.proc.terminate()
                w.proc.join(timeout=2.0)
            if w.proc.is_alive():
                w.proc.kill()
                w.proc.join()
            w.conn.close()
        self.workers = []
