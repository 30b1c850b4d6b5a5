"""The first-run mapper on real robot logs: Kümmerle et al. 2009's relation error.

Maps every Radish log present (FR079, MIT CSAIL, the Freiburg hospital and the hospital's
ROS 1 bag; raw wheel odometry) with :class:`~dynmap_sim.agent.mapping.first_run.FirstRunMapper`,
exactly as ``dynmap-sim slam-eval`` does, and prints the issue's table: the project's
loop-closed trajectory next to the published figures (translation error mean ± std [m]), with
the rotation error, raw odometry's and the front end's error, the correlative closures kept
and the ICP round's loop edges, mapping speed (scans/s) and back-end time, the CPU time and
how many times faster than real time that is (one core), and writes a figure of each map with
its trajectory (``--figures DIR``).

The logs are read from ``../shared/data/slam-benchmark`` (next to the repository) or from
``--data DIR``; without them the script says so and exits 0 (a clean clone has none).

    nice python benchmarks/bench_slam_logs.py [--data DIR] [--logs fr079 csail clinic ...] \
        [--mapper-params '{"seed_verify": false}'] [--figures DIR]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from dynmap_sim.agent.mapping.first_run import FirstRunConfig
from dynmap_sim.experiments.slam_eval import slam_eval

#: The hospital's published translation errors (Kümmerle et al. 2009; no Cartographer figure).
_CLINIC_PUBLISHED = ("0.637 ± 2.638", "0.143 ± 0.180", "-")
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
    "clinic": (
        "fr-clinic.raw.log.gz",
        "fr-clinic.relations",
        _CLINIC_PUBLISHED,
    ),
    # The same log as a ROS 1 bag: the same ranges and stamps, beam angles in float32. A
    # mapper robust to that rounding gives the same figure as from the CARMEN file.
    "clinic-bag": (
        "fr-clinic.orig.bag",
        "fr-clinic.relations",
        _CLINIC_PUBLISHED,
    ),
}
_HERE = Path(__file__).resolve()
#: ``../shared/data/slam-benchmark`` next to the repository (or next to its worktrees' folder)
DEFAULT_DATA = next(
    (
        p / "shared" / "data" / "slam-benchmark"
        for p in (_HERE.parents[2], _HERE.parents[3])
        if (p / "shared" / "data" / "slam-benchmark").is_dir()
    ),
    _HERE.parents[2] / "shared" / "data" / "slam-benchmark",
)


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
    ap.add_argument("--figures", type=Path, help="write each map with its trajectory here (PNG)")
    args = ap.parse_args()
    config = FirstRunConfig.from_params(**args.mapper_params)
    present = [n for n in args.logs if all((args.data / f).exists() for f in LOGS[n][:2])]
    if not present:
        print(f"skipped: the benchmark's logs are not in {args.data}; give --data DIR")
        return 0
    rows = []
    for name in present:
        log, rel, published = LOGS[name]
        print(f"mapping {name} ...", file=sys.stderr, flush=True)
        res = slam_eval(args.data / log, args.data / rel, config=config)
        rows.append((name, res, published))
        if args.figures is not None:
            _figure(args.figures / f"{name}.png", name, res)
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
        "| log | scans | raw odometry [m] | front end [m] | relations < 30 s [m] | closures kept "
        "| ICP loop edges | scans/s | front end [s] | back end [s] | CPU [s] | x real time (CPU) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, r, _ in rows:
        o, f, s = r.odometry_error, r.front_end_error, r.short_error
        cpu = r.front_end_cpu_s + r.back_end_cpu_s
        print(
            f"| {name} | {r.n_scans} | {o.translation_mean_m:.3f} | {f.translation_mean_m:.3f} "
            f"| {s.translation_mean_m:.3f} | {r.closure_search.get('consistent', 0)} "
            f"| {r.n_loop_closures} | {r.scans_per_s:.0f} "
            f"| {r.front_end_s:.1f} | {r.back_end_s:.1f} | {cpu:.1f} | {r.realtime_factor:.1f} |"
        )
    return 0


def _figure(path: Path, name: str, r) -> None:  # r: SlamEval
    """The loop-closed trajectory over the front end's and the raw odometry's, so that a
    broken map shows at a glance."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(7, 7))
    ax.plot(r.front_end[:, 0], r.front_end[:, 1], lw=0.6, color="0.6", label="front end")
    ax.plot(r.trajectory[:, 0], r.trajectory[:, 1], lw=0.8, color="C0", label="loop-closed")
    lc = r.loop_closed
    ax.set_title(
        f"{name}: {lc.translation_mean_m:.3f} ± {lc.translation_std_m:.3f} m, "
        f"{lc.rotation_mean_deg:.2f} ± {lc.rotation_std_deg:.2f} deg"
    )
    ax.set_aspect("equal")
    ax.legend(loc="best")
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
