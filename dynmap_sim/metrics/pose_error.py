"""Pose errors in the map frame with **no alignment**, ATE and RPE (docs/architecture.md §6).

The simulator knows the true map frame, so an estimate is judged exactly where it claims the
robot is: no Umeyama/Horn alignment is applied (unlike a SLAM benchmark on real data). ATE
here is the RMSE of the position errors, which equals ``evo_ape tum REF EST`` without ``-a``
(translation part); RPE follows Sturm et al. (2012), eq. 2–3: the error of relative motions
over a step delta, given with its unit (frames, seconds or metres; :func:`rpe`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim import se2
from dynmap_sim.metrics.result import Result

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


@dataclass(frozen=True, eq=False)
class ErrorStats(Result):
    """Summary of a sequence of errors (like evo's APE statistics)."""

    n: int
    mean: float
    median: float
    rmse: float
    max: float
    min: float
    std: float


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


#: Units of the RPE's step delta: poses apart, seconds apart, metres travelled (on the truth).
RPE_UNITS: tuple[str, ...] = ("frames", "s", "m")

#: Relative tolerance with which a delta in seconds or metres counts as reached (time stamps
#: and path lengths are sums of floats: 10 steps of 0.1 s may add up to 0.9999999999 s).
RPE_DELTA_RTOL = 1e-6


@dataclass(frozen=True, eq=False)
class RPEResult(Result):
    """Relative pose error over a step ``delta`` in ``unit`` (:data:`RPE_UNITS`): translation
    [m] and rotation [rad] statistics over all pairs."""

    delta: float
    translation: ErrorStats
    rotation: ErrorStats
    unit: str = "frames"

    @property
    def label(self) -> str:
        """``"RPE 10 frames"``, ``"RPE 1 s"``, ``"RPE 2 m"``: what the delta was."""
        return rpe_label(self.delta, self.unit)

    def to_dict(self) -> dict[str, object]:
        return {
            "delta": self.delta,
            "unit": self.unit,
            "translation": self.translation.to_dict(),
            "rotation": self.rotation.to_dict(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, object]) -> RPEResult:
        unit = str(d.get("unit", "frames"))
        delta = d["delta"]
        return cls(
            delta=int(delta) if unit == "frames" else float(delta),  # type: ignore[arg-type]
            translation=ErrorStats.from_dict(d["translation"]),  # type: ignore[arg-type]
            rotation=ErrorStats.from_dict(d["rotation"]),  # type: ignore[arg-type]
            unit=unit,
        )


def rpe_label(delta: float, unit: str) -> str:
    """The name of an RPE over ``delta`` ``unit``: ``"RPE 10 frames"``, ``"RPE 1 s"``."""
    return f"RPE {delta:g} {unit}"


def rpe_pairs(
    n: int,
    delta: float,
    unit: str = "frames",
    stamps_s: ArrayLike | None = None,
    truth: ArrayLike | None = None,
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Index pairs ``(i, j)`` of an RPE over ``delta`` ``unit`` in a sequence of ``n`` poses.

    ``"frames"``: ``j = i + delta`` (a whole number >= 1). ``"s"``: ``j`` is the first pose at
    least ``delta`` seconds after ``i`` by ``stamps_s``; ``"m"``: the first pose at least
    ``delta`` metres further along the path of ``truth`` (positions ``(n, 2+)``). Delta counts
    as reached within :data:`RPE_DELTA_RTOL`; poses with no such ``j`` start no pair.
    """
    if unit not in RPE_UNITS:
        raise ValueError(f"unit must be one of {RPE_UNITS}, got {unit!r}")
    if unit == "frames":
        if delta != int(delta) or delta < 1:
            raise ValueError(f"delta must be a whole number of frames >= 1, got {delta}")
        d = int(delta)
        i = np.arange(max(n - d, 0), dtype=np.int64)
        return i, i + d
    if not delta > 0:
        raise ValueError(f"delta must be > 0 {unit}, got {delta}")
    if unit == "s":
        if stamps_s is None:
            raise ValueError("an RPE over seconds needs stamps_s")
        q = np.asarray(stamps_s, dtype=np.float64).ravel()
    else:
        if truth is None:
            raise ValueError("an RPE over metres needs the true trajectory")
        xy = np.asarray(truth, dtype=np.float64)[:, :2]
        q = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    if q.shape != (n,):
        raise ValueError(f"{n} poses but {q.shape[0]} {'stamps' if unit == 's' else 'positions'}")
    if n and np.any(np.diff(q) < 0):
        raise ValueError("time stamps must not decrease")
    j = np.searchsorted(q, q + delta * (1.0 - RPE_DELTA_RTOL), side="left")
    i = np.arange(n, dtype=np.int64)
    keep = j < n
    return i[keep], j[keep].astype(np.int64)


def rpe(
    truth: ArrayLike,
    estimate: ArrayLike,
    delta: float = 10,
    unit: str = "frames",
    stamps_s: ArrayLike | None = None,
) -> RPEResult:
    """Relative pose error for all pairs ``(i, j)`` ``delta`` ``unit`` apart
    (:func:`rpe_pairs`; Sturm et al. 2012, eq. 2):
    ``E_i = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)`` with truth ``Q`` and estimate ``P``.

    ``unit``: ``"frames"`` (default; ``delta`` poses apart, like ``evo_rpe --delta_unit f
    --all_pairs``), ``"s"`` (``delta`` seconds apart by ``stamps_s``) or ``"m"`` (``delta``
    metres apart along the true path)."""
    t, e = _poses(truth, "truth"), _poses(estimate, "estimate")
    if t.shape != e.shape:
        raise ValueError(f"truth {t.shape} and estimate {e.shape} differ in shape")
    i, j = rpe_pairs(len(t), delta, unit, stamps_s, t)
    delta = int(delta) if unit == "frames" else float(delta)
    if len(i) == 0:
        return RPEResult(delta, error_stats([]), error_stats([]), unit)
    rel_t = se2.between(t[i], t[j])
    rel_e = se2.between(e[i], e[j])
    err = se2.between(rel_t, rel_e)
    return RPEResult(
        delta,
        error_stats(np.hypot(err[:, 0], err[:, 1])),
        error_stats(np.abs(err[:, 2])),
        unit,
    )
