"""Figures of the dynamic-map experiment like Biber & Duckett's Figs. 10–13.

* Fig. 10 — average likelihood of a range reading per day (we store the mean per-reading
  log-likelihood ``scan_loglik``; the figure shows its daily mean), per localizer;
* Fig. 11 — certainty: daily mean of ``λ_min`` of the inverse covariance, per localizer;
* Fig. 12 — relative frequency with which each timescale was selected, overall (every
  selection of every scan, from the ``timescale_counts`` table);
* Fig. 13 — daily usage frequency of λ1 (short-term) and λ5 (most long-term).

``write_dynamic_figures(out_dir)`` reads ``results.db`` of an experiment folder and writes
``dyn_likelihood_per_day.png``, ``dyn_lambda_min_per_day.png``, and per localizer
``dyn_timescale_usage_<label>.png`` and ``dyn_timescale_trend_<label>.png`` (only for
localizers that report these extras). The
aggregations are pure functions over arrays, tested on their own.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.plot_style import localizer_color

#: Biber & Duckett's timescales λ1–λ5 (Table 1): the bins of the per-scan fallback of
#: :func:`selection_counts_per_day` (results without the per-run ``timescale_counts``).
N_TIMESCALES = 5


def daily_means(day: NDArray[np.integer], values: NDArray[np.floating]) -> tuple[np.ndarray, ...]:
    """Days with finite values, and the mean of ``values`` per such day."""
    ok = np.isfinite(values)
    days = np.unique(day[ok])
    means = np.array([values[ok & (day == d)].mean() for d in days])
    return days, means


def selection_counts_per_day(
    day: NDArray[np.integer],
    timescale: NDArray[np.floating],
    selections: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, bool]:
    """Days, ``(n_days, 5)`` counts of timescale selections, and whether they count every
    selection: the per-run counts ``selections`` (days, counts) when there are any (what
    Figs. 12-13 count), else the first selection of each scan from per-scan ``timescale``."""
    if selections is not None and len(selections[0]):
        return selections[0], selections[1], True
    ok = np.isfinite(timescale) & (timescale >= 0) & (timescale < N_TIMESCALES)
    days = np.unique(day[ok])
    counts = np.array(
        [np.bincount(timescale[ok & (day == d)].astype(int), minlength=N_TIMESCALES) for d in days]
    )
    return days, counts.reshape(len(days), N_TIMESCALES), False


def _plot_per_day(series, ylabel: str, title: str, path: Path, log: bool = False) -> Path:
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, ax = plt.subplots(figsize=(7, 3.6))
    for label, color, days, means in series:
        ax.plot(days, means, marker="o", ms=3, color=color, label=label)
    ax.set_xlabel("day")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel(ylabel)
    if log:
        ax.set_yscale("log")
    ax.set_title(title, fontsize="medium")
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_timescale_usage(label: str, usage: np.ndarray, path: Path) -> Path:
    """Fig. 12: bar chart of the relative selection frequency of λ1..λ5."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 3.2))
    names = [f"λ{i + 1}" for i in range(len(usage))]
    ax.bar(names, usage, color=["C3", "C0", "C0", "C0", "C0"][: len(usage)])
    ax.set_ylabel("relative frequency")
    ax.set_title(f"{label}: timescale selected (cf. B&D Fig. 12)", fontsize="medium")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_timescale_trend(label: str, days: np.ndarray, usage: np.ndarray, path: Path) -> Path:
    """Fig. 13: usage of λ1 and λ5 per day."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, ax = plt.subplots(figsize=(7, 3.4))
    ax.plot(days, usage[:, 0], marker="o", ms=3, label="λ1 (short-term memory)")
    ax.plot(days, usage[:, -1], marker="s", ms=3, label=f"λ{usage.shape[1]} (most long-term)")
    ax.set_xlabel("day")
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_ylabel("usage frequency")
    ax.set_title(f"{label}: usage of λ1 and λ5 over time (cf. B&D Fig. 13)", fontsize="medium")
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_dynamic_figures(out_dir: str | Path) -> list[Path]:
    """Write the Fig. 10–13 look-alikes of an experiment folder; returns the files written."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    from dynmap_sim.experiments.results import ResultsDB

    out = Path(out_dir)
    written: list[Path] = []
    with ResultsDB.open(out) as db:
        labels = db.labels()
        data = [(label, db.per_scan(k)) for k, label in enumerate(labels)]
        selections = [db.timescale_counts_per_day(k) for k in range(len(labels))]
    # Figs. 12-13 count every selection; results without those counts fall back to the
    # first selection of each scan.
    sel_of = dict(zip(labels, selections, strict=True))
    color_of = {label: localizer_color(k) for k, label in enumerate(labels)}
    # Figs. 10-11 compare sample-based maps under their own perceptual model (eq. 6-8):
    # only localizers that select timescales; static MCL's likelihood field is another scale.
    data = [
        (lb, d) for lb, d in data if np.any(np.isfinite(d["timescale"]) & (d["timescale"] >= 0))
    ]
    per_day = (
        ("scan_loglik", "mean log-likelihood per reading",
         "Average scan likelihood per day (cf. B&D Fig. 10)", "dyn_likelihood_per_day.png", False),
        ("lambda_min", "mean λ_min of the inverse covariance",
         "Certainty of the localization per day (cf. B&D Fig. 11)", "dyn_lambda_min_per_day.png",
         True),
    )  # fmt: skip
    for key, ylabel, title, name, log in per_day:
        series = [(lb, color_of[lb], *daily_means(d["day"], d[key])) for lb, d in data]
        series = [s for s in series if len(s[2])]
        if series:
            written.append(_plot_per_day(series, ylabel, title, out / name, log=log))
    for label, d in data:
        if not np.any(np.isfinite(d["timescale"]) & (d["timescale"] >= 0)):
            continue
        safe = label.replace("/", "_").replace(" ", "_")
        days, counts, _ = selection_counts_per_day(d["day"], d["timescale"], sel_of[label])
        overall = counts.sum(axis=0) / max(int(counts.sum()), 1)
        usage = counts / np.maximum(counts.sum(axis=1, keepdims=True), 1)
        written.append(
            plot_timescale_usage(label, overall, out / f"dyn_timescale_usage_{safe}.png")
        )
        written.append(
            plot_timescale_trend(label, days, usage, out / f"dyn_timescale_trend_{safe}.png")
        )
    return written


def plot_local_map_timescales(
    dmap: object,
    xy: tuple[float, float],
    path: str | Path,
    levels: tuple[int, ...] = (4, 3, 2, 1),
    sigma_max_m: float = 0.10,
    title: str = "",
) -> Path:
    """Like B&D Figs. 7 and 9: the sub-maps ``levels`` (default λ5, λ4, λ3, λ2) of the local
    map nearest ``xy`` as points (medians of rays with ``σ < sigma_max_m``, as in §5.2).

    ``dmap`` is a :class:`~dynmap_sim.agent.maps.dynamic_map.DynamicMap` (e.g. ``loc.dmap`` of
    a ``dynamic-map`` localizer loaded from a checkpoint).
    """
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    from dynmap_sim.agent.maps.dynamic_map import DynamicMap

    if not isinstance(dmap, DynamicMap) or len(dmap) == 0:
        raise ValueError("plot_local_map_timescales needs a non-empty DynamicMap")
    c = dmap.centres
    i = int(np.argmin(np.hypot(*(c - np.asarray(xy, dtype=np.float64)).T)))
    lm = dmap.local_maps[i]
    fig, axes = plt.subplots(1, len(levels), figsize=(3.2 * len(levels), 3.4), squeeze=False)
    for ax, level in zip(axes[0], levels, strict=True):
        pts = lm.points(level, sigma_max_m)
        ax.plot(pts[:, 0], pts[:, 1], ".", ms=1.5, color="k")
        ax.plot(*lm.centre, "o", mfc="none", color="C3")
        ax.set_aspect("equal")
        ax.set_title(f"λ{level + 1} ({len(pts)} rays)", fontsize="small")
        ax.tick_params(labelsize="x-small")
    if title:
        fig.suptitle(title, fontsize="medium")
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
