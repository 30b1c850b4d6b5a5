"""The dynamic map: a set of local maps and its online/offline learning (Biber & Duckett §4.4).

* **Short-term memory** (λ1, "always"): after each localization step every local map whose
  centre is within ``update_radius_m`` (2.5 m) of the robot learns the scan (one §3.1 step);
  if no local map is that near, a new one is created at the robot's position and initialized
  (filled) with the scan.
* **Long-term memory** (λ2 per run, λ3–λ5 per day): the (scan, pose) pairs of the run / day
  are stored and learned offline, with exactly the same rule: for each local map, all points
  of the scans taken within ``update_radius_m`` form the measurements ``M`` of one time step.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.maps.local_map import TABLE1, LocalMap, Timescale

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class MapSnapshot:
    """The long-term sub-maps of every local map at one moment, compact (B&D Figs. 7, 9):
    ``medians_mm[k]`` is ``(L, n_rays of levels[k])`` uint16, the median range of each ray
    of each local map (0: no estimate or ``σ > sigma_max_m``); ``centres`` ``(L, 2)`` [m]."""

    centres: FloatArray
    levels: tuple[int, ...]
    medians_mm: tuple[NDArray[np.uint16], ...]
    sigma_max_m: float

    def points(self, local_map: int, level: int) -> FloatArray:
        """Map-frame points ``(N, 2)`` of one local map's sub-map ``level``."""
        mm = self.medians_mm[self.levels.index(level)][local_map]
        n = len(mm)
        th = np.arange(n) * (2.0 * np.pi / n)  # ray j at j 2π/n (LocalMap.ray_index)
        ok = mm > 0
        r = mm[ok].astype(np.float64) / 1000.0
        return self.centres[local_map] + r[:, None] * np.column_stack([np.cos(th), np.sin(th)])[ok]

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The snapshot as named arrays (``centres``, ``levels``, ``sigma_max_m`` and
        ``medians_mm_<level>``), as a day artifact is stored; :meth:`from_arrays` reads it."""
        out = {
            "centres": np.asarray(self.centres, dtype=np.float64),
            "levels": np.asarray(self.levels, dtype=np.int64),
            "sigma_max_m": np.asarray(self.sigma_max_m, dtype=np.float64),
        }
        for level, mm in zip(self.levels, self.medians_mm, strict=True):
            out[f"medians_mm_{level}"] = np.asarray(mm, dtype=np.uint16)
        return out

    @classmethod
    def from_arrays(cls, arrays: Mapping[str, np.ndarray]) -> MapSnapshot:
        """The snapshot of :meth:`to_arrays`."""
        levels = tuple(int(v) for v in np.asarray(arrays["levels"]).ravel())
        return cls(
            np.asarray(arrays["centres"], dtype=np.float64).reshape(-1, 2),
            levels,
            tuple(np.asarray(arrays[f"medians_mm_{v}"], dtype=np.uint16) for v in levels),
            float(arrays["sigma_max_m"]),
        )


class DynamicMap:
    """Local maps with their centres; learning entry points of §4.4."""

    def __init__(
        self,
        timescales: tuple[Timescale, ...] = TABLE1,
        max_range_m: float = 8.0,
        update_radius_m: float = 2.5,
        first_step_fills: bool = False,
    ) -> None:
        self.timescales = timescales
        self.max_range_m = float(max_range_m)
        self.update_radius_m = float(update_radius_m)
        #: See :class:`~dynmap_sim.agent.maps.sample_set.SampleSets`.
        self.first_step_fills = bool(first_step_fills)
        self.local_maps: list[LocalMap] = []

    def __len__(self) -> int:
        return len(self.local_maps)

    @property
    def centres(self) -> FloatArray:
        """Centres ``(L, 2)`` of the local maps [m] (read-only; cached until a local map is
        added: local maps are only ever appended, and a centre never moves)."""
        if not self.local_maps:
            return np.zeros((0, 2))
        c = self.__dict__.get("_centres")
        if c is None or len(c) != len(self.local_maps):
            c = np.array([lm.centre for lm in self.local_maps])
            c.flags.writeable = False
            self._centres = c
        return c

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state.pop("_centres", None)  # a cache
        return state

    def levels(self, interval: str) -> list[int]:
        """Indices of the timescales updated at ``interval`` ("always", "run", "day")."""
        return [i for i, ts in enumerate(self.timescales) if ts.interval == interval]

    def snapshot(
        self, levels: Sequence[int] = (1, 2, 3, 4), sigma_max_m: float = 0.10
    ) -> MapSnapshot:
        """The sub-maps ``levels`` (default λ2–λ5) of every local map as ray medians."""
        lv = tuple(int(v) for v in levels)
        meds = tuple(
            np.array([lm.median_ranges_mm(v, sigma_max_m) for lm in self.local_maps]).reshape(
                len(self.local_maps), self.timescales[v].n_rays
            )
            for v in lv
        )
        return MapSnapshot(self.centres.copy(), lv, meds, float(sigma_max_m))

    def near(self, xy: ArrayLike, radius_m: float) -> NDArray[np.int64]:
        """Indices of local maps with centres within ``radius_m`` of ``xy``, nearest first."""
        if not self.local_maps:
            return np.zeros(0, dtype=np.int64)
        d = np.hypot(*(self.centres - np.asarray(xy, dtype=np.float64)[:2]).T)
        idx = np.flatnonzero(d < radius_m)
        return idx[np.argsort(d[idx], kind="stable")]

    def add_local_map(
        self, centre_xy: ArrayLike, points_map: ArrayLike, rng: np.random.Generator
    ) -> int:
        """Create a local map at ``centre_xy`` and seed every sub-map with ``points_map``.

        The seed does not count as a time step: each sub-map's first update fills it (§3.5).
        """
        lm = LocalMap(
            centre_xy,
            self.timescales,
            self.max_range_m,
            self.__dict__.get("first_step_fills", True),
        )
        lm.learn_levels(range(len(self.timescales)), points_map, rng, fill=True, initialize=False)
        self.local_maps.append(lm)
        return len(self.local_maps) - 1

    def learn_online(
        self,
        pose: ArrayLike,
        points_map: ArrayLike,
        rng: np.random.Generator,
        *,
        levels: Sequence[int] | None = None,
        allow_new: bool = True,
    ) -> list[int]:
        """Short-term update after a localization step (§4.4); returns the updated maps.

        A new local map is created at the pose when none is within ``update_radius_m`` (and
        ``allow_new``); its index is returned then.
        """
        lv = self.levels("always") if levels is None else list(levels)
        idx = self.near(pose, self.update_radius_m)
        pts = np.asarray(points_map, dtype=np.float64).reshape(-1, 2)
        if idx.size == 0:
            if allow_new and len(pts) > 0:
                return [self.add_local_map(np.asarray(pose)[:2], pts, rng)]
            return []
        for i in idx:
            self.local_maps[int(i)].learn_levels(lv, pts, rng)
        return [int(i) for i in idx]

    def learn_offline(
        self,
        levels: Sequence[int],
        poses: ArrayLike,
        points_map: Sequence[FloatArray],
        rng: np.random.Generator,
    ) -> int:
        """One long-term step of ``levels`` from stored scans (§4.4); returns maps updated.

        ``poses`` ``(T, 3)`` and ``points_map`` (T arrays of map-frame points) are the run's
        or the day's (pose, scan) pairs. For each local map, the points of all scans taken
        within ``update_radius_m`` of its centre are the measurements of one time step.
        """
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        if not self.local_maps or len(poses) == 0 or not levels:
            return 0
        if len(points_map) != len(poses):
            raise ValueError("poses and points_map must have the same length")
        c = self.centres
        d = np.hypot(poses[:, None, 0] - c[None, :, 0], poses[:, None, 1] - c[None, :, 1])  # (T, L)
        near = d < self.update_radius_m
        n_updated = 0
        for i in np.flatnonzero(near.any(axis=0)):
            sel = np.flatnonzero(near[:, i])
            pts = np.concatenate([points_map[k] for k in sel]) if sel.size else np.zeros((0, 2))
            if len(pts) == 0:
                continue
            self.local_maps[int(i)].learn_levels(levels, pts, rng)
            n_updated += 1
        return n_updated

    # ------------------------------------------------------------------ memory
    @property
    def sample_bytes(self) -> int:
        """Bytes of all samples of all local maps."""
        return int(sum(lm.sample_bytes for lm in self.local_maps))

    def copy(self) -> DynamicMap:
        """A deep copy (a frozen snapshot, §5.3)."""
        out = DynamicMap(
            self.timescales,
            self.max_range_m,
            self.update_radius_m,
            self.__dict__.get("first_step_fills", True),
        )
        out.local_maps = [lm.copy() for lm in self.local_maps]
        return out
