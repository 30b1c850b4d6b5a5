"""``static-mcl``: Monte Carlo localization faithful to ROS 2 nav2's AMCL, on a fixed map.

Augmented KLD-sampling MCL (*Probabilistic Robotics* Table 8.3 "Augmented_MCL" and
Table 8.4 "KLD_Sampling_MCL"; Fox 2003) exactly as nav2_amcl composes it:

* the filter only updates after the odometry moved ``update_min_d`` [m] in x or y or
  ``update_min_a`` [rad] (``amcl_node.cpp``); in between, the reported pose is the last
  filter estimate carried along by odometry (the ``map -> odom`` transform AMCL publishes);
* prediction by the ``diff-corrected`` odometry model (:mod:`.motion_model`);
* correction by the likelihood field (:mod:`.likelihood_field`), ``likelihood_field`` or
  ``likelihood_field_prob`` with beam skipping;
* ``w_slow``/``w_fast`` running averages of the mean weight (Table 8.3 lines 10-11); during
  resampling each draw is a uniformly random pose in the map's free space with probability
  ``max(0, 1 - w_fast / w_slow)``, after which nav2's ``pf.c`` resets both averages
  (``recovery_reset``; the ``tuned`` config keeps them, as Table 8.3 does, so that a filter
  that converged to a wrong place after an injection keeps injecting);
* ``tuned`` only: the recovery rule is made robust to a changing world (Table 8.3 as nav2
  implements it fires on every drop of the raw 60-beam likelihood product, e.g. when
  furniture moved): (a) w_slow/w_fast average the per-beam (geometric-mean) likelihood over
  all valid beams, (b) injection starts only when ``w_fast`` stays below
  ``recovery_ratio_threshold`` of ``w_ref = max(w_slow, exp(recovery_floor_loglik))`` for
  ``recovery_min_updates`` consecutive updates (a moved chair lowers the likelihood a little,
  a kidnapping a lot), (c) at most ``recovery_max_fraction`` of the draws are random poses,
  so a large unmapped obstacle cannot wipe out the correct cluster, and (d) readings much
  shorter than the map predicts at the mean particle (people, moved furniture in front of
  mapped walls) are left out of the averages (``recovery_distance_filter_m``, Fox et al.
  1999's distance filter, :mod:`.distance_filter`), unless that would leave out more than
  half of them. See :class:`MCLConfig`;
* ``tuned`` only: **local resetting first** (Lenser & Veloso 2000's sensor resetting, drawn
  around the estimate): when this update's per-beam likelihood falls below half of
  ``w_ref``, up to 30 % of the draws are poses near the estimate, for at most 10 updates and
  only before the global gate above counts, to repair an odometry glitch (a missed turn on a
  real log) before it drifts the cloud off and opens the global gate
  (``recovery_local_ratio``);
* KLD-sampling picks the number of particles (0.5 m x 0.5 m x 10 degree bins,
  :mod:`.kld_sampling`), low-variance resampling draws them (:mod:`.resampling`);
* the estimate is the mean of the heaviest cluster of particles (clusters are connected
  occupied bins, as ``pf_cluster_stats``), with a weighted covariance (circular for theta),
  taken from the weighted set after the sensor update (AMCL takes it after resampling, when
  freshly injected random poses weigh as much as the rest and can drag the mean).

The map comes from a map source (:mod:`dynmap_sim.agent.maps.map_source`): the first run's
SLAM map (built by :class:`~dynmap_sim.agent.mapping.first_run.FirstRunMapper` on the
experiment's first run, whose estimates it reports meanwhile) or the prior walls rasterized
to a 5 cm grid; or it is handed over
(:class:`~dynmap_sim.agent.localization.localizer.MapUser`). It never changes afterwards.
"""

from __future__ import annotations

from dataclasses import asdict, replace
from typing import Annotated, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from pydantic import Field

from dynmap_sim import se2
from dynmap_sim.agent.grid import OCCUPIED, OccupancyGrid
from dynmap_sim.agent.localization.distance_filter import expected_ranges, short_readings
from dynmap_sim.agent.localization.kld_sampling import (
    ONE_BIN_RULES,
    bin_keys,
    kld_prefix_size,
    kld_prefix_size_lazy,
)
from dynmap_sim.agent.localization.likelihood_field import (
    LikelihoodFieldParams,
    LikelihoodTable,
    beam_likelihoods,
    endpoint_values,
    likelihood_field_prob_beams,
    likelihood_field_weights_beams,
    select_beams,
    valid_beams,
)
from dynmap_sim.agent.localization.localizer import Localizer, MapUser, register_localizer
from dynmap_sim.agent.localization.motion_model import sample_odometry_motion
from dynmap_sim.agent.localization.particle_filter_kernels import bin_clusters
from dynmap_sim.agent.localization.resampling import LowVarianceDraws, low_variance_resample
from dynmap_sim.agent.localization.see_through import see_through_logp, wall_depths
from dynmap_sim.agent.localization.verified_recovery import VerifiedRecovery
from dynmap_sim.agent.maps.map_source import MapSource, PriorWallsMap, make_map_source
from dynmap_sim.agent.params import (
    Finite,
    Fraction,
    NonNegative,
    NonNegativeInt,
    NotNaN,
    Positive,
    PositiveInt,
    int_range,
    params_dataclass,
)
from dynmap_sim.types import Diagnostic, LaserSpec, Odometry, PoseEstimate, Prior, Scan

FloatArray = NDArray[np.float64]


#: The laser models of :class:`MCLConfig` (nav2's names).
LASER_MODELS = ("likelihood_field", "likelihood_field_prob")
#: Where the global recovery's random poses go (:attr:`MCLConfig.recovery_global`).
GLOBAL_RECOVERY_MODES = ("inject", "verify")
#: What the recovery average does with a scan the distance filter leaves too few beams of
#: (:attr:`MCLConfig.recovery_occluded`).
OCCLUDED_MODES = ("all-beams", "hold")
#: At most this many particles: every update holds a few arrays of ``max_particles x
#: max_beams`` floats (60 beams: ~0.5 GB at this bound); the tuned config uses 8000.
MAX_PARTICLES = 1_000_000


@params_dataclass("static-mcl")
class MCLConfig:
    """AMCL's parameters with nav2's names, units and defaults (``nav2_params.yaml``,
    ``amcl_node.cpp``), and the rules the ``tuned`` configs add (``recovery_*`` beyond nav2's
    two alphas, ``see_through_*``, ``distance_filter_weights``), each off by default so that
    the defaults are nav2's AMCL. The measurements behind the tuned values:
    ``docs/tuning/localization.md``."""

    #: Odometry model (:mod:`.motion_model`): rotation noise from rotation (squared
    #: [rad/rad]); nav2's 0.2.
    alpha1: NonNegative = 0.2
    #: ... rotation noise from translation (squared [rad/m]); nav2's 0.2.
    alpha2: NonNegative = 0.2
    #: ... translation noise from translation (squared [m/m]); nav2's 0.2.
    alpha3: NonNegative = 0.2
    #: ... translation noise from rotation (squared [m/rad]); nav2's 0.2.
    alpha4: NonNegative = 0.2
    #: ``likelihood_field`` (AMCL's ``1 + sum p^3``) or ``likelihood_field_prob`` (the product
    #: of the beams, with beam skipping); nav2's default is the first.
    laser_model_type: str = "likelihood_field"
    #: Beams per update, evenly spaced over the scan (:func:`.select_beams`); nav2's 60.
    max_beams: NonNegativeInt = 60
    #: Distance [m] at which the likelihood field is clipped (the map's ``max_dist_m``); nav2's.
    laser_likelihood_max_dist: Positive = 2.0
    #: Readings at or beyond this [m] are ignored (<= 0: the sensor's range); nav2's 100.
    laser_max_range: Finite = 100.0
    #: Readings below this [m] are ignored (<= 0: the sensor's minimum); nav2's -1.
    laser_min_range: Finite = -1.0
    #: Weight of the Gaussian ("hit") part of the beam model; nav2's 0.5.
    z_hit: NonNegative = 0.5
    #: Weight of the uniform ("random") part, a density of ``z_rand / range_max``; nav2's 0.5.
    z_rand: NonNegative = 0.5
    #: Standard deviation [m] of the hit part; nav2's 0.2.
    sigma_hit: Positive = 0.2
    #: Beam skipping (``likelihood_field_prob``): ignore the beams that few particles see near
    #: an obstacle (an unmapped object); off in nav2.
    do_beamskip: bool = False
    #: A particle sees a beam near an obstacle within this distance [m]; nav2's 0.5.
    beam_skip_distance: Positive = 0.5
    #: A beam is skipped when at most this share of the particles sees it near one; nav2's 0.3.
    beam_skip_threshold: Fraction = 0.3
    #: ... unless this share of the beams would be skipped (the filter has likely diverged:
    #: all beams count); nav2's 0.9.
    beam_skip_error_threshold: Fraction = 0.9
    #: Fewest particles KLD-sampling keeps; nav2's 500.
    min_particles: PositiveInt = 500
    #: Most particles KLD-sampling keeps (at most :data:`MAX_PARTICLES`); nav2's 2000.
    max_particles: int_range(1, MAX_PARTICLES) = 2000
    #: KLD-sampling's bound on the K-L divergence (:mod:`.kld_sampling`); nav2's 0.05.
    pf_err: Annotated[Positive, Field(le=1.0)] = 0.05
    #: KLD-sampling's normal quantile ``z``; nav2's 0.99, which nav2 passes as the quantile
    #: itself (not a probability: :mod:`.kld_sampling`).
    pf_z: Positive = 0.99
    #: Side [m] of the KLD histogram's (and the clusters') bins; AMCL's 0.5 m.
    kld_cell_m: Positive = 0.5
    #: Heading width [rad] of those bins; AMCL's 10 degrees.
    kld_angle_rad: Positive = float(np.deg2rad(10.0))
    #: Particles when every draw falls into one KLD bin: ``max`` (nav2's ``pf_resample_limit``)
    #: or ``min`` (Fox 2003, *Probabilistic Robotics* Table 8.4: the bound counts from two
    #: bins on); :mod:`.kld_sampling`.
    kld_one_bin: str = "max"
    #: Smoothing of the slow average ``w_slow`` of the mean weight (Table 8.3 line 10); 0 with
    #: ``recovery_alpha_fast`` 0 is no recovery, nav2's default.
    recovery_alpha_slow: Fraction = 0.0
    #: Smoothing of the fast average ``w_fast`` (Table 8.3 line 11); nav2's 0.
    recovery_alpha_fast: Fraction = 0.0
    #: Reset ``w_slow`` and ``w_fast`` to 0 after injecting random poses, as nav2's ``pf.c``
    #: does (Table 8.3 does not).
    recovery_reset: bool = True
    #: Divide the (already normalized) weighted likelihood by the particle count again, as
    #: ``pf.c`` does, so that ``w_avg`` scales with 1/N; False: Table 8.3's average.
    recovery_w_avg_per_sample: bool = True
    #: Average the per-beam (geometric mean over all valid beams, beam skipping not applied)
    #: likelihood instead of nav2's raw product of the beams, whose scale swings by orders of
    #: magnitude from scan to scan; off in nav2.
    recovery_w_avg_per_beam: bool = False
    #: Inject only while ``w_fast / w_ref`` is below this ratio; the probability stays
    #: ``1 - w_fast / w_ref`` (Table 8.3 line 13); nav2's 1 (whenever it is below 1).
    recovery_ratio_threshold: NonNegative = 1.0
    #: ``w_ref = max(w_slow, exp(recovery_floor_loglik))`` [log per beam] (per-beam mode): lets
    #: a filter that converged wrongly right after global initialization, whose ``w_slow``
    #: starts at the wrong place's low level, inject; nav2: -inf, no floor.
    recovery_floor_loglik: NotNaN = float("-inf")
    #: ... and only after this many consecutive filter updates below it; nav2's 1.
    recovery_min_updates: PositiveInt = 1
    #: Cap on the injection probability, so that a large unmapped obstacle cannot replace the
    #: correct cluster at once; nav2's 1 (no cap).
    recovery_max_fraction: Fraction = 1.0
    #: Readings more than this [m] shorter than the map predicts at the mean particle are left
    #: out of the recovery average (Fox et al. 1999's distance filter, :mod:`.distance_filter`),
    #: so that people and moved furniture do not look like a kidnapping; 0 off (nav2).
    recovery_distance_filter_m: NonNegative = 0.0
    #: The distance filter applies only when it leaves at least this share of the valid beams.
    recovery_min_beam_share: Fraction = 0.5
    #: A scan the distance filter leaves fewer beams of: ``all-beams`` averages all valid
    #: beams; ``hold`` leaves the averages as they are while the gate is not counting
    #: (``n_low_updates == 0``: such a scan says nothing about the pose) and averages all beams
    #: once it counts.
    recovery_occluded: str = "all-beams"
    #: A global random pose at which more than this share of the last scan's readings end
    #: ``recovery_through_margin_m`` beyond the map's first occupied cell along the beam (only
    #: a wrong pose or a removed object explains them, Fox et al. 1999 §4.2) is not injected;
    #: 0 off (nav2).
    recovery_through_max_share: Fraction = 0.0
    #: How far [m] beyond the map's first occupied cell a reading must end to pass through a
    #: wall: the distance filter's 0.3 m, above a few cells of map error and the half-cell
    #: ray steps.
    recovery_through_margin_m: NonNegative = 0.3
    #: Local resetting (Lenser & Veloso 2000's sensor resetting, drawn around the estimate;
    #: per-beam mode): a share ``1 - w_last / (ratio * w_ref)`` of the draws are poses near the
    #: estimate (``w_last``: this update's per-beam average), to repair an odometry glitch
    #: before the global gate opens; stopped while the gate counts. 0 off (nav2).
    recovery_local_ratio: Fraction = 0.0
    #: Cap on the share of local draws per update.
    recovery_local_max_fraction: Fraction = 0.0
    #: Standard deviation [m] of the local draws around the estimate in x and y.
    recovery_local_sigma_xy: NonNegative = 0.5
    #: Standard deviation [rad] of the local draws around the estimate's heading.
    recovery_local_sigma_theta: NonNegative = 0.3
    #: Local resets allowed before the fit is back at ``w_ref`` (then global recovery only):
    #: after a kidnapping, local poses only fit the wrong place a little better.
    recovery_local_max_updates: NonNegativeInt = 10
    #: Where the global recovery's random poses go: ``inject`` (Table 8.3 line 13, nav2's
    #: ``pf.c``) into the one particle set; ``verify`` into a challenger set, a global
    #: localization filter of its own that replaces the tracked set only once its fit is
    #: verified (:mod:`.verified_recovery`; Jensfelt & Kristensen 2001's hypothesis
    #: verification). Needs ``recovery_w_avg_per_beam``.
    recovery_global: str = "inject"
    #: ``verify``: the challenger's per-beam fit must reach this share of ``w_ref`` ...
    recovery_accept_ratio: Fraction = 0.7
    #: ``verify``: ... for this many consecutive filter updates.
    recovery_accept_updates: NonNegativeInt = 3
    #: Negative information in the sensor update (``likelihood_field_prob``): a particle's
    #: reading that ends ``delta`` more than this [m] beyond the map's first occupied cell along
    #: its beam scores at most the beam model's ``z_hit exp(-(delta - margin)^2 / 2
    #: sigma_hit^2) + z_rand / range_max`` (:mod:`.see_through`), against a cloud sliding
    #: through walls; 0 off (nav2).
    see_through_margin_m: NonNegative = 0.0
    #: ... except for a reading more than this share of the particles sees through (a removed
    #: object, not a wrong pose): only readings that some particles see through and others do
    #: not tell particles apart.
    see_through_max_share: Fraction = 0.5
    #: Fox et al. 1999's distance filter in the weights too (``likelihood_field_prob``): readings
    #: more than ``recovery_distance_filter_m`` shorter than the map predicts at the mean particle
    #: (a person, a parked bed) are left out of the weights while the gate is not counting (a
    #: short reading can fit a wrong particle well); False: every valid beam (nav2).
    distance_filter_weights: bool = False
    #: Resample every this many filter updates; nav2's 1.
    resample_interval: PositiveInt = 1
    #: The filter updates after the odometry moved this far [m] in x or y; nav2's 0.25.
    update_min_d: NonNegative = 0.25
    #: ... or turned this much [rad]; nav2's 0.2.
    update_min_a: NonNegative = 0.2
    #: Standard deviation [m] of the initial particles around a given pose in x and y
    #: (without the prior's covariance); nav2's 0.5.
    init_sigma_xy: NonNegative = 0.5
    #: ... and in heading [rad]; nav2's pi/12.
    init_sigma_theta: NonNegative = float(np.pi / 12.0)

    def __post_init__(self) -> None:
        if self.min_particles > self.max_particles:
            raise ValueError(
                f"min_particles ({self.min_particles}) must be <= max_particles "
                f"({self.max_particles})"
            )
        if self.kld_one_bin not in ONE_BIN_RULES:
            raise ValueError(
                f"kld_one_bin must be one of {ONE_BIN_RULES}, got {self.kld_one_bin!r}"
            )
        if self.recovery_global not in GLOBAL_RECOVERY_MODES:
            raise ValueError(
                f"recovery_global must be one of {GLOBAL_RECOVERY_MODES}, "
                f"got {self.recovery_global!r}"
            )
        if self.recovery_global == "verify" and not self.recovery_w_avg_per_beam:
            raise ValueError(
                "recovery_global 'verify' compares per-beam fits; it needs "
                "recovery_w_avg_per_beam = true"
            )
        if self.recovery_occluded not in OCCLUDED_MODES:
            raise ValueError(
                f"recovery_occluded must be one of {OCCLUDED_MODES}, got {self.recovery_occluded!r}"
            )
        if self.laser_model_type not in LASER_MODELS:
            raise ValueError(
                f"laser_model_type must be one of {LASER_MODELS}, got {self.laser_model_type!r}"
            )
        prob = self.laser_model_type == "likelihood_field_prob"
        if (self.see_through_margin_m > 0 or self.distance_filter_weights) and not prob:
            raise ValueError(
                "see_through_margin_m > 0 and distance_filter_weights rescore "
                "single readings; they need laser_model_type = 'likelihood_field_prob'"
            )
        if self.distance_filter_weights and self.recovery_distance_filter_m <= 0:
            raise ValueError(
                "distance_filter_weights uses the distance filter's margin; "
                "it needs recovery_distance_filter_m > 0"
            )


#: nav2's defaults (``nav2_params.yaml`` / ``amcl_node.cpp``): recovery off, no beam skipping.
NAV2_DEFAULT = MCLConfig()

#: Tuned to the simulated sensors (URG-04LX) and first-run SLAM maps, wheel odometry, and worlds
#: that change (people, moved furniture, kidnapping): nav2's filter with the product model and
#: beam skipping, tighter odometry noise, 8000 particles at most, Table 8.3's recovery made
#: robust (per-beam averages, a gated and capped injection, the distance filter, local
#: resetting first), and negative information (see-through readings, the distance filter in
#: the weights). What each value rests on: docs/tuning/localization.md.
TUNED = MCLConfig(
    alpha1=0.05,
    alpha2=0.05,
    alpha3=0.02,
    alpha4=0.05,
    laser_model_type="likelihood_field_prob",
    max_beams=60,
    z_hit=0.9,
    z_rand=0.1,
    sigma_hit=0.12,
    do_beamskip=True,
    min_particles=500,
    max_particles=8000,
    pf_err=0.01,
    pf_z=2.326,
    recovery_alpha_slow=0.001,
    recovery_alpha_fast=0.1,
    recovery_reset=False,
    recovery_w_avg_per_sample=False,
    recovery_w_avg_per_beam=True,
    recovery_ratio_threshold=0.5,
    recovery_floor_loglik=-0.5,
    recovery_min_updates=5,
    recovery_max_fraction=0.35,
    recovery_distance_filter_m=0.3,
    recovery_occluded="hold",
    recovery_through_max_share=0.5,
    recovery_local_ratio=0.5,
    recovery_local_max_fraction=0.3,
    recovery_local_sigma_xy=0.5,
    recovery_local_sigma_theta=0.3,
    recovery_local_max_updates=10,
    update_min_d=0.1,
    update_min_a=0.1,
    init_sigma_xy=0.2,
    init_sigma_theta=0.1,
    see_through_margin_m=0.3,
    see_through_max_share=0.5,
    distance_filter_weights=True,
    kld_one_bin="min",
)

#: ``tuned`` without the rules that look past the end points (no see-through term, the
#: distance filter out of the weights, nav2's one-bin rule) and ``alpha3`` 0.05: the
#: likelihood field on every valid reading's end point. ``adaptive-memory``'s filter on the
#: static points (H&W §6.1) and :data:`WALLS_ONLY` were tuned with it.
TUNED_END_POINTS = replace(
    TUNED,
    see_through_margin_m=0.0,
    distance_filter_weights=False,
    kld_one_bin="max",
    alpha3=0.05,
)

#: :data:`TUNED_END_POINTS` for a map that lacks the furniture (the walls-only prior, H&W Fig. 4,
#: their static MCL of §7.3), where about half of the beams end on furniture: no floor under
#: ``w_ref`` (the true pose fits too poorly for it), nav2's 0.5 / 0.5 mixture (half of the
#: beams are "random" to this map), beam skipping from 0.3 m (AMCL's ratio to ``sigma_hit``,
#: which drops the furniture in front of walls) and ``all-beams`` for occluded scans (half of
#: the readings are short at the true pose on every scan).
WALLS_ONLY = replace(
    TUNED_END_POINTS,
    z_hit=0.5,
    z_rand=0.5,
    beam_skip_distance=0.3,
    recovery_floor_loglik=float("-inf"),
    recovery_occluded="all-beams",
)

#: The configs ``static-mcl``'s ``config`` parameter names (docs/tuning/localization.md).
CONFIGS: dict[str, MCLConfig] = {
    "nav2-default": NAV2_DEFAULT,
    "tuned": TUNED,
    "tuned-end-points": TUNED_END_POINTS,
    "walls-only": WALLS_ONLY,
}


#: Smallest variance [m^2 / rad^2] kept in a reported covariance: a particle set collapsed onto
#: one pose has a (numerically) singular covariance whose inverse is meaningless.
COV_FLOOR = 1e-9


def regularized_covariance(cov: ArrayLike, floor: float = COV_FLOOR) -> FloatArray:
    """``cov`` made symmetric positive definite: symmetrized, eigenvalues clipped to ``floor``."""
    c = np.asarray(cov, dtype=np.float64)
    c = 0.5 * (c + c.T)
    ev, vec = np.linalg.eigh(c)
    c = (vec * np.maximum(ev, floor)) @ vec.T
    return 0.5 * (c + c.T)


def information_lambda_min(cov: ArrayLike, floor: float = COV_FLOOR) -> float:
    """Smallest eigenvalue of the information matrix ``cov^-1`` (B&D §5.3, Fig. 11).

    Computed as ``1 / lambda_max(cov)`` with ``eigvalsh`` on the symmetrized covariance, which is
    exact for a positive definite ``cov`` and, unlike ``eigvalsh(inv(cov))``, never negative
    for an ill-conditioned one (whose inverse carries huge round-off).
    """
    c = np.asarray(cov, dtype=np.float64)
    lam_max = float(np.linalg.eigvalsh(0.5 * (c + c.T))[-1])
    return 1.0 / max(lam_max, floor)


#: What :func:`reported_covariance` keeps: the filter's covariance, its regularized copy and
#: the latter's information ``lambda_min``.
CovReport = tuple[FloatArray, FloatArray, float]


def reported_covariance(cov: FloatArray, last: CovReport | None) -> CovReport:
    """``(cov, regularized_covariance(cov), information_lambda_min(...) of that)``, or
    ``last`` when it was made from this very array: a filter's covariance changes only with
    a new estimate, which is a new array, so the odometry-only scans in between reuse it."""
    if last is not None and last[0] is cov:
        return last
    reg = regularized_covariance(cov)
    return cov, reg, information_lambda_min(reg)


def per_beam_average(log_w_prev: FloatArray, logp: NDArray[np.floating]) -> float:
    """Weighted mean scan likelihood per beam: ``(sum_i w_i prod_k p_ik) ** (1 / n_beams)``
    from log weights ``(N,)`` and per-beam ``log p`` ``(N, n_beams)``, in the log domain
    (the raw product under/overflows)."""
    lw = log_w_prev + logp.sum(axis=1, dtype=np.float64)
    m = float(lw.max())
    return float(np.exp((m + np.log(np.sum(np.exp(lw - m)))) / max(logp.shape[1], 1)))


def running_averages(
    w_slow: float, w_fast: float, w_avg: float, config: MCLConfig
) -> tuple[float, float]:
    """``w_slow``, ``w_fast`` after one more average ``w_avg`` (Table 8.3 lines 10-11);
    a zero average starts at ``w_avg``."""
    a_s, a_f = config.recovery_alpha_slow, config.recovery_alpha_fast
    return (
        w_avg if w_slow == 0 else w_slow + a_s * (w_avg - w_slow),
        w_avg if w_fast == 0 else w_fast + a_f * (w_avg - w_fast),
    )


def weighted_mean_pose(
    particles: FloatArray, weights: FloatArray
) -> tuple[FloatArray, FloatArray, float, float]:
    """Weighted mean pose (circular for theta) of a particle set, with the normalized weights
    and the weighted means of ``cos theta``, ``sin theta`` (:func:`weighted_pose_stats`)."""
    w = np.asarray(weights, dtype=np.float64)
    w = w / w.sum()
    c = float(np.sum(w * np.cos(particles[:, 2])))
    s = float(np.sum(w * np.sin(particles[:, 2])))
    mean = np.array(
        [float(np.sum(w * particles[:, 0])), float(np.sum(w * particles[:, 1])), np.arctan2(s, c)]
    )
    return mean, w, c, s


def weighted_pose_stats(
    particles: FloatArray, weights: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Weighted mean (circular for theta) and 3x3 covariance of a particle set.

    The theta variance is AMCL's circular ``-2 ln R`` (``R`` the mean resultant length);
    cross terms use the wrapped angle residuals.
    """
    mean, w, c, s = weighted_mean_pose(particles, weights)
    res = particles - mean
    res[:, 2] = se2.wrap_angle(res[:, 2])
    cov = (res * w[:, None]).T @ res
    r_len = min(max(np.hypot(c, s), 1e-12), 1.0)
    cov[2, 2] = max(-2.0 * np.log(r_len), 0.0)
    return mean, 0.5 * (cov + cov.T)


class AMCLFilter:
    """The particle filter of nav2's AMCL on a fixed :class:`OccupancyGrid` (no ROS)."""

    def __init__(self, grid: OccupancyGrid, laser: LaserSpec, config: MCLConfig) -> None:
        self.grid = grid
        self.laser = laser
        self.config = config
        self.beams = select_beams(laser.n_beams, config.max_beams)
        self.angles = laser.angles()[self.beams]
        self.range_max = (
            min(laser.range_max_m, config.laser_max_range)
            if config.laser_max_range > 0
            else laser.range_max_m
        )
        self.range_min = (
            max(laser.range_min_m, config.laser_min_range)
            if config.laser_min_range > 0
            else laser.range_min_m
        )
        self.lf = LikelihoodFieldParams(
            z_hit=config.z_hit,
            z_rand=config.z_rand,
            sigma_hit=config.sigma_hit,
            range_max=self.range_max,
            do_beamskip=config.do_beamskip,
            beam_skip_distance=config.beam_skip_distance,
            beam_skip_threshold=config.beam_skip_threshold,
            beam_skip_error_threshold=config.beam_skip_error_threshold,
        )
        self.table = LikelihoodTable(grid, self.lf)
        self.free_xy = grid.free_points()
        if len(self.free_xy) == 0:
            raise ValueError("the map has no free cells to draw random poses from")
        self.mount = np.asarray(laser.mount_pose, dtype=np.float64)
        self.particles = np.zeros((0, 3))
        self.weights = np.zeros(0)
        #: The valid readings and their angles of the last sensor update.
        self._last_beams: tuple[FloatArray, FloatArray] = (np.zeros(0), np.zeros(0))
        self.reset_recovery()
        self.n_random_injected = 0
        #: Poses drawn near the estimate by local resetting (``recovery_local_ratio``).
        self.n_local_injected = 0

    def reset_recovery(self) -> None:
        """Forget the recovery averages (at initialization, and in nav2 after injecting)."""
        self.w_slow = self.w_fast = self.w_last = 0.0
        self.n_low_updates = self.n_local_updates = 0

    # -- initialization ------------------------------------------------------------------
    def random_poses(self, n: int, rng: np.random.Generator) -> FloatArray:
        """``n`` uniformly random poses in the map's free space (AMCL's pose generator)."""
        idx = rng.integers(0, len(self.free_xy), size=n)
        jitter = (rng.random((n, 2)) - 0.5) * self.grid.resolution_m
        th = rng.uniform(-np.pi, np.pi, size=n)
        return np.column_stack([self.free_xy[idx] + jitter, th])

    def init_gaussian(self, mean: ArrayLike, cov: ArrayLike, rng: np.random.Generator) -> None:
        """Particles drawn from ``N(mean, cov)`` (AMCL ``pf_init``), ``max_particles`` of them."""
        n = self.config.max_particles
        p = rng.multivariate_normal(np.asarray(mean, float), np.asarray(cov, float), size=n)
        p[:, 2] = se2.wrap_angle(p[:, 2])
        self.particles = p
        self.weights = np.full(n, 1.0 / n)
        self.reset_recovery()

    def init_uniform(self, rng: np.random.Generator) -> None:
        """Global localization: ``max_particles`` random poses in free space."""
        n = self.config.max_particles
        self.particles = self.random_poses(n, rng)
        self.weights = np.full(n, 1.0 / n)
        self.reset_recovery()

    # -- filter steps --------------------------------------------------------------------
    def predict(self, odom_old: ArrayLike, odom_new: ArrayLike, rng: np.random.Generator) -> None:
        c = self.config
        self.particles = sample_odometry_motion(
            self.particles, odom_old, odom_new, (c.alpha1, c.alpha2, c.alpha3, c.alpha4), rng
        )

    def _beams_of(self, ranges_m: ArrayLike) -> tuple[FloatArray, FloatArray]:
        r = np.asarray(ranges_m, dtype=np.float64)[self.beams]
        ok = valid_beams(r, self.range_max) & (r >= self.range_min)
        return r[ok], self.angles[ok]

    def correct(self, ranges_m: ArrayLike) -> None:
        """Sensor update (``pf_update_sensor``) with the recovery averages."""
        r, a = self._beams_of(ranges_m)
        self._last_beams = (r, a)
        if len(r) == 0:
            return
        c = self.config
        # the distance filter's beams at the mean particle (Fox et al. 1999): for the weights
        # (distance_filter_weights) and the recovery averages (recovery_w_avg_per_beam)
        keep = (
            self._distance_filter_beams(self.weights, r, a)
            if c.distance_filter_weights or c.recovery_w_avg_per_beam
            else None
        )
        beam_logp = None  # (P, B) log p of the end points
        if c.laser_model_type == "likelihood_field_prob":
            beam_logp = self._endpoint_values(self.table.logp, self.particles, r, a)
            # the weights' beams: the distance filter's only while the recovery gate is not
            # counting (it measures "short" against the mean particle, which a kidnapping
            # makes wrong)
            w = slice(None)
            if c.distance_filter_weights and self.n_low_updates == 0 and keep is not None:
                w = keep
            lp = beam_logp[:, w]
            scored = self._see_through_scored(lp, r[w], a[w])
            logp, _ = likelihood_field_prob_beams(lp, self.table, self.lf, scored)
        else:
            p = self._endpoint_values(self.table.p, self.particles, r, a)
            logp = np.log(likelihood_field_weights_beams(p))
        w_prev = self.weights
        lw_prev = np.log(np.maximum(w_prev, 1e-300))
        logw = lw_prev + logp
        m = float(logw.max())
        total_scaled = float(np.sum(np.exp(logw - m)))
        total = np.exp(m) * total_scaled
        self.weights = np.exp(logw - m) / total_scaled
        if c.recovery_w_avg_per_beam:
            # Per-beam geometric mean over the beams the distance filter keeps (all valid
            # beams without it), beam skipping not applied.
            if keep is None:  # an occluded scan, recovery_occluded = "hold"
                return
            if beam_logp is None:
                beam_logp = self._endpoint_values(self.table.logp, self.particles, r, a)
            total = per_beam_average(lw_prev, beam_logp[:, keep])
            # This update's average feeds local resetting; a fit back at w_ref ends a
            # local-resetting episode.
            self.w_last = total
            if total >= self.reference_weight():
                self.n_local_updates = 0
        if total > 0 and np.isfinite(total):
            w_avg = total / len(self.particles) if c.recovery_w_avg_per_sample else total
            self.w_slow, self.w_fast = running_averages(self.w_slow, self.w_fast, w_avg, c)
            w_ref = self.reference_weight()
            low = w_ref > 0 and self.w_fast < c.recovery_ratio_threshold * w_ref
            self.n_low_updates = self.n_low_updates + 1 if low else 0

    def _see_through_scored(
        self, beam_logp: NDArray[np.float32], ranges_m: FloatArray, angles_rad: FloatArray
    ) -> NDArray[np.float32] | None:
        """``beam_logp`` with each see-through reading scored by how far it ends beyond its
        wall, where that is lower (:mod:`.see_through`; :attr:`MCLConfig.see_through_margin_m`,
        only readings at most ``see_through_max_share`` of the particles see through); None
        when that is off or changes nothing."""
        c = self.config
        if c.see_through_margin_m <= 0:
            return None
        depth = wall_depths(
            self.grid, self.particles, ranges_m, angles_rad, self.mount, c.see_through_margin_m
        )
        through = np.isfinite(depth)
        through &= through.mean(axis=0) <= c.see_through_max_share
        if not through.any():
            return None
        lf = self.lf
        score = see_through_logp(np.where(through, depth, np.inf), ranges_m,
                                 c.see_through_margin_m, lf.z_hit, lf.z_rand, lf.sigma_hit,
                                 lf.range_max)  # fmt: skip
        return np.minimum(beam_logp, score.astype(np.float32))

    def _endpoint_values(
        self,
        values: NDArray[np.generic],
        particles: FloatArray,
        ranges_m: FloatArray,
        angles_rad: FloatArray,
    ) -> NDArray[np.generic]:
        """``values`` of the likelihood table at the beams' end points ``(P, B)``."""
        return endpoint_values(values, particles, ranges_m, angles_rad, self.mount, self.grid)

    def _distance_filter_beams(
        self, weights: FloatArray, ranges_m: FloatArray, angles_rad: FloatArray
    ) -> NDArray[np.intp] | None:
        """Indices of the beams that feed the recovery average (and, with
        ``distance_filter_weights``, the weights): all, or with ``recovery_distance_filter_m``
        those not much shorter than the map predicts at the weighted mean particle (Fox et
        al. 1999), if at least ``recovery_min_beam_share`` of them remain; else all
        (``recovery_occluded = "all-beams"``) or None (``hold``: this scan does not feed the
        averages, and the weights take every beam)."""
        all_beams = np.arange(len(ranges_m))
        margin = self.config.recovery_distance_filter_m
        if margin <= 0:
            return all_beams
        mean = weighted_mean_pose(self.particles, weights)[0]
        laser_pose = se2.compose(mean, self.mount)
        expected = expected_ranges(self.grid, laser_pose, angles_rad, self.range_max)
        keep = np.nonzero(~short_readings(ranges_m, expected, margin))[0]
        if len(keep) >= self.config.recovery_min_beam_share * len(ranges_m):
            return keep
        hold = self.config.recovery_occluded == "hold" and self.n_low_updates == 0
        return None if hold else all_beams

    def through_shares(self, poses: FloatArray) -> FloatArray:
        """Per pose ``(N, 3)``, the share of the last scan's valid readings that end more than
        ``recovery_through_margin_m`` beyond the first occupied cell of the map along their
        beam (:attr:`MCLConfig.recovery_through_max_share`); 0 without a scan."""
        r, a = self._last_beams
        if len(r) == 0:
            return np.zeros(len(poses))
        margin = self.config.recovery_through_margin_m
        occupied = self.grid.occupancy == OCCUPIED  # once, not per pose
        out = np.empty(len(poses))
        for k, pose in enumerate(poses):
            laser_pose = se2.compose(pose, self.mount)
            exp = expected_ranges(self.grid, laser_pose, a, self.range_max, occupied)
            out[k] = np.count_nonzero(r > exp + margin) / len(r)
        return out

    def reference_weight(self) -> float:
        """``w_slow``, floored at ``exp(recovery_floor_loglik)`` in per-beam mode."""
        c = self.config
        if c.recovery_w_avg_per_beam and self.w_slow > 0:
            return max(self.w_slow, float(np.exp(c.recovery_floor_loglik)))
        return self.w_slow

    def gate_open(self) -> bool:
        """The global recovery's gate: ``w_fast / w_ref`` stayed below
        ``recovery_ratio_threshold`` for ``recovery_min_updates`` consecutive updates; never
        with both recovery alphas 0 (recovery off, as in nav2's AMCL)."""
        c = self.config
        if c.recovery_alpha_slow == 0.0 and c.recovery_alpha_fast == 0.0:
            # nav2's pf.c: both averages stay at their first value, w_fast / w_slow = 1,
            # no random poses; the per-beam floor must not turn that into a recovery
            return False
        return self.reference_weight() > 0 and self.n_low_updates >= max(1, c.recovery_min_updates)

    def injection_probability(self) -> float:
        """Probability that a resampling draw is a random pose (Table 8.3 line 13): 0 unless
        the gate is open (:meth:`gate_open`) and the random poses go into this set
        (``recovery_global = "inject"``; ``verify`` puts them into a challenger set,
        :mod:`.verified_recovery`)."""
        c = self.config
        if c.recovery_global != "inject" or not self.gate_open():
            return 0.0
        return min(max(0.0, 1.0 - self.w_fast / self.reference_weight()), c.recovery_max_fraction)

    def adopt(self, other: AMCLFilter) -> None:
        """Take over ``other``'s particles (a verified challenger). ``w_slow``, the fit of
        the tracking so far, stays the reference (``w_fast`` restarts at it): were the
        adopted place wrong after all, its lower fit opens the gate again as a kidnapping
        would, instead of becoming the new reference."""
        self.particles = other.particles.copy()
        self.weights = other.weights.copy()
        self.w_fast = self.w_slow
        self.w_last = 0.0
        self.n_low_updates = self.n_local_updates = 0

    def local_probability(self) -> float:
        """Probability that a resampling draw is a pose near the estimate (local resetting,
        :attr:`MCLConfig.recovery_local_ratio`): ``1 - w_last / (ratio * w_ref)``, capped at
        ``recovery_local_max_fraction``; 0 once the global gate counts or after
        ``recovery_local_max_updates`` resets without the fit back at ``w_ref``."""
        c = self.config
        w_ref = self.reference_weight()
        if (
            w_ref <= 0
            or c.recovery_local_ratio <= 0
            or self.w_last <= 0
            or self.n_low_updates > 0
            or self.n_local_updates >= c.recovery_local_max_updates
        ):
            return 0.0
        p = 1.0 - self.w_last / (c.recovery_local_ratio * w_ref)
        return min(max(0.0, p), c.recovery_local_max_fraction)

    def local_poses(self, center: ArrayLike, n: int, rng: np.random.Generator) -> FloatArray:
        """``n`` poses drawn from a normal distribution around ``center`` (local resetting)."""
        c = self.config
        sd = np.array([c.recovery_local_sigma_xy] * 2 + [c.recovery_local_sigma_theta])
        q = np.asarray(center, dtype=np.float64) + rng.standard_normal((n, 3)) * sd
        q[:, 2] = se2.wrap_angle(q[:, 2])
        return q

    def resample(self, rng: np.random.Generator, center: ArrayLike | None = None) -> None:
        """``pf_update_resample``: KLD-sized, low-variance, with random-pose injection; with
        the current estimate as ``center``, also local resetting (:meth:`local_probability`;
        without it, none: e.g. adaptive-memory's filter)."""
        c = self.config
        w_diff = self.injection_probability()
        n_max = c.max_particles
        # Candidate sequence in random draw order to size the set like AMCL's loop: the
        # low-variance draws, shuffled (``order``: what ``rng.permutation`` of the draws
        # would do to them).
        draws = LowVarianceDraws(self.weights, n_max, rng)
        order = rng.permutation(n_max)
        is_rand = rng.random(n_max) < w_diff
        p_loc = self.local_probability() if center is not None else 0.0
        if not is_rand.any() and p_loc <= 0:
            # Nothing new among the candidates: only the draws up to the loop's stop count.
            n = kld_prefix_size_lazy(
                lambda m: bin_keys(self.particles[draws.at(order[:m])], c.kld_cell_m,
                                   c.kld_angle_rad),
                n_max, c.pf_err, c.pf_z, c.min_particles, c.max_particles, c.kld_one_bin,
            )  # fmt: skip
            self._take_resampled(n, None, w_diff, rng)
            return
        cand = self.particles[draws.at(order)]
        if is_rand.any():
            at = np.flatnonzero(is_rand)
            poses = self.random_poses(len(at), rng)
            if c.recovery_through_max_share > 0:
                ok = self.through_shares(poses) <= c.recovery_through_max_share
                is_rand[at[~ok]] = False
                at, poses = at[ok], poses[ok]
            cand[at] = poses
        is_new, is_local = is_rand, np.zeros(n_max, dtype=bool)
        if p_loc > 0:
            is_local = ~is_rand & (rng.random(n_max) < p_loc)
            cand[is_local] = self.local_poses(center, int(is_local.sum()), rng)
            is_new = is_rand | is_local
            self.n_local_updates += 1
        keys = bin_keys(cand, c.kld_cell_m, c.kld_angle_rad)
        n = kld_prefix_size(keys, c.pf_err, c.pf_z, c.min_particles, c.max_particles,
                            c.kld_one_bin)  # fmt: skip
        n_new = int(is_new[:n].sum())
        self.n_random_injected += int(is_rand[:n].sum())
        self.n_local_injected += int(is_local[:n].sum())
        self._take_resampled(n - n_new, cand[:n][is_new[:n]] if n_new else None, w_diff, rng)

    def _take_resampled(
        self, n_drawn: int, new: FloatArray | None, w_diff: float, rng: np.random.Generator
    ) -> None:
        """:meth:`resample`'s new set: ``n_drawn`` low-variance draws of the particles, then
        the ``new`` poses (random and local), all weighted equally; the recovery averages
        forgotten after an injection step (``recovery_reset``)."""
        drawn = self.particles[low_variance_resample(self.weights, n_drawn, rng)]
        self.particles = drawn if new is None else np.concatenate([drawn, new])
        self.weights = np.full(len(self.particles), 1.0 / len(self.particles))
        if w_diff > 0 and self.config.recovery_reset:
            self.reset_recovery()

    def estimate(self) -> tuple[FloatArray, FloatArray]:
        """Mean and covariance of the heaviest cluster (``pf_cluster_stats``)."""
        c = self.config
        p = self.particles
        n_th = int(round(2 * np.pi / c.kld_angle_rad))
        ix = np.floor(p[:, 0] / c.kld_cell_m).astype(np.int64)
        iy = np.floor(p[:, 1] / c.kld_cell_m).astype(np.int64)
        it = np.floor((se2.wrap_angle(p[:, 2]) + np.pi) / c.kld_angle_rad).astype(np.int64) % n_th
        ix -= ix.min()
        iy -= iy.min()
        ny = int(iy.max()) + 3
        key = (ix * ny + iy) * n_th + it
        ukeys, inv = np.unique(key, return_inverse=True)
        if len(ukeys) == 1:
            return weighted_pose_stats(p, self.weights)
        label = bin_clusters(ukeys, ny, n_th)
        plabel = label[inv]
        cw = np.bincount(plabel, weights=self.weights)
        best = plabel == int(np.argmax(cw))
        return weighted_pose_stats(p[best], self.weights[best])

    def mean_beam_loglik(self, pose: ArrayLike, ranges_m: ArrayLike) -> float:
        """Mean per-beam log-likelihood of a scan at ``pose`` (``scan_loglik``)."""
        r, a = self._beams_of(ranges_m)
        if len(r) == 0:
            return float("nan")
        d = self._endpoint_values(self.table.dist, np.asarray(pose, float)[None, :], r, a)
        logp = np.log(beam_likelihoods(d, self.lf))
        return float(np.add.reduce(logp, axis=None) / logp.size)  # np.mean's sum, less overhead


@register_localizer("static-mcl")
class StaticMCL(Localizer, MapUser):
    """AMCL-faithful MCL on a map that never changes (the baseline of every comparison).

    ``config``: ``"tuned"``, ``"tuned-end-points"`` (``tuned`` without the see-through term:
    :data:`TUNED_END_POINTS`), ``"nav2-default"`` or ``"walls-only"`` (``tuned`` for a map that
    lacks the furniture, e.g. the walls-only prior: :data:`WALLS_ONLY`); ``map_source``: where
    the map comes from, a :class:`~dynmap_sim.agent.maps.map_source.MapSource` or its name:
    ``"first-run"`` (built by static SLAM on the experiment's first run) or ``"prior-walls"``
    (the walls the prior grants); ``overrides``: individual :class:`MCLConfig` fields to change;
    ``global_localization``: start every run from particles spread over the free space;
    ``mapper_params``: fields of the first-run SLAM's
    :class:`~dynmap_sim.agent.mapping.first_run.FirstRunConfig` (flat names).
    """

    diagnostics = (
        Diagnostic(
            "scan_loglik",
            "float64",
            doc="mean per-beam log-likelihood of the scan at the estimate (likelihood field)",
        ),
        Diagnostic("lambda_min", "float64", doc="smallest eigenvalue of the inverse covariance"),
    )
    #: The reported covariance of ``_cov`` (:func:`reported_covariance`; a class default,
    #: so that a localizer pickled before it existed resumes).
    _cov_reported: CovReport | None = None

    def __init__(
        self,
        laser: LaserSpec,
        rng: np.random.Generator,
        config: str = "tuned",
        map_source: str | MapSource = "first-run",
        overrides: dict[str, Any] | None = None,
        global_localization: bool = False,
        mapper_params: dict[str, Any] | None = None,
        **params: Any,
    ) -> None:
        super().__init__(laser, rng, **params)
        if config not in CONFIGS:
            raise ValueError(f"static-mcl: unknown config {config!r}; known: {sorted(CONFIGS)}")
        cfg = CONFIGS[config]
        if overrides:
            unknown = set(overrides) - set(asdict(cfg))
            if unknown:
                raise ValueError(f"static-mcl: unknown overrides {sorted(unknown)}")
            cfg = replace(cfg, **overrides)
        self.config_name = config
        self.config = cfg
        if isinstance(map_source, MapSource):
            if mapper_params:
                raise ValueError("static-mcl: mapper_params go with a map_source name only")
            self.map_source = map_source
        else:
            try:
                self.map_source = make_map_source(map_source, laser, mapper_params)
            except ValueError as exc:
                raise ValueError(f"static-mcl: {exc}") from None
        if not isinstance(global_localization, bool):
            raise TypeError(
                "static-mcl: global_localization must be true or false, "
                f"got {global_localization!r}"
            )
        self.global_localization = global_localization
        self.filter: AMCLFilter | None = None
        self._odom_at_update: FloatArray | None = None
        self._est_at_update = np.zeros(3)
        self._cov = np.eye(3)
        self._n_updates = 0
        #: The challenger of ``recovery_global = "verify"`` (:mod:`.verified_recovery`).
        self.recovery = VerifiedRecovery()

    # -- map -----------------------------------------------------------------------------
    @property
    def needs_prior_walls(self) -> bool:
        """Its map is still to be made from the prior's walls (``map_source =
        "prior-walls"``): every run's prior must grant them (a scenario checks this when it
        is loaded, before anything runs)."""
        return isinstance(self.map_source, PriorWallsMap) and not self.map_source.ready

    @property
    def grid(self) -> OccupancyGrid | None:
        """The (fixed) map, once the map source has it."""
        return self.map_source.grid

    def set_map(self, grid: OccupancyGrid) -> None:
        """Use ``grid`` as the (fixed) map
        (:class:`~dynmap_sim.agent.localization.localizer.MapUser`)."""
        self.map_source.set_grid(grid)
        self.filter = AMCLFilter(grid, self.laser, self.config)

    def _use_map_when_ready(self) -> None:
        """The filter on the map source's map, once it is there (made once)."""
        if self.filter is None and self.map_source.grid is not None:
            self.filter = AMCLFilter(self.map_source.grid, self.laser, self.config)

    def begin_run(self, prior: Prior) -> None:
        self._odom_at_update = None
        self._n_updates = 0
        self.recovery.reset()
        self.map_source.begin_run(prior)
        if self.map_source.building:  # the map source reports its estimates meanwhile
            return
        self._use_map_when_ready()
        assert self.filter is not None
        if prior.initial_pose is None or self.global_localization:
            self.filter.init_uniform(self.rng)
        else:
            cov = (
                np.asarray(prior.initial_pose_cov, float)
                if prior.initial_pose_cov is not None
                else np.diag([self.config.init_sigma_xy**2] * 2 + [self.config.init_sigma_theta**2])
            )
            self.filter.init_gaussian(prior.initial_pose, cov, self.rng)
        self._est_at_update, self._cov = self.filter.estimate()

    def end_run(self) -> None:
        self.map_source.end_run()
        self._use_map_when_ready()

    # -- filtering -----------------------------------------------------------------------
    def update(self, odom: Odometry, scan: Scan) -> PoseEstimate:
        pose_odom = np.asarray(odom.pose, dtype=np.float64)
        if self.map_source.building:
            est = self.map_source.update(odom, scan)
            est.extras["lambda_min"] = information_lambda_min(est.cov)
            return est
        f = self.filter
        if f is None:
            raise RuntimeError("static-mcl: update() before begin_run()")
        c = self.config
        do_update = False
        if self._odom_at_update is None:
            do_update = True  # AMCL: the first scan after init is always integrated
        else:
            delta = pose_odom - self._odom_at_update
            delta[2] = se2.wrap_angle(delta[2])
            if (
                abs(delta[0]) > c.update_min_d
                or abs(delta[1]) > c.update_min_d
                or (abs(delta[2]) > c.update_min_a)
            ):
                do_update = True
                f.predict(self._odom_at_update, pose_odom, self.rng)
        if do_update:
            f.correct(scan.ranges_m)
            self._n_updates += 1
            # The estimate is taken from the weighted set, before resampling: after it, the
            # random poses just injected for recovery would weigh as much as the others.
            self._est_at_update, self._cov = f.estimate()
            if c.recovery_global == "verify" and self.recovery.step(
                f, self._est_at_update, scan.ranges_m, self._odom_at_update, pose_odom, self.rng
            ):
                self._est_at_update, self._cov = f.estimate()
            if self._n_updates % max(1, c.resample_interval) == 0:
                f.resample(self.rng, center=self._est_at_update)
            self._odom_at_update = pose_odom.copy()
        mean = se2.compose(self._est_at_update, se2.between(self._odom_at_update, pose_odom))
        self._cov_reported = reported_covariance(self._cov, self._cov_reported)
        cov, lambda_min = self._cov_reported[1].copy(), self._cov_reported[2]
        extras = {
            "scan_loglik": f.mean_beam_loglik(mean, scan.ranges_m),
            "lambda_min": lambda_min,
            "n_particles": len(f.particles),
        }
        return PoseEstimate(mean=mean, cov=cov, extras=extras)
