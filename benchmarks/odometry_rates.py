"""The odometry error rates behind ``dynamic-map``'s ``C_O`` (B&D §4.3: "acquired
experimentally"): ``python benchmarks/odometry_rates.py``.

For each shipped tour scenario it simulates the first ``--days`` with dead reckoning only and
compares the odometry with the truth; for the FR079 log (when ``--data`` holds it) the raw
odometry with the corrected poses. It prints the rates of
:func:`~dynmap_sim.agent.localization.odometry_calibration.odometry_error_rates` (the 0.9
quantile over 10-scan windows of the error per unit of motion) next to the rates
``dynamic-map`` uses: its configured ``odom_k_xy`` / ``odom_k_th`` in the simulator, and the
rates it acquires from a given map's run in a replay (``odom_calibration``).
"""

from __future__ import annotations

import argparse
import sqlite3
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

from dynmap_sim.agent.localization.dynamic_map_localizer import DynamicMapConfig
from dynmap_sim.agent.localization.odometry_calibration import odometry_error_rates
from dynmap_sim.cli import day_range
from dynmap_sim.experiments.runner import run_experiment
from dynmap_sim.experiments.scenario import LocalizerConfig, load_scenario

ROOT = Path(__file__).resolve().parents[1]
SCENARIOS = ("apartment-28d", "lab-5w", "office-tour", "corridor-tour", "hall-tour")


def simulated(name: str, days: tuple[int, int]) -> list[tuple[str, float, float]]:
    """(run, k_xy, k_th) of each run of ``days`` of scenario ``name``, dead reckoning only."""
    sc = load_scenario(ROOT / "worlds" / "scenarios" / f"{name}.toml")
    sc = sc.model_copy(update={"localizers": [LocalizerConfig(name="odometry")]})
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        run_experiment(sc, Path(tmp) / "r", days=days, progress=False, workers=1)
        con = sqlite3.connect(Path(tmp) / "r" / "results.db")
        runs = con.execute("SELECT DISTINCT day, run FROM scans ORDER BY day, run").fetchall()
        for day, run in runs:
            q = (
                "SELECT s.x, s.y, s.theta, e.x, e.y, e.theta FROM scans s JOIN estimates e"
                " ON e.day = s.day AND e.run = s.run AND e.step = s.step"
                " WHERE s.day = ? AND s.run = ? AND e.loc = 0 ORDER BY s.step"
            )
            a = np.array(con.execute(q, (day, run)).fetchall(), dtype=np.float64)
            rates = odometry_error_rates(a[:, 3:], a[:, :3])
            if rates is not None:
                rows.append((f"day {day} run {run}", rates.k_xy, rates.k_th))
        con.close()
    return rows


def fr079(data: Path) -> tuple[float, float, int] | None:
    """The FR079 Pioneer's rates (raw odometry against the corrected poses), or None."""
    from dynmap_sim.experiments.reference import load_reference
    from dynmap_sim.io.carmen import read_carmen

    log, ref = data / "fr079.raw.log.gz", data / "fr079-corrected.log.gz"
    if not (log.is_file() and ref.is_file()):
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the reader's note on the log's reversing
        carmen = read_carmen(log)
    match = load_reference(ref, carmen, None, 0.05)
    rates = odometry_error_rates(carmen.odometry, match.poses)
    return None if rates is None else (rates.k_xy, rates.k_th, rates.n_windows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--days",
        type=day_range,
        default=(1, 1),
        help="day range simulated in each scenario, e.g. 1-2 (default: 1)",
    )
    ap.add_argument(
        "--data",
        type=Path,
        default=ROOT.parent / "shared" / "data" / "slam-benchmark",
        help="folder of the FR079 log and its corrected poses (skipped when absent)",
    )
    ap.add_argument(
        "--scenarios",
        default=",".join(SCENARIOS),
        help=f"comma-separated shipped scenarios (default: {','.join(SCENARIOS)})",
    )
    args = ap.parse_args(argv)
    names = [s.strip() for s in args.scenarios.split(",") if s.strip()]
    unknown = [n for n in names if not (ROOT / "worlds" / "scenarios" / f"{n}.toml").is_file()]
    if unknown:
        ap.error(f"--scenarios: no such shipped scenario {unknown}")
    c = DynamicMapConfig()
    print("odometry error rates, 0.9 quantile over 10-scan windows (k_xy, k_th):")
    print(f"  dynamic-map's configured C_O rates: {c.odom_k_xy:.4f}, {c.odom_k_th:.4f}")
    for name in names:
        for run, kxy, kth in simulated(name, args.days):
            print(f"  {name:15s} {run:14s} {kxy:.4f}  {kth:.4f}")
        sys.stdout.flush()
    pioneer = fr079(args.data)
    if pioneer is None:
        print(f"  FR079: no log in {args.data} (skipped)")
    else:
        print(
            f"  FR079 Pioneer (raw odometry vs corrected, {pioneer[2]} windows) "
            f"{pioneer[0]:.4f}  {pioneer[1]:.4f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
