"""Point-class precision and recall against the simulator's truth (H&W §4.4, Fig. 6).

Hentschel & Wagner classify scan points as *dynamic*, *semi-static* or *static*. Two truths:

* **By beam class** (:data:`BEAM_TO_POINT_CLASS`, :func:`confusion_matrix`): people are
  dynamic; furniture, exhibits, doors and other robots semi-static (they *can* move between
  runs); walls static. A fixed mapping: a cupboard that never moved is semi-static forever.
* **Seen before at that place** (:class:`SeenPlaces`, :func:`seen_before_point_classes`),
  the paper's meaning (§4.4, §7.3: semistatic points are those "not included in the long-term
  map"): dynamic = a person; semi-static = an object the robot has **not seen at that place
  in an earlier run** (new, or moved since it was last seen); static = the rest (walls, which
  the prior gives, and objects seen at their current place before). An object counts as seen
  in a run when at least one beam hit it; it is at the same place when every coordinate of
  its outline is within :data:`PLACE_TOL_M` of a place it was seen at. The first run of an
  experiment therefore has every object semi-static (H&W Fig. 6: 23 % on day 1), and an
  object moved between runs is semi-static on the run it is first seen at its new place and
  static after. Per object, not per surface: a face of a known, unmoved object seen for the
  first time is static.

:class:`PointClassTally` accumulates, per run and localizer, the confusion against the
seen-before truth and each predicted class's fraction of a scan's valid points (H&W Fig. 6's
shares). Beams that hit nothing, and points a localizer leaves *unknown*, are not scored.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.metrics.result import Result
from dynmap_sim.types import BeamClass

#: Point classes a localizer reports (``PoseEstimate.extras["point_classes"]``).
POINT_CLASSES: tuple[str, ...] = ("unknown", "dynamic", "semi-static", "static")

#: True point class of each :class:`BeamClass`, indexed by its value.
BEAM_TO_POINT_CLASS: NDArray[np.int8] = np.zeros(len(BeamClass), dtype=np.int8)
BEAM_TO_POINT_CLASS[BeamClass.PERSON] = 1
BEAM_TO_POINT_CLASS[[BeamClass.FURNITURE, BeamClass.EXHIBIT, BeamClass.DOOR, BeamClass.ROBOT]] = 2
BEAM_TO_POINT_CLASS[BeamClass.WALL] = 3
BEAM_TO_POINT_CLASS.setflags(write=False)


def confusion_matrix(beam_class: ArrayLike, predicted: ArrayLike) -> NDArray[np.int64]:
    """``(4, 4)`` counts ``[true point class, predicted point class]`` over all beams.

    ``beam_class`` holds :class:`BeamClass` values, ``predicted`` point classes 0..3; any
    shape, same size.
    """
    b = np.asarray(beam_class, dtype=np.int64).ravel()
    p = np.asarray(predicted, dtype=np.int64).ravel()
    if b.shape != p.shape:
        raise ValueError(f"beam classes {b.shape} and predictions {p.shape} differ in size")
    t = BEAM_TO_POINT_CLASS[b]
    n = len(POINT_CLASSES)
    return np.bincount(t * n + np.clip(p, 0, n - 1), minlength=n * n).reshape(n, n)


@dataclass(frozen=True, eq=False)
class ClassScores(Result):
    """Precision and recall per point class (dynamic, semi-static, static); NaN if undefined."""

    precision: tuple[float, float, float]
    recall: tuple[float, float, float]
    support: tuple[int, int, int]

    def to_dict(self) -> dict[str, list[float]]:
        return {
            "precision": list(self.precision),
            "recall": list(self.recall),
            "support": list(self.support),
        }


def class_scores(confusion: ArrayLike) -> ClassScores:
    """Precision/recall per class from a confusion matrix, ignoring true or predicted
    *unknown* (row and column 0)."""
    c = np.asarray(confusion, dtype=np.float64)[1:, 1:]
    tp = np.diag(c)
    with np.errstate(invalid="ignore", divide="ignore"):
        precision = tp / c.sum(axis=0)
        recall = tp / c.sum(axis=1)
    return ClassScores(
        precision=tuple(float(v) for v in precision),  # type: ignore[arg-type]
        recall=tuple(float(v) for v in recall),  # type: ignore[arg-type]
        support=tuple(int(v) for v in c.sum(axis=1)),  # type: ignore[arg-type]
    )


#: Point classes that can be new or moved (:data:`BEAM_TO_POINT_CLASS` semi-static).
_MOVABLE = 2
_STATIC = 3

#: An object is at a place it was seen at when every coordinate of its outline is within
#: this distance [m]: one cell of H&W's 50 mm long-term grids (§7.1), so a nudge the maps
#: cannot resolve is no move.
PLACE_TOL_M = 0.05


def object_places(
    n_objects: int,
    segments: ArrayLike,
    segment_object: ArrayLike,
    circles: ArrayLike,
    circle_object: ArrayLike,
) -> list[NDArray[np.float64]]:
    """Each object's place as one flat array of its coordinates (its segments' end points,
    then its circles' centres and radii, in the geometry's order), by object index."""
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    so = np.asarray(segment_object, dtype=np.int64).ravel()
    cir = np.asarray(circles, dtype=np.float64).reshape(-1, 3)
    co = np.asarray(circle_object, dtype=np.int64).ravel()
    return [np.concatenate([seg[so == k].ravel(), cir[co == k].ravel()]) for k in range(n_objects)]


@dataclass
class SeenPlaces:
    """Where the robot has seen each object in earlier runs: object id -> places (module doc).

    Plain data (it is checkpointed with the experiment after every run)."""

    tol_m: float = PLACE_TOL_M
    places: dict[str, list[NDArray[np.float64]]] = field(default_factory=dict)

    def _known(self, oid: str, place: NDArray[np.float64]) -> bool:
        return any(
            p.shape == place.shape and bool(np.all(np.abs(p - place) <= self.tol_m))
            for p in self.places.get(oid, ())
        )

    def seen_before(
        self, object_ids: Sequence[str], places: Sequence[NDArray[np.float64]]
    ) -> NDArray[np.bool_]:
        """Per object index: seen at this place in an earlier run."""
        return np.array(
            [self._known(oid, pl) for oid, pl in zip(object_ids, places, strict=False)],
            dtype=bool,
        )

    def remember(
        self,
        object_ids: Sequence[str],
        places: Sequence[NDArray[np.float64]],
        hit: ArrayLike,
    ) -> None:
        """Record the places of the objects ``hit`` (bool per object index) in this run."""
        for k in np.flatnonzero(np.asarray(hit, dtype=bool)[: len(places)]):
            oid, pl = object_ids[k], np.asarray(places[k], dtype=np.float64)
            if not self._known(oid, pl):
                self.places.setdefault(oid, []).append(pl.copy())


def seen_before_point_classes(
    beam_class: ArrayLike, beam_object: ArrayLike, seen: ArrayLike
) -> NDArray[np.int8]:
    """True point class per beam (module doc): people dynamic, walls static, any other
    object static when ``seen[beam_object]`` (seen at this place in an earlier run, from
    :meth:`SeenPlaces.seen_before`) and semi-static otherwise; beams that hit nothing 0."""
    b = np.asarray(beam_class, dtype=np.int64)
    obj = np.asarray(beam_object, dtype=np.int64)
    known = np.asarray(seen, dtype=bool).ravel()
    pc = BEAM_TO_POINT_CLASS[b].copy()
    movable = pc == _MOVABLE
    o = obj[movable]
    ok = (o >= 0) & (o < len(known))
    was_seen = np.zeros(o.shape, dtype=bool)
    was_seen[ok] = known[o[ok]]
    pc[movable] = np.where(was_seen, _STATIC, _MOVABLE).astype(np.int8)
    return pc


def point_confusion(true_class: ArrayLike, predicted: ArrayLike) -> NDArray[np.int64]:
    """``(4, 4)`` counts ``[true point class, predicted point class]``, both 0..3."""
    t = np.asarray(true_class, dtype=np.int64).ravel()
    p = np.asarray(predicted, dtype=np.int64).ravel()
    if t.shape != p.shape:
        raise ValueError(f"true classes {t.shape} and predictions {p.shape} differ in size")
    n = len(POINT_CLASSES)
    return np.bincount(np.clip(t, 0, n - 1) * n + np.clip(p, 0, n - 1), minlength=n * n).reshape(
        n, n
    )


@dataclass
class PointClassTally:
    """A localizer's reported point classes over one run: ``confusion`` ``(4, 4)`` against
    the seen-before truth, ``fraction_sum`` ``(4,)`` the sum over scans of each predicted
    class's share of the scan's valid (finite) readings, ``n_scans`` the scans that had
    point classes and valid readings (H&W Fig. 6's daily share = sums over a day's scans
    divided by theirs)."""

    confusion: NDArray[np.int64] = field(default_factory=lambda: np.zeros((4, 4), np.int64))
    fraction_sum: NDArray[np.float64] = field(default_factory=lambda: np.zeros(4))
    n_scans: int = 0

    def add(self, predicted: ArrayLike, ranges_m: ArrayLike, truth: ArrayLike | None) -> None:
        """One scan's predicted classes, its readings and (when known) its true classes
        (:meth:`add_scans` of one row; readings of another size add no shares)."""
        p = np.asarray(predicted, dtype=np.int64).ravel()
        r = np.asarray(ranges_m, dtype=np.float64).ravel()
        if r.shape == p.shape:
            self.add_scans(p[None], r[None], truth)
        elif truth is not None:
            self.confusion += point_confusion(truth, p)

    def add_scans(
        self, predicted: NDArray[np.int64], ranges_m: NDArray[np.floating], truth: ArrayLike | None
    ) -> None:
        """:meth:`add` of each row of ``predicted`` ``(T, B)`` with the same row of
        ``ranges_m`` ``(T, B)`` and of ``truth`` ``(T, B)`` (None: not known), in order: the
        same sums, the shares added scan by scan as :meth:`add` does."""
        p = np.asarray(predicted, dtype=np.int64)
        valid = np.isfinite(np.asarray(ranges_m, dtype=np.float64))
        n_valid = valid.sum(axis=1)
        rows = np.nonzero(n_valid)[0]
        n = len(p)
        key = (np.arange(n)[:, None] * 4 + np.clip(p, 0, 3))[valid]
        counts = np.bincount(key, minlength=4 * n).reshape(n, 4)
        for share in counts[rows] / n_valid[rows, None]:
            self.fraction_sum += share
        self.n_scans += len(rows)
        if truth is not None:
            self.confusion += point_confusion(truth, p)

    def merge(self, other: PointClassTally) -> None:
        self.confusion += other.confusion
        self.fraction_sum += other.fraction_sum
        self.n_scans += other.n_scans

    def fractions(self) -> NDArray[np.float64]:
        """Mean share of each class (unknown, dynamic, semi-static, static); NaN: no scans."""
        if not self.n_scans:
            return np.full(4, np.nan)
        return self.fraction_sum / self.n_scans
