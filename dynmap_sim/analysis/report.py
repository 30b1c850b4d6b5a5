"""A results folder's report: figures, ``summary.md`` and ``per_day.csv`` (docs/architecture.md §6).

Figures mirror the papers: the mean localization error per day for each localizer (H&W §7,
Fig. 7), the error over time within runs, scan likelihood and certainty (λ_min) over time
(B&D §5.2, Figs. 10–11) when a localizer reports them, and trajectories over the map.

A results folder without any ground truth (a ``replay`` of a log without ``--reference``)
is not scored: the summary says "this log has no ground truth" and lists what was measured
(time per scan, likelihoods), and the error figures are left out.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dynmap_sim.analysis.navigation import (
    nav_per_day,
    nav_summary_lines,
    plot_nav_per_day,
    plot_route_memory,
    write_nav_per_day_csv,
)
from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.metrics import (
    LOST_THRESHOLD_M,
    RUN_RPE_DELTA,
    RUN_RPE_UNIT,
    OverallSummary,
    PointClassTally,
    class_scores,
    mean_per_scan,
    overall_summary,
    rpe_label,
)
from dynmap_sim.plot_style import legend_columns, localizer_color
from dynmap_sim.studies.study import StudyReport, all_studies
from dynmap_sim.types import BeamClass

#: Columns of ``per_day.csv``, in order.
PER_DAY_COLUMNS = (
    "day",
    "localizer",
    "mean_error_m",
    "max_error_m",
    "rmse_m",
    "lost_fraction",
    "mean_scan_loglik",
    "mean_lambda_min",
)

#: Columns of ``point_classes_per_day.csv``, in order: each reported class's share of a scan's
#: valid readings averaged over the day's scans (H&W Fig. 6), and precision / recall against
#: the seen-before truth (:mod:`dynmap_sim.metrics.point_classes`).
POINT_CLASS_COLUMNS = (
    "day",
    "localizer",
    "dynamic_fraction",
    "semistatic_fraction",
    "static_fraction",
    "dynamic_precision",
    "dynamic_recall",
    "semistatic_precision",
    "semistatic_recall",
)

_CLASS_COLORS = {
    int(BeamClass.WALL): "black",
    int(BeamClass.FURNITURE): "tab:brown",
    int(BeamClass.EXHIBIT): "tab:purple",
    int(BeamClass.DOOR): "tab:olive",
    int(BeamClass.ROBOT): "tab:gray",
}


def _fmt(v: Any, nd: int = 3) -> str:
    if v is None:
        return "nan"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.{nd}f}"
    return str(v)


def _f(v: Any) -> float:
    return math.nan if v is None else float(v)


def per_day_rows(db: ResultsDB) -> list[dict[str, Any]]:
    """Rows of ``per_day.csv`` (day-major, localizers in scenario order)."""
    labels = db.labels()
    rows = db.query(
        "SELECT day, loc, mean_error_m, max_error_m, rmse_m, lost_fraction, "
        "mean_scan_loglik, mean_lambda_min FROM day_summaries ORDER BY day, loc"
    )
    return [
        {
            "day": int(r[0]),
            "localizer": labels[int(r[1])],
            **{c: _f(v) for c, v in zip(PER_DAY_COLUMNS[2:], r[2:], strict=True)},
        }
        for r in rows
    ]


def write_per_day_csv(db: ResultsDB, path: Path) -> Path:
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(PER_DAY_COLUMNS)
        for row in per_day_rows(db):
            w.writerow(
                [row["day"], row["localizer"]] + [_fmt(row[c], 6) for c in PER_DAY_COLUMNS[2:]]
            )
    return path


def point_class_rows(db: ResultsDB) -> list[dict[str, Any]]:
    """Rows of ``point_classes_per_day.csv`` (day-major, localizers in scenario order), for
    the localizers that reported point classes (none before results format 3)."""
    per_loc = [(label, db.point_class_truth_per_day(k)) for k, label in enumerate(db.labels())]
    days = sorted({d for _, t in per_loc for d in t})
    rows = []
    for day in days:
        for label, tallies in per_loc:
            t = tallies.get(day)
            if t is None:
                continue
            f = t.fractions()
            sc = class_scores(t.confusion)
            rows.append(
                {
                    "day": day,
                    "localizer": label,
                    "dynamic_fraction": float(f[1]),
                    "semistatic_fraction": float(f[2]),
                    "static_fraction": float(f[3]),
                    "dynamic_precision": sc.precision[0],
                    "dynamic_recall": sc.recall[0],
                    "semistatic_precision": sc.precision[1],
                    "semistatic_recall": sc.recall[1],
                }
            )
    return rows


def write_point_classes_csv(rows: list[dict[str, Any]], path: Path) -> Path:
    """``point_classes_per_day.csv`` from :func:`point_class_rows`."""
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(POINT_CLASS_COLUMNS)
        for row in rows:
            w.writerow(
                [row["day"], row["localizer"]] + [_fmt(row[c], 6) for c in POINT_CLASS_COLUMNS[2:]]
            )
    return path


#: What the summary says of a results folder without ground truth.
NO_GROUND_TRUTH = "this log has no ground truth"


def has_ground_truth(db: ResultsDB) -> bool:
    """Whether any stored scan has a truth pose (a replay without reference has none)."""
    return bool(db.query("SELECT 1 FROM scans WHERE x IS NOT NULL LIMIT 1"))


def overall_stats(db: ResultsDB) -> list[dict[str, Any]]:
    """Whole-experiment figures per localizer (ATE, RPE, lost/recovered; update time), from
    :func:`dynmap_sim.metrics.overall_summary` (its fields, the label, ``update_ms_per_scan``)."""
    out = []
    for k, label in enumerate(db.labels()):
        s = overall_of(db, k)
        t_rows = db.query("SELECT update_ms_per_scan, n_scans FROM run_summaries WHERE loc=?", (k,))
        update_ms = mean_per_scan([_f(u) for u, _ in t_rows], [n for _, n in t_rows])
        row = {"localizer": label, **s.to_dict(), "rpe_label": s.rpe_label}
        out.append(row | {"update_ms_per_scan": update_ms})
    return out


def overall_of(db: ResultsDB, loc: int) -> OverallSummary:
    """:func:`dynmap_sim.metrics.overall_summary` of localizer ``loc`` (runs by day and run)."""
    d = db.per_scan(loc)
    runs = np.column_stack([d["day"], d["run"]])
    return overall_summary(d["truth"], d["estimate"], d["t_s"], runs)


def _summary_md(
    db: ResultsDB,
    path: Path,
    figures: list[Path],
    studies: list[StudyReport],
    overall: list[dict[str, Any]],
) -> Path:
    """``summary.md``; ``overall``: :func:`overall_stats` of ``db``."""
    meta = db.meta()
    labels = db.labels()
    runs = db.query(
        "SELECT count(*), coalesce(sum(n_steps),0), coalesce(sum(duration_s),0), "
        "coalesce(sum(collisions),0), coalesce(sum(skipped_waypoints),0), "
        "coalesce(sum(wall_s),0), coalesce(avg(route_progress),0) FROM runs"
    )[0]
    n_runs, n_steps, robot_s, coll, skipped, wall_s, prog = runs
    rpe = overall[0]["rpe_label"] if overall else rpe_label(RUN_RPE_DELTA, RUN_RPE_UNIT)
    lines = [
        f"# {meta.get('scenario_name', 'experiment')}",
        "",
        f"- world: `{meta.get('world')}`; days {meta['days'][0]}-{meta['days'][1]}, "
        f"seed {meta.get('seed')}; {n_runs} of {len(meta.get('slots', []))} runs done"
        + ("" if meta.get("complete") else " (incomplete)"),
        f"- {n_steps} scans, {robot_s / 3600.0:.2f} h of robot time simulated in "
        f"{wall_s / 60.0:.1f} min of wall time",
        f"- collisions: {coll}; skipped waypoints: {skipped}; mean route progress "
        f"{100.0 * prog:.0f} %",
    ]
    if meta.get("reference_summary"):
        lines += [f"- {meta['reference_summary']}; scans without a reference pose are not scored"]
    if not has_ground_truth(db):
        lines += _no_truth_lines(db, overall)
        return _finish_summary(db, path, lines, labels, figures, studies)
    update = db.update_time_header()
    lines += [
        "",
        "## Overall (position error in the map frame, no alignment)",
        "",
        f"| localizer | ATE RMSE [m] | mean [m] | max [m] | mean heading [rad] | {rpe} [m] "
        f"| lost | lost episodes | recovered | mean time to recover [s] | {update} |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for s in overall:
        lines.append(
            f"| {s['localizer']} | {_fmt(s['ate_rmse_m'])} | {_fmt(s['mean_error_m'])} "
            f"| {_fmt(s['max_error_m'])} | {_fmt(s['mean_heading_error_rad'])} "
            f"| {_fmt(s['rpe_rmse_m'])} | {100.0 * s['lost_fraction']:.1f} % "
            f"| {s['lost_episodes']} | {s['recovered']} | {_fmt(s['mean_time_to_recover_s'], 1)} "
            f"| {_fmt(s['update_ms_per_scan'], 2)} |"
        )
    lines += [
        "",
        "## Per day",
        "",
        "| day | localizer | mean [m] | max [m] | RMSE [m] | lost | mean scan loglik "
        "| mean λ_min |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in per_day_rows(db):
        lines.append(
            f"| {r['day']} | {r['localizer']} | {_fmt(r['mean_error_m'])} "
            f"| {_fmt(r['max_error_m'])} | {_fmt(r['rmse_m'])} "
            f"| {100.0 * r['lost_fraction']:.1f} % | {_fmt(r['mean_scan_loglik'])} "
            f"| {_fmt(r['mean_lambda_min'], 1)} |"
        )
    return _finish_summary(db, path, lines, labels, figures, studies)


def _no_truth_lines(db: ResultsDB, overall: list[dict[str, Any]]) -> list[str]:
    """The overall section of a folder without ground truth: what was measured, no errors."""
    lines = [
        "",
        "## Overall",
        "",
        f"**{NO_GROUND_TRUTH}**: the poses on a raw log's laser lines are its odometry, so the "
        "localizers are not scored (no errors are stored). Give a reference log with the true "
        "poses (`replay --reference`) to score them.",
        "",
        f"| localizer | scans | {db.update_time_header()} | scans/s | mean scan loglik "
        "| mean λ_min |",
        "|---|---|---|---|---|---|",
    ]
    rows = {
        int(k): (_f(a), _f(b))
        for k, a, b in db.query(
            "SELECT loc, avg(scan_loglik), avg(lambda_min) FROM estimates GROUP BY loc"
        )
    }
    for k, s in enumerate(overall):
        ms = s["update_ms_per_scan"]
        rate = 1e3 / ms if ms and math.isfinite(ms) and ms > 0 else math.nan
        ll, lam = rows.get(k, (math.nan, math.nan))
        lines.append(
            f"| {s['localizer']} | {s['n_scans']} | {_fmt(ms, 2)} | {_fmt(rate, 1)} "
            f"| {_fmt(ll)} | {_fmt(lam, 1)} |"
        )
    return lines


def _finish_summary(
    db: ResultsDB,
    path: Path,
    lines: list[str],
    labels: list[str],
    figures: list[Path],
    studies: list[StudyReport],
) -> Path:
    """The sections after the per-day table (mapping runs, point classes, studies, events,
    figures); writes ``summary.md``."""
    mapping = _mapping_run_labels(db)
    if mapping:
        lines += [
            "",
            f"Day 1, run 1 is the mapping run of {', '.join(mapping)}: their estimates there "
            "are the first-run SLAM's, made while the map is built (so their day-1 rows are "
            "identical when day 1 has only that run).",
        ]
    conf = _confusions(db, len(labels))
    if any(c.sum() for c in conf):
        lines += [
            "",
            "## Point classes (H&W §4.4) against beam labels",
            "",
            "| localizer | class | precision | recall | support |",
            "|---|---|---|---|---|",
        ]
        for label, c in zip(labels, conf, strict=True):
            if not c.sum():
                continue
            sc = class_scores(c)
            for j, name in enumerate(("dynamic", "semi-static", "static")):
                lines.append(
                    f"| {label} | {name} | {_fmt(sc.precision[j])} | {_fmt(sc.recall[j])} "
                    f"| {sc.support[j]} |"
                )
    truth_rows = []
    for k, label in enumerate(labels):
        tallies = db.point_class_truth_per_day(k)
        if not tallies:
            continue
        total = PointClassTally()
        for t in tallies.values():
            total.merge(t)
        sc = class_scores(total.confusion)
        f = total.fractions()
        for j, name in enumerate(("dynamic", "semi-static", "static")):
            truth_rows.append(
                f"| {label} | {name} | {100 * f[j + 1]:.1f} % | {_fmt(sc.precision[j])} "
                f"| {_fmt(sc.recall[j])} | {sc.support[j]} |"
            )
    if truth_rows:
        lines += [
            "",
            "## Point classes against the truth seen before at that place (H&W §4.4)",
            "",
            "A person is dynamic; an object the robot has not seen at its current place in an "
            "earlier run (new or moved) semi-static; the rest static. Share: of a scan's valid "
            "points, averaged over the scans (per day in `point_classes_per_day.csv`).",
            "",
            "| localizer | class | share | precision | recall | support |",
            "|---|---|---|---|---|---|",
            *truth_rows,
        ]
    for rep in studies:
        if rep.summary_lines:
            lines += ["", *rep.summary_lines]
    events = db.query("SELECT kind, count(*) FROM events GROUP BY kind ORDER BY kind")
    if events:
        lines += ["", "## Events", ""]
        lines += [f"- {kind}: {n}" for kind, n in events]
    if figures:
        lines += ["", "## Figures", ""]
        lines += [f"![{f.stem}]({f.name})" for f in figures]
    path.write_text("\n".join(lines) + "\n")
    return path


#: Localizers (registry names) that map the experiment's first run with the first-run SLAM
#: (B&D §4); ``static-mcl`` does too with its default ``map_source = "first-run"``.
_FIRST_RUN_MAPPERS = ("dynamic-map", "static-map", "static-map+stm")


def _mapping_run_labels(db: ResultsDB) -> list[str]:
    """Labels (as code spans) of the localizers whose first run is a mapping run, as the
    localizers table names them (none when a replay handed them the log's map)."""
    if db.meta().get("map_from_log_poses"):
        return []
    out = []
    for label, name, params in db.query("SELECT label, name, params FROM localizers ORDER BY idx"):
        source = json.loads(params or "{}").get("map_source", "first-run")
        if name in _FIRST_RUN_MAPPERS or (name == "static-mcl" and source == "first-run"):
            out.append(f"`{label}`")
    return out


def _confusions(db: ResultsDB, n_loc: int) -> list[np.ndarray]:
    out = [np.zeros((4, 4), dtype=np.int64) for _ in range(n_loc)]
    for loc, blob in db.query("SELECT loc, confusion FROM point_classes"):
        out[int(loc)] += np.frombuffer(blob, dtype="<i8").reshape(4, 4)
    return out


# ---------------------------------------------------------------------- figures
def _fig_error_per_day(db: ResultsDB, path: Path) -> Path:
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    rows = per_day_rows(db)
    fig, ax = plt.subplots(figsize=(8, 4))
    labels = db.labels()
    n = len(labels)
    for k, label in enumerate(labels):
        r = [x for x in rows if x["localizer"] == label]
        days = np.array([x["day"] for x in r], dtype=float)
        mean = np.array([x["mean_error_m"] for x in r])
        mx = np.array([x["max_error_m"] for x in r])
        off = (k - (n - 1) / 2) * 0.8 / max(n, 1)
        color = localizer_color(k)
        ax.bar(days + off, mean, width=0.8 / max(n, 1), color=color, label=f"{label} (mean)")
        ax.plot(days + off, mx, "_", ms=10, color=color)
    ax.set_xlabel("day")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel("position error [m]")
    ax.set_title("Localization error per day (bars: mean, ticks: max)")
    _legend_below(fig, [ax])
    ax.grid(axis="y", alpha=0.3)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _legend_below(fig: Any, axes: list[Any]) -> None:
    """One legend of the entries of ``axes`` (each label once) below them, outside the data,
    and the layout made around it (replaces ``fig.tight_layout()``)."""
    entries: dict[str, Any] = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            entries.setdefault(label, handle)
    ncol = legend_columns(list(entries), fig.get_figwidth())
    rows = -(-len(entries) // ncol)
    height = fig.get_figheight()
    fig.set_figheight(height + 0.25 * rows)  # room for the legend, the axes keep their size
    bottom = 0.25 * rows / fig.get_figheight() + 0.02
    fig.tight_layout(rect=(0, bottom, 1, 1))
    if entries:
        fig.legend(
            list(entries.values()),
            list(entries),
            loc="lower center",
            ncol=ncol,
            fontsize="small",
            frameon=False,
        )


def _pick_runs(db: ResultsDB) -> list[tuple[str, int, int]]:
    """The first run, the run with the largest error of a localizer and the last run, each
    with its role (``first``, ``worst``, ``last``; one run may hold several). The odometry
    reference is left out of "worst": its drift grows over the experiment, so it would name
    the last run and hide the localizers' worst one."""
    runs = [(int(d), int(r)) for d, r in db.query("SELECT day, run FROM runs ORDER BY day, run")]
    if not runs:
        return []
    names = {int(k): name for k, name in db.query("SELECT idx, name FROM localizers")}
    rows = db.query("SELECT loc, day, run, max_error_m FROM run_summaries")
    scored = [(float(e), int(d), int(r)) for k, d, r, e in rows if names.get(int(k)) != "odometry"]
    scored = [s for s in scored if math.isfinite(s[0])]
    picks: dict[tuple[int, int], list[str]] = {runs[0]: ["first"]}
    if scored:
        _, d, r = max(scored, key=lambda s: (s[0], -s[1], -s[2]))
        picks.setdefault((d, r), []).append("worst")
    picks.setdefault(runs[-1], []).append("last")
    return [(" and ".join(roles), d, r) for (d, r), roles in sorted(picks.items())]


def _fig_error_over_time(db: ResultsDB, path: Path) -> Path:
    import matplotlib.pyplot as plt

    picks = _pick_runs(db)
    fig, axes = plt.subplots(len(picks), 1, figsize=(8, 2.4 * len(picks)), squeeze=False)
    for ax, (role, day, run) in zip(axes[:, 0], picks, strict=True):
        for k, label in enumerate(db.labels()):
            d = db.per_scan(k, day, run)
            t = d["t_s"] - d["t_s"][0] if len(d["t_s"]) else []
            ax.plot(t, d["err_m"], color=localizer_color(k), label=label)
        ax.axhline(LOST_THRESHOLD_M, color="gray", ls=":", lw=1)
        ax.set_title(f"{role} run: day {day}, run {run}", fontsize="small")
        ax.set_ylabel("error [m]")
    axes[-1, 0].set_xlabel("time in run [s]")
    axes[0, 0].legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _fig_trajectories(db: ResultsDB, path: Path) -> Path:
    import matplotlib.pyplot as plt

    picks = _pick_runs(db)
    fig, axes = plt.subplots(1, len(picks), figsize=(5 * len(picks), 5), squeeze=False)
    for ax, (role, day, run) in zip(axes[0], picks, strict=True):
        g = db.geometry(day, run)
        if g is not None:
            seg, cls = g
            for c in np.unique(cls):
                s = seg[cls == c]
                ax.plot(
                    np.stack([s[:, 0], s[:, 2]]),
                    np.stack([s[:, 1], s[:, 3]]),
                    color=_CLASS_COLORS.get(int(c), "black"),
                    lw=1,
                )
        route = np.asarray(db.meta().get("route") or np.zeros((0, 2)), float).reshape(-1, 2)
        if len(route):
            ax.plot(route[:, 0], route[:, 1], ":", color="gray", lw=1, label="route")
        for _, _, blob in (
            a for a in db.driver_artifacts("planned_path.f8") if a[:2] == (day, run)
        ):
            pp = np.frombuffer(blob, dtype="<f8").reshape(-1, 2)
            ax.plot(pp[:, 0], pp[:, 1], "--", color="tab:green", lw=1, label="last planned path")
        for k, label in enumerate(db.labels()):
            d = db.per_scan(k, day, run)
            if k == 0:
                ax.plot(
                    d["truth"][:, 0], d["truth"][:, 1], color="0.3", lw=3, label="truth", alpha=0.35
                )
            ax.plot(
                d["estimate"][:, 0],
                d["estimate"][:, 1],
                lw=1,
                color=localizer_color(k),
                label=label,
            )
        ax.set_aspect("equal")
        ax.set_title(f"{role} run: day {day}, run {run}", fontsize="small")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
    _legend_below(fig, list(axes[0]))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _fig_likelihood(db: ResultsDB, path: Path) -> Path | None:
    import matplotlib.pyplot as plt

    labels = db.labels()
    series = []
    for k, label in enumerate(labels):
        d = db.per_scan(k)
        if np.isfinite(d["scan_loglik"]).any() or np.isfinite(d["lambda_min"]).any():
            series.append((k, label, d))
    if not series:
        return None
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(9, 5), sharex=True)
    for k, label, d in series:
        x = np.arange(len(d["t_s"]))
        a1.plot(x, d["scan_loglik"], lw=0.6, color=localizer_color(k), label=label)
        a2.plot(x, d["lambda_min"], lw=0.6, color=localizer_color(k), label=label)
    a1.set_ylabel("scan log-likelihood")
    a2.set_ylabel("λ_min")
    a2.set_yscale("symlog")
    a2.set_xlabel("scan index over the experiment")
    a1.legend(fontsize="small")
    a1.set_title("Likelihood and certainty over time (cf. B&D Figs. 10-11)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _navigation(db: ResultsDB, out: Path) -> StudyReport | None:
    """``nav_per_day.csv``, the per-day figure, the route memory and a summary section, when
    the results hold navigation measures."""
    rows = nav_per_day(db)
    if not rows:
        return None
    rep = StudyReport(summary_lines=nav_summary_lines(db, rows))
    rep.files.append(write_nav_per_day_csv(rows, out / "nav_per_day.csv"))
    rep.figures.append(plot_nav_per_day(rows, out / "navigation_per_day.png"))
    mem = plot_route_memory(db, out / "route_memory.png")
    if mem is not None:
        rep.figures.append(mem)
    return rep


def _study_reports(out: Path) -> list[StudyReport]:
    """Each paper study that applies writes its figures, files and a summary section."""
    with ResultsDB.open(out) as db:
        db.remember_per_scan()
        return [st.write(db, out) for st in all_studies() if st.applies(db)]


class _InProcess:
    """What :func:`_studies_beside` gives where there is no second process: ``submit`` runs
    the call when its result is asked for."""

    def __init__(self) -> None:
        self._call: Any = None

    def submit(self, fn: Any, *args: Any) -> _InProcess:
        self._call = (fn, args)
        return self

    def result(self) -> Any:
        fn, args = self._call
        return fn(*args)

    def shutdown(self, wait: bool = True) -> None:
        pass


def _studies_beside() -> Any:
    """An executor for the studies' part of the report: a forked process beside this one
    (the studies and the rest take about the same time; a fork keeps the loaded modules and
    matplotlib's backend) when there are two cores and this process has no other thread to
    fork with, else :class:`_InProcess`. Either way the files are the same."""
    import multiprocessing as mp
    import os
    import threading
    from concurrent.futures import ProcessPoolExecutor

    fork = "fork" in mp.get_all_start_methods() and threading.active_count() == 1
    if (os.cpu_count() or 1) < 2 or not fork:
        return _InProcess()
    return ProcessPoolExecutor(1, mp_context=mp.get_context("fork"))


def write_report(out_dir: str | Path) -> list[Path]:
    """Write figures, ``summary.md`` and ``per_day.csv`` (and ``point_classes_per_day.csv``
    when a localizer reported point classes) into a results folder; the files written. The
    paper studies' part runs in a second process meanwhile (:func:`_studies_beside`)."""
    return make_report(out_dir).written


@dataclass(frozen=True)
class Report:
    """What :func:`make_report` wrote, and the whole-experiment figures it computed on the
    way (:func:`overall_stats`, for a caller that prints them too)."""

    written: list[Path]
    overall: list[dict[str, Any]]


def make_report(out_dir: str | Path) -> Report:
    """:func:`write_report`, with the :func:`overall_stats` it computed."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    out = Path(out_dir)
    with ResultsDB.open(out) as db:
        if not db.query("SELECT 1 FROM runs LIMIT 1"):
            from dynmap_sim.errors import InputError

            raise InputError(f"{out}: no finished run to report on")
    pool = _studies_beside()
    try:
        reports = pool.submit(_study_reports, out)  # forked before this process opens the db
        return _write_report_beside(out, reports)
    finally:
        pool.shutdown(wait=True)


def _write_report_beside(out: Path, reports: Any) -> Report:
    """:func:`write_report`'s own part; ``reports``: the studies' reports to come."""
    with ResultsDB.open(out) as db:
        db.remember_per_scan()
        written = [write_per_day_csv(db, out / "per_day.csv")]
        pc_rows = point_class_rows(db)
        if pc_rows:
            written.append(write_point_classes_csv(pc_rows, out / "point_classes_per_day.csv"))
        figs = (
            [
                _fig_error_per_day(db, out / "error_per_day.png"),
                _fig_error_over_time(db, out / "error_over_time.png"),
            ]
            if has_ground_truth(db)
            else []
        )
        figs.append(_fig_trajectories(db, out / "trajectories.png"))
        lik = _fig_likelihood(db, out / "likelihood_certainty.png")
        if lik is not None:
            figs.append(lik)
        nav = _navigation(db, out)
        # each paper study that applies adds its figures, files and a summary section
        studies = list(reports.result())
        if nav is not None:
            studies.insert(0, nav)
        for rep in studies:
            figs += rep.figures
            written += rep.files
        overall = overall_stats(db)
        written.append(_summary_md(db, out / "summary.md", figs, studies, overall))
        written += figs
    return Report(written, overall)
