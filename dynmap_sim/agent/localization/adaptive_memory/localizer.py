"""H&W §6.1: ``adaptive-memory``, Monte Carlo localization on the static points only, on the
long-term map whose expected ranges fit the current scan best.

Per scan (the data flow of H&W Fig. 2):

1. The pose is predicted from the last estimate and the odometry (the pose at hand when the
   scan arrives; everything below uses it, as MCL runs last in Fig. 2).
2. The scan (sensory memory) is segmented into boxes and tracked (:mod:`.object_tracker`,
   §4.2): points get dynamic / static / unknown (eqs. 10-11).
3. ``u`` of the tracker's static points update the current long-term slot's grid (eq. 1 picks
   the slot; :mod:`.ltm_map`, §4.3, eqs. 12-15), at the predicted pose (``ltm_update_pose``);
   a point the walls prior already explains adds free space only (``ltm_learn_prior_walls``).
4. The semistatic test (§4.4), on the long-term map as it was when the run began
   (``semistatic_map``): a non-dynamic point with no obstacle of that map within its
   uncertainty is semistatic; a fast box the current map mostly explains is not dynamic
   (``ltm_veto_dynamic``). Final classes: dynamic; semistatic; static (tracked, slow,
   explained by that map); unknown (not associated, explained by that map).
5. MCL (§6.1) with the project's AMCL core (:class:`~dynmap_sim.agent.localization.
   particle_filter.AMCLFilter`, ``mcl_config``) on the static points only; with fewer than
   ``min_static_points`` the explained unknown points are added (the first scan of a run has
   no associated box at all). The map is the long-term slot whose ray-cast expected ranges
   have the least mean squared error against the scan (every ``select_every_scans``).

Odometry, scans and the prior only: the agent never sees the truth.
"""

from __future__ import annotations

import math
from dataclasses import asdict, field, replace
from typing import Annotated, Any

import numpy as np
from numpy.typing import NDArray
from pydantic import Field

from dynmap_sim import se2
from dynmap_sim.agent.grid import FREE
from dynmap_sim.agent.localization.adaptive_memory.ltm_map import (
    LTMMap,
    LTMParams,
    point_covariances,
    semistatic_classes,
)
from dynmap_sim.agent.localization.adaptive_memory.memory_stores import (
    SLOT_INITS,
    LTMStore,
    SlotBuffer,
)
from dynmap_sim.agent.localization.adaptive_memory.object_tracker import (
    DYNAMIC,
    SEMISTATIC,
    STATIC,
    UNKNOWN,
    Boxes,
    ObjectTracker,
    TrackerParams,
    beam_trig,
    scan_points,
    segment_scan,
)
from dynmap_sim.agent.localization.likelihood_field import LikelihoodTable, select_beams
from dynmap_sim.agent.localization.localizer import Localizer, register_localizer
from dynmap_sim.agent.localization.particle_filter import (
    CONFIGS,
    AMCLFilter,
    reported_covariance,
)
from dynmap_sim.agent.params import (
    Finite,
    Fraction,
    NonNegative,
    NonNegativeInt,
    Positive,
    PositiveInt,
    int_range,
    params_dataclass,
)
from dynmap_sim.jit import compiled
from dynmap_sim.types import Diagnostic, LaserSpec, Odometry, PoseEstimate, Prior, Scan

FloatArray = NDArray[np.float64]

NAME = "adaptive-memory"
DAY_S = 86400.0
#: Values of ``AdaptiveMemoryConfig.ltm_update_pose``.
LTM_UPDATE_POSES = ("estimate", "predicted")
#: Values of ``AdaptiveMemoryConfig.semistatic_map``.
SEMISTATIC_MAPS = ("run_start", "current")


@params_dataclass(NAME)
class AdaptiveMemoryConfig:
    """Parameters of ``adaptive-memory`` (H&W 2011; § and eq. are the paper's; "ours" where
    the paper is silent)."""

    # -- stores (§3, eq. 1; §7.1) --------------------------------------------------------
    #: Sensory memory: slot length [s] and slots (§7.1: 0.1 s, 10).
    sm_dt_s: Positive = 0.1
    sm_slots: PositiveInt = 10
    #: Short-term memory: slot length [s] and slots (§7.1: 0.1 s, 100).
    stm_dt_s: Positive = 0.1
    stm_slots: PositiveInt = 100
    #: Long-term memory: slot length [s] and slots (§7.1: 8640 s, 10: one day).
    ltm_dt_s: Positive = 8640.0
    ltm_slots: PositiveInt = 10
    #: What a long-term slot starts from when it becomes current (ours; §3 is silent):
    #: ``copy_latest`` | ``prior_only`` | ``keep`` (:class:`.memory_stores.LTMStore`).
    slot_init: str = "copy_latest"
    #: Time of day [s] of a run's start (ours: the prior carries the day and run, not the
    #: clock; 36000 = 10:00, the apartment's run), plus ``run_spacing_s`` per later run of a
    #: day. ``t`` of eq. 1 is ``(day - 1)·86400 + run_clock_s + (run - 1)·run_spacing_s +``
    #: the time since the run's first scan, ``t_s`` the first midnight: the stamps' own
    #: origin (seconds since midnight in an experiment, a log's clock in a replay) is not
    #: added again.
    run_clock_s: NonNegative = 36000.0
    run_spacing_s: NonNegative = 0.0
    # -- long-term grids (§4.3, eqs. 12-15; §7.1) -----------------------------------------
    #: Grid cell [m] (§7.1: 50 mm).
    cell_m: Positive = 0.05
    #: Share of the static points that enter the long-term map per scan (§4.3, §7.1: 0.05).
    u: Fraction = 0.05
    #: The pose the long-term update uses (ours; Fig. 2 draws the LTM update before MCL):
    #: ``predicted`` (default): the odometry-predicted pose, before MCL as in Fig. 2;
    #: ``estimate``: after this scan's MCL step, with its covariance. Either way the §4.4
    #: test sees the map before this scan's points. ``predicted`` because learning the map at
    #: the pose just fitted to it reinforces that pose's errors (docs/tuning/adaptive-memory.md).
    ltm_update_pose: str = "predicted"
    #: The long-term map learns from a scan only when it already explains at least this
    #: share of the scan's static points (ours; 0: from every scan, as the paper). Meant
    #: against learning at a wrong pose; off by default because it also keeps new furniture
    #: out of the map on day 1 and leaves MCL with too few static points.
    ltm_min_explained: Fraction = 0.0
    #: Whether a sampled static point that the walls prior (H&W Fig. 4) already explains
    #: within its uncertainty adds occupied evidence: ``True`` is §4.3's transfer rule taken
    #: literally; ``False`` (default, ours) keeps only the free space along its beam. The
    #: prior's wall cells are pinned, so such a point adds nothing at the wall but a copy of
    #: it shifted by the pose error, which MCL then finds as likely as the wall itself; the
    #: walls stay what Fig. 4 calls them, "the landmarks for localization".
    ltm_learn_prior_walls: bool = False
    #: Inverse sensor model peak (ours; Elfes [15] style): P(occ) at the point's mean.
    p_hit: float = 0.7
    #: Free-space evidence along the sampled points' beams (ours; the paper has occupied
    #: evidence only, so moved furniture would never leave the map). On by default: week 2
    #: moves furniture every day and a map that keeps every old place attracts MCL to them.
    free_space: bool = True
    #: Log-odds added to a cell a sampled beam passed (ours: P = 0.4).
    l_free: Finite = -0.4
    #: Free space stops this many standard deviations of the point before it (ours).
    free_stop_sigma: Positive = 3.0
    #: Log-odds clamp (ours): a cell at ``l_max`` needs ~6 free passes to drop below
    #: ``l_occupied``, so a moved cupboard fades within a run, a wall seen past a person not.
    l_min: Finite = -2.0
    l_max: Positive = 3.5
    #: A cell is an obstacle (§4.4's test, §6.1's map) from this log-odds (ours: P = 0.92,
    #: three hits at a point's mean, so one scan's stray points never make an obstacle).
    l_occupied: Positive = 2.5
    #: Half-width of the Gaussian stencil of a point [cells] (ours: 3 cells = 15 cm, > 3σ of a
    #: well-localized point).
    stencil_cells: int_range(1, 20) = 3
    #: Floor added to every point covariance [m, std] (ours: half a cell).
    cov_floor_m: Positive = 0.025
    # -- reading covariance Σ_s (§4.1, eq. 4; URG-04LX datasheet) ---------------------------
    #: Range noise: max(sigma_r_min_m, sigma_r_rel · r) (URG-04LX: 10 mm or 1 %).
    sigma_r_min_m: NonNegative = 0.01
    sigma_r_rel: NonNegative = 0.01
    #: Bearing noise [rad] (ours: the 0.36° step's quantization, 0.36°/sqrt(12)).
    sigma_alpha_rad: NonNegative = float(np.deg2rad(0.36) / np.sqrt(12.0))
    # -- semistatic test (§4.4) ------------------------------------------------------------
    #: The long-term map a point is checked against (§4.4 names ``M_τ^LTM``; which state of
    #: it the paper leaves open, docs/replicas/hentschel-wagner.md):
    #: ``run_start`` (default): the current slot as it was when this run began, what earlier
    #: runs put in long-term memory, so an object new today stays semistatic all day (Fig. 6:
    #: 23 % on day 1, when only the walls are known); ``current``: the slot being written,
    #: before this scan's points, where ``u`` of a new object's points make it static within
    #: seconds. MCL's map and the dynamic veto use the current slot either way.
    semistatic_map: str = "run_start"
    #: "Within the uncertainty of the scan point" (ours: Mahalanobis <= 2, at least 1.5
    #: cells), searched at most this many cells away.
    semistatic_sigma: Positive = 2.0
    semistatic_max_cells: int_range(1, 20) = 4
    # -- objects (§4.2, eqs. 8-11) ----------------------------------------------------------
    #: Speed threshold of eq. 10 [m/s] (§7.1: 0.3).
    v_thres: Positive = 0.3
    #: Segmentation (ours; the paper gives none): adaptive breakpoint angle [deg] (Borges &
    #: Aldon 2004), least points of a box, missing beams bridged inside a segment.
    breakpoint_lambda_deg: Annotated[Positive, Field(le=89.0)] = 10.0
    min_box_points: PositiveInt = 3
    max_gap_beams: NonNegativeInt = 2
    #: The sliding-wall trap (ours; :mod:`.object_tracker`): boxes longer than this [m] are
    #: never dynamic (a person or a robot is shorter), nor those cut by the field of view
    #: and, with ``occlusion_never_dynamic``, by a nearer return next to them (not one across
    #: beams without a return: :mod:`.object_tracker`).
    max_dynamic_length_m: Positive = 1.2
    occlusion_never_dynamic: bool = True
    #: A fast box at least this share of whose points the long-term map explains is not
    #: dynamic (ours; 1 keeps only boxes the map explains entirely): a new face of a known
    #: cupboard makes its box's centre jump and look fast for a few scans, while a person
    #: stands where the map has free space.
    ltm_veto_dynamic: Fraction = 0.5
    #: Kalman filter (ours; "a common Kalman filter as in [7]"): white acceleration [m/s^2],
    #: centre measurement noise [m], initial speed std [m/s], association gate [m]; a box is
    #: dynamic after ``confirm_steps`` fast updates in a row (and static again after as many
    #: slow ones); a track is dropped after ``max_misses`` scans unseen.
    #: Leg pairing (ours; the paper boxes segments as they come): a laser at shin height sees
    #: a person as two legs, each a segment, whose centres swing fore and aft against each
    #: other over a stride, so a leg's box speeds up and stops while the person walks on, and
    #: the nearer leg hides an end of the farther one (the sliding-wall trap then keeps it
    #: from ever being dynamic). Segments no longer than ``leg_max_m`` [m] (an adult leg is
    #: 0.1-0.15 m across) whose centroids are mutual nearest within ``leg_pair_m`` [m] (the
    #: ROS ``leg_detector``'s ``leg_pair_separation_m``: a stride's leg spread at shin height)
    #: make one box, whose centre is the person's. 0 (the default) pairs nothing: 0.5 calls
    #: more of a walking person dynamic but shifts week 2's errors upwards on the H&W
    #: replica (docs/replicas/hentschel-wagner.md), so it stays an option.
    leg_pair_m: NonNegative = 0.0
    leg_max_m: Positive = 0.25
    track_sigma_accel: Positive = 1.0
    track_sigma_meas_m: Positive = 0.05
    track_sigma_v0: Positive = 1.0
    track_gate_m: Positive = 0.5
    confirm_steps: PositiveInt = 2
    max_misses: NonNegativeInt = 2
    # -- localization (§6.1) -----------------------------------------------------------------
    #: The project's AMCL configuration (``tuned-end-points`` | ``tuned`` | ``nav2-default`` |
    #: ``walls-only``) and field overrides. ``tuned-end-points``: the likelihood field on the
    #: static points' end points as §6.1 has it, the configuration this model was measured
    #: with (``tuned``'s see-through term was not measured here).
    mcl_config: str = "tuned-end-points"
    mcl_overrides: dict[str, Any] = field(default_factory=dict)
    #: Below this many static points, the explained unknown ones join (ours).
    min_static_points: NonNegativeInt = 20
    #: The points MCL uses: ``static`` (§6.1) or ``non-dynamic`` (static, unknown and
    #: semistatic: the whole scan but the people; ours, for comparison).
    mcl_points: str = "static"
    #: Map selection (§6.1: least mean squared error of expected ranges) every this many
    #: scans (ours: 1 Hz), over ``select_beams`` beams; switch only if better by
    #: ``select_margin`` (ours: 10 %, no flapping between equal maps).
    select_every_scans: PositiveInt = 10
    select_beams: PositiveInt = 60
    select_margin: Fraction = 0.1
    #: The MCL's likelihood field is rebuilt from the chosen long-term map every this many
    #: scans (ours: 5 s; the map changes a little every scan, the field costs a distance
    #: transform).
    map_refresh_scans: PositiveInt = 50

    def __post_init__(self) -> None:
        if not 0.5 < self.p_hit < 1.0:
            raise ValueError(f"p_hit must be in (0.5, 1), got {self.p_hit!r}")
        if self.l_free > 0 or self.l_min > 0:
            raise ValueError("l_free and l_min must be <= 0")
        if self.l_occupied > self.l_max:
            raise ValueError("l_occupied must be <= l_max")
        if self.semistatic_map not in SEMISTATIC_MAPS:
            raise ValueError(f"semistatic_map must be one of {SEMISTATIC_MAPS}")
        if self.ltm_update_pose not in LTM_UPDATE_POSES:
            raise ValueError(f"ltm_update_pose must be one of {LTM_UPDATE_POSES}")
        if self.mcl_points not in ("static", "non-dynamic"):
            raise ValueError("mcl_points must be 'static' or 'non-dynamic'")
        if self.slot_init not in SLOT_INITS:
            raise ValueError(f"slot_init must be one of {SLOT_INITS}")
        if self.mcl_config not in CONFIGS:
            raise ValueError(f"mcl_config must be one of {sorted(CONFIGS)}")
        unknown = set(self.mcl_overrides) - set(asdict(CONFIGS[self.mcl_config]))
        if unknown:
            raise ValueError(f"unknown mcl_overrides {sorted(unknown)}")

    def ltm_params(self) -> LTMParams:
        return LTMParams(
            p_hit=self.p_hit, free_space=self.free_space, l_free=self.l_free,
            free_stop_sigma=self.free_stop_sigma, l_min=self.l_min, l_max=self.l_max,
            l_occupied=self.l_occupied, stencil_cells=self.stencil_cells,
            semistatic_sigma=self.semistatic_sigma,
            semistatic_max_cells=self.semistatic_max_cells, cov_floor_m=self.cov_floor_m,
        )  # fmt: skip

    def tracker_params(self) -> TrackerParams:
        return TrackerParams(
            v_thres=self.v_thres, breakpoint_lambda_deg=self.breakpoint_lambda_deg,
            sigma_r_m=self.sigma_r_min_m, min_points=self.min_box_points,
            max_gap_beams=self.max_gap_beams, max_dynamic_length_m=self.max_dynamic_length_m,
            occlusion_never_dynamic=self.occlusion_never_dynamic,
            sigma_accel=self.track_sigma_accel, sigma_meas_m=self.track_sigma_meas_m,
            sigma_v0=self.track_sigma_v0, gate_m=self.track_gate_m,
            confirm_steps=self.confirm_steps, max_misses=self.max_misses,
            leg_pair_m=self.leg_pair_m, leg_max_m=self.leg_max_m,
        )  # fmt: skip


class StaticPointFilter(AMCLFilter):
    """The AMCL core fed only the beams of ``point_mask`` (the static points, §6.1): up to
    ``max_beams`` of them, evenly spread over the masked beams. Between :meth:`hold_beams`
    and :meth:`release_beams` (one scan) the beams of that scan are picked once.

    Two lazy things, neither pickled as such: the even spreads (``select_beams`` of each
    number of masked beams, a pure function of it) and the free cells of the grid
    (:attr:`free_xy`, listed only when random poses are drawn: rarely after a grid
    change)."""

    point_mask: NDArray[np.bool_] | None = None
    _held: tuple[Any, NDArray[np.bool_] | None, FloatArray, FloatArray] | None = None
    #: ``select_beams(n, max_beams)`` by ``n`` (dropped when pickled).
    _spreads: dict[int, NDArray[np.intp]] | None = None
    #: The grid whose free cells :attr:`free_xy` will list when next read (None: listed).
    _free_grid: Any = None
    _free_xy: FloatArray

    @property  # type: ignore[override]
    def free_xy(self) -> FloatArray:
        """Centres of the free cells of the latest grid that has any (AMCL's random poses)."""
        if self._free_grid is not None:
            self._free_xy = self._free_grid.free_points()
            self._free_grid = None
        return self._free_xy

    @free_xy.setter
    def free_xy(self, value: FloatArray) -> None:
        self._free_xy = value
        self._free_grid = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_free_xy"] = self.free_xy
        state.pop("_free_grid", None)
        state.pop("_spreads", None)
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        if "free_xy" in state:  # pickled before free_xy was lazy
            state["_free_xy"] = state.pop("free_xy")
        self.__dict__.update(state)

    def _beams_of(self, ranges_m: Any) -> tuple[FloatArray, FloatArray]:
        held = self._held
        if held is not None and held[0] is ranges_m and held[1] is self.point_mask:
            return held[2], held[3]
        r = np.asarray(ranges_m, dtype=np.float64)
        mask = self.point_mask
        idx = _masked_beams(r, float(self.range_max), float(self.range_min),
                            np.ones(len(r), bool) if mask is None else mask)  # fmt: skip
        n, max_beams = len(idx), self.config.max_beams
        if n > max_beams > 0:
            if self._spreads is None:
                self._spreads = {}
            pick = self._spreads.get(n)
            if pick is None:
                pick = self._spreads[n] = select_beams(n, max_beams)
            idx = idx[pick]
        return r[idx], self.all_angles[idx]

    def hold_beams(self, ranges_m: Any) -> None:
        """Pick the beams of ``ranges_m`` (with the current ``point_mask``) once, for every
        use until :meth:`release_beams` (neither may change meanwhile)."""
        self._held = None
        self._held = (ranges_m, self.point_mask, *self._beams_of(ranges_m))

    def release_beams(self) -> None:
        self._held = None

    def set_grid(self, grid: Any) -> None:
        """Localize on ``grid`` from now on, keeping the particles (and the free cells of
        the previous grid if this one has none); the likelihood table is recomputed where
        the distance field changed only."""
        self.grid = grid
        self.table = LikelihoodTable(grid, self.lf, previous=self.table)
        if np.any(grid.occupancy == FREE):  # grid.free_points() is not empty
            self._free_grid = grid


@compiled
def _masked_beams(r, range_max_m, range_min_m, mask):  # type: ignore[no-untyped-def]
    """The beams MCL may use (finite, ``0 < r < range_max_m``, ``r >= range_min_m``) among
    those of ``mask``, in order."""
    idx = np.empty(r.shape[0], dtype=np.intp)
    n = 0
    for i in range(r.shape[0]):
        v = r[i]
        if mask[i] and math.isfinite(v) and 0.0 < v < range_max_m and v >= range_min_m:
            idx[n] = i
            n += 1
    return idx[:n]


@register_localizer(NAME)
class AdaptiveMemoryLocalizer(Localizer):
    """Hentschel & Wagner's adaptive memory model (module doc); parameters are the fields
    of :class:`AdaptiveMemoryConfig`. Needs the prior's walls (H&W Fig. 4)."""

    needs_prior_walls = True

    diagnostics = (
        Diagnostic("n_dynamic", "int32", doc="valid points classified dynamic (eq. 10-11)"),
        Diagnostic("n_semistatic", "int32", doc="valid points classified semistatic (§4.4)"),
        Diagnostic("n_static", "int32", doc="valid points classified static"),
        Diagnostic("ltm_slot", "int16", doc="long-term slot whose map MCL used (§6.1)"),
        Diagnostic("static_points_used", "int32", doc="points that entered the MCL update"),
        Diagnostic("scan_loglik", "float64", doc="mean per-beam log-likelihood of the used points"),
        Diagnostic("n_tracked_objects", "int32", doc="boxes tracked in the short-term memory"),
        Diagnostic("lambda_min", "float64", doc="smallest eigenvalue of the inverse covariance"),
    )

    def __init__(self, laser: LaserSpec, rng: np.random.Generator, **params: Any) -> None:
        super().__init__(laser, rng)
        self.config = AdaptiveMemoryConfig(**params)
        c = self.config
        self.mcl = replace(CONFIGS[c.mcl_config], **c.mcl_overrides)
        self.lp = c.ltm_params()
        self.tracker = ObjectTracker(c.tracker_params())
        self.angles = laser.angles()
        self.mount = np.asarray(laser.mount_pose, dtype=np.float64)
        self.range_max = float(laser.range_max_m)
        self.sm: SlotBuffer[np.ndarray] = SlotBuffer(c.sm_dt_s, c.sm_slots)
        self.stm: SlotBuffer[np.ndarray] = SlotBuffer(c.stm_dt_s, c.stm_slots)
        self.ltm: LTMStore | None = None
        self._prior_map: LTMMap | None = None
        self.filter: StaticPointFilter | None = None
        self.used_slot = -1
        self._t0 = 0.0
        #: the stamp of the run's first scan [s] (None before it): eq. 1's clock runs from it
        self._stamp0: float | None = None
        self._est = np.zeros(3)
        self._cov = np.eye(3)
        self._cov_reported: tuple[FloatArray, FloatArray, float] | None = None
        self._odom_prev: FloatArray | None = None
        self._odom_at_update: FloatArray | None = None
        self._est_at_update = np.zeros(3)
        self._n_scans = 0
        self._day = 0
        #: The beams' cosines and sines for the segmentation (lazy; not pickled).
        self._beam_trig: FloatArray | None = None

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_beam_trig"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        state.setdefault("_beam_trig", None)  # pickled before it was kept
        self.__dict__.update(state)

    # -- run ------------------------------------------------------------------------------
    def begin_run(self, prior: Prior) -> None:
        c = self.config
        if self.ltm is None:
            if prior.walls is None or len(prior.walls) == 0:
                raise ValueError(f"{NAME} needs the prior's walls (H&W Fig. 4)")
            seed = None if prior.initial_pose is None else np.asarray(prior.initial_pose)[:2]
            self._prior_map = LTMMap.from_prior(prior.walls, seed, c.cell_m, self.lp)
            self.ltm = LTMStore(c.ltm_dt_s, c.ltm_slots, c.slot_init, self._prior_map.copy)
        self._day = prior.day
        self._t0 = (
            max(prior.day - 1, 0) * DAY_S + c.run_clock_s + max(prior.run - 1, 0) * c.run_spacing_s
        )
        self._stamp0 = None
        self.ltm.activate(self._t0)
        #: §4.4's map with ``semistatic_map = "run_start"``: the long-term memory before this run
        self._run_start_map = self.ltm.map().copy() if c.semistatic_map == "run_start" else None
        self.tracker.reset()
        self.sm.clear()
        self.stm.clear()
        self.used_slot = self.ltm.current
        grid = self.ltm.map(self.used_slot).occupancy_grid(self.lp)
        self.filter = StaticPointFilter(grid, self.laser, self.mcl)
        self.filter.all_angles = self.angles
        if prior.initial_pose is None:
            self.filter.init_uniform(self.rng)
        else:
            cov = (
                np.asarray(prior.initial_pose_cov, float)
                if prior.initial_pose_cov is not None
                else np.diag([self.mcl.init_sigma_xy**2] * 2 + [self.mcl.init_sigma_theta**2])
            )
            self.filter.init_gaussian(prior.initial_pose, cov, self.rng)
        self._est, self._cov = self.filter.estimate()
        self._est_at_update = self._est.copy()
        self._odom_prev = None
        self._odom_at_update = None
        self._n_scans = 0

    # -- one scan -------------------------------------------------------------------------
    def update(self, odom: Odometry, scan: Scan) -> PoseEstimate:
        f, ltm = self.filter, self.ltm
        if f is None or ltm is None:
            raise RuntimeError(f"{NAME}: update() before begin_run()")
        c = self.config
        if self._stamp0 is None:
            self._stamp0 = float(scan.stamp_s)
        t = self._t0 + (float(scan.stamp_s) - self._stamp0)
        ltm.activate(t)  # eq. 1
        pose_odom = np.asarray(odom.pose, dtype=np.float64)
        # 1. the predicted pose
        pred = (
            self._est
            if self._odom_prev is None
            else se2.apply_increment(self._est, self._odom_prev, pose_odom)
        )
        self._odom_prev = pose_odom.copy()
        ranges = np.asarray(scan.ranges_m, dtype=np.float64)
        self.sm.put(t, ranges)  # sensory memory (§4.1)
        # 2. objects (§4.2)
        if self._beam_trig is None:
            self._beam_trig = beam_trig(self.angles, self.mount)
        boxes = segment_scan(ranges, self.angles, self.mount, self.range_max,
                             self.tracker.params, self._beam_trig)  # fmt: skip
        box_cls, _ = self.tracker.update(boxes, pose_odom, t)
        # 3. long-term map update (§4.3) with u of the tracker's static points
        vi, rv, sig_r, cls_v, lab, stat = self._scan_points(ranges, boxes, box_cls)
        pts, covs = point_covariances(pred, self._cov, self.mount, rv, self.angles[vi],
                                      c.sigma_alpha_rad, sig_r)  # fmt: skip
        cur = ltm.map()
        explained = cur.explained(pts, covs, self.lp)  # for step 4, before this scan's points
        ref = self._run_start_map
        known = explained if ref is None else ref.explained(pts, covs, self.lp)
        n_take = int(round(c.u * len(stat)))
        if c.ltm_min_explained > 0 and len(stat) and np.mean(explained[stat]) < c.ltm_min_explained:
            n_take = 0  # the map disagrees with most of the scan: the pose is not trusted
        take = self.rng.choice(stat, size=n_take, replace=False) if n_take else stat[:0]
        if n_take and c.ltm_update_pose == "predicted":
            laser_xy = se2.compose(pred, self.mount)[:2]
            p_take, c_take = pts[take], covs[take]
            cur.update(laser_xy, p_take, c_take, self.lp, self._hits(p_take, c_take))
        # 4. the semistatic test (§4.4)
        classes, n_class = self._final_classes(cls_v, lab, explained, known, len(boxes.length), vi,
                                               len(ranges))  # fmt: skip
        self.stm.put(t, classes)  # short-term memory: the classified scan
        # 5. map selection and MCL (§6.1) on the static points
        if self._n_scans % c.select_every_scans == 0:
            self._select_map(pred, ranges)
        elif self._n_scans % c.map_refresh_scans == 0:
            self._use_map(self.used_slot)
        f.point_mask = self._mcl_points(classes, n_class, vi)
        f.hold_beams(ranges)  # this scan's beams, picked once (released below)
        self._mcl_step(pose_odom, ranges)
        self._n_scans += 1
        mean = se2.apply_increment(self._est_at_update, self._odom_at_update, pose_odom)
        self._est = mean
        cov, lambda_min = self._reported_cov()
        if n_take and c.ltm_update_pose == "estimate":
            ti = vi[take]
            p2, c2 = point_covariances(mean, cov, self.mount, ranges[ti], self.angles[ti],
                                       c.sigma_alpha_rad, sig_r[take])  # fmt: skip
            cur.update(se2.compose(mean, self.mount)[:2], p2, c2, self.lp, self._hits(p2, c2))
        r_used, _ = f._beams_of(ranges)
        extras = {
            "point_classes": classes,
            "n_dynamic": int(n_class[DYNAMIC]),
            "n_semistatic": int(n_class[SEMISTATIC]),
            "n_static": int(n_class[STATIC]),
            "ltm_slot": int(self.used_slot),
            "static_points_used": len(r_used),
            "scan_loglik": f.mean_beam_loglik(mean, ranges),
            "n_tracked_objects": self.tracker.n_tracks,
            "lambda_min": lambda_min,
        }
        f.release_beams()
        return PoseEstimate(mean=mean, cov=cov, extras=extras)

    def _mcl_points(
        self, classes: NDArray[np.int8], n_class: NDArray[np.int64], vi: NDArray[np.intp]
    ) -> NDArray[np.bool_]:
        """Which beams MCL weighs (§6.1): the static points; with ``mcl_points``
        "non-dynamic" every valid beam (``vi``) not classed dynamic; with fewer than
        ``min_static_points`` static points the unknown ones too."""
        use = classes == STATIC
        if self.config.mcl_points == "non-dynamic":
            use = np.zeros(len(classes), dtype=bool)
            use[vi] = classes[vi] != DYNAMIC
        elif int(n_class[STATIC]) < self.config.min_static_points:
            use |= classes == UNKNOWN
        return use

    def _scan_points(
        self, ranges: FloatArray, boxes: Boxes, box_cls: NDArray[np.int8]
    ) -> tuple[NDArray[np.intp], FloatArray, FloatArray, NDArray[np.int8], NDArray[np.intp],
               NDArray[np.intp]]:  # fmt: skip
        """The valid returns of the scan (:func:`.object_tracker.scan_points`)."""
        c = self.config
        return scan_points(ranges, self.range_max, boxes, box_cls, c.sigma_r_min_m,
                           c.sigma_r_rel)  # fmt: skip

    def _final_classes(
        self,
        cls_v: NDArray[np.int8],
        lab: NDArray[np.intp],
        explained: NDArray[np.bool_],
        known: NDArray[np.bool_],
        n_boxes: int,
        vi: NDArray[np.intp],
        n_beams: int,
    ) -> tuple[NDArray[np.int8], NDArray[np.int64]]:
        """§4.4 (:func:`.ltm_map.semistatic_classes`): the veto (``ltm_veto_dynamic``) on the
        current map's verdicts ``explained``, semistatic what ``semistatic_map`` does not
        ``known``."""
        return semistatic_classes(cls_v, lab, explained, known, n_boxes,
                                  self.config.ltm_veto_dynamic, vi, n_beams)  # fmt: skip

    def _reported_cov(self) -> tuple[FloatArray, float]:
        """The reported covariance (regularized) and its information's smallest eigenvalue,
        computed once per filter estimate: ``_cov`` changes only with one."""
        self._cov_reported = reported_covariance(self._cov, self._cov_reported)
        return self._cov_reported[1].copy(), self._cov_reported[2]

    def _hits(self, points: FloatArray, covs: FloatArray) -> NDArray[np.bool_] | None:
        """The sampled points that add occupied evidence (``ltm_learn_prior_walls``): all,
        or those the walls prior does not explain."""
        if self.config.ltm_learn_prior_walls or self._prior_map is None:
            return None
        return ~self._prior_map.explained(points, covs, self.lp)

    def _mcl_step(self, pose_odom: FloatArray, ranges: FloatArray) -> None:
        """StaticMCL's update rule: filter when the odometry moved ``update_min_d/a``."""
        f, m = self.filter, self.mcl
        assert f is not None
        if self._odom_at_update is None:
            do = True
        else:
            d = pose_odom - self._odom_at_update
            d[2] = se2.wrap_angle(d[2])
            do = abs(d[0]) > m.update_min_d or abs(d[1]) > m.update_min_d
            do = do or abs(d[2]) > m.update_min_a
            if do:
                f.predict(self._odom_at_update, pose_odom, self.rng)
        if not do:
            return
        f.correct(ranges)
        self._est_at_update, self._cov = f.estimate()
        f.resample(self.rng)
        self._odom_at_update = pose_odom.copy()

    def _select_map(self, pose: FloatArray, ranges: FloatArray) -> None:
        """§6.1: the filled slot whose expected ranges fit the scan with the least mean
        squared error (at the predicted pose, ``select_beams`` beams)."""
        ltm, c = self.ltm, self.config
        assert ltm is not None and self.filter is not None
        slots = ltm.filled()
        best, best_mse, used_mse = self.used_slot, np.inf, np.inf
        if len(slots) > 1:
            beams = select_beams(len(ranges), c.select_beams)
            r = ranges[beams]
            ok = np.isfinite(r) & (r > 0)
            r = np.minimum(np.where(ok, r, self.range_max), self.range_max)
            ok |= np.isposinf(ranges[beams])
            laser_pose = se2.compose(pose, self.mount)
            for k in slots:
                e = ltm.map(k).expected_ranges(laser_pose, self.angles[beams], self.range_max,
                                               self.lp)  # fmt: skip
                mse = float(np.mean((e[ok] - r[ok]) ** 2)) if ok.any() else np.inf
                if k == self.used_slot:
                    used_mse = mse
                if mse < best_mse:
                    best, best_mse = k, mse
            if best != self.used_slot and not best_mse < (1.0 - c.select_margin) * used_mse:
                best = self.used_slot
        if self.used_slot not in slots:
            best = ltm.current
        self.used_slot = best
        self._use_map(best)

    def _use_map(self, slot: int) -> None:
        """MCL on long-term slot ``slot``'s map from now on. The grid and its likelihood field
        are rebuilt only when the map's cells differ from the filter's grid (the same cells
        make the same grid)."""
        f, ltm = self.filter, self.ltm
        assert f is not None and ltm is not None
        m = ltm.map(slot)
        occ = m.ternary(self.lp)
        g = f.grid
        same = (
            g.occupancy.shape == occ.shape
            and g.resolution_m == m.resolution
            and np.array_equal(g.origin_xy_m, m.origin)
            and np.array_equal(g.occupancy, occ)
        )
        if not same:
            f.set_grid(m.occupancy_grid(self.lp, ternary=occ))

    # -- day ------------------------------------------------------------------------------
    def day_artifacts(self) -> dict[str, dict[str, np.ndarray]]:
        """``ltm``: the current long-term slot's grid after the day (log-odds ``(H, W)``
        float32, rows along y, ``origin_m``, ``resolution_m``, ``ltm_slot``), as the
        ``dynamic-map`` hands over its map (named arrays). Runs at other times of day fill
        other slots (with ``slot_init = copy_latest``, copies of the latest map then); one
        run a day at a fixed time, as H&W's, only ever fills this one."""
        if self.ltm is None or self.ltm.current < 0:
            return {}
        m = self.ltm.map()
        return {
            "ltm": {
                "logodds": m.logodds.copy(),
                "origin_m": m.origin.copy(),
                "resolution_m": np.array(m.resolution),
                "ltm_slot": np.array(self.ltm.current, dtype=np.int16),
            }
        }

    def ltm_bytes(self) -> int:
        """Memory of the long-term grids held now [bytes]."""
        if self.ltm is None:
            return 0
        return sum(self.ltm.map(k).logodds.nbytes for k in self.ltm.filled())
