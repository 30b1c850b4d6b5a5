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

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.maps.local_map_numba import (
    numba_available,
    polar_rays,
    scan_log_likelihoods,
)
from dynmap_sim.agent.maps.sample_set import (
    SampleSets,
    mixture_log_likelihood,
    table_log_likelihood,
    to_mm,
)
from dynmap_sim.jit import kernel_backend

FloatArray = NDArray[np.float64]


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
        polar: tuple[FloatArray, FloatArray] | None = None,
        backend: str = "auto",
    ) -> None:
        """One §3.1 update of each sub-map of ``levels`` in turn with the points (all of one
        time step); points farther than ``max_range_m`` from the centre are ignored. The
        points' millimetre ranges and ray indices are computed once (per number of rays):
        without ``polar``, by ``backend`` (:data:`dynmap_sim.jit.KERNEL_BACKENDS`) ``"numba"``
        (``"auto"`` when installed) in one compiled pass (:func:`.local_map_numba.polar_rays`,
        the same values)."""
        kernel = kernel_backend(backend) if polar is None else None
        if kernel is not None:
            levels = list(levels)
            n_rays = list(dict.fromkeys(self.timescales[level].n_rays for level in levels))
            pts = np.asarray(points_map, dtype=np.float64).reshape(-1, 2)
            mm, rays = polar_rays(pts, self.centre, self.max_range_m,
                                  np.array(n_rays, dtype=np.int64), kernel == "python")  # fmt: skip
            for level in levels:
                row = rays[n_rays.index(self.timescales[level].n_rays)]
                self.sub[level].update(row, mm, rng, fill=fill, initialize=initialize)
            return
        ang, dist = self.polar(points_map) if polar is None else polar
        ok = dist <= self.max_range_m
        ang_ok = ang[ok]
        mm = to_mm(dist[ok])
        rays: dict[int, NDArray[np.int64]] = {}
        for level in levels:
            n_rays = self.timescales[level].n_rays
            if n_rays not in rays:
                rays[n_rays] = self.ray_index(ang_ok, n_rays)
            self.sub[level].update(rays[n_rays], mm, rng, fill=fill, initialize=initialize)

    # ------------------------------------------------------------------ perceptual model
    def log_likelihood(
        self,
        level: int,
        polar: tuple[FloatArray, FloatArray],
        *,
        sigma_min_m: float = 0.0,
        min_outlier_ratio: float = 0.0,
    ) -> FloatArray:
        """Per-reading ``log p(d)`` (eq. 6–8) of readings given in this map's polar frame."""
        ang, dist = polar
        ray = self.ray_index(ang, self.timescales[level].n_rays)
        if sigma_min_m > 0.0:  # fast path (σ = 0 needs the exact point-mass handling)
            tab = self.sub[level].model_table(self.max_range_m, sigma_min_m, min_outlier_ratio)
            return table_log_likelihood(tab, ray, dist, self.max_range_m)
        return mixture_log_likelihood(
            self.sub[level].estimates(),
            ray,
            dist,
            self.max_range_m,
            sigma_min_m=sigma_min_m,
            min_outlier_ratio=min_outlier_ratio,
        )

    def log_likelihoods(
        self,
        levels: Sequence[int],
        polar: tuple[FloatArray, FloatArray],
        *,
        sigma_min_m: float = 0.0,
        min_outlier_ratio: float = 0.0,
    ) -> FloatArray:
        """:meth:`log_likelihood` of several levels at once, ``(len(levels), N)``.

        The same values, computed in one pass over the levels' stacked model tables (one
        gather, one ``exp``/``log``) instead of one pass per level; the stack is cached until
        one of its tables changes.
        """
        ang, dist = polar
        n = len(dist)
        levels = list(levels)
        if sigma_min_m <= 0.0 or not levels:
            out = np.empty((len(levels), n))
            for b, level in enumerate(levels):
                out[b] = self.log_likelihood(
                    level,
                    polar,
                    sigma_min_m=sigma_min_m,
                    min_outlier_ratio=min_outlier_ratio,
                )
            return out
        table, offsets, _ = self._model_stack(levels, sigma_min_m, min_outlier_ratio)
        rays = np.empty(len(levels) * n, dtype=np.int64)
        by_n_rays: dict[int, NDArray[np.int64]] = {}
        for b, level in enumerate(levels):
            n_rays = self.timescales[level].n_rays
            if n_rays not in by_n_rays:
                by_n_rays[n_rays] = self.ray_index(ang, n_rays)
            np.add(by_n_rays[n_rays], offsets[b], out=rays[b * n : (b + 1) * n])
        ll = table_log_likelihood(table, rays, np.tile(dist, len(levels)), self.max_range_m)
        return ll.reshape(len(levels), n)

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
        backend: str = "auto",
        out: FloatArray | None = None,
        columns: tuple[FloatArray, FloatArray] | None = None,
    ) -> FloatArray:
        """:meth:`log_likelihoods` of map-frame points ``(N, 2)``, ``(len(levels), N)``
        (written into ``out`` when given).

        ``backend`` ``"numba"`` (extra ``fast``; ``"auto"``: when installed, for the floored
        model ``sigma_min_m > 0``) projects and scores in one compiled loop
        (:mod:`.local_map_numba`, the same values to rounding); ``"numpy"``:
        :meth:`polar` and :meth:`log_likelihoods`. ``columns`` (optional): the points' x
        and y as contiguous arrays, which the compiled loop reads (a scan scored under
        several local maps is split once).
        """
        if backend not in ("auto", "numpy", "numba"):
            raise ValueError(f'backend must be "auto", "numpy" or "numba", got {backend!r}')
        levels = list(levels)
        pts = np.asarray(points_map, dtype=np.float64).reshape(-1, 2)
        compiled = backend == "numba" or (backend == "auto" and numba_available())
        if compiled and sigma_min_m > 0.0 and levels:
            table, offsets, n_rays = self._model_stack(levels, sigma_min_m, min_outlier_ratio)
            return scan_log_likelihoods(
                pts, self.centre, table, offsets, n_rays, self.max_range_m, out, columns
            )
        ll = self.log_likelihoods(
            levels,
            self.polar(pts),
            sigma_min_m=sigma_min_m,
            min_outlier_ratio=min_outlier_ratio,
        )
        if out is None:
            return ll
        out[...] = ll
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
