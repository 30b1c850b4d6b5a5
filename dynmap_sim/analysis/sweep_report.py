"""The report of a sweep (``dynmap-sim sweep``): error per day over seeds with 95 % intervals,
and paired differences between localizers, from the cells' results folders.

Writes into the sweep's folder:

* ``sweep_summary.csv`` — per scenario, parameter variant, localizer and day: the number of
  seeds, the mean over seeds of the day's mean position error, its sample standard deviation
  and 95 % confidence interval (Student t, :mod:`dynmap_sim.metrics.intervals`);
* ``sweep_paired.csv`` — paired differences per day, seed by seed: between the localizers
  of one variant (the later-listed minus the earlier, e.g. ``dynamic-map`` − ``static-mcl
  tuned``) and between the variants of a localizer whose parameters the sweep varies;
* ``sweep_error_per_day.png`` — the mean error per day with its interval as a band;
* ``sweep_summary.md`` — the cells, the whole-sweep numbers (each seed's mean over its days,
  then the interval over seeds), the tables above and how the intervals are made.

Only finished cells count; failed ones are listed in the summary.
"""

from __future__ import annotations

import csv
import math
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dynmap_sim.errors import InputError
from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.experiments.sweep import cell_finished, read_index
from dynmap_sim.metrics import CI_LEVEL, MeanInterval, mean_interval, paired_difference

SUMMARY_COLUMNS = (
    "scenario",
    "variant",
    "localizer",
    "day",
    "n_seeds",
    "mean_error_m",
    "sd_error_m",
    "ci95_low_m",
    "ci95_high_m",
)
PAIRED_COLUMNS = (
    "scenario",
    "variant_a",
    "localizer_a",
    "variant_b",
    "localizer_b",
    "day",
    "n_seeds",
    "mean_diff_m",
    "sd_diff_m",
    "ci95_low_m",
    "ci95_high_m",
)


@dataclass(frozen=True)
class Arm:
    """One line of the sweep: a localizer of a scenario with one set of parameter values."""

    scenario: str
    variant: str
    localizer: str

    @property
    def title(self) -> str:
        return self.localizer + (f" [{self.variant}]" if self.variant else "")


@dataclass
class SweepData:
    """The finished cells' day errors: ``errors[arm][day][seed]`` [m], arms in sweep order."""

    index: dict[str, Any]
    arms: list[Arm]
    errors: dict[Arm, dict[int, dict[int, float]]]
    failed: list[dict[str, Any]]
    n_done: int


def load_sweep(out_dir: str | Path) -> SweepData:
    """Read a sweep folder: ``sweep.json`` and the day summaries of its finished cells."""
    out = Path(out_dir)
    index = read_index(out)
    arms: dict[Arm, None] = {}
    errors: dict[Arm, dict[int, dict[int, float]]] = defaultdict(lambda: defaultdict(dict))
    failed = []
    n_done = 0
    for entry in index["cells"]:
        folder = out / entry["dir"]
        if not cell_finished(folder, entry["key"]):
            if entry.get("status") == "failed":
                failed.append(entry)
            continue
        n_done += 1
        with ResultsDB.open(folder) as db:
            labels = db.labels()
            rows = db.query("SELECT loc, day, mean_error_m FROM day_summaries ORDER BY loc, day")
        for label in labels:
            arms.setdefault(Arm(entry["scenario"], entry.get("variant", ""), label))
        for loc, day, err in rows:
            arm = Arm(entry["scenario"], entry.get("variant", ""), labels[int(loc)])
            errors[arm][int(day)][int(entry["seed"])] = math.nan if err is None else float(err)
    return SweepData(index, list(arms), errors, failed, n_done)


def _days(data: SweepData, arm: Arm) -> list[int]:
    return sorted(data.errors.get(arm, {}))


def _overall(data: SweepData, arm: Arm) -> dict[int, float]:
    """Each seed's mean over its days of the day's mean error."""
    per_seed: dict[int, list[float]] = defaultdict(list)
    for by_seed in data.errors.get(arm, {}).values():
        for seed, v in by_seed.items():
            per_seed[seed].append(v)
    return {
        s: float(np.nanmean(v)) if np.isfinite(v).any() else math.nan for s, v in per_seed.items()
    }


def summary_rows(data: SweepData) -> list[tuple[Arm, int, MeanInterval]]:
    """Per arm and day: the interval over seeds of the day's mean error."""
    out = []
    for arm in data.arms:
        for day in _days(data, arm):
            out.append((arm, day, mean_interval(list(data.errors[arm][day].values()))))
    return out


def arm_pairs(data: SweepData) -> list[tuple[Arm, Arm]]:
    """The paired comparisons ``(a, b)`` (``a - b``): localizers of one scenario and variant
    (the later-listed minus the earlier), and the variants of a localizer whose own
    parameters differ between them (the later variant minus the earlier)."""
    pairs = []
    for i, b in enumerate(data.arms):
        for a in data.arms[i + 1 :]:
            if a.scenario != b.scenario:
                continue
            if a.variant == b.variant and a.localizer != b.localizer:
                pairs.append((a, b))
            elif a.localizer == b.localizer and a.variant != b.variant:
                own = f"{a.localizer}."
                va = sorted(p for p in a.variant.split("; ") if p.startswith(own))
                vb = sorted(p for p in b.variant.split("; ") if p.startswith(own))
                if va != vb:
                    pairs.append((a, b))
    return pairs


def _paired(x: dict[int, float], y: dict[int, float]) -> MeanInterval:
    seeds = sorted(set(x) & set(y))
    return paired_difference([x[s] for s in seeds], [y[s] for s in seeds])


def paired_rows(data: SweepData) -> list[tuple[Arm, Arm, int, MeanInterval]]:
    """Per pair (:func:`arm_pairs`) and day: the interval of the per-seed differences."""
    out = []
    for a, b in arm_pairs(data):
        for day in sorted(set(_days(data, a)) & set(_days(data, b))):
            out.append((a, b, day, _paired(data.errors[a][day], data.errors[b][day])))
    return out


def overall_rows(data: SweepData) -> list[tuple[Arm, MeanInterval]]:
    """Per arm: the interval over seeds of each seed's mean over its days."""
    return [(arm, mean_interval(list(_overall(data, arm).values()))) for arm in data.arms]


def overall_paired_rows(data: SweepData) -> list[tuple[Arm, Arm, MeanInterval]]:
    """Per pair: the interval of the per-seed differences of the means over the days."""
    return [(a, b, _paired(_overall(data, a), _overall(data, b))) for a, b in arm_pairs(data)]


def _num(v: float, nd: int = 6) -> str:
    return "nan" if math.isnan(v) else f"{v:.{nd}f}"


def _write_csv(path: Path, columns: tuple[str, ...], rows: list[list[Any]]) -> Path:
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        w.writerows(rows)
    return path


def _ci_cells(m: MeanInterval) -> list[Any]:
    return [m.n, _num(m.mean), _num(m.sd), _num(m.low), _num(m.high)]


def write_summary_csv(data: SweepData, path: Path) -> Path:
    rows = [
        [arm.scenario, arm.variant, arm.localizer, day, *_ci_cells(m)]
        for arm, day, m in summary_rows(data)
    ]
    return _write_csv(path, SUMMARY_COLUMNS, rows)


def write_paired_csv(data: SweepData, path: Path) -> Path:
    rows = [
        [a.scenario, a.variant, a.localizer, b.variant, b.localizer, day, *_ci_cells(m)]
        for a, b, day, m in paired_rows(data)
    ]
    return _write_csv(path, PAIRED_COLUMNS, rows)


def _fig_error_per_day(data: SweepData, path: Path) -> Path:
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    from dynmap_sim.analysis.report import _legend_below

    scenarios = list(dict.fromkeys(a.scenario for a in data.arms))
    fig, axes = plt.subplots(
        len(scenarios), 1, figsize=(8, 3.6 * len(scenarios)), squeeze=False, sharex=False
    )
    rows = summary_rows(data)
    for ax, scn in zip(axes[:, 0], scenarios, strict=True):
        for arm in [a for a in data.arms if a.scenario == scn]:
            r = [(d, m) for a, d, m in rows if a == arm]
            days = np.array([d for d, _ in r], dtype=float)
            mean = np.array([m.mean for _, m in r])
            low = np.array([m.low for _, m in r])
            high = np.array([m.high for _, m in r])
            (line,) = ax.plot(days, mean, "o-", ms=4, label=arm.title)
            ax.fill_between(days, low, high, color=line.get_color(), alpha=0.2, lw=0)
            if len(days) == 1:  # a band needs two days: show the interval as a bar
                ax.errorbar(days, mean, yerr=[mean - low, high - mean], color=line.get_color())
        n_seeds = len({c["seed"] for c in data.index["cells"] if c["scenario"] == scn})
        ax.set_title(f"{scn}: mean position error per day, {CI_LEVEL:.0%} CI over {n_seeds} seeds")
        ax.set_xlabel("day")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_ylabel("position error [m]")
        ax.set_ylim(bottom=0.0)
        ax.grid(alpha=0.3)
    _legend_below(fig, list(axes[:, 0]))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _ci(m: MeanInterval, nd: int = 3) -> str:
    if math.isnan(m.mean):
        return "n/a"
    if math.isnan(m.low):
        return f"{m.mean:.{nd}f} (one seed: no interval)"
    return f"{m.mean:.{nd}f} [{m.low:.{nd}f}, {m.high:.{nd}f}]"


def _md_table(header: list[str], rows: list[list[str]]) -> list[str]:
    return [
        "| " + " | ".join(header) + " |",
        "|" + "|".join("---" for _ in header) + "|",
        *["| " + " | ".join(r) + " |" for r in rows],
    ]


def summary_md(data: SweepData) -> str:
    """``sweep_summary.md``: cells, whole-sweep numbers, per-day and paired tables."""
    idx = data.index
    n = len(idx["cells"])
    d = idx.get("definition", {})
    lines = [
        f"# Sweep {idx.get('name')}",
        "",
        f"{n} cells ({', '.join(d.get('scenarios', []))}; seeds {d.get('seeds')}"
        + (f"; days {d['days'][0]}-{d['days'][1]}" if d.get("days") else "")
        + (f"; set {d['set']}" if d.get("set") else "")
        + f"): {data.n_done} finished, {len(data.failed)} failed, "
        f"{n - data.n_done - len(data.failed)} not run.",
        "",
        f"Intervals: {CI_LEVEL:.0%} confidence intervals of the mean over seeds, Student t with "
        "n - 1 degrees of freedom (the spread is estimated from the same few seeds; the normal "
        "1.96 would be too narrow: with 4 seeds t = 3.18). Differences are paired seed by "
        "seed: both localizers saw the same world, people and sensor noise, so the variation "
        "common to both cancels.",
        "",
        "## Mean position error over the whole sweep [m]",
        "",
        "Each seed's mean over its days of the day's mean error; mean [95 % CI] over seeds.",
        "",
    ]
    lines += _md_table(
        ["scenario", "localizer", "seeds", "mean error [m]"],
        [[a.scenario, a.title, str(m.n), _ci(m)] for a, m in overall_rows(data)],
    )
    pairs = overall_paired_rows(data)
    if pairs:
        lines += ["", "## Paired differences over the whole sweep [m]", ""]
        lines += _md_table(
            ["scenario", "a − b", "seeds", "mean difference [m]", "verdict"],
            [
                [a.scenario, f"{a.title} − {b.title}", str(m.n), _ci(m), _verdict(a, b, m)]
                for a, b, m in pairs
            ],
        )
    lines += ["", "## Mean position error per day [m]", "", "![](sweep_error_per_day.png)", ""]
    lines += _md_table(
        ["scenario", "localizer", "day", "seeds", "mean [95 % CI]"],
        [[a.scenario, a.title, str(day), str(m.n), _ci(m)] for a, day, m in summary_rows(data)],
    )
    per_day = paired_rows(data)
    if per_day:
        lines += ["", "## Paired differences per day [m]", ""]
        lines += _md_table(
            ["scenario", "a − b", "day", "seeds", "mean difference [95 % CI]"],
            [
                [a.scenario, f"{a.title} − {b.title}", str(day), str(m.n), _ci(m)]
                for a, b, day, m in per_day
            ],
        )
    if data.failed:
        lines += ["", "## Failed cells", ""]
        lines += [
            f"- `{c['dir']}` ({c['scenario']}, seed {c['seed']}"
            + (f", {c['variant']}" if c.get("variant") else "")
            + f"): {str(c.get('error')).splitlines()[0] if c.get('error') else 'unknown error'}"
            for c in data.failed
        ]
    return "\n".join(lines) + "\n"


def _verdict(a: Arm, b: Arm, m: MeanInterval) -> str:
    """In words: which is lower, when the interval excludes zero."""
    if math.isnan(m.low):
        return "no interval"
    if m.high < 0:
        return f"{a.title} lower"
    if m.low > 0:
        return f"{b.title} lower"
    return "no clear difference"


def headline(out_dir: str | Path) -> list[str]:
    """A few lines for the terminal: each arm's whole-sweep mean error with its interval,
    and the paired differences."""
    data = load_sweep(out_dir)
    lines = [f"{a.scenario}  {a.title}: mean error {_ci(m)} m" for a, m in overall_rows(data)]
    lines += [
        f"{a.scenario}  {a.title} − {b.title}: {_ci(m)} m ({_verdict(a, b, m)})"
        for a, b, m in overall_paired_rows(data)
    ]
    return lines


def write_sweep_report(out_dir: str | Path) -> list[Path]:
    """Write ``sweep_summary.csv``, ``sweep_paired.csv``, ``sweep_error_per_day.png`` and
    ``sweep_summary.md`` into a sweep folder; InputError when no cell has finished."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    out = Path(out_dir)
    data = load_sweep(out)
    if data.n_done == 0:
        raise InputError(f"{out}: no finished cell to report on")
    written = [
        write_summary_csv(data, out / "sweep_summary.csv"),
        write_paired_csv(data, out / "sweep_paired.csv"),
        _fig_error_per_day(data, out / "sweep_error_per_day.png"),
    ]
    md = out / "sweep_summary.md"
    md.write_text(summary_md(data), encoding="utf-8")
    return [*written, md]
