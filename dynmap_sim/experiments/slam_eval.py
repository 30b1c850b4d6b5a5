"""``dynmap-sim slam-eval``: the first-run mapper on a recorded CARMEN log, scored by
Kümmerle et al. 2009's relation error (:mod:`dynmap_sim.metrics.relation_error`).

The log's scans and odometry go through :class:`~dynmap_sim.agent.mapping.first_run.
FirstRunMapper` exactly as on the first run of a simulated experiment (online front end,
then loop closure and the pose graph in ``finish()``). The loop-closed trajectory of every
scan is scored against the benchmark's relations (and, for comparison, the front end's and
the raw odometry's), timed (front end and back end), and can be written in TUM format
with the log's own time stamps.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.mapping.first_run import FirstRunConfig, FirstRunMapper
from dynmap_sim.errors import InputError
from dynmap_sim.io.logs import BagOptions, read_log
from dynmap_sim.metrics.relation_error import RelationError, read_relations, relation_error

FloatArray = NDArray[np.float64]


@dataclass
class SlamEval:
    """The outcome of :func:`slam_eval`: errors of the loop-closed trajectory, the front
    end's and raw odometry's, the trajectory, and timings."""

    log: Path
    n_scans: int
    stamps_s: FloatArray
    trajectory: FloatArray
    front_end: FloatArray
    loop_closed: RelationError
    front_end_error: RelationError
    odometry_error: RelationError
    short_error: RelationError
    n_loop_closures: int
    front_end_s: float
    back_end_s: float
    #: the log's odometry source and its unsigned reversing
    #: (:class:`~dynmap_sim.io.carmen.CarmenLog`)
    odometry_source: str = "odom-lines"
    n_reversals: int = 0
    reversals: str = "repair"
    #: CPU seconds of the front end and the back end (one core: the mapper is sequential)
    front_end_cpu_s: float = math.nan
    back_end_cpu_s: float = math.nan
    #: the loop-closure search's counts (:attr:`.loop_closure.LoopClosure.stats`): why
    #: candidates were rejected, how many were verified and kept as consistent
    closure_search: dict[str, int] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        """The log's span [s], first to last scan."""
        return float(self.stamps_s[-1] - self.stamps_s[0]) if len(self.stamps_s) else 0.0

    @property
    def realtime_factor(self) -> float:
        """The log's span over the mapper's CPU time: how many times faster than real time
        the mapping runs on one core."""
        return self.duration_s / max(self.front_end_cpu_s + self.back_end_cpu_s, 1e-9)

    @property
    def scans_per_s(self) -> float:
        return self.n_scans / max(self.front_end_s + self.back_end_s, 1e-9)

    def summary(self) -> dict[str, Any]:
        """The JSON the CLI writes: the loop-closed trajectory's relation error and timings."""
        r = self.loop_closed
        return {
            "log": str(self.log),
            "n_scans": self.n_scans,
            "n_relations": r.n_relations,
            "n_unmatched": r.n_unmatched,
            "translation_mean_m": r.translation_mean_m,
            "translation_std_m": r.translation_std_m,
            "rotation_mean_deg": r.rotation_mean_deg,
            "rotation_std_deg": r.rotation_std_deg,
            "front_end": self.front_end_error.to_dict(),
            "odometry": self.odometry_error.to_dict(),
            "under_30s": self.short_error.to_dict(),
            "n_loop_closures": self.n_loop_closures,
            "front_end_s": self.front_end_s,
            "back_end_s": self.back_end_s,
            "scans_per_s": self.scans_per_s,
            "front_end_cpu_s": self.front_end_cpu_s,
            "back_end_cpu_s": self.back_end_cpu_s,
            "duration_s": self.duration_s,
            "realtime_factor": self.realtime_factor,
            "odometry_source": self.odometry_source,
            "odometry_reversals": self.reversals,
            "odometry_reversals_found": self.n_reversals,
            "closure_search": dict(self.closure_search),
        }

    def table(self) -> list[str]:
        """The printed table: one row per trajectory."""
        rows = [
            f"{'trajectory':<24} {'n':>5} {'translation [m]':>18} {'rotation [deg]':>16}",
        ]
        for name, r in (
            ("loop-closed (mapper)", self.loop_closed),
            ("front end", self.front_end_error),
            ("raw odometry", self.odometry_error),
            ("mapper, relations <30 s", self.short_error),
        ):
            rows.append(
                f"{name:<24} {r.n_relations:>5} "
                f"{r.translation_mean_m:>8.3f} ± {r.translation_std_m:<7.3f} "
                f"{r.rotation_mean_deg:>6.2f} ± {r.rotation_std_deg:<6.2f}"
            )
        rows.append(
            f"{self.n_scans} scans, {self.n_loop_closures} loop closures; front end "
            f"{self.front_end_s:.1f} s, back end {self.back_end_s:.1f} s, "
            f"{self.scans_per_s:.0f} scans/s; CPU {self.front_end_cpu_s:.1f} + "
            f"{self.back_end_cpu_s:.1f} s, {self.realtime_factor:.1f}x real time"
        )
        if self.closure_search:
            counts = ", ".join(f"{k} {v}" for k, v in self.closure_search.items() if v)
            rows.append(f"closure search: {counts or 'no keyframe far enough along'}")
        return rows


def slam_eval(
    log: Path,
    relations: Path,
    config: FirstRunConfig | None = None,
    progress: bool = False,
    note: Callable[[str], None] | None = None,
    odometry: str = "auto",
    reversals: str = "repair",
    bag: BagOptions | None = None,
) -> SlamEval:
    """Map ``log`` with the first-run mapper and score it against ``relations``; ``odometry``
    which of the log's odometry records to use, ``reversals`` what to do with its unsigned
    reversing (:func:`~dynmap_sim.io.carmen.read_carmen`); a ROS bag ``log`` is read as
    ``bag`` says (:func:`~dynmap_sim.io.logs.read_log`)."""
    from tqdm.auto import tqdm

    data = read_log(log, odometry=odometry, reversals=reversals, bag=bag)
    if len(data) < 2:
        raise InputError(f"{log}: the log has fewer than 2 scans")
    try:
        rel = read_relations(relations)
    except OSError as exc:
        raise InputError(f"--relations {relations}: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise InputError(f"--relations: {exc}") from None
    if len(rel) == 0:
        raise InputError(f"--relations {relations}: no relations in the file")
    mapper = FirstRunMapper(data.laser, data.odometry[0], config)
    front = np.zeros((len(data), 3))
    t0, c0 = time.perf_counter(), time.process_time()
    for k, (odom, scan) in enumerate(
        tqdm(data.stream(), disable=not progress, desc=Path(log).name, unit="scan")
    ):
        front[k] = mapper.update(odom, scan).mean
    t1, c1 = time.perf_counter(), time.process_time()
    if note is not None and progress:
        note("closing loops and optimizing the pose graph ...")
    static = mapper.finish()
    t2, c2 = time.perf_counter(), time.process_time()
    traj = np.asarray(static.trajectory, dtype=np.float64)
    stamps = data.stamps_s
    lc = relation_error(stamps, traj, rel)
    if lc.n_relations == 0:
        raise InputError(
            f"--relations {relations}: none of its {len(rel)} relations names two scans of "
            f"{log} by time stamp (another log's relations?)"
        )
    if note is not None and lc.n_unmatched:
        note(f"note: {lc.n_unmatched} of {len(rel)} relations name no scan of the log; left out")
    dt = np.abs(rel.t2 - rel.t1)
    short = rel.__class__(rel.t1[dt < 30], rel.t2[dt < 30], rel.delta[dt < 30])
    return SlamEval(
        log=Path(log),
        n_scans=len(data),
        stamps_s=stamps,
        trajectory=traj,
        front_end=front,
        loop_closed=lc,
        front_end_error=relation_error(stamps, front, rel),
        odometry_error=relation_error(stamps, data.odometry, rel),
        short_error=relation_error(stamps, traj, short),
        n_loop_closures=static.n_loop_closures,
        front_end_s=t1 - t0,
        back_end_s=t2 - t1,
        odometry_source=data.odometry_source,
        n_reversals=data.n_reversals,
        reversals=data.reversals,
        front_end_cpu_s=c1 - c0,
        back_end_cpu_s=c2 - c1,
        closure_search=dict(mapper.loop_closure.stats),
    )
