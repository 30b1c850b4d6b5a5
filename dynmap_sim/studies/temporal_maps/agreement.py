"""How well a time-specific map predicted the world of each run, measured against the truth.

``fremen`` and ``markov-grid`` localize each run on the map their temporal model predicts
for the run's time (Krajník et al., ECMR 2015; Saarinen et al., IROS 2012), and hand over
every such map as the ``temporal_map`` day artifact (the prediction made at the run's first
scan, before the run was learned from). Here each map is set against the true static world
of its own run (walls, furniture where it stood, closed doors: the ``geometry`` table):

* the true surfaces are rasterized onto the map's cells (every ``step_m`` along each
  segment); a cell is predicted occupied above ``threshold``;
* **precision**: the share of predicted occupied cells within ``tol_cells`` of a true
  surface; **recall**: the share of true surface cells the map had seen that have a
  predicted occupied cell within ``tol_cells`` (a cell never seen cannot be predicted);
* both on all seen cells, and on the **changing cells**: those occupied in some runs of the
  experiment and free in others (doors, moved and periodic furniture), away from the
  surfaces that never change. On all cells the walls dominate; the changing cells are where
  a temporal model has anything to predict.

Doors get series of their own: for each door whose leaf moves, each of the leaf's two
positions, its true occupancy and each map's mean predicted probability there (the highest
within the tolerance of each cell), per run.

Distances are in the map frame without alignment, as every error of the testbed; one cell
of tolerance (5 cm) absorbs the localization error of the scans the models learned from.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from dynmap_sim.agent.grid import points_on_segments
from dynmap_sim.studies.biber_duckett.findings import weeks_of_days
from dynmap_sim.types import BeamClass

#: The day artifact of the temporal-map localizers.
ARTIFACT = "temporal_map"
#: Fewest cells of a door leaf's position for its series (a leaf is 20 or more).
MIN_DOOR_CELLS = 5

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class MapAgreement:
    """Per predicted map (one a run) of one localizer: its run and agreement with the truth.

    ``precision`` / ``recall`` on all seen cells, ``changing_precision`` /
    ``changing_recall`` on the changing cells (NaN where there is nothing to count);
    ``n_changing`` the true surface cells among the seen changing cells; ``week`` the
    calendar week (Monday to Sunday, 1 = the first day's); ``clock_h`` the run's time of day
    [h]; ``loc`` the localizer's index (its colour in the figures).
    """

    loc: int
    label: str
    day: NDArray[np.int64]
    clock_h: FloatArray
    run: NDArray[np.int64]
    week: NDArray[np.int64]
    precision: FloatArray
    recall: FloatArray
    changing_precision: FloatArray
    changing_recall: FloatArray
    n_changing: NDArray[np.int64]

    def weekly(self, values: FloatArray) -> tuple[NDArray[np.int64], FloatArray]:
        """``(weeks, mean of values per week)``: the mean over the run numbers of each run
        number's mean that week (NaN-aware), so that a week missing a run of the day (day 1's
        first run maps the world) weighs the times of day as the other weeks do."""
        weeks = np.unique(self.week)
        means = []
        for w in weeks:
            slots = [_mean_seen(values, (self.week == w) & (self.run == r)) for r in
                     np.unique(self.run[self.week == w])]  # fmt: skip
            means.append(_mean_seen(np.array(slots), np.ones(len(slots), bool)))
        return weeks, np.array(means)


@dataclass(frozen=True)
class DoorSeries:
    """One position of a door leaf that moves: per run the true occupancy of its cells
    (``truth``, 1: the leaf is there) and each localizer's mean predicted occupancy there
    (``predicted[label]``, NaN where the map had not seen it), at ``day`` + ``clock_h`` [h];
    ``locs[label]`` the localizer's index."""

    centre_m: FloatArray
    day: NDArray[np.int64]
    clock_h: FloatArray
    truth: FloatArray
    predicted: dict[str, FloatArray]
    locs: dict[str, int]


@dataclass(frozen=True)
class Frame:
    """The cell lattice of a predicted map: origin [m], cell size [m], shape (rows along y)."""

    origin_m: tuple[float, float]
    resolution_m: float
    shape: tuple[int, int]


def rasterize(segments: FloatArray, frame: Frame, step_m: float | None = None) -> BoolArray:
    """Cells of ``frame`` crossed by ``segments`` ``(N, 4)`` (samples every ``step_m``,
    default a quarter cell, as the agent's grid rasterizes the prior's walls)."""
    step = frame.resolution_m / 4 if step_m is None else step_m
    out = np.zeros(frame.shape, bool)
    pts = points_on_segments(segments, step)
    ij = np.floor((pts - np.array(frame.origin_m)) / frame.resolution_m).astype(np.int64)
    h, w = frame.shape
    ok = (ij[:, 0] >= 0) & (ij[:, 0] < w) & (ij[:, 1] >= 0) & (ij[:, 1] < h)
    out[ij[ok, 1], ij[ok, 0]] = True
    return out


def _dilate(mask: BoolArray, cells: int) -> BoolArray:
    if cells <= 0:
        return mask
    return ndimage.binary_dilation(mask, np.ones((3, 3), bool), iterations=cells)


def precision_recall(
    predicted: BoolArray, truth: BoolArray, seen: BoolArray, region: BoolArray, tol_cells: int
) -> tuple[float, float]:
    """``(precision, recall)`` of ``predicted`` occupied cells against ``truth`` surface cells
    inside ``region`` (module docstring); NaN where nothing is counted."""
    pred = predicted & region
    true = truth & region & seen
    n_pred, n_true = int(pred.sum()), int(true.sum())
    precision = float((pred & _dilate(truth, tol_cells)).sum() / n_pred) if n_pred else np.nan
    recall = float((true & _dilate(predicted, tol_cells)).sum() / n_true) if n_true else np.nan
    return precision, recall


def temporal_localizers(db: Any) -> list[tuple[int, str]]:
    """``(index, label)`` of every localizer that handed over ``temporal_map`` artifacts."""
    if not db.has_table("artifacts"):
        return []
    rows = db.query("SELECT DISTINCT loc FROM artifacts WHERE name=? ORDER BY loc", (ARTIFACT,))
    labels = dict(db.query("SELECT idx, label FROM localizers"))
    return [(int(i), str(labels[i])) for (i,) in rows]


@dataclass(frozen=True)
class _Map:
    day: int
    run: int
    p: FloatArray  # NaN where never seen
    frame: Frame


def _maps(db: Any, loc: int) -> list[_Map]:
    out = []
    for day, arrays in db.artifacts(loc, ARTIFACT):
        p = np.asarray(arrays["p_occupied"], np.float64)
        ox, oy = np.asarray(arrays["origin_m"], np.float64).tolist()
        frame = Frame(
            (ox, oy),
            float(arrays["resolution_m"]),
            (int(p.shape[1]), int(p.shape[2])),
        )
        for k, run in enumerate(np.asarray(arrays["run"]).tolist()):
            out.append(_Map(int(day), int(run), p[k], frame))
    return out


class _Truth:
    """The true surface and door cells of each run on one frame (cached per run)."""

    def __init__(self, db: Any, frame: Frame, step_m: float | None) -> None:
        self.db, self.frame, self.step_m = db, frame, step_m
        self._cache: dict[tuple[int, int], tuple[BoolArray, BoolArray] | None] = {}

    def cells(self, day: int, run: int) -> tuple[BoolArray, BoolArray] | None:
        """``(surface cells, door cells)`` of a run; None without its geometry."""
        key = (day, run)
        if key not in self._cache:
            geo = self.db.geometry(day, run)
            if geo is None:
                self._cache[key] = None
            else:
                seg, cls = geo
                static = (cls != int(BeamClass.PERSON)) & (cls != int(BeamClass.ROBOT))
                self._cache[key] = (
                    rasterize(seg[static], self.frame, self.step_m),
                    rasterize(seg[cls == int(BeamClass.DOOR)], self.frame, self.step_m),
                )
        return self._cache[key]


def changing_region(truths: list[BoolArray], tol_cells: int) -> BoolArray:
    """Cells occupied in some of ``truths`` and free in others, outside ``tol_cells`` of
    the cells occupied in all of them (the surfaces that never change)."""
    stack = np.stack(truths)
    always, ever = stack.all(axis=0), stack.any(axis=0)
    return ever & ~always & ~_dilate(always, tol_cells)


def map_agreement(
    db: Any, threshold: float = 0.5, tol_cells: int = 1, step_m: float | None = None
) -> tuple[list[MapAgreement], list[DoorSeries]]:
    """:class:`MapAgreement` of every temporal-map localizer of a results database and the
    :class:`DoorSeries` of its changing doors (module docstring); empty without
    ``temporal_map`` artifacts. ``threshold``: the probability above which a cell is
    predicted occupied (the localizers' ``occupied_threshold`` default)."""
    locs = temporal_localizers(db)
    if not locs:
        return [], []
    runs = db.query("SELECT day, run, date, start_s FROM runs ORDER BY day, run")
    dates = {int(d): dt.date.fromisoformat(str(date)) for d, _, date, _ in runs}
    clock = {(int(d), int(r)): float(s) / 3600.0 for d, r, _, s in runs}
    week = weeks_of_days(dates) if dates else {}
    maps = {label: _maps(db, loc) for loc, label in locs}
    index = {label: loc for loc, label in locs}
    frame = next((m[0].frame for m in maps.values() if m), None)
    if frame is None:
        return [], []
    truth = _Truth(db, frame, step_m)
    keys = sorted({(m.day, m.run) for ms in maps.values() for m in ms if m.frame == frame})
    cells = {k: c for k in keys if (c := truth.cells(*k)) is not None}
    if not cells:
        return [], []
    region = changing_region([c[0] for c in cells.values()], tol_cells)
    everywhere = np.ones(frame.shape, bool)
    out = []
    for label, ms in maps.items():
        rows = []
        for m in ms:
            c = cells.get((m.day, m.run))
            if c is None or m.frame != frame:
                continue
            seen = np.isfinite(m.p)
            pred = seen & (np.nan_to_num(m.p) > threshold)
            pa, ra = precision_recall(pred, c[0], seen, everywhere, tol_cells)
            pc, rc = precision_recall(pred, c[0], seen, region, tol_cells)
            n_ch = int((c[0] & region & seen).sum())
            rows.append((m.day, m.run, pa, ra, pc, rc, n_ch))
        if not rows:
            continue
        a = np.array(rows, np.float64)
        day, run = a[:, 0].astype(np.int64), a[:, 1].astype(np.int64)
        out.append(
            MapAgreement(
                loc=index[label],
                label=label,
                day=day,
                run=run,
                week=np.array([week.get(int(d), 1) for d in day], np.int64),
                clock_h=np.array(
                    [clock.get(k, np.nan) for k in zip(day.tolist(), run.tolist(), strict=True)]
                ),
                precision=a[:, 2],
                recall=a[:, 3],
                changing_precision=a[:, 4],
                changing_recall=a[:, 5],
                n_changing=a[:, 6].astype(np.int64),
            )
        )
    return out, _door_series(maps, index, cells, frame, clock, tol_cells)


def _mean_seen(p: FloatArray | None, cells: BoolArray) -> float:
    """Mean of ``p`` over ``cells`` where seen (NaN: no map, or none of them seen)."""
    if p is None:
        return np.nan
    v = p[cells]
    return float(np.nanmean(v)) if np.isfinite(v).any() else np.nan


def _mean_near(p: FloatArray | None, cells: BoolArray, tol_cells: int) -> float:
    """Mean over ``cells`` of the highest predicted occupancy within ``tol_cells`` of each
    (the tolerance of :func:`precision_recall`); NaN where none of them was seen."""
    if p is None:
        return np.nan
    near = ndimage.maximum_filter(np.where(np.isfinite(p), p, -1.0), size=2 * tol_cells + 1)
    v = near[cells]
    v = v[v >= 0]
    return float(v.mean()) if v.size else np.nan


def _door_series(
    maps: dict[str, list[_Map]],
    index: dict[str, int],
    cells: dict[tuple[int, int], tuple[BoolArray, BoolArray]],
    frame: Frame,
    clock: dict[tuple[int, int], float],
    tol_cells: int,
) -> list[DoorSeries]:
    """Per door whose leaf moves over the runs, each of the leaf's two positions (open
    against a wall, shut across the doorway): the true occupancy of its cells and each
    map's mean predicted occupancy there (within ``tol_cells``), per run."""
    keys = sorted(cells)
    doors = np.stack([cells[k][1] for k in keys])
    freq = doors.mean(axis=0)
    labels, n = ndimage.label(_dilate(doors.any(axis=0), 1), np.ones((3, 3), bool))
    by_key = {
        label: {(m.day, m.run): m.p for m in ms if m.frame == frame} for label, ms in maps.items()
    }
    out = []
    for g in range(1, n + 1):
        group = labels == g
        for leaf in (group & (freq > 0) & (freq < 0.5), group & (freq >= 0.5) & (freq < 1)):
            if leaf.sum() < MIN_DOOR_CELLS:
                continue  # a door that never moved
            predicted = {
                label: np.array([_mean_near(ps.get(k), leaf, tol_cells) for k in keys])
                for label, ps in by_key.items()
            }
            iy, ix = np.nonzero(leaf)
            centre = (
                np.array(frame.origin_m)
                + (np.array([ix.mean(), iy.mean()]) + 0.5) * frame.resolution_m
            )
            out.append(
                DoorSeries(
                    centre_m=centre,
                    day=np.array([k[0] for k in keys], np.int64),
                    clock_h=np.array([clock.get(k, np.nan) for k in keys]),
                    truth=doors[:, leaf].mean(axis=1),
                    predicted=predicted,
                    locs=index,
                )
            )
    return out
