"""Measure which of week 3's person beams ``adaptive-memory`` calls dynamic, by the person's
true speed (H&W eq. 10: dynamic if ``v >= v_thres = 0.3 m/s``, §7.1).

The experiment's truth scores every person beam as dynamic, whatever the person's speed, so
its recall mixes people no speed threshold can call dynamic (standing, turning, slowing at a
goal or for the robot) with those it should. This runs the H&W scenario
(``worlds/scenarios/apartment-28d-hw.toml``, its driver and world, ``adaptive-memory`` the only
localizer) through the experiment runner, instrumented from outside: per scan of the days
from ``--from-day`` on it takes the truth the runner records (true pose, beam classes, the
people's positions and velocities) and the classes the localizer reports, and gives each
person beam to the person whose centre is nearest to its end point. It prints the share of
person beams of people slower than ``v_thres`` (and below 0.05 m/s: standing), the dynamic
recall for the faster and the slower ones, the precision of the dynamic class over all beams,
and for the fast person beams not called dynamic the tracker's reason (no box, a box cut by
the field of view or a nearer return, or tracked as slow).

    python benchmarks/hw_person_beams.py --out /tmp/hw-person-beams --seed 0 [--days 1-21] \
        [--param leg_pair_m=0.5 ...]

Takes about as long as the scenario's days with one localizer (about 90 s for days 1-21).
"""

from __future__ import annotations

import argparse
import tomllib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dynmap_sim import se2
from dynmap_sim.agent.localization.adaptive_memory import object_tracker
from dynmap_sim.analysis.scenarios import load_scenario
from dynmap_sim.experiments import episode, localizer_pool
from dynmap_sim.experiments.runner import run_experiment
from dynmap_sim.types import BeamClass

SCENARIO = Path(__file__).resolve().parents[1] / "worlds/scenarios/apartment-28d-hw.toml"
#: H&W §7.1's speed threshold of eq. 10 [m/s].
V_THRES = 0.3
#: Below this speed [m/s] a person counts as standing.
STANDING_MPS = 0.05
#: Reasons a fast person beam is not dynamic, in report order.
REASONS = ("no box", "box cut (never dynamic)", "new track", "tracked slow", "tracked fast, vetoed")


@dataclass
class Tally:
    """Per person beam ``(day, speed [m/s], predicted class, reason code)``, and the dynamic
    predictions over all scored beams: ``n_dynamic``, ``n_dynamic_not_person``."""

    rows: list[tuple[int, float, int, int]] = field(default_factory=list)
    n_dynamic: int = 0
    n_dynamic_not_person: int = 0


def _reason(label: int, never: bool, box_class: int) -> int:
    if label < 0:
        return 0
    if never:
        return 1
    return {object_tracker.UNKNOWN: 2, object_tracker.STATIC: 3}.get(box_class, 4)


@contextmanager
def instrumented(tally: Tally, from_day: int) -> Iterator[None]:
    """Record the truth of every scan (``episode.RunRecorder.record``), the tracker's boxes
    (``ObjectTracker.update``) and, per ``adaptive-memory`` update from ``from_day`` on, the
    person beams into ``tally``; the three methods are restored on exit. Needs the run in
    this process (``workers=1``) and the people kept (``keep_scans=True``)."""
    truth: list[tuple[Any, ...]] = []
    record, track, update = (
        episode.RunRecorder.record,
        object_tracker.ObjectTracker.update,
        localizer_pool.LocalizerRun.update,
    )

    def record_truth(self: Any, obs: Any, tr: Any, collision: bool) -> Any:
        out = record(self, obs, tr, collision)
        people = self._people_of
        crowd = people.__self__.world.crowd if people is not None else None
        truth.append(
            (
                np.array(tr["pose"], dtype=np.float64),
                np.array(tr["beam_class"], dtype=np.int8),
                None if crowd is None else (crowd.pos.copy(), crowd.vel.copy()),
            )
        )
        return out

    def track_boxes(self: Any, boxes: Any, odom_pose: Any, t_s: float) -> Any:
        cls, speed = track(self, boxes, odom_pose, t_s)
        self.last_boxes = (boxes, cls.copy())
        return cls, speed

    def update_scored(self: Any, t_s: float, odom: Any, ranges: Any, *args: Any) -> Any:
        est = update(self, t_s, odom, ranges, *args)
        if not truth:
            return est
        pose, beam_class, people = truth.pop(0)
        if self.prior.day < from_day or "point_classes" not in est.extras:
            return est
        pc = np.asarray(est.extras["point_classes"])
        person = beam_class == BeamClass.PERSON
        tally.n_dynamic += int(np.sum(pc == object_tracker.DYNAMIC))
        tally.n_dynamic_not_person += int(np.sum((pc == object_tracker.DYNAMIC) & ~person))
        pb = np.flatnonzero(person & (pc != object_tracker.UNKNOWN))
        if people is None or not len(pb) or not len(people[0]):
            return est
        loc = self.loc
        boxes, box_cls = loc.tracker.last_boxes
        laser = se2.compose(pose, loc.mount)
        a = laser[2] + loc.angles[pb]
        r = np.asarray(ranges, dtype=np.float64)[pb]
        ends = laser[:2] + r[:, None] * np.column_stack([np.cos(a), np.sin(a)])
        d = np.linalg.norm(ends[:, None, :] - people[0][None, :, :], axis=2)
        who = np.argmin(np.where(np.isfinite(d), d, np.inf), axis=1)
        speed = np.linalg.norm(people[1][who], axis=1)
        for j, b in enumerate(pb):
            lab = int(boxes.labels[b])
            never = bool(boxes.never_dynamic[lab]) if lab >= 0 else False
            why = _reason(lab, never, int(box_cls[lab]) if lab >= 0 else -1)
            tally.rows.append((int(self.prior.day), float(speed[j]), int(pc[b]), why))
        return est

    episode.RunRecorder.record = record_truth  # type: ignore[method-assign]
    object_tracker.ObjectTracker.update = track_boxes  # type: ignore[method-assign]
    localizer_pool.LocalizerRun.update = update_scored  # type: ignore[method-assign]
    try:
        yield
    finally:
        episode.RunRecorder.record = record  # type: ignore[method-assign]
        object_tracker.ObjectTracker.update = track  # type: ignore[method-assign]
        localizer_pool.LocalizerRun.update = update  # type: ignore[method-assign]


def report(tally: Tally) -> list[str]:
    """The measurements of the module doc, as lines."""
    if not tally.rows:
        return ["no person beam scored"]
    a = np.array(tally.rows, dtype=np.float64)
    day, speed, pc, why = a[:, 0].astype(int), a[:, 1], a[:, 2].astype(int), a[:, 3].astype(int)
    fast, dyn = speed >= V_THRES, pc == object_tracker.DYNAMIC
    prec = 1.0 - tally.n_dynamic_not_person / max(tally.n_dynamic, 1)
    standing = float(np.mean(speed < STANDING_MPS))
    lines = [
        f"person beams scored: {len(a)}; of people slower than {V_THRES} m/s: "
        f"{np.mean(~fast):.3f}; standing (< {STANDING_MPS} m/s): {standing:.3f}",
        f"dynamic recall: all {np.mean(dyn):.3f}, people >= {V_THRES} m/s "
        f"{np.mean(dyn[fast]) if fast.any() else float('nan'):.3f}, slower "
        f"{np.mean(dyn[~fast]) if (~fast).any() else float('nan'):.3f}",
        f"dynamic precision over all beams: {prec:.4f} ({tally.n_dynamic} dynamic points)",
        "fast person beams not dynamic, by the tracker's reason:",
    ]
    miss = fast & ~dyn
    for k, name in enumerate(REASONS):
        lines.append(f"  {name}: {int(np.sum(miss & (why == k)))}")
    lines.append("per day: person beams, share slower than v_thres, recall all / fast")
    for d in np.unique(day):
        m, mf = day == d, (day == d) & fast
        rf = np.mean(dyn[mf]) if mf.any() else float("nan")
        lines.append(f"  day {d}: {int(m.sum())}, {np.mean(~fast[m]):.3f}, "
                     f"{np.mean(dyn[m]):.3f} / {rf:.3f}")  # fmt: skip
    return lines


def _param(arg: str, ap: argparse.ArgumentParser) -> tuple[str, Any]:
    """``NAME=VALUE`` as a name and its TOML value; a malformed one ends with a usage error."""
    name, eq, value = arg.partition("=")
    try:
        if not (eq and name.isidentifier()):
            raise ValueError("expected NAME=VALUE")
        return name, tomllib.loads(f"v = {value}")["v"]
    except (ValueError, tomllib.TOMLDecodeError) as exc:
        ap.error(f"--param {arg!r}: {exc}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, required=True, help="results folder (overwritten)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--days", default="1-21", help="days to run, e.g. 1-21")
    ap.add_argument("--from-day", type=int, default=15, help="first day scored (week 3: 15)")
    ap.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                    help="an adaptive-memory parameter for this run, a TOML value "
                         "(e.g. leg_pair_m=0.5); repeatable")  # fmt: skip
    args = ap.parse_args()
    d0, d1 = (int(x) for x in args.days.split("-"))
    params = dict(_param(a, ap) for a in args.param)
    sc = load_scenario(SCENARIO)
    sc.localizers[:] = [c.model_copy(update={"params": {**c.params, **params}})
                        for c in sc.localizers if c.name == "adaptive-memory"]  # fmt: skip
    tally = Tally()
    with instrumented(tally, args.from_day):
        run_experiment(sc, out_dir=args.out, days=(d0, d1), seed=args.seed, workers=1,
                       keep_scans=True, progress=False, overwrite=True)  # fmt: skip
    print(f"{SCENARIO.name}, seed {args.seed}, days {d0}-{d1}, scored from day {args.from_day}")
    print("\n".join(report(tally)))


if __name__ == "__main__":
    main()
