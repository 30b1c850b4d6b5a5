"""Localization with raw odometry on a real robot log, scored against its corrected poses
(issue 16: "no jumps"; mean, max, lost, scans/s).

Replays the Radish log FR079 (raw wheel odometry) exactly as ``dynmap-sim replay
fr079.raw.log.gz --localizer L ... --map-from-log-poses --reference fr079-corrected.log.gz``
does: every localizer gets the map of the keyframe scans at the corrected poses (a grid for
``static-mcl``, the scans for ``dynamic-map``), then localizes twice on the raw log (pass 1,
pass 2); errors only where a corrected pose matches a scan by time stamp. Printed per
localizer and pass: mean, max error [m], the share of scans more than 1 m off and lost
(> 0.5 m), and the update speed in scans/s (CPU of ``update()`` alone). CSAIL has no
corrected log, so it cannot be scored this way. ``--seeds 0-4`` replays once per seed (``replay
--seed``: another draw of every particle filter) and adds the spread over the seeds per
localizer and pass.

The logs are read from ``../shared/data/slam-benchmark`` (next to the repository) or from
``--data DIR``; without them the script says so and exits 0 (a clean clone has none).

    python benchmarks/bench_localization_logs.py [--data DIR] [--seeds 0-4] \
        [--localizer static-mcl --localizer dynamic-map ...]
"""

from __future__ import annotations

import argparse
import sqlite3
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from dynmap_sim.cli import seed_list
from dynmap_sim.errors import InputError
from dynmap_sim.experiments.replay import replay_log
from dynmap_sim.io.carmen import CarmenOdometryWarning

LOG, REFERENCE = "fr079.raw.log.gz", "fr079-corrected.log.gz"
DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "slam-benchmark"
DEFAULT_LOCALIZERS = ["static-mcl", "static-mcl,config=nav2-default", "dynamic-map"]


def pass_rows(db: Path, localizers: list[str]) -> list[tuple[str, int, np.ndarray, float]]:
    """``(localizer, pass, errors [m], update ms a scan)`` of a replay's results folder."""
    con = sqlite3.connect(db / "results.db")
    rows = []
    for loc, label in enumerate(localizers):
        for day in (1, 2):
            err = np.array(
                [
                    e
                    for (e,) in con.execute(
                        "SELECT err_m FROM estimates WHERE loc=? AND day=? AND err_m IS NOT NULL",
                        (loc, day),
                    )
                ]
            )
            (ms,) = con.execute(
                "SELECT update_ms_per_scan FROM run_summaries WHERE loc=? AND day=?", (loc, day)
            ).fetchone()
            rows.append((label, day, err, float(ms)))
    con.close()
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder of the logs")
    ap.add_argument(
        "--localizer",
        action="append",
        help="a localizer by registry name with optional parameters; repeat "
        f"(default: {', '.join(DEFAULT_LOCALIZERS)})",
    )
    ap.add_argument(
        "--seeds",
        type=seed_list,
        default=(0,),
        help="replay once per seed of the localizers' generators: 0-4, 0,2,5 or 7 (default: 0)",
    )
    args = ap.parse_args()
    log, ref = args.data / LOG, args.data / REFERENCE
    missing = [p for p in (log, ref) if not p.exists()]
    if missing:
        print(f"skipped: the benchmark's logs are not there ({missing[0]}); give --data DIR")
        return 0
    localizers = args.localizer or DEFAULT_LOCALIZERS
    notes: list[str] = []
    per_seed = {}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in tqdm(
            args.seeds, desc="FR079 replays", unit="seed", disable=len(args.seeds) < 2
        ):
            try:
                # each replay reads the same log: its odometry warnings go with the notes,
                # printed once after the replays (the other warnings as they came)
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always", CarmenOdometryWarning)
                    out = replay_log(
                        log, localizers, Path(tmp) / f"seed{seed}", map_from_log_poses=True,
                        note=notes.append, reference=ref, seed=seed,
                    )  # fmt: skip
            except InputError as exc:
                ap.error(str(exc))
            for w in caught:
                if issubclass(w.category, CarmenOdometryWarning):
                    notes.append(f"warning: {w.message}")
                else:
                    warnings.showwarning(w.message, w.category, w.filename, w.lineno)
            per_seed[seed] = pass_rows(out, localizers)
    for n in dict.fromkeys(notes):
        print(n)
    print(f"FR079, raw odometry, map from the corrected poses ({LOG} vs {REFERENCE})")
    print("| localizer | seed | pass | mean [m] | max [m] | > 1 m | lost (> 0.5 m) | scans/s |")
    print("|---|---|---|---|---|---|---|---|")
    for seed, rows in per_seed.items():
        for label, day, err, ms in rows:
            print(
                f"| {label} | {seed} | {day} | {err.mean():.3f} | {err.max():.2f} | "
                f"{100 * np.mean(err > 1.0):.1f} % | {100 * np.mean(err > 0.5):.1f} % | "
                f"{1000.0 / ms:.0f} |"
            )
    if len(per_seed) > 1:
        print(f"over {len(per_seed)} seeds, per localizer and pass:")
        for k, (label, day, _, _) in enumerate(next(iter(per_seed.values()))):
            errs = [rows[k][2] for rows in per_seed.values()]
            means = [e.mean() for e in errs]
            maxes = [e.max() for e in errs]
            jumped = sum(int(e.max() > 1.0) for e in errs)
            print(
                f"  {label} pass {day}: mean {min(means):.3f}-{max(means):.3f} m, max "
                f"{min(maxes):.2f}-{max(maxes):.2f} m, {jumped} of {len(errs)} with a jump "
                "over 1 m"
            )
    print("targets (issue 16): no jump over 1 m, mean <= 0.05 m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
