"""The leaderboard of a benchmark folder: each localizer judged over many worlds.

Per world and localizer it takes the whole experiment's figures (ATE RMSE, maximum error,
lost share: :func:`dynmap_sim.metrics.overall_summary`; jumps: :func:`count_jumps`; for
driven runs the navigation measures). Over the worlds, each world is one sample: medians and
90th percentiles with percentile bootstrap intervals over worlds
(:func:`~dynmap_sim.metrics.intervals.bootstrap_interval`), the share of worlds that meet
the bar (:data:`BAR_ATE_M`, :data:`BAR_MAX_M`), and the paired per-world differences of
ATE against the baseline localizer. A world whose cell failed is listed, not averaged.
"""

from __future__ import annotations

import csv
import math
import re
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dynmap_sim.analysis.navigation import missed_goal_lines
from dynmap_sim.analysis.report import overall_of
from dynmap_sim.errors import InputError
from dynmap_sim.experiments.benchmark import read_benchmark
from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.experiments.sweep import read_index
from dynmap_sim.metrics.intervals import BootstrapInterval, bootstrap_interval
from dynmap_sim.metrics.jumps import count_jumps
from dynmap_sim.plot_style import localizer_color

#: A world passes for a localizer when its ATE RMSE is at most this [m] ...
BAR_ATE_M = 0.10
#: ... and no scan's error exceeds this [m] (the lost threshold).
BAR_MAX_M = 0.5
#: The odometry reference is reported but never ranked (it is no localizer).
REFERENCE_CLASSES = ("odometry",)
#: Worlds listed as the worst, with the command that re-runs each alone.
N_WORST = 10


@dataclass(frozen=True)
class WorldRow:
    """One localizer on one world."""

    world: str
    kind: str
    localizer: str
    ate_m: float
    max_m: float
    lost: float
    jumps: int
    wall_s: float
    goals: float = math.nan  # share of runs with the goal reached (driven runs)
    collisions: int = 0
    near_misses: int = 0
    stuck_s: float = 0.0

    @property
    def passes(self) -> bool:
        return self.ate_m <= BAR_ATE_M and self.max_m <= BAR_MAX_M


@dataclass(frozen=True)
class DayRow:
    """One localizer on one day of one world: that day's ATE RMSE [m]."""

    world: str
    localizer: str
    day: int
    ate_m: float


@dataclass(frozen=True)
class LocalizerScore:
    """One localizer over all worlds."""

    localizer: str
    n_worlds: int
    ate_median: BootstrapInterval
    ate_p90: BootstrapInterval
    max_median: BootstrapInterval
    passing: BootstrapInterval  # share of worlds meeting the bar
    vs_baseline: BootstrapInterval | None  # mean per-world ATE difference (this - baseline)
    jumps: int
    goals: float
    collisions: int


@dataclass
class Leaderboard:
    """What :func:`leaderboard` read and computed."""

    name: str
    out_dir: Path
    baseline: str | None
    rows: list[WorldRow]
    scores: list[LocalizerScore]
    failed: dict[str, str] = field(default_factory=dict)  # world -> error
    pending: list[str] = field(default_factory=list)
    references: tuple[str, ...] = ()  # labels of reference localizers (odometry): not ranked
    days: list[DayRow] = field(default_factory=list)
    #: world -> one line per driven run that missed its goal, saying why
    missed: dict[str, list[str]] = field(default_factory=dict)

    def worst(self, n: int = N_WORST) -> list[tuple[str, WorldRow]]:
        """The ``n`` worlds with the largest ATE of any ranked localizer, each with the row
        of that localizer."""
        ranked = [r for r in self.rows if r.localizer not in self.references]
        worst: dict[str, WorldRow] = {}
        for r in ranked:
            if r.world not in worst or _key(r) > _key(worst[r.world]):
                worst[r.world] = r
        order = sorted(worst.values(), key=_key, reverse=True)[:n]
        return [(r.world, r) for r in order]


def _key(r: WorldRow) -> float:
    return r.ate_m if math.isfinite(r.ate_m) else math.inf


def _world_of(entry: dict[str, Any]) -> str:
    return Path(entry.get("scenario_path") or entry["scenario"]).stem


def _days_of_cell(db: ResultsDB, world: str) -> list[DayRow]:
    labels = db.labels()
    return [
        DayRow(world, labels[int(loc)], int(day), math.nan if rmse is None else float(rmse))
        for loc, day, rmse in db.query("SELECT loc, day, rmse_m FROM day_summaries ORDER BY day")
    ]


def _rows_of_cell(folder: Path, world: str, kind: str, wall_s: float) -> list[WorldRow]:
    with ResultsDB.open(folder) as db:
        nav = db.query(
            "SELECT count(*), coalesce(sum(goal_reached), 0), coalesce(sum(collisions), 0), "
            "coalesce(sum(near_misses), 0), coalesce(sum(stuck_s), 0) FROM nav_runs"
        )[0]
        out = []
        for k, label in enumerate(db.labels()):
            s = overall_of(db, k)
            d = db.per_scan(k)
            runs = np.column_stack([d["day"], d["run"]])
            jumps = count_jumps(d["truth"], d["estimate"], runs)
            goals = nav[1] / nav[0] if nav[0] else math.nan
            out.append(
                WorldRow(
                    world,
                    kind,
                    label,
                    s.ate_rmse_m,
                    s.worst_error_m,
                    s.lost_fraction,
                    jumps,
                    wall_s,
                    goals,
                    int(nav[2]),
                    int(nav[3]),
                    float(nav[4]),
                )  # fmt: skip
            )
    return out


def _score(label: str, rows: list[WorldRow], base: dict[str, WorldRow] | None) -> LocalizerScore:
    ate = np.array([r.ate_m for r in rows])
    mx = np.array([r.max_m for r in rows])
    vs = None
    if base is not None:
        diffs = [r.ate_m - base[r.world].ate_m for r in rows if r.world in base]
        vs = bootstrap_interval(diffs, "mean")
    goals = [r.goals for r in rows if math.isfinite(r.goals)]
    return LocalizerScore(
        label,
        len(rows),
        bootstrap_interval(ate, "median"),
        bootstrap_interval(ate, "p90"),
        bootstrap_interval(mx, "median"),
        bootstrap_interval([float(r.passes) for r in rows], "share"),
        vs,
        sum(r.jumps for r in rows),
        float(np.mean(goals)) if goals else math.nan,
        sum(r.collisions for r in rows),
    )


def leaderboard(out_dir: str | Path) -> Leaderboard:
    """Read a benchmark folder (:mod:`dynmap_sim.experiments.benchmark`) into a
    :class:`Leaderboard`."""
    out = Path(out_dir)
    record = read_benchmark(out)
    kinds = {w["name"]: w.get("kind") or "file" for w in record["worlds"]}
    runs = out / "runs"
    if not (runs / "sweep.json").is_file():
        raise InputError(f"{out}: the benchmark has not run yet (no runs/sweep.json)")
    index = read_index(runs)
    rows: list[WorldRow] = []
    failed: dict[str, str] = {}
    pending: list[str] = []
    classes: dict[str, str] = {}
    days: list[DayRow] = []
    missed: dict[str, list[str]] = {}
    for entry in index["cells"]:
        world = _world_of(entry)
        if entry["status"] == "failed":
            failed[world] = str(entry.get("error")).splitlines()[0]
            continue
        if entry["status"] != "done":
            pending.append(world)
            continue
        folder = runs / entry["dir"]
        rows += _rows_of_cell(folder, world, kinds.get(world, "file"), entry.get("wall_s") or 0)
        with ResultsDB.open(folder) as db:
            classes |= {str(lb): str(n) for lb, n in db.query("SELECT label, name FROM localizers")}
            days += _days_of_cell(db, world)
            lines = missed_goal_lines(db)
            if lines:
                missed[world] = lines
    references = tuple(lb for lb, n in classes.items() if n in REFERENCE_CLASSES)
    labels = list(dict.fromkeys(r.localizer for r in rows))
    baseline = record.get("baseline") or next(
        (lb for lb in labels if classes.get(lb) == "static-mcl"), None
    )
    if baseline is not None and rows and baseline not in labels:
        raise InputError(f"{out}: baseline {baseline!r} is no localizer of the benchmark")
    base = {r.world: r for r in rows if r.localizer == baseline} if baseline else None
    scores = [
        _score(lb, [r for r in rows if r.localizer == lb], None if lb == baseline else base)
        for lb in labels
        if lb not in references
    ]
    return Leaderboard(
        record["name"], out, baseline, rows, scores, failed, pending, references, days, missed
    )


# ---------------------------------------------------------------------- writing
def _ci(b: BootstrapInterval | None, nd: int = 3) -> str:
    if b is None or math.isnan(b.value):
        return "—"
    if math.isnan(b.low):
        return f"{b.value:.{nd}f}"
    return f"{b.value:.{nd}f} [{b.low:.{nd}f}, {b.high:.{nd}f}]"


def _pct(b: BootstrapInterval) -> str:
    if math.isnan(b.value):
        return "—"
    if math.isnan(b.low):
        return f"{100 * b.value:.0f} %"
    return f"{100 * b.value:.0f} % [{100 * b.low:.0f}, {100 * b.high:.0f}]"


def leaderboard_md(board: Leaderboard) -> str:
    """``leaderboard.md``: the scores, the worst worlds with their commands, the failures."""
    n_worlds = len({r.world for r in board.rows})
    driven = any(math.isfinite(s.goals) for s in board.scores)
    lines = [
        f"# Leaderboard: {board.name}",
        "",
        f"{n_worlds} worlds; 95 % percentile bootstrap intervals over worlds; a world passes "
        f"with ATE ≤ {BAR_ATE_M} m and no error over {BAR_MAX_M} m. Baseline of the paired "
        f"differences: `{board.baseline}`.",
        "",
        "| localizer | ATE median [m] | ATE p90 [m] | max median [m] | worlds passing | "
        "ATE − baseline [m] | jumps > 0.5 m |" + (" goals | collisions |" if driven else ""),
        "|---|---|---|---|---|---|---|" + ("---|---|" if driven else ""),
    ]
    for s in board.scores:
        row = (
            f"| {s.localizer} | {_ci(s.ate_median)} | {_ci(s.ate_p90)} | {_ci(s.max_median)} | "
            f"{_pct(s.passing)} | {_ci(s.vs_baseline)} | {s.jumps} |"
        )
        if driven:
            goals = "—" if math.isnan(s.goals) else f"{100 * s.goals:.1f} %"
            row += f" {goals} | {s.collisions} |"
        lines.append(row)
    lines += ["", "## The worst worlds", ""]
    lines += ["| world | kind | worst localizer | ATE [m] | max [m] | re-run alone |"]
    lines += ["|---|---|---|---|---|---|"]
    for world, r in board.worst():
        cmd = (
            f"`dynmap-sim run {board.out_dir / 'scenarios' / (world + '.toml')} "
            f"--out {board.out_dir / 'rerun' / world} --report`"
        )
        lines.append(
            f"| {world} | {r.kind} | {r.localizer} | {r.ate_m:.3f} | {r.max_m:.3f} | {cmd} |"
        )
    wall = [r.wall_s for r in board.rows if r.localizer == board.rows[0].localizer]
    if wall:
        lines += [
            "",
            f"Time per world: median {np.median(wall):.0f} s, most {max(wall):.0f} s "
            f"(sum {sum(wall) / 60:.1f} min of worker time).",
        ]
    if board.missed:
        lines += ["", "## Goals not reached", "", _miss_tally(board.missed), ""]
        lines += [f"- {w}: {line}" for w, ls in board.missed.items() for line in ls]
    if board.failed:
        lines += ["", "## Failed worlds", ""] + [f"- {w}: {e}" for w, e in board.failed.items()]
    if board.pending:
        lines += ["", f"Not run yet: {', '.join(board.pending)} (the same command resumes)."]
    return "\n".join(lines) + "\n"


def _miss_tally(missed: dict[str, list[str]]) -> str:
    """How many of the runs named in ``missed`` ended for each cause the navigation stack
    gave (the bracket at the end of its ``unreachable`` event: ``no_way``, ``lost``,
    ``stuck``), the others as ``other``."""
    causes: Counter[str] = Counter()
    for ls in missed.values():
        for line in ls:
            if line.startswith("and "):
                continue
            m = re.search(r"\((\w+)\)$", line)
            causes[m.group(1) if m else "other"] += 1
    return "By cause: " + ", ".join(f"{k} {n}" for k, n in sorted(causes.items())) + "."


def leaderboard_headline(board: Leaderboard) -> list[str]:
    """The lines ``dynmap-sim benchmark`` prints when done: ``leaderboard.md`` up to its
    first section (the title, the bar and the scores table)."""
    return leaderboard_md(board).split("\n## ")[0].rstrip().split("\n")


CSV_COLUMNS = (
    "world", "kind", "localizer", "ate_rmse_m", "max_error_m", "lost_fraction", "jumps",
    "goals_reached", "collisions", "near_misses", "stuck_s", "passes", "wall_s",
)  # fmt: skip


def write_leaderboard_csv(board: Leaderboard, path: Path) -> Path:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_COLUMNS)
        for r in board.rows:
            w.writerow(
                [r.world, r.kind, r.localizer, f"{r.ate_m:.6f}", f"{r.max_m:.6f}",
                 f"{r.lost:.6f}", r.jumps, "" if math.isnan(r.goals) else f"{r.goals:.4f}",
                 r.collisions, r.near_misses, f"{r.stuck_s:.1f}", int(r.passes),
                 f"{r.wall_s:.1f}"]
            )  # fmt: skip
    return path


def plot_leaderboard(board: Leaderboard, path: Path, n_named: int = 3) -> Path:
    """Per-world ATE, one column per localizer (deterministic jitter), the bar as a line,
    and the ``n_named`` worst worlds of each column named."""
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    labels = [s.localizer for s in board.scores]
    order = {lb: k for k, lb in enumerate(dict.fromkeys(r.localizer for r in board.rows))}
    fig, ax = plt.subplots(figsize=(max(5.0, 1.8 * len(labels) + 1.5), 4.5))
    for j, label in enumerate(labels):
        rows = sorted((r for r in board.rows if r.localizer == label), key=_key)
        y = np.array([r.ate_m for r in rows])
        x = j + 0.25 * (np.arange(len(rows)) / max(len(rows) - 1, 1) - 0.5)
        ax.scatter(x, y, s=14, color=localizer_color(order[label]), zorder=3)
        for xi, r in list(zip(x, rows, strict=True))[-n_named:]:
            ax.annotate(
                r.world, (xi, r.ate_m), fontsize=6, xytext=(4, 0), textcoords="offset points"
            )
    ax.axhline(BAR_ATE_M, color="0.5", ls="--", lw=0.8, label=f"bar {BAR_ATE_M} m")
    ax.set_xticks(range(len(labels)), labels, rotation=15, fontsize="small")
    ax.set_xlim(-0.6, len(labels) - 0.4)
    ax.set_yscale("log")
    ax.yaxis.set_major_locator(matplotlib.ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
    ax.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_ylabel("ATE RMSE per world [m]")
    ax.set_title(f"{board.name}: {len({r.world for r in board.rows})} worlds", fontsize="medium")
    ax.legend(fontsize="small", loc="upper left")
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_per_day(board: Leaderboard, path: Path) -> Path:
    """Each localizer's ATE RMSE per day: the median over the worlds, and the band between
    their 25th and 75th percentiles."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    order = {lb: k for k, lb in enumerate(dict.fromkeys(r.localizer for r in board.rows))}
    fig, ax = plt.subplots(figsize=(8, 4.2))
    for label, k in order.items():
        if label in board.references:
            continue
        by_day: dict[int, list[float]] = {}
        for r in board.days:
            if r.localizer == label and math.isfinite(r.ate_m):
                by_day.setdefault(r.day, []).append(r.ate_m)
        if not by_day:
            continue
        d = np.array(sorted(by_day))
        q = np.array([np.percentile(by_day[int(x)], [25, 50, 75]) for x in d])
        ax.plot(d, q[:, 1], marker=".", color=localizer_color(k), label=label)
        ax.fill_between(d, q[:, 0], q[:, 2], color=localizer_color(k), alpha=0.15, lw=0)
    ax.axhline(BAR_ATE_M, color="0.5", ls="--", lw=0.8, label=f"bar {BAR_ATE_M} m")
    ax.set_yscale("log")
    ax.set_xlabel("day")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel("ATE RMSE of the day [m]")
    n = len({r.world for r in board.days})
    ax.set_title(f"{board.name}: median over {n} worlds, 25-75 % band", fontsize="medium")
    ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0))
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_leaderboard(out_dir: str | Path) -> list[Path]:
    """Write ``leaderboard.md``, ``leaderboard.csv`` and ``leaderboard.png`` (and, over more
    than one day, ``leaderboard_per_day.png``) into a benchmark folder; the files written."""
    board = leaderboard(out_dir)
    out = Path(out_dir)
    written = [
        out / "leaderboard.md",
        write_leaderboard_csv(board, out / "leaderboard.csv"),
    ]
    written[0].write_text(leaderboard_md(board), encoding="utf-8")
    if board.rows:
        written.append(plot_leaderboard(board, out / "leaderboard.png"))
    if len({r.day for r in board.days}) > 1:
        written.append(plot_per_day(board, out / "leaderboard_per_day.png"))
    return written
