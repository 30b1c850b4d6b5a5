"""Figures like Hentschel & Wagner's (§7.3): the long-term map after day 7 (Fig. 5) and
after day 22 with the route memory (Fig. 8), the shares of dynamic and semistatic points
per day (Fig. 6), and the mean and max position error per day against static MCL (Fig. 7).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from dynmap_sim.studies.hentschel_wagner.data import (
    SCORED_CLASSES,
    HWData,
    LTMGrid,
    class_scores_per_day,
    week_of,
)

#: Week boundaries drawn on the per-day figures (after days 7, 14, 21).
_WEEK_EDGES = (7.5, 14.5, 21.5)


def _weeks(ax: Any, days: Any) -> None:
    from matplotlib.ticker import MaxNLocator

    lo, hi = (min(days), max(days)) if len(days) else (1, 1)
    for x in _WEEK_EDGES:
        if lo < x < hi:
            ax.axvline(x, color="0.8", lw=0.8, zorder=0)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("day")


def plot_point_shares(data: HWData, path: Path) -> Path | None:
    """Fig. 6: the subject's daily share of dynamic and semistatic points (solid) and the
    truth's (dashed: seen-before truth, of the readings that hit something)."""
    import matplotlib.pyplot as plt

    s = data.shares
    if s is None or data.subject is None:
        return None
    fig, ax = plt.subplots(figsize=(7, 3.6))
    for cls, name, color in ((1, "dynamic", "tab:red"), (2, "semistatic", "tab:blue")):
        ax.plot(s.days, 100 * s.fractions[:, cls], "o-", color=color, ms=3, label=name)
        ax.plot(s.days, 100 * s.truth[:, cls], "--", color=color, lw=1, label=f"{name} (truth)")
    _weeks(ax, s.days.tolist())
    ax.set_ylabel("share of the scan's points [%]")
    ax.set_title(
        f"Dynamic and semistatic points per day, {data.subject[1]} (cf. H&W Fig. 6)",
        fontsize="small",
    )
    ax.legend(fontsize="small", ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.18))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_class_scores(data: HWData, path: Path) -> Path | None:
    """Fig. 6's shares (top: the subject's, solid; the truth's, dashed) beside how right they
    are: per class and day, precision and recall against the seen-before truth and, as grey
    bars on the right axis, the truth's own count of that class's beams (person beams,
    beams on objects new or moved since an earlier run, known beams)."""
    import matplotlib.pyplot as plt

    s = data.shares
    if s is None or data.subject is None:
        return None
    sc = class_scores_per_day(s)
    fig, axes = plt.subplots(4, 1, figsize=(7, 9), sharex=True)
    colors = ("tab:red", "tab:blue", "tab:gray")
    for k, (name, color) in enumerate(zip(SCORED_CLASSES[:2], colors, strict=False)):
        axes[0].plot(s.days, 100 * s.fractions[:, k + 1], "o-", color=color, ms=3, label=name)
        axes[0].plot(s.days, 100 * s.truth[:, k + 1], "--", color=color, lw=1,
                     label=f"{name} (truth)")  # fmt: skip
    axes[0].set_ylabel("share [%]")
    axes[0].set_title(f"{data.subject[1]}: point classes per day (cf. H&W Fig. 6) and their "
                      "precision / recall against the truth", fontsize="small")  # fmt: skip
    axes[0].legend(fontsize="x-small", ncol=4)
    for k, (name, color) in enumerate(zip(SCORED_CLASSES, colors, strict=True)):
        ax = axes[k + 1]
        bars = ax.twinx()
        bars.bar(sc.days, sc.truth_points[:, k], color="0.85", width=0.8, zorder=0)
        bars.set_ylabel(f"true {name} beams", fontsize="small")
        ax.set_zorder(bars.get_zorder() + 1)
        ax.patch.set_visible(False)
        ax.plot(sc.days, sc.precision[:, k], "o-", color=color, ms=3, label="precision")
        ax.plot(sc.days, sc.recall[:, k], "s--", color=color, ms=3, lw=1, label="recall")
        ax.set_ylim(-0.02, 1.02)
        ax.set_ylabel(name)
        ax.legend(fontsize="x-small", loc="lower left")
    _weeks(axes[-1], s.days.tolist())
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_error_per_day(data: HWData, path: Path) -> Path | None:
    """Fig. 7: mean (solid) and max (dotted) position error per day, the subject against
    every static MCL; days a localizer was lost on (> 0.5 m) are marked."""
    import matplotlib.pyplot as plt

    if not data.series:
        return None
    fig, ax = plt.subplots(figsize=(7, 3.8))
    for k, (label, s) in enumerate(data.series.items()):
        color = f"C{k}"
        ax.plot(s.days, s.mean_error_m, "o-", color=color, ms=3, label=f"{label} mean")
        ax.plot(s.days, s.max_error_m, ":", color=color, lw=1, label=f"{label} max")
    days = sorted({int(d) for s in data.series.values() for d in s.days})
    _weeks(ax, days)
    ax.set_yscale("log")
    ax.axhline(0.5, color="0.5", lw=0.6, ls="--")
    ax.set_ylabel("position error [m]")
    ax.set_title("Position error per day (cf. H&W Fig. 7; dashed: lost at 0.5 m)", fontsize="small")
    ax.legend(fontsize="small", ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.18))
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_ltm(
    grid: LTMGrid,
    path: Path,
    title: str,
    walls: np.ndarray | None = None,
    route_memory: dict[str, Any] | None = None,
) -> Path:
    """A long-term map (occupancy, darker = occupied) with the true walls of that run and,
    for Fig. 8, the route memory (prior route, learned routes, blocked segments)."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 6.5))
    ax.imshow(
        grid.prob,
        origin="lower",
        extent=grid.extent,
        cmap="Greys",
        vmin=0.0,
        vmax=1.0,
        interpolation="nearest",
    )
    if walls is not None and len(walls):
        ax.plot(
            np.stack([walls[:, 0], walls[:, 2]]),
            np.stack([walls[:, 1], walls[:, 3]]),
            color="tab:green",
            lw=0.6,
            alpha=0.6,
        )
        ax.plot([], [], color="tab:green", lw=0.6, label="true walls and objects")
    if route_memory is not None:
        blocked = {tuple(e) for e in route_memory.get("blocked", [])}
        for route in route_memory.get("routes", []):
            xy = np.array([[w["x_m"], w["y_m"]] for w in route["waypoints"]]).reshape(-1, 2)
            color = "tab:blue" if route.get("prior") else "tab:orange"
            ax.plot(xy[:, 0], xy[:, 1], color=color, lw=1.8)
            ids = route.get("ids", [])
            for j in range(1, len(ids)):
                if (ids[j - 1], ids[j]) in blocked:
                    ax.plot(xy[j - 1 : j + 1, 0], xy[j - 1 : j + 1, 1], color="red", lw=3)
        ax.plot([], [], color="tab:blue", lw=1.8, label="prior route")
        ax.plot([], [], color="tab:orange", lw=1.8, label="learned routes")
        ax.plot([], [], color="red", lw=3, label="blocked")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title, fontsize="small")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize="x-small", loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def route_memory_after(db: Any, day: int) -> tuple[int, dict[str, Any]] | None:
    """The driver's route memory after the last run of ``day`` (or the last day before)."""
    mems = [m for m in db.driver_artifacts("route_memory.json") if m[0] <= day]
    if not mems:
        return None
    d, _, blob = mems[-1]
    return d, json.loads(blob.decode())


def week_label(day: int) -> str:
    return f"day {day} (week {week_of(day)})"
