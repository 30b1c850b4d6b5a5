"""``dynamic-map``: Biber & Duckett's localization on a dynamic map (§4.3–4.4), and its static
variants ``static-map`` / ``static-map+stm`` (§5.3).

Per scan ``z_t`` (with odometry):

1. **Prediction**: ``x̂⁻ = x̂_{t−1} ⊕ Δodom`` with an odometry covariance ``C_O`` that grows
   with the motion (the paper's was "acquired experimentally": ours are the simulated robots'
   rates, or acquired from a given map's run, :mod:`.odometry_calibration`).
2. **Scan matching against the current map** built after the previous step, with the adaptive
   odometry prior of eq. 9: minimise ``E_S + κ·E_O`` with κ = 0 first (``kappa_first``, an
   option that is not B&D's, starts higher); while the result is not within two standard
   deviations of the odometry prediction (Mahalanobis distance under ``C_O`` ≤ 2), set κ to
   ``kappa0`` and double it. If no κ brings it back, the prediction is used. When the first
   match fits the map much better than the forced one (``slip_fit_ratio``, not B&D), the
   odometry's heading is taken to have slipped and the scheme runs again with the scan's
   heading in the prediction. The ICP is
   :func:`dynmap_sim.agent.mapping.scan_matcher.match_scan` (point-to-line, its prior term
   is ``(x − x̂⁻)ᵀ κ C_O⁻¹ (x − x̂⁻)``).
3. **Current map for t+1** from ``z_t`` at the posterior (:mod:`..maps.current_map`): greedy
   timescale selection over the local maps within 4 m, safe mode.
4. **Learning** (§4.4): λ1 learns ``z_t`` in the local maps within 2.5 m (a new local map where
   there is none); the (pose, scan) pair is stored; λ2 learns the run in :meth:`end_run`,
   λ3–λ5 the day in :meth:`end_day`. For speed, the offline steps use a uniformly random
   subset of the stored scans (``ltm_scans_per_run`` of a run for λ2, ``ltm_day_scans_per_run``
   of each run for the day; 0 = all): the rule picks random measurements anyway, and a
   random subset still holds far more than ``u·n`` measurements per ray.

The first run (``prior.first_run``, or no local maps yet) is mapped by the static SLAM of
:class:`~dynmap_sim.agent.mapping.first_run.FirstRunMapper`; its keyframes, thinned to one per
``local_map_spacing_m``, become the initial local maps (§4), and the run's optimized
trajectory feeds the first long-term update.

Per scan ``PoseEstimate.extras``: ``scan_loglik`` (mean per-reading log-likelihood of the
scan under the selected models), ``scan_lik`` (mean per-reading likelihood, Fig. 10),
``lambda_min`` (smallest eigenvalue of the inverse covariance, Fig. 11), ``timescale`` (level
of the best-fitting selection, 0 = λ1 … 4 = λ5, -1 none), ``timescales`` (levels of all
selections, Figs. 12–13), ``safe_mode``, ``kappa`` (final κ of eq. 9), ``odometry_slip``
(the scan's heading taken, ``slip_fit_ratio``), ``n_local_maps``.

Filling (``first_step_fills``, default False): a sample set grows by ``u·n`` samples per
time step until it is full, as §3.1 states ("until it is full an update just consists of
adding u·n randomly chosen samples"), so λ5 (u = 0.05, 100 samples, one step a day) takes
about 20 days to fill. That growth is one of §5.4's reasons why λ5 is used more and more
("the median filter becomes more precise as the number of samples in the long-term memory
map increases"). ``True`` lets a ray's first time step take up to ``n`` measurements, the way
the toy example of §3.5 is initialized (λ5 is then full after the first day).

``min_update_dist_m`` / ``min_update_angle_rad`` (default 0: every scan, as in the paper)
skip scans taken before the robot moved that far since the last processed scan: those get
the odometry prediction and ``extras = {"skipped": True}`` (no likelihood, no timescale).

Static variants (§5.3): the map is learned exactly like ``dynamic-map`` until the end of day
``freeze_after_day`` (1), then frozen — a snapshot of the dynamic map after the first day.
``static-map`` then localizes with λ2–λ5 of the snapshot only; ``static-map+stm`` also keeps
the short-term memory λ1 learning online.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Annotated, Any

import numpy as np
from numpy.typing import ArrayLike
from pydantic import Field

from dynmap_sim import se2
from dynmap_sim.agent.localization.localizer import Localizer, ScanMapUser, register_localizer
from dynmap_sim.agent.localization.odometry_calibration import (
    OdometryRates,
    odometry_error_rates,
)
from dynmap_sim.agent.mapping.first_run import FirstRunConfig, FirstRunMapper
from dynmap_sim.agent.mapping.scan_matcher import (
    MatchResult,
    PointMap,
    match_scan,
    position_information,
    worst_position_sigma,
)
from dynmap_sim.agent.mapping.scan_points import (
    BeamDirections,
    first_per_cell,
    scan_points_base,
)
from dynmap_sim.agent.maps.current_map import CurrentMap, SynthesisParams, synthesize_current_map
from dynmap_sim.agent.maps.dynamic_map import DynamicMap, MapSnapshot
from dynmap_sim.agent.maps.local_map import TABLE1
from dynmap_sim.agent.maps.sample_set import to_mm
from dynmap_sim.agent.params import (
    NonNegative,
    NonNegativeInt,
    Positive,
    PositiveInt,
    params_dataclass,
)
from dynmap_sim.types import (
    Diagnostic,
    FloatArray,
    LaserSpec,
    Odometry,
    PoseEstimate,
    Prior,
    Scan,
)

_MODES = ("dynamic", "static", "static+stm")


def lambda_min(cov: FloatArray) -> float:
    """Smallest eigenvalue of the inverse of a 3x3 covariance (B&D §5.3, Fig. 11).

    The inverse of ``0.5 (cov + covᵀ) + 10⁻¹² I``, symmetrized; the matrix is assembled from
    scalars with the same operations as the array expression (``+ 0.0`` off the diagonal, as
    adding ``10⁻¹² I`` does), so the same bits in fewer numpy calls.
    """
    (c00, c01, c02), (c10, c11, c12), (c20, c21, c22) = np.asarray(cov, dtype=np.float64).tolist()
    # (IEEE addition commutes: c01 + c10 is c10 + c01, so each pair is one value)
    m01, m02, m12 = 0.5 * (c01 + c10) + 0.0, 0.5 * (c02 + c20) + 0.0, 0.5 * (c12 + c21) + 0.0
    info = np.linalg.inv(
        np.array(
            [
                [0.5 * (c00 + c00) + 1e-12, m01, m02],
                [m01, 0.5 * (c11 + c11) + 1e-12, m12],
                [m02, m12, 0.5 * (c22 + c22) + 1e-12],
            ]
        )
    )
    sym = info + info.T
    sym *= 0.5
    return float(np.linalg.eigvalsh(sym)[0])


def odometry_covariance(
    delta: FloatArray, sigma_xy0: float, k_xy: float, sigma_th0: float, k_th: float
) -> FloatArray:
    """``C_O`` of one odometry increment ``delta`` (robot frame) rotated to be added in the
    map frame at heading 0: diagonal, std ``sigma0 + k·|motion|``."""
    d = float(np.hypot(delta[0], delta[1]))
    a = abs(float(delta[2]))
    sxy = sigma_xy0 + k_xy * d + 0.5 * k_xy * a
    sth = sigma_th0 + k_th * a + 0.5 * k_th * d
    return np.diag([sxy**2, sxy**2, sth**2])


def fit_cost(res: MatchResult, n_points: int, max_correspondence_m: float) -> float:
    """Mean squared residual [m²] of a match over all ``n_points`` scan points, a point
    without a correspondence counting as ``max_correspondence_m`` away."""
    if n_points == 0 or not np.isfinite(res.rmse_m):
        return float("inf")
    sq = res.n_matched * res.rmse_m**2 + (n_points - res.n_matched) * max_correspondence_m**2
    return float(sq / n_points)


def moved_at_least(delta: FloatArray, dist_m: float, angle_rad: float) -> bool:
    """Whether the motion ``delta`` (x, y [m], θ [rad]) went ``dist_m`` or turned
    ``angle_rad`` (0 and 0: any motion, also none)."""
    return bool(np.hypot(delta[0], delta[1]) >= dist_m or abs(delta[2]) >= angle_rad)


def remap_degenerate(
    pose: FloatArray, pred: FloatArray, scan_info: FloatArray, sigma_max_m: float
) -> FloatArray:
    """``pose`` with its move from ``pred`` dropped along each position direction in which the
    scan term ``scan_info`` (3x3, x y θ; the heading marginalized out) leaves a standard
    deviation over ``sigma_max_m`` [m] (Zhang, Kaess & Singh 2016, solution remapping)."""
    lam, vec = np.linalg.eigh(position_information(scan_info))
    move = pose[:2] - pred[:2]
    for k in range(2):
        if not lam[k] > 1.0 / sigma_max_m**2:
            v = vec[:, k]
            move = move - float(v @ move) * v
    out = pose.copy()
    out[:2] = pred[:2] + move
    return out


@params_dataclass("dynamic-map")
class DynamicMapConfig:
    """Parameters of the dynamic-map localizer and its static variants (lengths in m,
    angles in rad). A scenario's ``params`` table gives them by name. The measurements behind
    the non-paper values: ``docs/tuning/localization.md``."""

    #: Static variants (§5.3): the map freezes after the end of this day ("a snapshot of the
    #: dynamic map after the first day").
    freeze_after_day: PositiveInt = 1
    #: Local maps within this distance of the pose are the "nearby local maps" of the
    #: current-map synthesis (§4.3 step 1: "4 meters in our experiments").
    select_radius_m: Positive = 4.0
    #: Local maps within this distance learn a scan online and offline (§4.4: "< 2.5 m");
    #: with no local map that near, a new one is made.
    update_radius_m: Positive = 2.5
    #: The first run's keyframes become the initial local maps (§4), thinned to one per this
    #: distance (the paper's lab: 76 local maps on ~9.6 km / 75 runs of a few-room lab).
    local_map_spacing_m: Positive = 2.0
    #: The synthesis selects timescales until fewer readings than this are unexplained
    #: (§4.3 step 5: "20 in our experiments").
    min_readings: NonNegativeInt = 20
    #: At most this many readings (evenly subsampled) enter the synthesis (0: all): the
    #: selection needs far fewer than a scan's 682 to tell timescales apart, and it is the
    #: most expensive step.
    max_select_readings: NonNegativeInt = 240
    #: Only rays whose estimated standard deviation is at most this become current-map points
    #: (§4.3 step 6: "5 cm in our experiments").
    sigma_max_m: Positive = 0.05
    #: A reading counts as explained when its density ``p(d)`` (eq. 6) is at least this
    #: [1/m] (§4.3 step 4: "a threshold is used here"; 0.5/m: about 3 sigma of a 5 cm ray).
    explained_density: NonNegative = 0.5
    #: Floor of the perceptual model's sigma [m] (eq. 7) (1 cm, the URG-04LX's noise at 1 m;
    #: a ray learned from a few equal samples is not infinitely sharp).
    sigma_min_m: Positive = 0.01
    #: ``C_O`` (§4.3: "a covariance matrix that was acquired experimentally"): standard
    #: deviation in x and y ``odom_sigma_xy0_m + odom_k_xy (d + a/2)`` [m] for a step of ``d``
    #: [m] and turn ``a`` [rad] between two scans; 1 mm: a robot that stands still does not
    #: move ...
    odom_sigma_xy0_m: Positive = 0.001
    #: ... with the rate [m per m (+ rad/2)] acquired experimentally for the simulated robots
    #: (§4.3): their odometry's error rate against the truth (:func:`.odometry_error_rates`),
    #: rounded. Eq. 9 takes the match whenever it lies within two standard deviations of the
    #: prediction, so ``C_O`` bounds how far a match may slide a scan along a blank corridor.
    odom_k_xy: NonNegative = 0.008
    #: ... and in theta ``odom_sigma_th0_rad + odom_k_th (a + d/2)`` [rad] ...
    odom_sigma_th0_rad: Positive = 0.01
    #: ... (the simulated robots' rate [rad per rad (+ m/2)], as in x and y).
    odom_k_th: NonNegative = 0.055
    #: ``C_O`` "acquired experimentally" (§4.3; :mod:`.odometry_calibration`) for a given
    #: map: when the map comes with the poses and odometry of every scan of its run
    #: (:meth:`DynamicMapLocalizer.set_map_from_scans`, e.g. replay's ``--map-from-log-poses``),
    #: ``odom_k_xy`` and ``odom_k_th`` are replaced by the odometry's error rates against those
    #: poses (the ``σ0`` terms stay): a real robot's odometry is its own. Not from the
    #: first-run SLAM's trajectory, whose per-scan jitter exceeds the simulated odometry's
    #: error. False: the rates above, always.
    odom_calibration: bool = True
    #: ... over windows of this many scans (1 s at 10 Hz) ...
    odom_calibration_window: PositiveInt = 10
    #: ... taking this quantile of the windows' error rates.
    odom_calibration_quantile: Annotated[Positive, Field(le=1.0)] = 0.9
    #: First non-zero κ of eq. 9 (§4.3 step 4 doubles it from here).
    kappa0: Positive = 0.25
    #: κ of the first match. B&D §4.3: 0, the default (the scan alone; "in most cases the
    #: result from scan matching is so much more exact than odometry that incorporation of
    #: the prior E_O would only worsen the result"). > 0 is not B&D: the odometry prior from
    #: the first match on, doubled from there while the result leaves the two-sigma region,
    #: against the scan's bias along a blank corridor.
    kappa_first: NonNegative = 0.0
    #: Degenerate directions (not B&D; 0 = off, the paper): where the scan term of the
    #: accepted match constrains the position along a direction only to a standard deviation
    #: over this [m] (the heading marginalized out, :func:`worst_position_sigma`; e.g. along a
    #: corridor whose walls are blank), the match's move along that direction is dropped and
    #: the odometry prediction kept there (Zhang, Kaess & Singh 2016's solution remapping).
    degenerate_sigma_m: NonNegative = 0.0
    #: Odometry whose heading slipped (not B&D; 0 = off, the paper's scheme): when the first
    #: match lies outside the two-sigma region of ``C_O`` and fits the current map this many
    #: times better (:func:`fit_cost`) than the last match eq. 9's doubling κ forced toward
    #: the prediction, the prediction takes the first match's heading and steps 3-4 of §4.3
    #: run again from it. A pose forced toward a heading that slipped (one wheel on a door
    #: sill) fits visibly worse, while the heading is what scan matching gets right even where
    #: its position is weak; 1.25 held the real log it was measured on.
    slip_fit_ratio: NonNegative = 1.25
    #: At most this many doublings of κ; if none brings the result within two standard
    #: deviations of the odometry prediction, the prediction is used (0.25 * 2^12 = 1024).
    max_kappa_doublings: NonNegativeInt = 12
    #: At most this many scan points (evenly subsampled) enter ICP.
    max_match_points: PositiveInt = 200
    #: ICP correspondence gate [m].
    max_correspondence_m: Positive = 0.3
    #: ICP iterations per κ.
    max_iterations: PositiveInt = 20
    #: Fewer matched points (or current-map points) than this: the prediction is used.
    min_matched: NonNegativeInt = 20
    #: The current map is thinned to one point per square cell of this side [m] (0: off):
    #: the long-term maps hold several nearly equal points per surface.
    map_voxel_m: NonNegative = 0.05
    #: λ2 learns a uniformly random subset of this many of a run's scans (0: all; §4.4 picks
    #: random measurements anyway, and 1500 scans still hold far more than ``u n`` per ray).
    ltm_scans_per_run: NonNegativeInt = 1500
    #: Scans taken before the robot moved this far [m] ...
    min_update_dist_m: NonNegative = 0.0
    #: ... and turned this much [rad] since the last processed scan get the odometry
    #: prediction only (0: every scan, as in the paper; like AMCL's ``update_min_*``).
    min_update_angle_rad: NonNegative = 0.0
    #: A scan is learned (λ1 online, and stored for λ2-λ5) only once the odometry says the
    #: robot moved this far [m] ...
    learn_min_dist_m: NonNegative = 0.01
    #: ... or turned this much [rad] since the last learned scan (0 and 0: every scan, as
    #: in the paper). §3's samples are independent draws of a ray; scans from a standing
    #: robot repeat one draw, and while it waits (behind a person, for a door) λ1 learns its
    #: own estimate over and over, so the estimate creeps with nothing to hold it. The
    #: laser's range accuracy (1 cm) and the turn that moves a point at 1 m by as much:
    #: below both the robot stands; a driving robot (3 cm a scan at 0.35 m/s) learns every
    #: scan, as in the paper.
    learn_min_angle_rad: NonNegative = 0.01
    #: λ3-λ5 learn this many random scans of each of the day's runs (0: all).
    ltm_day_scans_per_run: NonNegativeInt = 1500
    #: Keep a snapshot of λ2-λ5 after each day's learning (for figures like B&D Fig. 9; the
    #: uint16 medians of 3,960 rays: about 8 kB per local map and day).
    day_snapshots: bool = True
    #: Long-term anchor (not in B&D; 0 = off, the paper): each scan is also matched against
    #: a current map of λ2–λ5 alone, and when that match pins the position (worst-direction
    #: sigma of its scan term at most ``ltm_anchor_max_sigma_m``) and lies more than this [m]
    #: from the match with λ1, its pose is taken: λ1 learns the robot's own scans at its own
    #: estimates, so along a blank corridor nothing else holds the estimate from sliding.
    ltm_anchor_tol_m: NonNegative = 0.0
    #: ... (the long-term match must be this good [m] to override; see above).
    ltm_anchor_max_sigma_m: NonNegative = 0.05
    #: A ray's first time step takes up to ``n`` measurements (the toy example of §3.5);
    #: False: ``u n`` per step until full, as §3.1 states (λ5 then fills in ~20 days, one
    #: of §5.4's reasons why λ5 is used more and more).
    first_step_fills: bool = False

    @property
    def synthesis(self) -> SynthesisParams:
        """The current-map synthesis thresholds (§4.3)."""
        return SynthesisParams(
            select_radius_m=self.select_radius_m,
            min_readings=self.min_readings,
            sigma_max_m=self.sigma_max_m,
            explained_density=self.explained_density,
            sigma_min_m=self.sigma_min_m,
            max_readings=self.max_select_readings,
        )

    @property
    def odom_params(self) -> tuple[float, float, float, float]:
        """The arguments of :func:`odometry_covariance` after ``delta``."""
        return (self.odom_sigma_xy0_m, self.odom_k_xy, self.odom_sigma_th0_rad, self.odom_k_th)


class DynamicMapLocalizer(Localizer, ScanMapUser):
    """Scan matching on a multi-timescale dynamic map (B&D §4); see the module docstring.

    ``mode``: ``"dynamic"``, ``"static"`` or ``"static+stm"`` (the registered variants set
    it); ``config``: a :class:`DynamicMapConfig`; ``params``: its fields by name (replacing
    those of ``config``), e.g. a scenario's ``params`` table; ``mapper_params``: fields of
    the first run's SLAM (:meth:`~.first_run.FirstRunConfig.from_params`) when it maps.

    Besides its declared :attr:`diagnostics`, it hands over a ``map_snapshot`` artifact
    (:meth:`day_artifacts`) on every day its map learned.
    """

    diagnostics = (
        Diagnostic(
            "scan_loglik",
            "float64",
            doc="mean per-reading log-likelihood of the scan under the selected models (Fig. 10)",
        ),
        Diagnostic(
            "lambda_min", "float64", doc="smallest eigenvalue of the inverse covariance (Fig. 11)"
        ),
        Diagnostic(
            "timescale",
            "int64",
            doc="level of the best-fitting selection, 0 = λ1 ... 4 = λ5 (4 in safe mode), -1 none",
        ),
        Diagnostic("safe_mode", "bool", doc="the current map fell back to safe mode (§4.3)"),
        Diagnostic(
            "odometry_slip",
            "bool",
            doc="the odometry's heading judged slipped, the scan's taken (slip_fit_ratio)",
        ),
        Diagnostic(
            "timescale_counts",
            "int64",
            (len(TABLE1),),
            per="run",
            counts_of="timescales",
            doc="selections of each timescale λ1-λ5 over the run, every one of every scan "
            "(Figs. 12-13)",
        ),
    )

    def __init__(
        self,
        laser: LaserSpec,
        rng: np.random.Generator,
        mode: str = "dynamic",
        config: DynamicMapConfig | None = None,
        mapper_params: dict[str, Any] | None = None,
        **params: Any,
    ) -> None:
        if config is not None and not isinstance(config, DynamicMapConfig):
            raise TypeError(f"{type(self).__name__}: config must be a DynamicMapConfig")
        cfg = replace(config or DynamicMapConfig(), **params)
        super().__init__(laser, rng)
        #: The first run's SLAM (a scenario's ``mapper_params``, as for ``static-mcl``).
        self.mapper_config = FirstRunConfig.from_params(**(mapper_params or {}))
        if mode not in _MODES:
            raise ValueError(f"mode must be one of {_MODES}, got {mode!r}")
        self.mode = mode
        self.config = cfg
        self._beams = BeamDirections(laser)
        self.dmap = DynamicMap(
            TABLE1, float(laser.range_max_m), cfg.update_radius_m, cfg.first_step_fills
        )
        self.frozen = False
        self.days_done = 0
        self._pose = np.zeros(3)
        self._cov = np.diag([1e-4, 1e-4, 1e-4])
        self._last_odom: FloatArray | None = None
        #: odometry pose of the last learned scan (``learn_min_dist_m``)
        self._learned_odom: FloatArray | None = None
        self._mapper: FirstRunMapper | None = None
        self._cmap_points = np.zeros((0, 2))
        self._cmap: PointMap | None = None
        # the current map of λ2–λ5 alone (``ltm_anchor_tol_m``)
        self._anchor_points = np.zeros((0, 2))
        self._anchor_map: PointMap | None = None
        # (pose, ranges in mm) pairs of the current run and of the current day (§4.4)
        self._run_poses: list[FloatArray] = []
        self._run_ranges: list[np.ndarray] = []
        self._day_poses: list[FloatArray] = []
        self._day_ranges: list[np.ndarray] = []
        self.n_scans = 0
        self.n_safe_mode = 0
        #: (day, MapSnapshot of λ2–λ5) after each day's offline learning, while learning
        #: and ``config.day_snapshots``: the map's own history, for figures like B&D Fig. 9
        self.day_snapshots: list[tuple[int, MapSnapshot]] = []
        self._day = 0
        #: the first map came from scans at given poses (:meth:`set_map_from_scans`)
        self._map_given = False
        #: ``C_O``'s rates acquired from a given map's run (``odom_calibration``); None: the
        #: configured ones
        self.odom_rates: OdometryRates | None = None

    # ------------------------------------------------------------------ pickling
    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        state["_cmap"] = None  # a KD-tree: rebuilt from _cmap_points on demand
        state["_anchor_map"] = None
        return state

    # ------------------------------------------------------------------ levels
    def _odom_params(self) -> tuple[float, float, float, float]:
        """The arguments of :func:`odometry_covariance` after ``delta``: the configured ones,
        with the rates acquired from the map's run when there are any."""
        c = self.config
        rates = self.__dict__.get("odom_rates")  # None in pickles made before calibration
        if rates is None:
            return c.odom_params
        return (c.odom_sigma_xy0_m, rates.k_xy, c.odom_sigma_th0_rad, rates.k_th)

    def _calibrate_odometry(self, odometry: ArrayLike, poses: ArrayLike) -> None:
        """``C_O`` acquired from a given map's run (``odom_calibration``): the odometry's
        error rates against its poses (:func:`odometry_error_rates`); kept as configured when
        the run has too few windows that moved."""
        c = self.config
        if not c.odom_calibration:
            return
        rates = odometry_error_rates(
            odometry, poses, c.odom_calibration_window, c.odom_calibration_quantile
        )
        if rates is not None:
            self.odom_rates = rates

    @property
    def selectable_levels(self) -> list[int]:
        """Timescales the localization may select (static-map: λ2–λ5 only)."""
        if self.frozen and self.mode == "static":
            return [1, 2, 3, 4]
        return [0, 1, 2, 3, 4]

    @property
    def learns_stm(self) -> bool:
        return not self.frozen or self.mode == "static+stm"

    @property
    def learns_ltm(self) -> bool:
        return not self.frozen

    # ------------------------------------------------------------------ run protocol
    def begin_run(self, prior: Prior) -> None:
        self._pose = (
            np.zeros(3)
            if prior.initial_pose is None
            else np.asarray(prior.initial_pose, dtype=np.float64).reshape(3).copy()
        )
        self._cov = (
            np.diag([1e-4, 1e-4, 1e-4])
            if prior.initial_pose_cov is None
            else np.asarray(prior.initial_pose_cov, dtype=np.float64).copy()
        )
        self._last_odom = None
        self._learned_odom = None
        self._day = int(prior.day)
        self._cmap_points = np.zeros((0, 2))
        self._cmap = None
        self._anchor_points = np.zeros((0, 2))
        self._anchor_map = None
        self._run_poses, self._run_ranges = [], []
        self._mapper = None
        mapped = self._map_given and len(self.dmap) > 0
        if (prior.first_run or len(self.dmap) == 0) and not self.frozen and not mapped:
            mapper_config = self.__dict__.get("mapper_config") or FirstRunConfig()
            self._mapper = FirstRunMapper(self.laser, self._pose, mapper_config, prior.walls)

    def _beam_directions(self) -> BeamDirections:
        """The laser's beam directions (cached; rebuilt for pickles made before the cache)."""
        beams = self.__dict__.get("_beams")
        if beams is None:
            beams = self._beams = BeamDirections(self.laser)
        return beams

    def _points_map(self, pose: FloatArray, ranges_m: np.ndarray) -> FloatArray:
        return se2.transform_points(
            pose, scan_points_base(self.laser, ranges_m, self._beam_directions())
        )

    def update(self, odom: Odometry, scan: Scan) -> PoseEstimate:
        self.n_scans += 1
        ranges = np.asarray(scan.ranges_m, dtype=np.float32)
        if self._mapper is not None:
            est = self._mapper.update(odom, scan)
            self._store(est.mean, ranges)
            est.extras.update(
                lambda_min=lambda_min(est.cov),
                timescale=-1,
                timescales=(),
                safe_mode=False,
                odometry_slip=False,
                n_local_maps=0,
            )
            return est
        opose = np.asarray(odom.pose, dtype=np.float64)
        kappa = 0.0
        sigma_m = float("inf")
        slipped = False
        anchored = None
        if self._last_odom is not None:
            delta = se2.between(self._last_odom, opose)
            if not moved_at_least(
                delta, self.config.min_update_dist_m, self.config.min_update_angle_rad
            ):  # not moved enough: odometry only, the scan is not used (like AMCL's update_min_*)
                c_o = odometry_covariance(delta, *self._odom_params())
                return PoseEstimate(
                    mean=se2.compose(self._pose, delta),
                    cov=self._propagated_cov(c_o),
                    extras={"skipped": True},
                )
        pts_base = scan_points_base(self.laser, ranges, self._beam_directions())
        if self._last_odom is None:
            self._last_odom = opose.copy()
        else:
            self._last_odom = opose.copy()
            pred = se2.compose(self._pose, delta)
            c_o = odometry_covariance(delta, *self._odom_params())
            pose, cov, kappa, sigma_m, slipped = self._match(
                pts_base, pred, c_o, self._current_point_map()
            )
            if self._anchoring:
                anchored = self._anchor(pts_base, pred, c_o, pose)
                if anchored is not None:
                    pose, cov = anchored
            self._pose, self._cov = pose, cov
        pts_map = se2.transform_points(self._pose, pts_base)
        cur = synthesize_current_map(
            self.dmap, self._pose, pts_map, self.selectable_levels, self.config.synthesis
        )
        self._set_current_map(cur)
        if self._anchoring:
            levels = [level for level in self.selectable_levels if level != 0]
            self._set_anchor_map(
                synthesize_current_map(
                    self.dmap, self._pose, pts_map, levels, self.config.synthesis
                ).points
            )
        if self._moved_since_learning(opose):
            self._learned_odom = opose.copy()
            if self.learns_stm:
                self.dmap.learn_online(
                    self._pose, pts_map, self.rng, levels=[0], allow_new=not self.frozen
                )
            if self.learns_ltm:
                self._store(self._pose, ranges)
        self.n_safe_mode += int(cur.safe_mode)
        extras = {
            "scan_loglik": cur.scan_loglik,
            "scan_lik": cur.scan_lik,
            "lambda_min": lambda_min(self._cov),
            "timescale": (4 if cur.safe_mode else cur.timescale),
            "timescales": tuple(level for _, level in cur.selections),
            "safe_mode": cur.safe_mode,
            "kappa": kappa,
            "position_sigma_m": sigma_m,
            "anchored": anchored is not None,
            "n_local_maps": len(self.dmap),
            "odometry_slip": slipped,
        }
        return PoseEstimate(mean=self._pose.copy(), cov=self._cov.copy(), extras=extras)

    def _moved_since_learning(self, opose: FloatArray) -> bool:
        """Whether the odometry moved ``learn_min_dist_m`` or turned ``learn_min_angle_rad``
        since the last learned scan (always true for a run's first scan)."""
        last = self.__dict__.get("_learned_odom")  # absent in pickles made before the rule
        if last is None:
            return True
        c = self.config
        return moved_at_least(se2.between(last, opose), c.learn_min_dist_m, c.learn_min_angle_rad)

    # ------------------------------------------------------------------ eq. 9
    def _match(
        self, pts_base: FloatArray, pred: FloatArray, c_o: FloatArray, target: PointMap | None
    ) -> tuple[FloatArray, FloatArray, float, float, bool]:
        """Scan matching against ``target`` with the adaptive odometry prior (§4.3, eq. 9):
        pose, covariance, final κ, :func:`worst_position_sigma` of the scan term (``inf``:
        no match, the prediction is returned) and whether the odometry's heading was judged to
        have slipped and the scan's taken (``slip_fit_ratio``)."""
        c = self.config
        if target is None or len(pts_base) < c.min_matched:
            return pred, self._propagated_cov(c_o), float("nan"), float("inf"), False
        step = max(1, int(np.ceil(len(pts_base) / c.max_match_points)))
        pts = pts_base[::step]
        info_o = np.linalg.inv(c_o)

        kw = {"max_correspondence_m": c.max_correspondence_m, "max_iterations": c.max_iterations}
        kappa = c.kappa_first  # B&D: 0, the scan alone
        prior = {"prior_mean": pred, "prior_info": kappa * info_o} if kappa > 0 else {}
        first = match_scan(pts, target, pred, **kw, **prior)
        res, kappa, accepted = self._eq9_bound(pts, target, pred, info_o, first, kw)
        slipped = self._slipped(first, res, len(pts))
        if slipped:  # the heading from the scan, the position still bound by the odometry
            pred_h = np.array([pred[0], pred[1], first.pose[2]])
            res, kappa, accepted = self._eq9_bound(pts, target, pred_h, info_o, first, kw)
        if not accepted:
            return pred, self._propagated_cov(c_o), float("inf"), float("inf"), slipped
        pose = res.pose
        if c.degenerate_sigma_m > 0:
            pose = remap_degenerate(pose, pred, res.scan_info, c.degenerate_sigma_m)
        return pose, res.cov, kappa, worst_position_sigma(res.scan_info), slipped

    def _eq9_bound(
        self,
        pts: FloatArray,
        target: PointMap,
        pred: FloatArray,
        info_o: FloatArray,
        first: MatchResult,
        kw: dict[str, float],
    ) -> tuple[MatchResult, float, bool]:
        """B&D §4.3 steps 3-4: ``first`` if it lies within two standard deviations of
        ``pred`` under ``C_O`` (information ``info_o``), else the matches with the prior
        ``κ E_O`` at ``pred``, κ doubling from ``kappa0``, until one does: the last match,
        its κ and whether it lies within."""
        c = self.config

        def within(res: MatchResult) -> bool:
            e = res.pose - pred
            e[2] = se2.wrap_one(float(e[2]))  # float arithmetic: fewer numpy calls
            return self._usable(res) and float(e @ info_o @ e) <= 4.0  # two standard deviations

        if within(first):
            return first, c.kappa_first, True
        kappa = max(c.kappa0, 2.0 * c.kappa_first)
        res = first
        for _ in range(c.max_kappa_doublings):
            res = match_scan(pts, target, pred, prior_mean=pred, prior_info=kappa * info_o, **kw)
            if within(res):
                return res, kappa, True
            kappa *= 2.0
        return res, kappa, False

    def _usable(self, res: MatchResult) -> bool:
        """The match has a finite pose and at least ``min_matched`` correspondences."""
        return res.n_matched >= self.config.min_matched and bool(np.all(np.isfinite(res.pose)))

    def _slipped(self, first: MatchResult, forced: MatchResult, n_points: int) -> bool:
        """Eq. 9 forced the match away from ``first``, which fits ``slip_fit_ratio`` times
        better (see :class:`DynamicMapConfig`)."""
        c = self.config
        if c.slip_fit_ratio <= 0 or first is forced or not self._usable(first):
            return False
        cost = fit_cost(first, n_points, c.max_correspondence_m)
        return c.slip_fit_ratio * cost < fit_cost(forced, n_points, c.max_correspondence_m)

    @property
    def _anchoring(self) -> bool:
        """The long-term anchor is on and λ1 takes part (``ltm_anchor_tol_m``)."""
        return self.config.ltm_anchor_tol_m > 0 and 0 in self.selectable_levels

    def _anchor(
        self, pts_base: FloatArray, pred: FloatArray, c_o: FloatArray, pose: FloatArray
    ) -> tuple[FloatArray, FloatArray] | None:
        """The match against λ2–λ5 alone, when it pins the position and lies more than
        ``ltm_anchor_tol_m`` from ``pose`` (see :class:`DynamicMapConfig`); else None."""
        c = self.config
        pose_l, cov_l, _, sigma_l, _ = self._match(pts_base, pred, c_o, self._anchor_point_map())
        if sigma_l > c.ltm_anchor_max_sigma_m:
            return None
        if np.hypot(*(pose_l[:2] - pose[:2])) <= c.ltm_anchor_tol_m:
            return None
        return pose_l, cov_l

    def _set_anchor_map(self, pts: FloatArray) -> None:
        self._anchor_points = self._thinned(pts)
        self._anchor_map = None

    def _anchor_point_map(self) -> PointMap | None:
        self._anchor_map = self._point_map(self._anchor_points, self._anchor_map)
        return self._anchor_map

    def _propagated_cov(self, c_o: FloatArray) -> FloatArray:
        c, s = np.cos(self._pose[2]), np.sin(self._pose[2])
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        return self._cov + rot @ c_o @ rot.T

    # ------------------------------------------------------------------ current map
    def _thinned(self, pts: FloatArray) -> FloatArray:
        """``pts`` thinned to one per ``map_voxel_m`` cell (first in order)."""
        if len(pts) and self.config.map_voxel_m > 0:
            pts = pts[first_per_cell(pts, self.config.map_voxel_m)]
        return pts

    def _set_current_map(self, cur: CurrentMap) -> None:
        pts = self._thinned(cur.points)
        if self._cmap is not None and np.array_equal(pts, self._cmap_points):
            return  # the same points as the last scan's (long-term timescales): keep the KD-tree
        self._cmap_points = pts
        self._cmap = None

    def _current_point_map(self) -> PointMap | None:
        self._cmap = self._point_map(self._cmap_points, self._cmap)
        return self._cmap

    def _point_map(self, points: FloatArray, built: PointMap | None) -> PointMap | None:
        """``built``, or a :class:`PointMap` of ``points`` built now (None: fewer than
        ``min_matched`` points, nothing to match against)."""
        if built is None and len(points) >= self.config.min_matched:
            return PointMap(points)
        return built

    # ------------------------------------------------------------------ learning (§4.4)
    def _store(self, pose: FloatArray, ranges: np.ndarray) -> None:
        r = np.where(np.isfinite(ranges), ranges, 0.0)
        self._run_poses.append(np.asarray(pose, dtype=np.float64).copy())
        self._run_ranges.append(to_mm(r))

    def _stored_points(self, poses: list[FloatArray], ranges_mm: list[np.ndarray]) -> list:
        out = []
        for pose, r_mm in zip(poses, ranges_mm, strict=True):
            r = r_mm.astype(np.float64) / 1000.0
            r[r_mm == 0] = np.inf
            out.append(self._points_map(pose, r))
        return out

    def end_run(self) -> None:
        """λ2 learns the run offline; after the first run, the initial local maps are made."""
        if self._mapper is not None:
            smap = self._mapper.finish()
            self._mapper = None
            if len(smap.trajectory) == len(self._run_poses):
                self._run_poses = [p.copy() for p in smap.trajectory]
            kfs = smap.keyframes
            self._init_local_maps([kf.pose for kf in kfs], [kf.ranges_m for kf in kfs])
        if self.learns_ltm and self._run_poses:
            sel = self._random_subset(len(self._run_poses), self.config.ltm_scans_per_run)
            poses = [self._run_poses[k] for k in sel]
            pts = self._stored_points(poses, [self._run_ranges[k] for k in sel])
            self.dmap.learn_offline(self.dmap.levels("run"), np.array(poses), pts, self.rng)
            sel = self._random_subset(len(self._run_poses), self.config.ltm_day_scans_per_run)
            self._day_poses += [self._run_poses[k] for k in sel]
            self._day_ranges += [self._run_ranges[k] for k in sel]
        self._run_poses, self._run_ranges = [], []

    def _random_subset(self, n: int, k: int) -> np.ndarray:
        """``min(n, k)`` indices out of ``n``, uniformly at random, in time order."""
        if k <= 0 or n <= k:
            return np.arange(n)
        return np.sort(self.rng.choice(n, size=k, replace=False))

    def end_day(self) -> None:
        """λ3–λ5 learn the day offline; static variants freeze after ``freeze_after_day``."""
        if self.learns_ltm and self._day_poses:
            pts = self._stored_points(self._day_poses, self._day_ranges)
            self.dmap.learn_offline(
                self.dmap.levels("day"), np.array(self._day_poses), pts, self.rng
            )
            if self.config.day_snapshots:
                self.day_snapshots.append((self._day, self.dmap.snapshot()))
        self._day_poses, self._day_ranges = [], []
        self.days_done += 1
        if self.mode != "dynamic" and self.days_done >= self.config.freeze_after_day:
            self.frozen = True

    def day_artifacts(self) -> dict[str, dict[str, np.ndarray]]:
        """``map_snapshot``: λ2–λ5 of every local map after this day's learning
        (:meth:`MapSnapshot.to_arrays`), on the days the map learned (and
        ``config.day_snapshots``)."""
        if self.day_snapshots and self.day_snapshots[-1][0] == self._day:
            return {"map_snapshot": self.day_snapshots[-1][1].to_arrays()}
        return {}

    def set_map_from_scans(
        self,
        poses: np.ndarray,
        ranges_m: Sequence[np.ndarray],
        run_poses: np.ndarray | None = None,
        run_odometry: np.ndarray | None = None,
    ) -> None:
        """The first map from scans at given poses (:class:`ScanMapUser`; e.g. a log's
        corrected poses): the end of a first run (§4, §4.4) with the poses given instead of
        the first-run SLAM's — initial local maps from the scans, then :meth:`end_run` and
        :meth:`end_day` learn them as the run and the day they stand for (a static variant
        freezes as after its first day). ``run_poses`` and ``run_odometry`` (both or neither,
        ``(N, 3)`` for every scan of that run, NaN poses unknown): ``C_O`` is acquired from
        them (``odom_calibration``)."""
        if (run_poses is None) != (run_odometry is None):
            raise ValueError("set_map_from_scans: give run_poses and run_odometry together")
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        if len(poses) == 0 or len(poses) != len(ranges_m):
            raise ValueError(
                f"set_map_from_scans: {len(poses)} poses for {len(ranges_m)} scans (need >= 1 each)"
            )
        self._init_local_maps(poses, ranges_m)
        for pose, r in zip(poses, ranges_m, strict=True):
            self._store(pose, np.asarray(r, dtype=np.float64))
        if run_poses is not None and run_odometry is not None:
            self._calibrate_odometry(run_odometry, run_poses)
        self.end_run()
        self.end_day()
        self._map_given = True

    def _init_local_maps(self, poses: Sequence[FloatArray], ranges_m: Sequence[np.ndarray]) -> None:
        """Initial local maps from the first run's keyframes (§4), ``local_map_spacing_m``
        apart; each is filled with its own keyframe scan (robot ``poses``, ``ranges_m`` [m])."""
        for pose, r in zip(poses, ranges_m, strict=True):
            pose = np.asarray(pose, dtype=np.float64)
            if len(self.dmap.near(pose, self.config.local_map_spacing_m)):
                continue
            self.dmap.add_local_map(pose[:2], self._points_map(pose, r), self.rng)


@register_localizer("dynamic-map")
class DynamicMapLocalization(DynamicMapLocalizer):
    """Biber & Duckett's dynamic map (all five timescales, never frozen)."""

    def __init__(self, laser: LaserSpec, rng: np.random.Generator, **params: Any) -> None:
        super().__init__(laser, rng, mode="dynamic", **params)


@register_localizer("static-map")
class StaticMapLocalization(DynamicMapLocalizer):
    """The dynamic map after day 1, frozen; localizes with λ2–λ5 only (§5.3)."""

    def __init__(self, laser: LaserSpec, rng: np.random.Generator, **params: Any) -> None:
        super().__init__(laser, rng, mode="static", **params)


@register_localizer("static-map+stm")
class StaticMapSTMLocalization(DynamicMapLocalizer):
    """The frozen day-1 snapshot plus a live short-term memory λ1 (§5.3)."""

    def __init__(self, laser: LaserSpec, rng: np.random.Generator, **params: Any) -> None:
        super().__init__(laser, rng, mode="static+stm", **params)
