"""Measure static-mcl on the apartment's static week 1 (days 1-7) through the experiment runner.

Day 1 is the first run: ``map_source="first-run"`` localizers report their SLAM front end's
estimates and build the map at the end of it; days 2-7 localize on that fixed map. The
``prior-walls`` variants localize on the walls the prior grants from day 1 on. Prints, per
localizer, the mean and max position error over the week, the lost fraction (> 0.5 m) and
per-day means, and checks the baseline's bar (tuned: mean <= 0.05 m, max <= 0.20 m, never
lost).

    python benchmarks/mcl_apartment_week1.py --out /tmp/mcl-week1 [--days 1-7] [--force]
"""

from __future__ import annotations

import argparse
import sqlite3
import time
from pathlib import Path

import numpy as np

from dynmap_sim.errors import InputError
from dynmap_sim.experiments.runner import run_experiment
from dynmap_sim.experiments.scenario import parse_scenario


def scenario(days: tuple[int, int], seed: int, people: bool) -> dict:
    return {
        "name": "mcl-apartment-week1",
        "world": "apartment",
        "days": list(days),
        "seeds": [seed],
        "people": people,
        "driver": {"kind": "tour"},
        "prior": {"map": "walls", "initial_pose": "known"},
        "localizers": [
            {"name": "odometry"},
            {"name": "static-mcl", "label": "tuned", "params": {"config": "tuned"}},
            {"name": "static-mcl", "label": "nav2", "params": {"config": "nav2-default"}},
            {
                "name": "static-mcl",
                "label": "tuned-walls",
                "params": {"config": "tuned", "map_source": "prior-walls"},
            },
        ],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="results folder")
    ap.add_argument("--days", default="1-7", help="day range, e.g. 1-7")
    ap.add_argument("--seed", type=int, default=0, help="world and noise seed")
    ap.add_argument("--no-people", action="store_true", help="the world without its people")
    ap.add_argument("--force", action="store_true", help="replace earlier results in --out")
    args = ap.parse_args()
    a, _, b = args.days.partition("-")
    days = (int(a), int(b or a))
    sc = parse_scenario(scenario(days, args.seed, not args.no_people))
    t0 = time.perf_counter()
    try:
        out = run_experiment(sc, args.out, seed=args.seed, progress=False, overwrite=args.force)
    except InputError as exc:  # e.g. earlier results in --out without --force
        raise SystemExit(f"error: {exc}") from None
    print(f"ran days {days[0]}-{days[1]} in {time.perf_counter() - t0:.0f} s -> {out}")
    con = sqlite3.connect(Path(out) / "results.db")
    labels = [r[0] for r in con.execute("SELECT label FROM localizers ORDER BY idx")]
    for k, lab in enumerate(labels):
        err = np.array(
            [r[0] for r in con.execute("SELECT err_m FROM estimates WHERE loc=?", (k,))], float
        )
        per_day = con.execute(
            "SELECT day, mean_error_m, max_error_m FROM run_summaries WHERE loc=? ORDER BY day",
            (k,),
        ).fetchall()
        days_txt = " ".join(f"d{d}:{m:.3f}/{x:.3f}" for d, m, x in per_day)
        print(
            f"{lab:>12}: mean {np.nanmean(err):.3f} m  max {np.nanmax(err):.3f} m  "
            f"lost {np.mean(err > 0.5):.3f}  n={len(err)}  [{days_txt}]"
        )
        if lab == "tuned":
            ok = np.nanmean(err) <= 0.05 and np.nanmax(err) <= 0.20 and not np.any(err > 0.5)
            print(f"{'':>12}  bar (mean<=0.05, max<=0.20, never lost): {'PASS' if ok else 'FAIL'}")


if __name__ == "__main__":
    main()
