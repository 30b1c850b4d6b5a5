"""Kümmerle et al. 2009's relation error of a SLAM trajectory ("On measuring the accuracy of
SLAM algorithms", Autonomous Robots 27(4), eq. 2).

The reference is a set of relations ``(t1, t2, delta)``: the pose of the robot at time
``t2`` expressed in its frame at ``t1`` (manually verified scan alignments). For each
relation the estimate's own relative pose ``x_t1^-1 ⊕ x_t2`` is compared with ``delta``;
the error ``e = delta^-1 ⊕ (x_t1^-1 ⊕ x_t2)`` is split into its translation ``|e_xy|`` [m]
and its absolute rotation ``|e_θ|`` [deg]. The benchmark reports mean ± std of both over all
relations (as GMapping's 0.061 ± 0.044 m on FR079). No alignment is needed: the metric only
sees relative motions, so a global offset or a drifting frame do not count, only the
local and loop-closing consistency the relations cover.

Relations name scans by time stamp; estimates are looked up by the nearest stamp within
``max_dt_s`` (the benchmark's stamps are the logs' own, so exact matches are the rule).
Relations whose stamps have no scan are counted in ``n_unmatched`` and left out.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim import se2
from dynmap_sim.metrics.result import Result

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Relations:
    """A benchmark's relations: ``t1``, ``t2`` ``(M,)`` [s], ``delta`` ``(M, 3)`` (x, y, θ)."""

    t1: FloatArray
    t2: FloatArray
    delta: FloatArray

    def __len__(self) -> int:
        return len(self.t1)


def read_relations(path: str | Path) -> Relations:
    """Read a relations file: one relation a line, ``t1 t2 x y z roll pitch yaw`` (the 2-D
    benchmark's format; ``z``, roll and pitch are ignored) or ``t1 t2 x y yaw``; ``#``
    comments and blank lines are skipped. A malformed line is a :class:`ValueError` naming it."""
    rows: list[tuple[float, float, float, float, float]] = []
    text = Path(path).read_text(encoding="utf-8", errors="replace")
    for ln, line in enumerate(text.splitlines(), start=1):
        tok = line.split()
        if not tok or tok[0].startswith("#"):
            continue
        try:
            v = [float(t) for t in tok]
        except ValueError:
            raise ValueError(f"{path}: line {ln}: expected numbers, got {line.strip()!r}") from None
        if len(v) == 8:
            rows.append((v[0], v[1], v[2], v[3], v[7]))
        elif len(v) == 5:
            rows.append((v[0], v[1], v[2], v[3], v[4]))
        else:
            raise ValueError(
                f"{path}: line {ln}: expected 't1 t2 x y z roll pitch yaw' (8 numbers) or "
                f"'t1 t2 x y yaw' (5), got {len(v)}"
            )
    a = np.array(rows, dtype=np.float64).reshape(-1, 5)
    return Relations(a[:, 0], a[:, 1], a[:, 2:5].copy())


@dataclass(frozen=True, eq=False)
class RelationError(Result):
    """Kümmerle's relation error: mean ± std of translation [m] and absolute rotation [deg]
    over the matched relations (NaN when none), with the length filter that was applied."""

    n_relations: int
    n_unmatched: int
    translation_mean_m: float
    translation_std_m: float
    translation_max_m: float
    rotation_mean_deg: float
    rotation_std_deg: float
    rotation_max_deg: float
    min_length_m: float = 0.0
    max_length_m: float = float("inf")


def relation_errors(
    stamps_s: ArrayLike,
    poses: ArrayLike,
    relations: Relations,
    max_dt_s: float = 1e-3,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per-relation errors of the trajectory ``poses`` ``(N, 3)`` at ``stamps_s`` ``(N,)``:
    ``(translation_m, rotation_rad, matched)`` of shape ``(M,)``, NaN where a relation's
    stamp has no scan within ``max_dt_s`` (``matched`` is then 0, else 1)."""
    t = np.asarray(stamps_s, dtype=np.float64)
    p = np.asarray(poses, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) != len(t):
        raise ValueError(f"poses must be (N, 3) with N = len(stamps_s), got {p.shape}")
    order = np.argsort(t, kind="stable")
    ts, ps = t[order], p[order]
    i1, ok1 = _nearest(ts, relations.t1, max_dt_s)
    i2, ok2 = _nearest(ts, relations.t2, max_dt_s)
    ok = ok1 & ok2
    est = se2.between(ps[i1], ps[i2])
    err = se2.between(relations.delta, est)
    trans = np.where(ok, np.hypot(err[:, 0], err[:, 1]), np.nan)
    rot = np.where(ok, np.abs(se2.wrap_angle(err[:, 2])), np.nan)
    return trans, rot, ok.astype(np.float64)


def _nearest(ts: FloatArray, q: FloatArray, tol: float) -> tuple[NDArray[np.intp], NDArray]:
    if len(ts) == 0:
        return np.zeros(len(q), dtype=np.intp), np.zeros(len(q), dtype=bool)
    j = np.clip(np.searchsorted(ts, q), 1, max(len(ts) - 1, 1))
    lo = np.clip(j - 1, 0, len(ts) - 1)
    hi = np.clip(j, 0, len(ts) - 1)
    pick = np.where(np.abs(ts[lo] - q) <= np.abs(ts[hi] - q), lo, hi)
    return pick, np.abs(ts[pick] - q) <= tol


def relation_error(
    stamps_s: ArrayLike,
    poses: ArrayLike,
    relations: Relations,
    min_length_m: float = 0.0,
    max_length_m: float = float("inf"),
    max_dt_s: float = 1e-3,
) -> RelationError:
    """Kümmerle et al. 2009's relation error of ``poses`` at ``stamps_s`` against
    ``relations``, restricted to relations whose reference translation ``|delta_xy|`` lies in
    ``[min_length_m, max_length_m]`` (all by default)."""
    length = np.hypot(relations.delta[:, 0], relations.delta[:, 1])
    keep = (length >= min_length_m) & (length <= max_length_m)
    sub = Relations(relations.t1[keep], relations.t2[keep], relations.delta[keep])
    trans, rot, matched = relation_errors(stamps_s, poses, sub, max_dt_s)
    ok = matched > 0
    tr, ro = trans[ok], np.degrees(rot[ok])

    def stat(a: FloatArray, f) -> float:  # noqa: ANN001
        return float(f(a)) if a.size else float("nan")

    return RelationError(
        n_relations=int(ok.sum()),
        n_unmatched=int((~ok).sum()),
        translation_mean_m=stat(tr, np.mean),
        translation_std_m=stat(tr, np.std),
        translation_max_m=stat(tr, np.max),
        rotation_mean_deg=stat(ro, np.mean),
        rotation_std_deg=stat(ro, np.std),
        rotation_max_deg=stat(ro, np.max),
        min_length_m=float(min_length_m),
        max_length_m=float(max_length_m),
    )
