"""``dynmap-sim replay``: run the mapper and localizers on a recorded log (CARMEN or ROS bag).

The log is replayed twice, as two runs of a small experiment written to the same results
store as simulated experiments (:mod:`dynmap_sim.experiments.results`):

* **day 1, run 1 — mapping**: localizers that build their own map (``first_run=True``, e.g.
  ``static-mcl`` with ``map_source="first-run"``) run their first-run SLAM on the log;
* **day 2, run 1 — localization**: every localizer localizes on the log again against the
  map it now has.

With ``map_from_log_poses=True`` the map is instead rendered directly from poses (keyframes
every 0.3 m / 0.3 rad): the reference poses when there is a reference, else the poses on the
log's laser lines (on a raw log: its odometry). It goes to every localizer that accepts a
map: a grid to a :class:`~dynmap_sim.agent.localization.localizer.MapUser`
(``static-mcl``), the keyframe scans at those poses to a
:class:`~dynmap_sim.agent.localization.localizer.ScanMapUser` (``dynamic-map``); the others
still map on day 1 (``note`` says which), and when none accepts one the option is refused.

The results folder reads like a simulated experiment's: ``meta`` names the log as the world,
lists the two runs as ``slots`` (so the report says "2 of 2 runs done") and keeps the log's
first time stamp (``log_start_s``: the export writes the log's own clock); every
``update()`` is timed (CPU) and checked against the localizer contract; the time per scan of
each localizer is stored as ``update_ms_per_scan`` of ``run_summaries``, as for a run.

**Ground truth** comes only from a reference (``reference=``, :mod:`.reference`): a CARMEN
log whose laser lines carry true poses, matched to the scans by time stamp (the log itself
may be its own reference). Scans without a matching reference pose have no truth and no
error. Without a reference the log has no ground truth (a raw log's laser-line poses are its
odometry): truth and errors are stored as NULL, ``meta.has_reference`` is false and the
report says "this log has no ground truth" instead of scoring the localizers.
Localizer names are registry names, optionally with parameters:
``static-mcl,config=nav2-default,map_source=first-run``.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dynmap_sim import se2
from dynmap_sim.agent.grid import OccupancyGrid
from dynmap_sim.agent.localization.localizer import Localizer, MapUser, ScanMapUser, make_localizer
from dynmap_sim.errors import InputError
from dynmap_sim.experiments.localizer_pool import DiagnosticsRecorder, LocalizerRun
from dynmap_sim.experiments.reference import (
    REFERENCE_TOLERANCE_S,
    ReferenceMatch,
    load_reference,
    start_pose,
)
from dynmap_sim.experiments.results import ResultsDB, RunRecord
from dynmap_sim.experiments.runner import ExperimentRunner, localizer_seeds
from dynmap_sim.io.carmen import CarmenLog
from dynmap_sim.io.logs import BagOptions, log_digest, read_log
from dynmap_sim.io.rosbag import is_bag
from dynmap_sim.types import Prior


def json_or_text(text: str) -> Any:
    """A command-line parameter value: JSON where it parses (numbers, true/false, lists),
    else the text itself."""
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def parse_localizer_arg(arg: str) -> tuple[str, dict[str, Any]]:
    """``"name,key=value,..."`` -> ``(name, params)``; values parsed as JSON when possible."""
    name, *rest = [s.strip() for s in arg.split(",") if s.strip()]
    params: dict[str, Any] = {}
    for item in rest:
        key, sep, val = item.partition("=")
        if not sep or not key:
            raise InputError(f"--localizer {arg!r}: expected name,key=value,... got {item!r}")
        params[key] = json_or_text(val)
    return name, params


def keyframe_indices(poses: np.ndarray, dist_m: float = 0.3, angle_rad: float = 0.3) -> list[int]:
    """Indices of poses ``(T, 3)`` taken as keyframes every ``dist_m`` / ``angle_rad``."""
    keep = [0]
    for k in range(1, len(poses)):
        rel = se2.between(poses[keep[-1]], poses[k])
        if np.hypot(rel[0], rel[1]) > dist_m or abs(rel[2]) > angle_rad:
            keep.append(k)
    return keep


def keyframe_scans(
    log: CarmenLog, poses: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The log's keyframes (every 0.3 m / 0.3 rad) at ``poses`` ``(T, 3)`` (NaN rows skipped;
    default: the poses on its laser lines): their poses ``(K, 3)`` and ranges ``(K, B)`` [m]."""
    if poses is None:
        if log.reference is None:
            raise InputError(f"{log.path}: --map-from-log-poses needs laser lines with poses")
        poses = log.reference
    have = np.flatnonzero(np.isfinite(poses).all(axis=1))
    kf = have[keyframe_indices(poses[have])]
    return poses[kf], log.ranges_m[kf]


def _give_maps(
    log: CarmenLog,
    ref: ReferenceMatch | None,
    locs: list[Localizer],
    localizers: Sequence[str],
    note: Callable[[str], None] | None,
) -> list[bool]:
    """``--map-from-log-poses``: the map from the log's poses (the reference's when given) to
    every localizer that takes one — a grid to a :class:`MapUser`, the keyframe scans at
    those poses to a :class:`ScanMapUser` (with a reference also its poses of every scan and
    the log's odometry, from which ``dynamic-map`` acquires ``C_O``); which localizers got
    one."""
    grids = [isinstance(loc, MapUser) for loc in locs]
    scans = [isinstance(loc, ScanMapUser) and not g for loc, g in zip(locs, grids, strict=True)]
    takes = [g or m for g, m in zip(grids, scans, strict=True)]
    if not any(takes):
        raise InputError(
            f"--map-from-log-poses: none of the localizers takes a map ({', '.join(localizers)}"
            "); give one that does (e.g. static-mcl, dynamic-map) or drop the option"
        )
    # the reference's poses of the map's run (None: the laser lines' own, which are not handed
    # to a localizer that acquires its odometry model from them: they may be the odometry)
    run_poses = ref.poses if ref is not None else None
    kf_poses, kf_ranges = keyframe_scans(log, run_poses)
    grid = OccupancyGrid.from_scans(kf_poses, kf_ranges, log.laser) if any(grids) else None
    for loc, g, m in zip(locs, grids, scans, strict=True):
        if g:
            loc.set_map(grid)
        elif m and run_poses is not None:  # the map's run: its poses and the log's odometry
            loc.set_map_from_scans(kf_poses, kf_ranges, run_poses, log.odometry)
        elif m:
            loc.set_map_from_scans(kf_poses, kf_ranges)
    others = [a for a, t in zip(localizers, takes, strict=True) if not t]
    if note is not None and others:
        takers = ", ".join(a for a, t in zip(localizers, takes, strict=True) if t)
        note(
            f"note: --map-from-log-poses: the map from the log's poses goes to {takers}; "
            f"not to {', '.join(others)}, which take no map (a localizer that maps "
            "builds its own on the first pass)"
        )
    return takes


def _run_pass(
    log: CarmenLog,
    locs: list[Localizer],
    priors: list[Prior],
    day: int,
    truth: np.ndarray,
    labels: list[str] | None = None,
) -> RunRecord:
    n_loc, n = len(locs), len(log)
    labels = labels or [type(loc).__name__ for loc in locs]
    est = np.full((n_loc, n, 3), np.nan)
    cov = np.full((n_loc, n, 3), np.nan)
    update_s = np.zeros(n_loc)
    diags = [DiagnosticsRecorder(loc, n) for loc in locs]
    wall0 = time.perf_counter()
    for loc, prior in zip(locs, priors, strict=True):
        loc.begin_run(prior)
    for k, (odom, scan) in enumerate(log.stream()):
        for i, loc in enumerate(locs):
            t_up = time.thread_time()  # CPU: as a run's (LocalizerRun.update)
            e = loc.update(odom, scan)
            update_s[i] += time.thread_time() - t_up
            where = f"on pass {day} ({'mapping' if day == 1 else 'localization'}) at scan {k}"
            mean, c = LocalizerRun.checked_estimate(labels[i], loc, e, where)
            est[i, k] = mean
            cov[i, k] = np.diag(c)
            if e.extras:
                diags[i].scan(k, e.extras)
    for loc, diag in zip(locs, diags, strict=True):
        loc.end_run()
        diag.end_run(loc)
        loc.end_day()
        diag.end_day(loc)
    t0 = float(log.stamps_s[0])
    date, start_s = _log_date_and_start(log)
    return RunRecord(
        day=day,
        run=1,
        date=date,
        start_s=start_s,
        t_s=log.stamps_s - t0,
        truth=np.asarray(truth, dtype=np.float64),
        collision=np.zeros(n, dtype=bool),
        estimates=est,
        cov_diag=cov,
        confusion=np.zeros((n_loc, 4, 4), dtype=np.int64),
        terminated=True,
        route_progress=1.0,
        skipped_waypoints=0,
        wall_s=time.perf_counter() - wall0,
        events=[],
        update_s=update_s,
        diagnostics=[d.out for d in diags],
    )


def _log_date_and_start(log: CarmenLog) -> tuple[str, float]:
    """The log's first date (UTC; 1970-01-01 without absolute stamps) and time of day [s]."""
    t0 = float(log.stamps_s[0])
    if not 0 < t0 < 253402300799:  # before 9999-12-31: a date can be made of it
        return dt.date(1970, 1, 1).isoformat(), 0.0
    start = dt.datetime.fromtimestamp(t0, tz=dt.UTC)
    return start.date().isoformat(), float(start.hour * 3600 + start.minute * 60 + start.second)


def _make_localizers(
    specs: list[tuple[str, dict[str, Any]]], data: CarmenLog, seed: int
) -> list[Localizer]:
    """The localizers ``(name, params)`` of ``specs`` for the log's laser, each with its
    generator from ``seed`` (:func:`~dynmap_sim.experiments.runner.localizer_seeds`)."""
    rngs = localizer_seeds(seed, len(specs))
    try:
        return [
            make_localizer(name, laser=data.laser, rng=rngs[k + 1], **params)
            for k, (name, params) in enumerate(specs)
        ]
    except (TypeError, ValueError) as exc:
        raise InputError(f"--localizer: {exc}") from None


def _replay_start(data: CarmenLog, ref: ReferenceMatch | None) -> np.ndarray:
    """The pose ``(x, y, θ)`` [m, rad] each pass starts from: the reference's at the first
    scan, else the frame the laser-line poses (and a map from them) are in."""
    if ref is not None:
        return start_pose(data, ref.poses)
    return data.reference[0] if data.reference is not None else np.zeros(3)


def _replay_hash(
    log: Path,
    data: CarmenLog,
    localizers: list[str],
    map_from_log_poses: bool,
    bag: BagOptions | None,
    seed: int,
    ref: ReferenceMatch | None,
) -> str:
    """The replay's experiment hash: the log's and the reference's contents and every
    option that changes the results."""
    ident = log_digest(log)
    ident.update(json.dumps([localizers, bool(map_from_log_poses)]).encode())
    if bag is not None and bag.given():
        ident.update(json.dumps(dataclasses.asdict(bag)).encode())
    ident.update(json.dumps([data.odometry_source, data.reversals]).encode())
    if seed:  # seed 0 keeps the hash of the replays before the option
        ident.update(json.dumps({"seed": seed}).encode())
    if ref is not None:
        ident.update(log_digest(ref.path).digest())
        ident.update(json.dumps([ref.offset_s, ref.tolerance_s]).encode())
    return ident.hexdigest()


def _reference_meta(ref: ReferenceMatch | None) -> dict[str, Any]:
    """The ``meta`` entries that say how the reference matched the log (empty ones without
    a reference)."""
    return {
        "has_reference": ref is not None,
        "reference_path": str(ref.path) if ref is not None else None,
        "reference_offset_s": ref.offset_s if ref is not None else None,
        "reference_offset_source": ref.offset_source if ref is not None else None,
        "reference_tolerance_s": ref.tolerance_s if ref is not None else None,
        "reference_matched": ref.n_matched if ref is not None else 0,
        "reference_summary": ref.describe() if ref is not None else None,
    }


def _replay_meta(
    log: Path,
    data: CarmenLog,
    ref: ReferenceMatch | None,
    seed: int,
    experiment_hash: str,
    map_from_log_poses: bool,
    keep_scans: bool,
) -> dict[str, Any]:
    """The replay's ``meta`` (as yet incomplete): the log as the world, its two passes as
    the slots, the reference's match and the options."""
    date, start_s = _log_date_and_start(data)
    return {
        "scenario": None,
        "scenario_name": f"replay:{Path(log).name}",
        "world": f"{'ROS bag' if is_bag(log) else 'CARMEN log'} {Path(log).name}",
        "log_path": str(log),
        "log_message": data.message,
        "log_start_s": float(data.stamps_s[0]),
        "seed": seed,
        "days": [1, 2],
        "slots": [[1, 1, date, start_s], [2, 1, date, start_s]],
        "first_date": date,
        "experiment_hash": experiment_hash,
        "laser": dataclasses.asdict(data.laser),
        **_reference_meta(ref),
        "map_from_log_poses": bool(map_from_log_poses),
        "odometry_source": data.odometry_source,
        "odometry_reversals": data.reversals,
        "odometry_reversals_found": data.n_reversals,
        "keep_scans": bool(keep_scans),
        "complete": False,
    }


def _replay_passes(
    db: ResultsDB,
    data: CarmenLog,
    locs: list[Localizer],
    labels: list[str],
    given_map: list[bool],
    start: np.ndarray,
    truth: np.ndarray,
    keep_scans: bool,
    seed: int,
) -> None:
    """The mapping pass (day 1) and the localization pass (day 2) of the log, each written
    to ``db`` as run 1 of its day; a localizer given the log's map does not map on day 1."""
    for day in (1, 2):
        priors = [
            Prior(initial_pose=start.copy(), day=day, run=1, first_run=day == 1 and not g)
            for g in given_map
        ]
        rec = _run_pass(data, locs, priors, day, truth, labels=labels)
        if keep_scans:
            rec = dataclasses.replace(rec, ranges=data.ranges_m)
        summaries = [ExperimentRunner._run_summary(k, rec) for k in range(len(locs))]
        db.write_run(rec, summaries, True, None, "replay", seed)


def replay_log(
    log: Path,
    localizers: list[str],
    out_dir: Path,
    map_from_log_poses: bool,
    note: Callable[[str], None] | None = None,
    reference: Path | None = None,
    reference_offset_s: float | None = None,
    reference_tolerance_s: float = REFERENCE_TOLERANCE_S,
    odometry: str = "auto",
    reversals: str = "repair",
    seed: int = 0,
    bag: BagOptions | None = None,
    keep_scans: bool = False,
) -> Path:
    """Replay CARMEN ``log`` through ``localizers`` into a results store in ``out_dir``;
    ``note`` gets what the user should know (which localizers took the log's map, how the
    reference matched). ``reference``: a CARMEN log with the true poses on its laser lines,
    matched by time stamp (:func:`~dynmap_sim.experiments.reference.load_reference`, with
    ``reference_offset_s`` ``None`` = estimated, and ``reference_tolerance_s``); ``None``:
    the log has no ground truth and no errors are stored. ``odometry``: which of the log's
    odometry records the localizers get and ``reversals`` what to do with its unsigned
    reversing (:func:`~dynmap_sim.io.carmen.read_carmen`). ``seed``: the root of the
    localizers' random generators (:func:`~dynmap_sim.experiments.runner.localizer_seeds`),
    as ``run --seed`` (another seed: another draw of every particle filter). A ROS bag
    ``log`` is read as ``bag`` says (:func:`~dynmap_sim.io.logs.read_log`); ``keep_scans``
    stores every scan's ranges, as ``run --keep-scans`` (for ``export --mcap``'s ``/scan``)."""
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise InputError(f"seed must be an integer >= 0, got {seed!r}")
    data = read_log(log, odometry=odometry, reversals=reversals, bag=bag)
    if len(data) < 2:
        raise InputError(f"{log}: the log has fewer than 2 scans")
    ref: ReferenceMatch | None = None
    if reference is not None:
        ref = load_reference(reference, data, reference_offset_s, reference_tolerance_s)
        if note is not None:
            note(f"note: {ref.describe()}")
    truth = ref.poses if ref is not None else np.full((len(data), 3), np.nan)
    specs = [parse_localizer_arg(a) for a in localizers]
    locs = _make_localizers(specs, data, seed)
    given_map = (
        _give_maps(data, ref, locs, localizers, note) if map_from_log_poses else [False] * len(locs)
    )
    start = _replay_start(data, ref)
    experiment_hash = _replay_hash(log, data, localizers, map_from_log_poses, bag, seed, ref)
    db = ResultsDB.create(out_dir, overwrite=True)
    try:
        db.set_meta(
            **_replay_meta(log, data, ref, seed, experiment_hash, map_from_log_poses, keep_scans)
        )
        db.set_localizers(
            [(a, name, params) for a, (name, params) in zip(localizers, specs, strict=True)]
        )
        labels = list(localizers)
        _replay_passes(db, data, locs, labels, given_map, start, truth, keep_scans, seed)
        db.set_meta(complete=True)
    finally:
        db.close()
    return Path(out_dir)
