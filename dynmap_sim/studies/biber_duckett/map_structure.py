"""What the dynamic map's long-term memories hold, measured against the true world (B&D §5.2).

Biber & Duckett verified visually that the accuracy of the local maps increased over time:
"in parts of the environment where changes often occur, static parts like walls emerge while
moving objects like chairs that could be observed in the initial map disappear" (§5.2,
Fig. 7). With ground truth this is a number. For every day a ``dynamic-map`` handed over a
snapshot of its sub-maps λ2–λ5 (the ``map_snapshot`` day artifact in the results store, a
:class:`~dynmap_sim.agent.maps.dynamic_map.MapSnapshot`: ray medians with ``σ ≤ 10 cm``),
take all their points and measure, per timescale,

* ``on_walls``: the share of points within ``tol_m`` of a wall (the building: never moves);
* ``on_world``: the share within ``tol_m`` of any true surface of that day's last run
  (walls, furniture where it stood, doors, exhibits);
* ``median_dist_m``: the median distance to the nearest true surface of that day.

Distances are in the map frame without alignment, like every error of the testbed (the map
frame starts at the known initial pose), so the first-run SLAM's own distortion is part of
them. Surfaces are sampled every ``step_m`` (1 cm), so distances are exact to 5 mm.
"""

from __future__ import annotations

import csv
import io
import pickle
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from dynmap_sim.agent.maps.dynamic_map import MapSnapshot
from dynmap_sim.errors import InputError
from dynmap_sim.types import BeamClass

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class MapStructure:
    """Per day and long-term level: points, and how many lie on true surfaces."""

    days: tuple[int, ...]
    levels: tuple[int, ...]  # 1 = λ2 ... 4 = λ5
    n_points: NDArray[np.int64]  # (days, levels)
    on_walls: FloatArray  # (days, levels), share within tol_m of a wall
    on_world: FloatArray  # (days, levels), share within tol_m of any true surface
    median_dist_m: FloatArray  # (days, levels)
    tol_m: float


def surface_samples(
    segments: FloatArray, classes: NDArray[np.integer], step_m: float = 0.01
) -> tuple[FloatArray, NDArray[np.int8]]:
    """Points every ``step_m`` along each segment ``(x0, y0, x1, y1)`` and their class."""
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    n = np.maximum(2, np.ceil(length / step_m).astype(np.int64) + 1)
    k = np.repeat(np.arange(len(seg)), n)
    t = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    t = t / np.repeat(n - 1, n)
    pts = seg[k, :2] + t[:, None] * (seg[k, 2:] - seg[k, :2])
    return pts, np.asarray(classes, dtype=np.int8)[k]


#: The least search bound [m] of :func:`_nearest_for_median` (it only prunes the search: a
#: map point is rarely this far from the world's surfaces).
MEDIAN_SEARCH_M = 0.5


def _nearest_for_median(tree: cKDTree, p: FloatArray, bound_m: float) -> FloatArray:
    """Each point's distance to its nearest neighbour in ``tree`` [m], exact up to
    ``bound_m`` and inf beyond: the median and every fraction below the bound are exactly
    those of the full distances (when fewer than half and one points are within the bound,
    the search is redone unbounded). The bound prunes the tree search: the H&W replica's 112
    map levels took 1.3 s instead of 3.4 s."""
    d = tree.query(p, distance_upper_bound=bound_m)[0]
    if np.count_nonzero(np.isfinite(d)) < len(d) // 2 + 1:
        d = tree.query(p)[0]
    return d


def map_structure(
    snapshots: Sequence[tuple[int, Any]],
    geometry: Callable[[int], tuple[FloatArray, NDArray[np.integer]] | None],
    tol_m: float = 0.05,
    step_m: float = 0.01,
) -> MapStructure:
    """:class:`MapStructure` of ``snapshots`` ``[(day, MapSnapshot), ...]``; ``geometry(day)``
    gives the true ``(segments, classes)`` of that day (None: the day is skipped)."""
    days, rows = [], []
    levels: tuple[int, ...] = ()
    for day, snap in snapshots:
        geo = geometry(int(day))
        if geo is None:
            continue
        surf, cls = surface_samples(geo[0], geo[1], step_m)
        world = cKDTree(surf)
        walls = surf[cls == int(BeamClass.WALL)]
        wall_tree = cKDTree(walls) if len(walls) else None
        levels = tuple(snap.levels)
        row = []
        for level in levels:
            pts = [snap.points(i, level) for i in range(len(snap.centres))]
            p = np.concatenate(pts) if pts else np.zeros((0, 2))
            if len(p) == 0:
                row.append((0, np.nan, np.nan, np.nan))
                continue
            d = _nearest_for_median(world, p, max(MEDIAN_SEARCH_M, tol_m))
            dw = (
                wall_tree.query(p, distance_upper_bound=tol_m)[0]
                if wall_tree is not None
                else np.full(len(p), np.inf)
            )
            on_walls, on_world = float(np.mean(dw < tol_m)), float(np.mean(d < tol_m))
            row.append((len(p), on_walls, on_world, float(np.median(d))))
        days.append(int(day))
        rows.append(row)
    arr = np.array(rows, dtype=np.float64).reshape(len(days), len(levels), 4)
    return MapStructure(
        days=tuple(days),
        levels=levels,
        n_points=arr[:, :, 0].astype(np.int64),
        on_walls=arr[:, :, 1],
        on_world=arr[:, :, 2],
        median_dist_m=arr[:, :, 3],
        tol_m=float(tol_m),
    )


#: The day artifact in which a ``dynamic-map`` hands over its λ2–λ5 snapshot.
SNAPSHOT_ARTIFACT = "map_snapshot"


def dynamic_map_snapshots(db: Any) -> list[tuple[int, MapSnapshot]]:
    """The daily snapshots ``[(day, MapSnapshot), ...]`` of the first ``dynamic-map`` in a
    results database (its ``map_snapshot`` day artifacts); empty when there are none."""
    rows = db.query("SELECT idx, name FROM localizers ORDER BY idx")
    dyn = [int(i) for i, name in rows if name == "dynamic-map"]
    if not dyn:
        return []
    if db.format < 2:
        return _format1_snapshots(db, dyn[0])
    return [
        (day, MapSnapshot.from_arrays(arrays))
        for day, arrays in db.artifacts(dyn[0], SNAPSHOT_ARTIFACT)
    ]


class _Gone:
    """Stands in for a class of an old pickle that this version no longer has."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        pass

    def __setstate__(self, state: Any) -> None:
        if isinstance(state, dict):
            self.__dict__.update(state)


class _OldPickle(pickle.Unpickler):
    """Loads a localizer pickled by an earlier version: classes that moved or went away
    since become :class:`_Gone` (only the snapshots are read from it)."""

    def find_class(self, module: str, name: str) -> Any:
        try:
            return super().find_class(module, name)
        except (AttributeError, ImportError):
            return type(name, (_Gone,), {"__module__": module})


def _format1_snapshots(db: Any, loc: int) -> list[tuple[int, MapSnapshot]]:
    """Results format 1 stored no artifacts: its snapshots are only in the checkpoint's
    pickled localizer (its ``day_snapshots``)."""
    meta = db.meta()
    cp = db.load_checkpoint(meta["experiment_hash"], meta["seed"], to_resume=False)
    if cp is None or len(cp.localizers) <= loc:
        return []
    try:
        state = _OldPickle(io.BytesIO(cp.localizers[loc])).load()  # our own checksummed file
        snaps = list(getattr(state, "day_snapshots", []))
    except Exception as exc:  # noqa: BLE001 - any failure: this version cannot read it
        raise InputError(
            f"{db.path}: results format 1 keeps the dynamic map's daily snapshots only in its "
            f"pickled checkpoint, which this version cannot load ({type(exc).__name__}: "
            f"{exc}); report it with the dynmap_sim version that wrote it"
        ) from None
    return [(int(day), snap) for day, snap in snaps if isinstance(snap, MapSnapshot)]


def map_structure_from_db(
    db: Any, snapshots: list[tuple[int, Any]] | None = None, tol_m: float = 0.05
) -> MapStructure | None:
    """:func:`map_structure` of the first ``dynamic-map`` of a results database against each
    day's last run; None without snapshots. ``snapshots``: its daily snapshots when already
    loaded (:func:`dynamic_map_snapshots`)."""
    snaps = dynamic_map_snapshots(db) if snapshots is None else snapshots
    if not snaps:
        return None
    last_run = dict(db.query("SELECT day, MAX(run) FROM geometry GROUP BY day"))

    def geometry(day: int) -> tuple[FloatArray, NDArray[np.integer]] | None:
        run = last_run.get(day)
        return None if run is None else db.geometry(day, int(run))

    ms = map_structure(snaps, geometry, tol_m)
    return ms if ms.days else None


def write_map_structure_csv(ms: MapStructure, path: Path) -> Path:
    """``day, timescale, n_points, on_walls, on_world, median_dist_m`` per day and level."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["day", "timescale", "n_points", "on_walls", "on_world", "median_dist_m"])
        for a, day in enumerate(ms.days):
            for b, level in enumerate(ms.levels):
                values = (ms.on_walls[a, b], ms.on_world[a, b], ms.median_dist_m[a, b])
                w.writerow(
                    [day, f"lambda{level + 1}", int(ms.n_points[a, b])]
                    + [f"{v:.4f}" for v in values]
                )
    return path


def plot_map_structure(ms: MapStructure, path: Path) -> Path:
    """Share of each long-term map's points on walls and on any true surface, per day."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharex=True)
    for b, level in enumerate(ms.levels):
        axes[0].plot(ms.days, 100 * ms.on_walls[:, b], marker=".", label=f"λ{level + 1}")
        axes[1].plot(ms.days, 100 * ms.on_world[:, b], marker=".", label=f"λ{level + 1}")
    tol = f"{100 * ms.tol_m:.0f} cm"
    axes[0].set_title(f"points within {tol} of a wall")
    axes[1].set_title(f"points within {tol} of any true surface that day")
    for ax in axes:
        ax.set_xlabel("day")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_ylabel("share of the sub-map's points [%]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle("The long-term memories against the true world (cf. B&D §5.2, Fig. 7)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
