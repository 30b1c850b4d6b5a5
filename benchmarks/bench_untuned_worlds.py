"""Measure the localizers on the three worlds nobody tuned them for (issue 16).

Runs the tour scenarios of the office floor (``worlds/scenarios/office-tour.toml``), the
hospital ward with its 28 m corridor (``corridor-tour.toml``) and the library hall with its
two mirror-image study rooms (``hall-tour.toml``) through the experiment engine, each into a
folder of its own (a temporary one unless ``--out`` is given), and prints one table: per
world and localizer the ATE RMSE, the mean and the largest position error, the lost fraction
(error > 0.5 m) and whether the localizer meets the issue's bar: ATE RMSE <= 0.10 m and no
error above 0.5 m (odometry is shown for the drift, not judged). Then the per-day mean errors
and the wall time of each world's run.

It measures, it does not tune: the scenarios' localizer settings are used as they are.

    python benchmarks/bench_untuned_worlds.py                  # all days: about 5 min a world
    python benchmarks/bench_untuned_worlds.py --days 1-2 --worlds corridor,hall
    python benchmarks/bench_untuned_worlds.py --out /tmp/untuned   # keep the results folders
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

from dynmap_sim.analysis.report import overall_stats
from dynmap_sim.cli import day_range
from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.experiments.runner import run_experiment
from dynmap_sim.experiments.scenario import load_scenario

SCENARIOS = Path(__file__).resolve().parents[1] / "worlds" / "scenarios"
#: world name -> its tour scenario
WORLDS = {
    "office": SCENARIOS / "office-tour.toml",
    "corridor": SCENARIOS / "corridor-tour.toml",
    "hall": SCENARIOS / "hall-tour.toml",
}
#: the issue's bar: ATE RMSE at most this [m] ...
BAR_ATE_M = 0.10
#: ... and no position error above this [m]
BAR_MAX_M = 0.5


def world_list(text: str) -> list[str]:
    """Comma-separated names out of :data:`WORLDS`."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    bad = [n for n in names if n not in WORLDS]
    if bad or not names:
        raise argparse.ArgumentTypeError(f"worlds are some of {', '.join(WORLDS)}, not {text!r}")
    return names


def measure(world: str, out: Path, days: tuple[int, int] | None, seed: int, workers: int):
    """Run ``world``'s tour into ``out``; its overall rows, per-day means and wall time [s]."""
    scn = load_scenario(WORLDS[world])
    t0 = time.perf_counter()
    run_experiment(scn, out, days=days, seed=seed, progress=False, overwrite=True, workers=workers)
    wall_s = time.perf_counter() - t0
    with ResultsDB.open(out) as db:
        rows = overall_stats(db)
        per_day = {
            label: db.query(
                "SELECT day, mean_error_m FROM day_summaries WHERE loc=? ORDER BY day", (k,)
            )
            for k, label in enumerate(db.labels())
        }
    return rows, per_day, wall_s


def verdict(label: str, ate_m: float, max_m: float) -> str:
    if label == "odometry":
        return "(drift)"
    ok = ate_m <= BAR_ATE_M and max_m <= BAR_MAX_M and not math.isnan(ate_m)
    return "yes" if ok else "NO"


def add_tour_arguments(ap: argparse.ArgumentParser) -> None:
    """The options of a run of the worlds' tours: ``--days``, ``--worlds``, ``--seed``,
    ``--workers``, ``--out``, ``--force`` (also :mod:`mcl_untuned_variants`'s)."""
    ap.add_argument(
        "--days",
        type=day_range,
        help="day range for every world, e.g. 1-2 (default: each scenario's whole calendar)",
    )
    ap.add_argument(
        "--worlds",
        type=world_list,
        default=list(WORLDS),
        help=f"comma-separated worlds to run (default: {','.join(WORLDS)})",
    )
    ap.add_argument("--seed", type=int, default=0, help="world and noise seed (default: 0)")
    ap.add_argument(
        "--workers",
        type=int,
        default=1,
        help="localizer worker processes per run (default: 1, sequential in-process)",
    )
    ap.add_argument(
        "--out",
        type=Path,
        help="keep each world's results in OUT/<world> (default: a temporary folder, removed)",
    )
    ap.add_argument("--force", action="store_true", help="replace results already in OUT/<world>")


def check_out(ap: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """Refuse (before anything runs) to replace results in ``--out`` without ``--force``."""
    if args.out is None or args.force:
        return
    taken = [args.out / w for w in args.worlds if (args.out / w).exists()]
    taken = [d for d in taken if not d.is_dir() or any(d.iterdir())]
    if taken:
        ap.error(f"{taken[0]} already holds results; give --force to replace them")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_tour_arguments(ap)
    args = ap.parse_args()
    check_out(ap, args)
    with tempfile.TemporaryDirectory(prefix="untuned-worlds-") as tmp:
        base = args.out if args.out is not None else Path(tmp)
        results = {w: measure(w, base / w, args.days, args.seed, args.workers) for w in args.worlds}
    head = ("world", "localizer", "ATE RMSE [m]", "mean [m]", "max [m]", "lost", "bar")
    table = [head]
    for world, (rows, _, _) in results.items():
        for r in rows:
            table.append(
                (
                    world,
                    r["localizer"],
                    f"{r['ate_rmse_m']:.3f}",
                    f"{r['mean_error_m']:.3f}",
                    f"{r['max_error_m']:.3f}",
                    f"{100.0 * r['lost_fraction']:.1f} %",
                    verdict(r["localizer"], r["ate_rmse_m"], r["max_error_m"]),
                )
            )
    widths = [max(len(row[j]) for row in table) for j in range(len(head))]
    days = "all days" if args.days is None else f"days {args.days[0]}-{args.days[1]}"
    print(
        f"untuned worlds, {days}, seed {args.seed}; bar: ATE <= {BAR_ATE_M} m, max <= {BAR_MAX_M} m"
    )
    for row in table:
        print(
            "  ".join(
                c.ljust(w) if j < 2 else c.rjust(w)
                for j, (c, w) in enumerate(zip(row, widths, strict=True))
            )
        )
    print()
    for world, (_, per_day, wall_s) in results.items():
        print(f"{world}: {wall_s:.0f} s wall; per-day mean error [m]")
        for label, pd in per_day.items():
            print(f"  {label:>18}: " + " ".join(f"d{d}:{m:.3f}" for d, m in pd))


if __name__ == "__main__":
    main()
