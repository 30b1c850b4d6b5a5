"""What the Hentschel & Wagner study reads from a results store (pure reads, no figures).

* the **subject**: the localizer named ``adaptive-memory`` (H&W's model), or else the first
  localizer that reported point classes (its output is what Fig. 6 counts);
* the **static MCL baselines**: ``static-mcl`` localizers, the one on the walls-only prior
  (``map_source = "prior-walls"``, H&W Fig. 4 and §7.3) first;
* per day: mean / max error and lost share (``day_summaries``), the point-class shares and
  scores against the seen-before truth (``point_class_truth``), navigation (``nav_runs``);
* the subject's **long-term maps** from its day artifacts (:func:`ltm_grid`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.metrics import LOST_THRESHOLD_M, PointClassTally, class_scores

#: H&W's weeks (§7): days 1-7 static, 8-14 changed every day, 15-21 people, 22-28 blocked.
DAYS_PER_WEEK = 7
#: H&W's grid cells (§7.1) [m]: the resolution assumed when an artifact does not say.
DEFAULT_RESOLUTION_M = 0.05


def week_of(day: int) -> int:
    """H&W's week of ``day`` (1-based): days 1-7 are week 1."""
    return (int(day) - 1) // DAYS_PER_WEEK + 1


@dataclass
class DaySeries:
    """Per-day figures of one localizer: ``days`` and aligned arrays."""

    label: str
    days: NDArray[np.int64]
    mean_error_m: NDArray[np.float64]
    max_error_m: NDArray[np.float64]
    lost_fraction: NDArray[np.float64]

    def on(self, day: int, what: str) -> float:
        k = np.flatnonzero(self.days == day)
        return float(getattr(self, what)[k[0]]) if len(k) else float("nan")


@dataclass
class PointShares:
    """The subject's point classes per day: ``days``, ``fractions`` ``(D, 4)`` (unknown,
    dynamic, semi-static, static: shares of the valid readings averaged over the day's
    scans), ``truth`` ``(D, 4)`` the truth's shares of the readings that hit something,
    ``tallies`` per day."""

    days: NDArray[np.int64]
    fractions: NDArray[np.float64]
    truth: NDArray[np.float64]
    tallies: list[PointClassTally] = field(default_factory=list)

    def pooled(self, days: list[int]) -> PointClassTally:
        t = PointClassTally()
        for d, tally in zip(self.days.tolist(), self.tallies, strict=True):
            if d in days:
                t.merge(tally)
        return t


@dataclass
class HWData:
    """Everything the study measures on (module doc); ``subject`` None: no H&W model ran."""

    subject: tuple[int, str] | None
    baselines: list[tuple[int, str, bool]]  # (loc, label, on the walls-only prior)
    series: dict[str, DaySeries]
    shares: PointShares | None
    nav: list[tuple[int, int, Any]]
    n_days: int
    bounds: tuple[float, float, float, float] | None
    #: the scenario's driver (``autonomous``: the robot drove itself, as H&W's did)
    driver_kind: str | None = None


def localizer_rows(db: Any) -> list[tuple[int, str, str, dict[str, Any]]]:
    rows = db.query("SELECT idx, label, name, params FROM localizers ORDER BY idx")
    return [(int(i), lab, name, json.loads(p or "{}")) for i, lab, name, p in rows]


def find_subject(db: Any) -> tuple[int, str] | None:
    """The localizer under study (module doc), or None."""
    rows = localizer_rows(db)
    for idx, label, name, _ in rows:
        if name == "adaptive-memory":
            return idx, label
    for idx, label, _, _ in rows:
        if db.point_class_truth_per_day(idx):
            return idx, label
    return None


def day_series(db: Any, loc: int, label: str) -> DaySeries:
    rows = db.query(
        "SELECT day, mean_error_m, max_error_m, lost_fraction FROM day_summaries WHERE loc=? "
        "ORDER BY day",
        (loc,),
    )
    a = np.array(rows, dtype=np.float64).reshape(-1, 4)
    return DaySeries(label, a[:, 0].astype(np.int64), a[:, 1], a[:, 2], a[:, 3])


def point_shares(db: Any, loc: int) -> PointShares | None:
    per_day = db.point_class_truth_per_day(loc)
    if not per_day:
        return None
    days = np.array(sorted(per_day), dtype=np.int64)
    tallies = [per_day[int(d)] for d in days]
    fractions = np.array([t.fractions() for t in tallies]).reshape(len(days), 4)
    truth = np.full((len(days), 4), np.nan)
    for k, t in enumerate(tallies):
        rows = t.confusion.sum(axis=1).astype(float)
        hit = rows[1:].sum()
        if hit > 0:
            truth[k] = rows / hit
            truth[k, 0] = np.nan
    return PointShares(days, fractions, truth, tallies)


def load(db: Any) -> HWData:
    subject = find_subject(db)
    base = [
        (idx, label, params.get("map_source") == "prior-walls")
        for idx, label, name, params in localizer_rows(db)
        if name == "static-mcl"
    ]
    base.sort(key=lambda b: not b[2])
    series = {}
    for idx, label in ([subject] if subject else []) + [(i, lab) for i, lab, _ in base]:
        series[label] = day_series(db, idx, label)
    meta = db.meta()
    bounds = meta.get("bounds")
    return HWData(
        subject=subject,
        baselines=base,
        series=series,
        shares=point_shares(db, subject[0]) if subject else None,
        nav=db.nav_runs(),
        n_days=len({int(d) for (d,) in db.query("SELECT DISTINCT day FROM runs")}),
        bounds=tuple(bounds) if bounds else None,
        driver_kind=((meta.get("scenario") or {}).get("driver") or {}).get("kind"),
    )


#: The scored classes of :func:`class_scores_per_day`, in column order (point-class codes 1-3).
SCORED_CLASSES = ("dynamic", "semistatic", "static")


@dataclass
class DayClassScores:
    """The subject's classes against the seen-before truth, per day: ``days`` and ``(D, 3)``
    arrays over :data:`SCORED_CLASSES`: ``precision``, ``recall`` (NaN where undefined),
    ``truth_points`` (the truth's own count of person, new-or-moved-object and known beams)
    and ``predicted_points`` (the beams the subject gave that class), unknown excluded."""

    days: NDArray[np.int64]
    precision: NDArray[np.float64]
    recall: NDArray[np.float64]
    truth_points: NDArray[np.int64]
    predicted_points: NDArray[np.int64]


def class_scores_per_day(shares: PointShares) -> DayClassScores:
    """Precision and recall of each class on each day (:class:`DayClassScores`)."""
    n = len(shares.days)
    prec, rec = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    truth, pred = np.zeros((n, 3), np.int64), np.zeros((n, 3), np.int64)
    for k, t in enumerate(shares.tallies):
        sc = class_scores(t.confusion)
        prec[k], rec[k] = sc.precision, sc.recall
        truth[k] = sc.support
        pred[k] = np.asarray(t.confusion)[1:, 1:].sum(axis=0)
    return DayClassScores(shares.days.copy(), prec, rec, truth, pred)


def dynamic_scores(shares: PointShares, days: list[int]) -> tuple[float, float, int]:
    """Dynamic precision, recall and support pooled over ``days``."""
    sc = class_scores(shares.pooled(days).confusion)
    return sc.precision[0], sc.recall[0], sc.support[0]


def semistatic_scores(shares: PointShares, days: list[int]) -> tuple[float, float, int]:
    """Semistatic precision, recall and support pooled over ``days``."""
    sc = class_scores(shares.pooled(days).confusion)
    return sc.precision[1], sc.recall[1], sc.support[1]


def lost_threshold_m() -> float:
    return LOST_THRESHOLD_M


# ------------------------------------------------------------------ long-term maps
@dataclass
class LTMGrid:
    """One long-term map: ``prob`` ``(H, W)`` occupancy probability, rows along y, the
    lower-left corner ``origin_m`` and ``resolution_m``; ``name`` of the artifact array."""

    prob: NDArray[np.float64]
    origin_m: tuple[float, float]
    resolution_m: float
    name: str

    @property
    def extent(self) -> tuple[float, float, float, float]:
        h, w = self.prob.shape
        x0, y0 = self.origin_m
        r = self.resolution_m
        return (x0, x0 + w * r, y0, y0 + h * r)


def _as_probability(g: NDArray[np.float64]) -> NDArray[np.float64]:
    """Probabilities as they are; anything outside [0, 1] read as log-odds."""
    finite = g[np.isfinite(g)]
    if finite.size and (finite.min() < 0.0 or finite.max() > 1.0):
        return 1.0 / (1.0 + np.exp(-np.clip(g, -50, 50)))
    return g


def _pick_grid(arrays: dict[str, np.ndarray]) -> tuple[str, NDArray[np.float64]] | None:
    """The long-term map among a day's artifact arrays: the largest 2-D array, or of a
    ``(slots, H, W)`` stack the slot named by a ``current_slot``/``slot``/``ltm_slot`` entry
    (else the last one)."""
    best: tuple[str, NDArray[np.float64]] | None = None
    for name, a in arrays.items():
        a = np.asarray(a)
        if a.dtype.kind not in "fiub" or a.ndim not in (2, 3) or min(a.shape[-2:]) < 4:
            continue
        if a.ndim == 3:
            slot = -1
            for key in ("current_slot", "ltm_slot", "slot", "latest_slot"):
                if key in arrays and np.asarray(arrays[key]).size == 1:
                    slot = int(np.asarray(arrays[key]).ravel()[0])
                    break
            a = a[slot % a.shape[0]]
        if best is None or a.size > best[1].size:
            best = (name, a.astype(np.float64))
    return best


def _scalar(arrays: dict[str, np.ndarray], keys: tuple[str, ...]) -> float | None:
    for key in keys:
        if key in arrays and np.asarray(arrays[key]).size == 1:
            return float(np.asarray(arrays[key]).ravel()[0])
    return None


def _origin(arrays: dict[str, np.ndarray]) -> tuple[float, float] | None:
    for key in ("origin_m", "origin", "grid_origin_m", "origin_xy_m"):
        if key in arrays and np.asarray(arrays[key]).size >= 2:
            o = np.asarray(arrays[key], dtype=np.float64).ravel()
            return float(o[0]), float(o[1])
    return None


def ltm_grid(
    db: Any, loc: int, day: int, bounds: tuple[float, float, float, float] | None = None
) -> LTMGrid | None:
    """The subject's long-term map after ``day`` (or the latest day before it that left
    one), from its day artifacts: named arrays with a grid ``(H, W)`` or ``(slots, H, W)``
    of occupancy probability or log-odds (rows along y), its ``origin_m`` (x, y of the
    lower-left corner; default the world's lower-left bound) and ``resolution_m`` (default
    50 mm, H&W §7.1). None when it left no grid."""
    names = [n for (n,) in db.query("SELECT DISTINCT name FROM artifacts WHERE loc=?", (loc,))]
    found: tuple[int, LTMGrid] | None = None
    for name in names:
        for d, arrays in db.artifacts(loc, name):
            if not isinstance(arrays, dict) or d > day:
                continue
            picked = _pick_grid(arrays)
            if picked is None:
                continue
            res = _scalar(arrays, ("resolution_m", "resolution", "cell_m", "cell_size_m"))
            origin = _origin(arrays)
            if origin is None:
                origin = (bounds[0], bounds[1]) if bounds else (0.0, 0.0)
            grid = LTMGrid(
                _as_probability(picked[1]),
                origin,
                res if res else DEFAULT_RESOLUTION_M,
                f"{name}:{picked[0]}",
            )
            if found is None or d >= found[0]:
                found = (d, grid)
    return None if found is None else found[1]


def ltm_day(db: Any, loc: int, day: int) -> int | None:
    """The day of the artifact :func:`ltm_grid` would use for ``day``."""
    rows = db.query("SELECT max(day) FROM artifacts WHERE loc=? AND day<=?", (loc, day))
    return None if not rows or rows[0][0] is None else int(rows[0][0])
