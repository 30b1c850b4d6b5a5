"""MCL on a time-specific map predicted by a temporal model of every cell (shared base).

The base of ``fremen`` (:mod:`.fremen_localizer`) and ``markov-grid``
(:mod:`.markov_grid_localizer`): at the start of each run the temporal model predicts every
cell's occupancy probability at the run's time; the cells above ``occupied_threshold``
become the occupied cells of an :class:`~dynmap_sim.agent.grid.OccupancyGrid` on which the
project's MCL core (``static-mcl``'s :class:`~.particle_filter.AMCLFilter`, its likelihood
field and recovery) localizes for the whole run, as Krajník et al. (ECMR 2015) localize on
the FreMEn-predicted map of the time. At the end of the run the model learns from the run's
scans at their estimated poses, as ``adaptive-memory`` learns its long-term map: the scans
of each ``observation_interval_s`` window are traced into a grid
(:meth:`OccupancyGrid.from_scans`), each cell it saw occupied or free is one observation
of that cell at the window's middle time.

The cell frame (origin, resolution, size) is the prior's walls rasterized to a 5 cm grid;
the walls are the models' first observation (occupied), and the free space the prior implies
is free in the first map without being an observation (the prior does not know the
furniture: a "free" observation of a chair's cell a second before the run sees it would be
a change). So both localizers need the prior's walls.

The scans the models learn from are placed by a second MCL on the first map, which never
changes (``learn_poses = "fixed-map"``, the default): Krajník et al.'s robots learned their
spectral models while localized on a static map, and a map that learns from the estimates made
on itself carries every bias of one run into the next and drifts with them (``"own"``; the
measurements are in the docs' tuning notes on FreMEn). It costs a second filter.

The first run (``first_map = "slam"``, the default) is mapped as ``static-mcl``'s and
``dynamic-map``'s are, by the project's first-run SLAM anchored on the prior's walls
(:class:`~dynmap_sim.agent.maps.map_source.FirstRunMap`), and its scans at the optimized
poses are the models' first observations: Krajník et al. build their maps from a localized
robot too, and a map learned from scans placed by MCL on the bare walls of a furnished room
learns that MCL's errors. ``first_map = "walls"`` localizes the first run on the walls
instead (for worlds whose prior walls are all there is).

The run's time [s] is ``(day − 1) · 86400`` plus the time of day: by default the first
scan's stamp (an experiment stamps seconds since midnight), or ``run_clock_s + (run − 1) ·
run_spacing_s`` when ``run_clock_s`` is set (a replayed log's clock is not the time of
day), plus the time since the run's first scan. The map is therefore built at the run's
first scan, not at :meth:`begin_run`.
"""

from __future__ import annotations

from abc import abstractmethod
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.agent.grid import FREE, OCCUPIED, UNKNOWN, OccupancyGrid
from dynmap_sim.agent.localization.particle_filter import StaticMCL
from dynmap_sim.agent.maps.map_source import FirstRunMap
from dynmap_sim.types import LaserSpec, Odometry, PoseEstimate, Prior, Scan

DAY_S = 86400.0


class TemporalMapMCL(StaticMCL):
    """``static-mcl`` on the map a temporal model predicts for each run (module docstring).

    ``first_map``: ``"slam"`` or ``"walls"``, what the first run localizes on;
    ``learn_poses``: ``"fixed-map"`` or ``"own"``, whose estimates place the scans the models
    learn from (both: module docstring); ``mapper_params``: the first-run SLAM's fields, as
    ``static-mcl``'s;
    ``config`` and ``overrides``: the MCL configuration, as ``static-mcl``'s (default
    ``tuned`` after a SLAM first run, whose maps hold the furniture, ``walls-only`` on the
    walls, the configuration for a map without it);
    ``occupied_threshold``: probability above which a predicted cell is occupied (0.5: the
    more likely state); ``observation_interval_s`` [s]: the scans of one window make one
    observation per cell (600: much shorter than the 6 h shortest period the models resolve,
    so a cell is taken constant within it, and long enough that a window sees most cells
    near the route); ``learn_every_scans``: every k-th scan enters learning (5: neighbouring
    scans see the same cells); ``run_clock_s``, ``run_spacing_s`` [s]: the run's time of day
    when the stamps are not it (module docstring).
    """

    def __init__(
        self,
        laser: LaserSpec,
        rng: np.random.Generator,
        first_map: str = "slam",
        learn_poses: str = "fixed-map",
        mapper_params: dict[str, Any] | None = None,
        config: str | None = None,
        overrides: dict[str, Any] | None = None,
        occupied_threshold: float = 0.5,
        observation_interval_s: float = 600.0,
        learn_every_scans: int = 5,
        run_clock_s: float | None = None,
        run_spacing_s: float = 0.0,
        **params: Any,
    ) -> None:
        name = type(self).name
        if first_map not in ("slam", "walls"):
            raise ValueError(f"{name}: first_map must be 'slam' or 'walls', not {first_map!r}")
        slam = first_map == "slam"
        if mapper_params and not slam:
            raise ValueError(f"{name}: mapper_params go with first_map = 'slam' only")
        super().__init__(
            laser,
            rng,
            config=config or ("tuned" if slam else "walls-only"),
            map_source="first-run" if slam else "prior-walls",
            overrides=overrides,
            mapper_params=mapper_params,
        )
        self.first_map = first_map
        if learn_poses not in ("fixed-map", "own"):
            raise ValueError(
                f"{name}: learn_poses must be 'fixed-map' or 'own', not {learn_poses!r}"
            )
        self.learn_poses = learn_poses
        #: The MCL on the first map whose estimates the models learn from (``fixed-map``).
        self.anchor: StaticMCL | None = None
        if params:
            raise TypeError(f"{name}: unknown parameters {sorted(params)}")
        if not 0.0 < occupied_threshold < 1.0:
            raise ValueError(f"{name}: occupied_threshold must be in (0, 1)")
        if not observation_interval_s > 0 or int(learn_every_scans) < 1:
            raise ValueError(f"{name}: observation_interval_s > 0 and learn_every_scans >= 1")
        self.occupied_threshold = float(occupied_threshold)
        self.observation_interval_s = float(observation_interval_s)
        self.learn_every_scans = int(learn_every_scans)
        self.run_clock_s = None if run_clock_s is None else float(run_clock_s)
        self.run_spacing_s = float(run_spacing_s)
        #: The cell frame: the prior walls' grid (None before the first run).
        self.frame: OccupancyGrid | None = None
        #: Cells ever observed (flat ``H·W``): the others are unknown in a predicted map.
        self.seen: NDArray[np.bool_] | None = None
        self._prior: Prior | None = None
        self._day_origin_s = 0.0
        self._stamp0: float | None = None
        self._run_time0_s = 0.0
        self._n_scans = 0
        self._scans: list[tuple[int, float, NDArray, NDArray]] = []
        #: The day's runs: (run, time [s], occupancy probability each localized on).
        self._day_maps: list[tuple[int, float, NDArray[np.float16]]] = []
        self._maps_day = 0

    # -- the temporal model (subclasses) ---------------------------------------------------
    @abstractmethod
    def _make_model(self, n_cells: int) -> None:
        """Create the temporal model of ``n_cells`` cells (the flat cell frame)."""

    @abstractmethod
    def _observe(self, t_s: float, cells: NDArray[np.int64], states: NDArray[np.float64]) -> None:
        """Learn that ``cells`` (flat indices) were in ``states`` (1 occupied) at ``t_s``."""

    @abstractmethod
    def _predict(self, t_s: float) -> NDArray[np.float64]:
        """Occupancy probability of every cell (flat ``H·W``) at ``t_s``."""

    # -- the map ---------------------------------------------------------------------------
    def predicted_grid(self, t_s: float, p: NDArray[np.float64] | None = None) -> OccupancyGrid:
        """The time-specific map at ``t_s`` [s]: cells seen and predicted above the
        threshold occupied, the other seen cells free, never-seen cells unknown (``p``: the
        prediction at ``t_s`` when already made)."""
        assert self.frame is not None and self.seen is not None
        p = self._predict(t_s) if p is None else p
        occ = np.full(self.seen.size, UNKNOWN, np.int8)
        occ[self.seen] = FREE
        occ[self.seen & (p > self.occupied_threshold)] = OCCUPIED
        f = self.frame
        return OccupancyGrid(occ.reshape(f.shape), f.origin_xy_m, f.resolution_m, f.max_dist_m)

    def _run_time(self, stamp_s: float) -> float:
        """The run's clock [s] at a scan stamped ``stamp_s`` (module docstring)."""
        if self._stamp0 is None:
            self._stamp0 = float(stamp_s)
            assert self._prior is not None
            if self.run_clock_s is None:
                tod = self._stamp0
            else:
                tod = self.run_clock_s + max(self._prior.run - 1, 0) * self.run_spacing_s
            self._run_time0_s = self._day_origin_s + tod
        return self._run_time0_s + (float(stamp_s) - self._stamp0)

    # -- the run ---------------------------------------------------------------------------
    def begin_run(self, prior: Prior) -> None:
        if self.frame is None:
            if prior.walls is None or len(prior.walls) == 0:
                raise ValueError(f"{self.name} needs the prior's walls (its cell frame)")
            seed = None if prior.initial_pose is None else np.asarray(prior.initial_pose)[:2]
            self.frame = OccupancyGrid.from_segments(prior.walls, free_seed_xy_m=seed)
            self.seen = np.zeros(self.frame.occupancy.size, bool)
            self._make_model(self.seen.size)
        self._prior = prior
        if prior.day != self._maps_day:
            self._day_maps, self._maps_day = [], prior.day
        self._day_origin_s = max(prior.day - 1, 0) * DAY_S
        self._stamp0 = None
        self._n_scans = 0
        self._scans = []

    def update(self, odom: Odometry, scan: Scan) -> PoseEstimate:
        t = self._run_time(scan.stamp_s)
        if self._prior is not None:  # the run's first scan: its map, then MCL's begin_run
            prior, self._prior = self._prior, None
            assert self.frame is not None and self.seen is not None
            if not self.seen.any():  # the very first run: the walls are the first observation
                walls = np.flatnonzero(self.frame.occupancy.ravel() == OCCUPIED)
                self._learn(t, walls, np.ones(walls.size))
                self.seen[self.frame.occupancy.ravel() == FREE] = True
            if self.map_source.ready:  # else the first-run SLAM maps this run
                p = self._predict(t)
                self.set_map(self.predicted_grid(t, p))
                kept = np.where(self.seen, p, np.nan).astype(np.float16)
                self._day_maps.append((prior.run, t, kept.reshape(self.frame.shape)))
            super().begin_run(prior)
            if self.anchor is None and self.learn_poses == "fixed-map" and self.map_source.ready:
                self._make_anchor(self.frame)  # first_map = "walls": the walls are the map
            if self.anchor is not None:
                self.anchor.begin_run(prior)
        est = super().update(odom, scan)
        learned = est if self.anchor is None else self.anchor.update(odom, scan)
        if self._n_scans % self.learn_every_scans == 0:
            ranges = np.asarray(scan.ranges_m, np.float64)
            self._scans.append((self._n_scans, t, learned.mean.copy(), ranges))
        self._n_scans += 1
        return est

    def _make_anchor(self, grid: OccupancyGrid) -> None:
        """The MCL on the fixed map ``grid`` whose estimates the models learn from."""
        anchor = StaticMCL(self.laser, self.rng.spawn(1)[0], map_source="prior-walls")
        anchor.config = self.config
        anchor.set_map(grid)
        self.anchor = anchor

    def end_run(self) -> None:
        mapped = self.map_source.building
        super().end_run()
        if self.anchor is not None:
            self.anchor.end_run()
        if mapped:  # the first run: learn from its scans at the SLAM's optimized poses
            assert isinstance(self.map_source, FirstRunMap)
            static_map = self.map_source.static_map
            assert static_map is not None
            if self.learn_poses == "fixed-map":
                self._make_anchor(static_map.grid)
            traj = static_map.trajectory
            self._scans = [(n, t, traj[n].copy(), r) for n, t, _, r in self._scans]
            self.map_source.static_map = None  # its keyframes are not needed any more
        if not self._scans:
            return
        times = np.array([s[1] for s in self._scans])
        window = np.floor((times - times[0]) / self.observation_interval_s).astype(np.int64)
        for w in np.unique(window):
            idx = np.flatnonzero(window == w)
            poses = np.array([self._scans[i][2] for i in idx])
            ranges = np.array([self._scans[i][3] for i in idx])
            cells, states = self._trace(poses, ranges)
            self._learn(float(np.mean(times[idx])), cells, states)
        self._scans = []

    def day_artifacts(self) -> dict[str, dict[str, np.ndarray]]:
        """``temporal_map``: the maps the day's runs localized on, as predicted at each run's
        first scan before it was learned from (``p_occupied`` ``(runs, H, W)`` float16, rows
        along y, NaN where never seen; ``run``, ``t_s`` [s] per map; ``origin_m``,
        ``resolution_m``): what the model expected, to set against the truth of each run."""
        if self.frame is None or not self._day_maps:
            return {}
        return {
            "temporal_map": {
                "p_occupied": np.stack([m[2] for m in self._day_maps]),
                "run": np.array([m[0] for m in self._day_maps], np.int64),
                "t_s": np.array([m[1] for m in self._day_maps]),
                "origin_m": self.frame.origin_xy_m.copy(),
                "resolution_m": np.array(self.frame.resolution_m),
            }
        }

    def _learn(self, t_s: float, cells: NDArray[np.int64], states: NDArray[np.float64]) -> None:
        assert self.seen is not None
        self.seen[cells] = True
        self._observe(t_s, cells, states)

    def _trace(self, poses: NDArray, ranges: NDArray) -> tuple[NDArray[np.int64], NDArray]:
        """Flat frame cells seen by scans at ``poses`` and their states (1: occupied)."""
        f = self.frame
        assert f is not None
        g = OccupancyGrid.from_scans(poses, ranges, self.laser, resolution_m=f.resolution_m)
        iy, ix = np.nonzero(g.occupancy != UNKNOWN)
        fx, fy = f.cell_of(g.cell_centers(ix, iy))
        h, w = f.shape
        inside = (fx >= 0) & (fx < w) & (fy >= 0) & (fy < h)
        cells = (fy * w + fx)[inside].astype(np.int64)
        states = (g.occupancy[iy, ix] == OCCUPIED)[inside].astype(np.float64)
        # the two lattices coincide (both on multiples of the resolution); a cell met twice
        # by rounding keeps its occupied reading
        order = np.lexsort((-states, cells))
        cells, states = cells[order], states[order]
        first = np.concatenate([[True], cells[1:] != cells[:-1]])
        return cells[first], states[first]
