"""Pose errors in the map frame with **no alignment**, ATE and RPE (DESIGN.md §6).

The simulator knows the true map frame, so an estimate is judged exactly where it claims the
robot is: no Umeyama/Horn alignment is applied (unlike a SLAM benchmark on real data). ATE
here is the RMSE of the position errors, which equals ``evo_ape tum REF EST`` without ``-a``
(translation part); RPE follows Sturm et al. (2012), eq. 2–3: the error of relative motions
over a fixed step delta.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim import se2

FloatArray = NDArray[np.float64]


def _poses(a: ArrayLike, name: str) -> FloatArray:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {arr.shape}")
    return arr


def position_errors(truth: ArrayLike, estimate: ArrayLike) -> FloatArray:
    """Euclidean distance between true and estimated positions [m], shape ``(N,)``."""
    t, e = _poses(truth, "truth"), _poses(estimate, "estimate")
    return np.hypot(e[:, 0] - t[:, 0], e[:, 1] - t[:, 1])


def heading_errors(truth: ArrayLike, estimate: ArrayLike) -> FloatArray:
    """Absolute wrapped heading difference [rad] in ``[0, pi]``, shape ``(N,)``."""
    t, e = _poses(truth, "truth"), _poses(estimate, "estimate")
    return np.abs(se2.wrap_angle(e[:, 2] - t[:, 2]))


@dataclass(frozen=True)
class ErrorStats:
    """Summary of a sequence of errors (like evo's APE statistics)."""

    n: int
    mean: float
    median: float
    rmse: float
    max: float
    min: float
    std: float

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict[str, float]) -> ErrorStats:
        return cls(**d)


def error_stats(errors: ArrayLike) -> ErrorStats:
    """Statistics of errors; NaN fields when ``errors`` is empty. NaN entries are ignored."""
    e = np.asarray(errors, dtype=np.float64).ravel()
    e = e[np.isfinite(e)]
    if e.size == 0:
        nan = float("nan")
        return ErrorStats(0, nan, nan, nan, nan, nan, nan)
    return ErrorStats(
        n=int(e.size),
        mean=float(e.mean()),
        median=float(np.median(e)),
        rmse=float(np.sqrt(np.mean(e * e))),
        max=float(e.max()),
        min=float(e.min()),
        std=float(e.std()),
    )


def ate(truth: ArrayLike, estimate: ArrayLike) -> ErrorStats:
    """Absolute trajectory error (translation) without alignment; ``.rmse`` is the ATE [m]."""
    return error_stats(position_errors(truth, estimate))


@dataclass(frozen=True)
class RPEResult:
    """Relative pose error over ``delta`` steps: translation [m] and rotation [rad] stats."""

    delta: int
    translation: ErrorStats
    rotation: ErrorStats

    def to_dict(self) -> dict[str, object]:
        return {
            "delta": self.delta,
            "translation": self.translation.to_dict(),
            "rotation": self.rotation.to_dict(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, object]) -> RPEResult:
        return cls(
            delta=int(d["delta"]),  # type: ignore[arg-type]
            translation=ErrorStats.from_dict(d["translation"]),  # type: ignore[arg-type]
            rotation=ErrorStats.from_dict(d["rotation"]),  # type: ignore[arg-type]
        )


def rpe(truth: ArrayLike, estimate: ArrayLike, delta: int = 10) -> RPEResult:
    """Relative pose error for all pairs ``(i, i + delta)`` (Sturm et al. 2012, eq. 2):
    ``E_i = (Q_i^-1 Q_{i+d})^-1 (P_i^-1 P_{i+d})`` with truth ``Q`` and estimate ``P``."""
    if delta < 1:
        raise ValueError("delta must be >= 1")
    t, e = _poses(truth, "truth"), _poses(estimate, "estimate")
    if t.shape != e.shape:
        raise ValueError(f"truth {t.shape} and estimate {e.shape} differ in shape")
    if len(t) <= delta:
        return RPEResult(delta, error_stats([]), error_stats([]))
    rel_t = se2.between(t[:-delta], t[delta:])
    rel_e = se2.between(e[:-delta], e[delta:])
    err = se2.between(rel_t, rel_e)
    return RPEResult(
        delta,
        error_stats(np.hypot(err[:, 0], err[:, 1])),
        error_stats(np.abs(err[:, 2])),
    )
