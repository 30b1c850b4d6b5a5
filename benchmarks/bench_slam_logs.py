"""The first-run mapper on real robot logs: Kümmerle et al. 2009's relation error (issue 16).

Maps the Radish logs FR079 and MIT CSAIL (raw wheel odometry) with
:class:`~dynmap_sim.agent.mapping.first_run.FirstRunMapper`, exactly as ``dynmap-sim
slam-eval`` does, and prints the issue's table: the project's loop-closed trajectory next to
the published figures (translation error mean ± std [m]), with the rotation error, raw
odometry's and the front end's error, the number of loop closures, mapping speed (scans/s)
and back-end time.

The logs are read from ``../shared/data/slam-benchmark`` (next to the repository) or from
``--data DIR``; without them the script says so and exits 0 (a clean clone has none).

    nice python benchmarks/bench_slam_logs.py [--data DIR] [--logs fr079 csail] \
        [--mapper-params '{"seed_verify": false}']
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from dynmap_sim.agent.mapping.first_run import FirstRunConfig
from dynmap_sim.experiments.slam_eval import slam_eval

#: name -> (log, relations, published translation errors "mean ± std" [m]:
#: GMapping, graph mapping (Kümmerle et al. 2009), Cartographer (Hess et al. 2016, Table II)).
LOGS = {
    "fr079": (
        "fr079.raw.log.gz",
        "fr079.relations",
        ("0.061 ± 0.044", "0.056 ± 0.042", "0.045 ± 0.035"),
    ),
    "csail": (
        "mit-csail.raw.log.gz",
        "mit-csail.relations",
        ("0.049 ± 0.049", "0.004 ± 0.009", "0.032 ± 0.036"),
    ),
}
DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "slam-benchmark"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder of the logs")
    ap.add_argument("--logs", nargs="+", default=list(LOGS), choices=list(LOGS), help="logs to map")
    ap.add_argument(
        "--mapper-params",
        type=json.loads,
        default={},
        help="first-run mapper parameters as JSON, e.g. '{\"seed_window\": [0, 0]}' (seed off)",
    )
    args = ap.parse_args()
    config = FirstRunConfig.from_params(**args.mapper_params)
    missing = [
        args.data / f for name in args.logs for f in LOGS[name][:2] if not (args.data / f).exists()
    ]
    if missing:
        print(f"skipped: the benchmark's logs are not there ({missing[0]}); give --data DIR")
        return 0
    rows = []
    for name in args.logs:
        log, rel, published = LOGS[name]
        print(f"mapping {name} ...", file=sys.stderr, flush=True)
        rows.append((name, slam_eval(args.data / log, args.data / rel, config=config), published))
    print()
    print(
        "| log | first-run SLAM, relation error [m] | rotation [deg] | GMapping | graph mapping "
        "| Cartographer (Hess 2016) |"
    )
    print("|---|---|---|---|---|---|")
    for name, r, pub in rows:
        lc = r.loop_closed
        print(
            f"| {name} | {lc.translation_mean_m:.3f} ± {lc.translation_std_m:.3f} "
            f"| {lc.rotation_mean_deg:.2f} ± {lc.rotation_std_deg:.2f} | {' | '.join(pub)} |"
        )
    print()
    print(
        "| log | scans | raw odometry [m] | front end [m] | relations < 30 s [m] | loop closures "
        "| scans/s | front end [s] | back end [s] |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, r, _ in rows:
        o, f, s = r.odometry_error, r.front_end_error, r.short_error
        print(
            f"| {name} | {r.n_scans} | {o.translation_mean_m:.3f} | {f.translation_mean_m:.3f} "
            f"| {s.translation_mean_m:.3f} | {r.n_loop_closures} | {r.scans_per_s:.0f} "
            f"| {r.front_end_s:.1f} | {r.back_end_s:.1f} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
