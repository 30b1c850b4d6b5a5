"""Figures of the temporal-map study: agreement per day, and each changing door over a week."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dynmap_sim.studies.temporal_maps.agreement import DoorSeries, MapAgreement


def _per_day(days: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u = np.unique(days)
    means = []
    for d in u:
        v = values[days == d]
        means.append(float(np.nanmean(v)) if np.isfinite(v).any() else np.nan)
    return u, np.array(means)


def plot_agreement(agreements: list[MapAgreement], path: Path) -> Path:
    """Precision and recall of the predicted occupied cells per day (mean over the day's
    runs), on all seen cells and on the changing ones, one line per localizer."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, axes = plt.subplots(2, 2, figsize=(10, 6.2), sharex=True)
    panels = (
        ("precision", "all seen cells: precision"),
        ("recall", "all seen cells: recall"),
        ("changing_precision", "changing cells: precision"),
        ("changing_recall", "changing cells: recall"),
    )
    for ax, (field, title) in zip(axes.ravel(), panels, strict=True):
        for a in agreements:
            d, v = _per_day(a.day, getattr(a, field))
            ax.plot(d, v, marker=".", color=f"C{a.loc}", label=a.label)
        ax.set_title(title, fontsize=10)
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    for ax in axes[1]:
        ax.set_xlabel("day")
    axes[0, 0].legend(fontsize=8, loc="lower left")
    fig.suptitle("The map each run localized on, predicted before it, against the run's truth")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_doors(doors: list[DoorSeries], path: Path, days: int = 7, max_doors: int = 4) -> Path:
    """For up to ``max_doors`` door-leaf positions (two a door), the last ``days`` days of
    runs: the true occupancy of the position (squares) and each localizer's predicted
    occupancy of its cells."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = doors[:max_doors]
    fig, axes = plt.subplots(len(shown), 1, figsize=(11, 2.3 * len(shown) + 0.6), squeeze=False)
    for ax, door in zip(axes[:, 0], shown, strict=True):
        keep = door.day > door.day.max() - days
        x = door.day[keep] + np.nan_to_num(door.clock_h[keep]) / 24.0
        ax.plot(x, door.truth[keep], "ks", ms=7, mfc="none", label="truth at the run")
        for label, p in door.predicted.items():
            ax.plot(x, p[keep], marker="o", ls=":", color=f"C{door.locs[label]}", label=label)
        ax.set_ylim(-0.05, 1.05)
        ax.set_ylabel("occupied")
        ax.set_title(
            f"door leaf position at ({door.centre_m[0]:.1f}, {door.centre_m[1]:.1f}) m, "
            f"occupied at {100 * float(door.truth.mean()):.0f} % of the runs",
            fontsize=10,
        )
        ax.grid(alpha=0.3)
    axes[-1, 0].set_xlabel("day + time of day / 24 (runs)")
    axes[0, 0].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.suptitle("Doors: the predicted occupancy each run localized on, against the truth")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
