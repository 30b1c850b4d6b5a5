"""The temporal maps of a benchmark folder against the truth, over its worlds.

For every finished world of a benchmark (``dynmap-sim benchmark SUITE``) whose localizers
include ``fremen`` or ``markov-grid``, the temporal-map study's per-run agreement
(:func:`dynmap_sim.studies.temporal_maps.agreement.map_agreement`: each run's predicted map,
made before the run, against the run's true world); per localizer and week, over the worlds:
the mean of each world's changing-cell precision, recall and F1 with a 95 % percentile
bootstrap interval over worlds, and the mean absolute error of the predicted occupancy of
the doors whose leaf moves. Writes ``temporal_map_weeks.png`` and ``temporal_map_weeks.csv``
into the folder and prints the table.

    python benchmarks/temporal_map_agreement.py results/benchmark-periodic-apartments
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

from dynmap_sim.errors import InputError
from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.experiments.sweep import read_index
from dynmap_sim.metrics.intervals import bootstrap_interval
from dynmap_sim.plot_style import localizer_color
from dynmap_sim.studies.temporal_maps.agreement import MapAgreement, map_agreement
from dynmap_sim.studies.temporal_maps.study import changing_f1


def world_weeks(folder: Path, colours: dict[str, int]) -> dict[str, dict[str, dict[int, float]]]:
    """``{label: {measure: {week: value}}}`` of one world (measures ``precision``,
    ``recall``, ``f1`` on the changing cells and ``door_mae``); ``colours`` gets each
    label's localizer index (its colour in every figure)."""
    with ResultsDB.open(folder) as db:
        agreements, doors = map_agreement(db)
    out: dict[str, dict[str, dict[int, float]]] = {}
    for a in agreements:
        colours.setdefault(a.label, a.loc)
        weeks, f1 = changing_f1(a)
        _, p = a.weekly(a.changing_precision)
        _, r = a.weekly(a.changing_recall)
        m = out.setdefault(a.label, {})
        for name, values in (("precision", p), ("recall", r), ("f1", f1)):
            m[name] = {int(w): float(v) for w, v in zip(weeks, values, strict=True)}
        m["door_mae"] = _door_mae(a, doors)
    return out


def _door_mae(a: MapAgreement, doors: list) -> dict[int, float]:
    """Per week, the mean |predicted - true| occupancy of the moving doors' cells."""
    week_of_day = dict(zip(a.day.tolist(), a.week.tolist(), strict=True))
    errs: dict[int, list[float]] = {}
    for door in doors:
        err = np.abs(door.predicted[a.label] - door.truth)
        for d, e in zip(door.day.tolist(), err.tolist(), strict=True):
            if np.isfinite(e) and d in week_of_day:
                errs.setdefault(week_of_day[d], []).append(e)
    return {w: float(np.mean(v)) for w, v in sorted(errs.items())}


Data = dict[str, dict[str, dict[int, list[float]]]]


def collect(bench: Path, colours: dict[str, int]) -> Data:
    """``{label: {measure: {week: [value per world]}}}`` over the benchmark's done worlds
    (``colours``: as :func:`world_weeks`)."""
    runs = bench / "runs"
    if not (runs / "sweep.json").is_file():
        raise InputError(f"{bench}: no benchmark here (no runs/sweep.json)")
    out: dict[str, dict[str, dict[int, list[float]]]] = {}
    for entry in read_index(runs)["cells"]:
        if entry["status"] != "done":
            continue
        for label, measures in world_weeks(runs / entry["dir"], colours).items():
            for name, weeks in measures.items():
                for w, v in weeks.items():
                    out.setdefault(label, {}).setdefault(name, {}).setdefault(w, []).append(v)
    if not out:
        raise InputError(f"{bench}: no finished world with a fremen or markov-grid")
    return out


MEASURES = ("precision", "recall", "f1", "door_mae")


def table(data: Data) -> list[list[str]]:
    """Rows ``label, week, worlds, then each measure as 'mean [lo, hi]'``."""
    rows = []
    for label, measures in data.items():
        for w in sorted(measures["f1"]):
            cells = []
            for name in MEASURES:
                values = measures.get(name, {}).get(w, [])
                b = bootstrap_interval(values, "mean")
                cells.append(f"{b.value:.3f} [{b.low:.3f}, {b.high:.3f}]" if values else "")
            rows.append([label, str(w), str(len(measures["f1"][w])), *cells])
    return rows


def plot(data: Data, colours: dict[str, int], path: Path) -> Path:
    """Changing-cell F1 and door error per week, mean over worlds with its interval."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for k, (label, measures) in enumerate(data.items()):
        for ax, name in zip(axes, ("f1", "door_mae"), strict=True):
            weeks = sorted(measures.get(name, {}))
            if not weeks:
                continue
            b = [bootstrap_interval(measures[name][w], "mean") for w in weeks]
            y = np.array([x.value for x in b])
            lo, hi = np.array([x.low for x in b]), np.array([x.high for x in b])
            ax.errorbar(np.array(weeks) + 0.06 * k, y, yerr=[y - lo, hi - y], marker="o",
                        capsize=3, color=localizer_color(colours.get(label, k)),
                        label=label)  # fmt: skip
    axes[0].set_title("changing cells: F1 of the predicted occupied cells", fontsize=10)
    axes[1].set_title("moving doors: mean |predicted - true| occupancy", fontsize=10)
    for ax in axes:
        ax.set_xlabel("calendar week")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle("Each run's predicted map against its truth: mean over worlds, 95 % interval")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("bench", type=Path, help="benchmark folder (dynmap-sim benchmark --out)")
    args = ap.parse_args(argv)
    colours: dict[str, int] = {}
    try:
        data = collect(args.bench, colours)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    rows = table(data)
    head = ["localizer", "week", "worlds", "changing P", "changing R", "changing F1", "door MAE"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for r in rows:
        print("| " + " | ".join(r) + " |")
    with open(args.bench / "temporal_map_weeks.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(head)
        w.writerows(rows)
    print(plot(data, colours, args.bench / "temporal_map_weeks.png"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
