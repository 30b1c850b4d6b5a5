"""Local maps: 360° polar sample-set sub-maps at several timescales (Biber & Duckett §4.1).

A local map is linked to the global map by the position of its centre (map frame). Each of
its sub-maps is a 360° "range scan" from that centre: ray ``j`` of a sub-map with ``R`` rays
points at angle ``j·2π/R`` (map-frame axes) and holds a dynamic sample set (§3.1). A 2-D point
seen from nearby is projected to the centre: it goes to the closest ray, with the distance
from the centre as its range (§4.1).

:data:`TABLE1` holds the timescales of Table 1: rays 360/360/720/1440/1440, samples
5/10/50/100/100, update ratios 0.2 (always) / 0.8 (per run) / 0.8, 0.2, 0.05 (daily) — 329,400
samples per local map, 658,800 bytes at 2 bytes per sample.

Sub-maps grow by ``u·n`` samples per time step until full (§3.1); ``first_step_fills=True``
lets each ray's first time step fill it instead (the initialization of the toy, §3.5).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.maps.sample_set import SampleSets, mixture_log_likelihood
from dynmap_sim.jit import compiled

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True)
class Timescale:
    """One row of Table 1: update ratio, when it is updated, rays and samples per ray."""

    name: str
    update_ratio: float
    interval: str  # "always" (after each localization step), "run" or "day"
    n_rays: int
    n_samples: int

    @property
    def half_life_steps(self) -> float:
        """Half-life ``ln 2 / λ`` with ``λ = −ln(1 − u)`` in update intervals (§3.2)."""
        return float(np.log(2.0) / -np.log(1.0 - self.update_ratio))


#: Table 1 of Biber & Duckett: λ1 is the short-term memory, λ2–λ5 the long-term memories.
TABLE1: tuple[Timescale, ...] = (
    Timescale("lambda1", 0.2, "always", 360, 5),
    Timescale("lambda2", 0.8, "run", 360, 10),
    Timescale("lambda3", 0.8, "day", 720, 50),
    Timescale("lambda4", 0.2, "day", 1440, 100),
    Timescale("lambda5", 0.05, "day", 1440, 100),
)


class LocalMap:
    """A local map at ``centre_xy`` (map frame, metres) with one sub-map per timescale."""

    def __init__(
        self,
        centre_xy: ArrayLike,
        timescales: tuple[Timescale, ...] = TABLE1,
        max_range_m: float = 8.0,
        first_step_fills: bool = False,
    ) -> None:
        self.centre = np.asarray(centre_xy, dtype=np.float64).reshape(2).copy()
        self.timescales = timescales
        self.max_range_m = float(max_range_m)
        self.sub = [
            SampleSets(ts.n_rays, ts.n_samples, ts.update_ratio, first_step_fills)
            for ts in timescales
        ]

    # ------------------------------------------------------------------ geometry
    def polar(self, points_map: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Bearing [rad, 0..2π) and distance [m] of map-frame points seen from the centre."""
        p = np.asarray(points_map, dtype=np.float64).reshape(-1, 2) - self.centre
        ang = np.arctan2(p[:, 1], p[:, 0]) % (2.0 * np.pi)
        return ang, np.hypot(p[:, 0], p[:, 1])

    @staticmethod
    def ray_index(bearing_rad: ArrayLike, n_rays: int) -> NDArray[np.int64]:
        """Closest ray of a sub-map with ``n_rays`` rays (ray ``j`` at ``j·2π/n_rays``)."""
        b = np.asarray(bearing_rad, dtype=np.float64)
        return (np.rint(b * (n_rays / (2.0 * np.pi))).astype(np.int64)) % n_rays

    def ray_directions(self, level: int) -> FloatArray:
        """Unit vectors ``(n_rays, 2)`` of the rays of sub-map ``level`` (cached, read-only)."""
        n = self.timescales[level].n_rays
        cache = self.__dict__.setdefault("_dirs", {})
        if n not in cache:
            a = np.arange(n) * (2.0 * np.pi / n)
            dirs = np.stack([np.cos(a), np.sin(a)], axis=1)
            dirs.flags.writeable = False
            cache[n] = dirs
        return cache[n]

    # ------------------------------------------------------------------ learning
    def learn_levels(
        self,
        levels: Sequence[int],
        points_map: ArrayLike,
        rng: np.random.Generator,
        *,
        fill: bool = False,
        initialize: bool = True,
    ) -> None:
        """One §3.1 update of each sub-map of ``levels`` in turn with the points (all of one
        time step); points farther than ``max_range_m`` from the centre are ignored. The
        points' millimetre ranges and ray indices are computed once, for every number of
        rays among the levels, in one compiled pass (:func:`_polar_rays`)."""
        levels = list(levels)
        n_rays = list(dict.fromkeys(self.timescales[level].n_rays for level in levels))
        pts = np.asarray(points_map, dtype=np.float64).reshape(-1, 2)
        mm = np.empty(len(pts), dtype=np.uint16)
        rays = np.empty((len(n_rays), len(pts)), dtype=np.int64)
        k = _polar_rays(np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]),
                        float(self.centre[0]), float(self.centre[1]), self.max_range_m,
                        np.array(n_rays, dtype=np.int64), mm, rays)  # fmt: skip
        for level in levels:
            row = rays[n_rays.index(self.timescales[level].n_rays), :k]
            self.sub[level].update(row, mm[:k], rng, fill=fill, initialize=initialize)

    # ------------------------------------------------------------------ perceptual model
    def _model_stack(
        self, levels: list[int], sigma_min_m: float, min_outlier_ratio: float
    ) -> tuple[FloatArray, NDArray[np.int64], NDArray[np.int64]]:
        """The levels' model tables stacked ``(sum of rays, 4)``, each level's first row and
        its number of rows (rays).

        Cached per ``levels`` and model floors: a level whose samples changed since
        (:attr:`.SampleSets.version`; λ1 after every online step) has its table recomputed
        and its rows copied into the stack in place, the others are kept."""
        key = (tuple(levels), float(sigma_min_m), float(min_outlier_ratio))
        cached = self.__dict__.get("_stack")
        if cached is None or cached[0] != key:
            tabs = [
                self.sub[level].model_table(self.max_range_m, sigma_min_m, min_outlier_ratio)
                for level in levels
            ]
            offsets = np.concatenate([[0], np.cumsum([len(t) for t in tabs])[:-1]])
            n_rays = np.array([len(t) for t in tabs], dtype=np.int64)
            versions = [self.sub[level].version for level in levels]
            cached = (key, versions, np.concatenate(tabs), offsets.astype(np.int64), n_rays)
            self._stack = cached
            return cached[2], cached[3], cached[4]
        versions, stack, offsets, n_rays = cached[1:]
        for b, level in enumerate(levels):
            sub = self.sub[level]
            if sub.version != versions[b]:  # (a level's number of rays never changes)
                tab = sub.model_table(self.max_range_m, sigma_min_m, min_outlier_ratio)
                stack[offsets[b] : offsets[b] + len(tab)] = tab
                versions[b] = sub.version
        return stack, offsets, n_rays

    def scan_log_likelihoods(
        self,
        levels: Sequence[int],
        points_map: FloatArray,
        *,
        sigma_min_m: float = 0.0,
        min_outlier_ratio: float = 0.0,
        out: FloatArray | None = None,
        columns: tuple[FloatArray, FloatArray] | None = None,
    ) -> FloatArray:
        """Per-reading ``log p(d)`` (eq. 6–8) of map-frame points ``(N, 2)`` under the
        sub-maps ``levels``, ``(len(levels), N)`` (written into ``out``, C-contiguous, when
        given): each point projected to the centre (bearing, distance, §4.1) goes to the
        closest ray of each sub-map.

        With a floor ``sigma_min_m > 0`` the points are projected and scored in one compiled
        loop over the levels' stacked model tables (:func:`_scan_loglik`); without one (the
        paper's model exactly, whose rays of equal samples are point masses) by
        :func:`.sample_set.mixture_log_likelihood`. ``columns`` (optional): the points' x and
        y as contiguous arrays (a scan scored under several local maps is split once).
        """
        levels = list(levels)
        pts = np.asarray(points_map, dtype=np.float64).reshape(-1, 2)
        if columns is None:
            columns = (np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]))
        if out is None:
            out = np.empty((len(levels), len(columns[0])))
        if not levels:
            return out
        if sigma_min_m > 0.0:
            table, offsets, n_rays = self._model_stack(levels, sigma_min_m, min_outlier_ratio)
            _scan_loglik(columns[0], columns[1], float(self.centre[0]), float(self.centre[1]),
                         table, offsets, n_rays, self.max_range_m, out)  # fmt: skip
            return out
        ang, dist = self.polar(pts)
        for b, level in enumerate(levels):
            ray = self.ray_index(ang, self.timescales[level].n_rays)
            out[b] = mixture_log_likelihood(self.sub[level].estimates(), ray, dist,
                                            self.max_range_m,
                                            min_outlier_ratio=min_outlier_ratio)  # fmt: skip
        return out

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        # caches: copies of the model tables, ray directions, points
        for name in ("_stack", "_dirs", "_points"):
            state.pop(name, None)
        return state

    def points(self, level: int, sigma_max_m: float = 0.05) -> FloatArray:
        """Map-frame points of the medians of sub-map ``level`` with ``σ ≤ sigma_max_m`` (§4.3);
        read-only, cached until the sub-map learns."""
        est = self.sub[level].estimates()
        cache = self.__dict__.setdefault("_points", {})
        held = cache.get((level, sigma_max_m))
        if held is not None and held[0] is est:  # the same estimates object: unchanged samples
            return held[1]
        ok = (est.count > 0) & (est.sigma_m <= sigma_max_m)
        pts = self.centre + est.rho_m[ok, None] * self.ray_directions(level)[ok]
        pts.flags.writeable = False
        cache[(level, sigma_max_m)] = (est, pts)
        return pts

    def median_ranges_mm(self, level: int, sigma_max_m: float = 0.10) -> NDArray[np.uint16]:
        """Median range [mm] of every ray of sub-map ``level``, 0 where the ray has no
        samples or ``σ > sigma_max_m`` (a compact form of :meth:`points`, for snapshots)."""
        est = self.sub[level].estimates()
        ok = (est.count > 0) & (est.sigma_m <= sigma_max_m)
        mm = np.clip(np.rint(est.rho_m * 1000.0), 1, 65535)
        return np.where(ok, mm, 0).astype(np.uint16)

    @property
    def first_step_fills(self) -> bool:
        """Whether a ray's first time step fills its sample sets (see :class:`SampleSets`)."""
        return self.sub[0].fills_first_step if self.sub else True

    # ------------------------------------------------------------------ memory
    @property
    def n_samples_capacity(self) -> int:
        """Sample slots of all sub-maps (329,400 for Table 1)."""
        return int(sum(ts.n_rays * ts.n_samples for ts in self.timescales))

    @property
    def sample_bytes(self) -> int:
        """Bytes of the sample storage of all sub-maps (2 per sample)."""
        return int(sum(s.sample_bytes for s in self.sub))

    @property
    def nbytes(self) -> int:
        """Bytes of samples plus per-ray counts of all sub-maps."""
        return int(sum(s.nbytes for s in self.sub))

    def copy(self) -> LocalMap:
        """A deep copy."""
        out = LocalMap(self.centre, self.timescales, self.max_range_m, self.first_step_fills)
        out.sub = [s.copy() for s in self.sub]
        return out


# ---------------------------------------------------------------------- compiled kernels
@compiled
def _scan_loglik(px, py, cx, cy, table, offsets, n_rays, max_range_m, out):  # type: ignore[no-untyped-def]
    """``out[b, i] = log p`` (eq. 6–8) of point ``(px_i, py_i)`` seen from the centre
    ``(cx, cy)`` under the level whose model-table rows (:meth:`.SampleSets.model_table`)
    start at ``offsets[b]`` (``n_rays[b]`` rays)."""
    two_pi = 2.0 * math.pi
    for i in range(px.shape[0]):
        dx = px[i] - cx
        dy = py[i] - cy
        ang = math.atan2(dy, dx) % two_pi
        dist = math.hypot(dx, dy)
        inside = dist >= 0.0 and dist <= max_range_m
        for b in range(offsets.shape[0]):
            nr = n_rays[b]
            ray = np.int64(np.rint(ang * (nr / two_pi))) % nr
            row = offsets[b] + ray
            z = dist - table[row, 0]
            p = math.exp(table[row, 2] - z * z * table[row, 1])
            if inside:
                p += table[row, 3]
            out[b, i] = math.log(p) if p > 0.0 else -math.inf


@compiled
def _polar_rays(px, py, cx, cy, max_range_m, n_rays, mm, rays):  # type: ignore[no-untyped-def]
    """The points within ``max_range_m`` of ``(cx, cy)``, in order: their ranges rounded to
    millimetres (clipped to ``[0, 65535]``) in ``mm`` and their closest rays in ``rays[b]``
    for sub-maps of ``n_rays[b]`` rays (ray ``j`` at ``j·2π/n_rays[b]``); returns how many."""
    two_pi = 2.0 * math.pi
    k = 0
    for i in range(px.shape[0]):
        dx = px[i] - cx
        dy = py[i] - cy
        dist = math.hypot(dx, dy)
        if not dist <= max_range_m:
            continue
        ang = math.atan2(dy, dx) % two_pi
        mm[k] = np.uint16(min(max(np.rint(dist * 1000.0), 0.0), 65535.0))
        for b in range(n_rays.shape[0]):
            nr = n_rays[b]
            rays[b, k] = np.int64(np.rint(ang * (nr / two_pi))) % nr
        k += 1
    return k
