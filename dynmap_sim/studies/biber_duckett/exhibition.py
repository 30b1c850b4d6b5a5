"""The toaster exhibition in the dynamic map's memory (Biber & Duckett §5.2, Fig. 9).

B&D show one local map near the exhibition with its timescales λ2–λ5 on several days: the
stands appear in the short long-term maps while they are there and fade after their removal,
while λ5 keeps the permanent structure. With ground truth this can be measured: cast the rays
of that local map in the true geometry of an exhibition day; the rays whose first hit is an
exhibit are the *exhibit rays*. On every day a ``dynamic-map`` kept a snapshot of its map
(:class:`~dynmap_sim.agent.maps.dynamic_map.MapSnapshot`), the share of exhibit rays whose
median lies within ``tol_m`` of the exhibit says how much of the exhibition each timescale
remembers.

:func:`exhibit_memory` is a pure function of arrays; :func:`exhibition_from_db` finds the
exhibition and the snapshots in a results folder (the ``dynamic-map``'s daily
``map_snapshot`` artifacts), and :func:`plot_exhibition` draws the Fig. 9 look-alike.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.studies.biber_duckett.map_structure import dynamic_map_snapshots
from dynmap_sim.types import BeamClass

FloatArray = NDArray[np.float64]


def first_hits(
    origin_xy: FloatArray, n_rays: int, segments: FloatArray, max_range_m: float
) -> tuple[FloatArray, NDArray[np.int64]]:
    """Range [m] and segment index of the first hit of ``n_rays`` rays (ray ``j`` at
    ``j 2π / n_rays``) from ``origin_xy``; ``inf`` and ``-1`` without a hit in range."""
    th = np.arange(n_rays) * (2.0 * np.pi / n_rays)
    d = np.column_stack([np.cos(th), np.sin(th)])[:, None, :]  # (n, 1, 2)
    p = segments[None, :, :2]
    e = segments[None, :, 2:] - p
    w = p - np.asarray(origin_xy, dtype=np.float64)[None, None, :]

    def cross(a: FloatArray, b: FloatArray) -> FloatArray:
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    den = cross(d, e)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = cross(w, e) / den
        u = cross(w, d) / den
    ok = (np.abs(den) > 1e-12) & (t > 1e-9) & (u >= 0.0) & (u <= 1.0) & (t <= max_range_m)
    t = np.where(ok, t, np.inf)
    k = np.argmin(t, axis=1)
    r = t[np.arange(n_rays), k]
    return r, np.where(np.isfinite(r), k, -1)


@dataclass(frozen=True)
class ExhibitMemory:
    """Share of a local map's exhibit rays that remember the exhibit, per day and level."""

    local_map: int
    centre: FloatArray
    n_exhibit_rays: dict[int, int]  # per level
    days: tuple[int, ...]
    levels: tuple[int, ...]
    share: FloatArray  # (days, levels); NaN where no exhibit ray has an estimate


def exhibit_memory(
    snapshots: list[tuple[int, Any]],
    segments: FloatArray,
    segment_class: NDArray[np.integer],
    max_range_m: float,
    tol_m: float = 0.10,
) -> ExhibitMemory | None:
    """Exhibit memory of the local map that sees most of the exhibits in ``segments`` (the
    true geometry of an exhibition day, ``segment_class`` per row), over ``snapshots``
    ``[(day, MapSnapshot), ...]``; None when no local map sees an exhibit."""
    if not snapshots:
        return None
    last = snapshots[-1][1]
    ex = np.asarray(segment_class) == int(BeamClass.EXHIBIT)
    if not ex.any() or len(last.centres) == 0:
        return None
    n5 = last.medians_mm[-1].shape[1]
    counts = []
    for c in last.centres:
        _, k = first_hits(c, n5, segments, max_range_m)
        counts.append(int(np.sum((k >= 0) & ex[np.maximum(k, 0)])))
    best = int(np.argmax(counts))
    if counts[best] == 0:
        return None
    centre = last.centres[best]
    levels = last.levels
    share = np.full((len(snapshots), len(levels)), np.nan)
    n_rays_ex: dict[int, int] = {}
    for b, level in enumerate(levels):
        n = last.medians_mm[b].shape[1]
        r, k = first_hits(centre, n, segments, max_range_m)
        rays = np.flatnonzero((k >= 0) & ex[np.maximum(k, 0)])
        n_rays_ex[level] = len(rays)
        for a, (_, snap) in enumerate(snapshots):
            if best >= len(snap.centres):
                continue  # the local map did not exist yet
            mm = snap.medians_mm[b][best, rays]
            have = mm > 0
            if have.any():
                share[a, b] = float(np.mean(np.abs(mm[have] / 1000.0 - r[rays][have]) < tol_m))
    return ExhibitMemory(
        best, centre, n_rays_ex, tuple(d for d, _ in snapshots), tuple(levels), share
    )


def exhibition_from_db(
    db: Any, snapshots: list[tuple[int, Any]] | None = None
) -> tuple[ExhibitMemory, list, tuple, list[int]] | None:
    """(memory, snapshots, (segments, classes) of an exhibition day, exhibition days) of the
    first ``dynamic-map`` in a results database, or None (no such localizer, no exhibition,
    no snapshots). ``snapshots``: that localizer's daily snapshots when
    already loaded (:func:`~.map_structure.dynamic_map_snapshots`)."""
    geo_rows = db.query("SELECT day, run FROM geometry ORDER BY day, run")
    ex_days, ex_geom = [], None
    for day, run in geo_rows:
        g = db.geometry(int(day), int(run))
        if g is not None and np.any(g[1] == int(BeamClass.EXHIBIT)):
            if int(day) not in ex_days:
                ex_days.append(int(day))
            ex_geom = ex_geom or g
    if ex_geom is None:
        return None
    snaps = dynamic_map_snapshots(db) if snapshots is None else snapshots
    if not snaps:
        return None
    range_max_m = float(db.meta()["laser"]["range_max_m"])
    mem = exhibit_memory(snaps, ex_geom[0], ex_geom[1], range_max_m)
    if mem is None:
        return None
    return mem, snaps, ex_geom, ex_days


def fig9_days(days: tuple[int, ...], exhibition_days: list[int]) -> list[int]:
    """Four snapshot days like Fig. 9: before, during (middle and last day), well after."""
    first, last = min(exhibition_days), max(exhibition_days)
    before = [d for d in days if d < first]
    during = [d for d in days if first <= d <= last]
    after = [d for d in days if d >= last + 3] or [d for d in days if d > last]
    mid = (len(during) - 1) // 2
    picks = before[-1:] + during[mid : mid + 1] + during[-1:]
    picks += after[:1]
    return sorted(dict.fromkeys(picks))


def plot_exhibition(
    mem: ExhibitMemory,
    snapshots: list,
    geometry: tuple[FloatArray, NDArray[np.integer]],
    exhibition_days: list[int],
    path: Path,
) -> Path:
    """λ5..λ2 of the exhibition's local map on the :func:`fig9_days` (rows), exhibits red."""
    import matplotlib.pyplot as plt

    by_day = dict(snapshots)
    days = fig9_days(mem.days, exhibition_days)
    levels = tuple(reversed(mem.levels))
    segs, cls = geometry
    ex = np.asarray(cls) == int(BeamClass.EXHIBIT)
    c = mem.centre
    near = np.hypot(segs[:, 0] - c[0], segs[:, 1] - c[1]) < 8.0
    fig, axes = plt.subplots(
        len(days), len(levels), figsize=(2.6 * len(levels), 2.6 * len(days)), squeeze=False
    )
    for row, day in zip(axes, days, strict=True):
        for ax, level in zip(row, levels, strict=True):
            for s in segs[near & ~ex]:
                ax.plot(s[[0, 2]], s[[1, 3]], color="0.85", lw=0.8)
            if day in exhibition_days:
                for s in segs[ex]:
                    ax.plot(s[[0, 2]], s[[1, 3]], color="tab:red", lw=1.2)
            pts = by_day[day].points(mem.local_map, level)
            ax.plot(pts[:, 0], pts[:, 1], ".", ms=1.2, color="k")
            ax.plot(*c, "o", mfc="none", color="tab:blue")
            share = mem.share[mem.days.index(day), mem.levels.index(level)]
            ax.set_title(f"day {day}, λ{level + 1}: {100 * share:.0f} % exhibit", fontsize=7)
            ax.set_xlim(c[0] - 5.0, c[0] + 5.0)
            ax.set_ylim(c[1] - 5.0, c[1] + 5.0)
            ax.set_aspect("equal")
            ax.tick_params(labelsize=5)
    fig.suptitle(
        "The exhibition (red, days "
        f"{min(exhibition_days)}-{max(exhibition_days)}) in one local map (cf. B&D Fig. 9)",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
