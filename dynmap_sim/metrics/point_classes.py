"""Point-class precision and recall against the simulator's beam labels (H&W §4.4, Fig. 6).

Hentschel & Wagner classify scan points as *dynamic*, *semi-static* or *static*. The truth
comes from each beam's hit class (:class:`dynmap_sim.types.BeamClass`): people are dynamic;
furniture, exhibits, doors and other robots are semi-static (they move between runs); walls
are static. Beams that hit nothing, and points a localizer leaves *unknown*, are not scored.
"""

from __future__ import annotations

from dataclasses import dataclass

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
