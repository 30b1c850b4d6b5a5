"""The first run's SLAM front end: scan-to-map ICP against the recent keyframes.

Biber & Duckett §4: "an initial map is built from the first run ... by a classical static
SLAM algorithm ... based on scan matching. The output is a set of selected laser scans with
relations between them" -- the *keyframes* kept here. Each scan is matched by point-to-line
ICP (:func:`.scan_matcher.match_scan`, Huber loss) against a local map made of the last
keyframes, seeded by odometry, with an odometry prior (B&D eq. 9 with a fixed κ = 1) whose
covariance grows with the motion. Where a correlative search around the odometry prediction
finds a clearly better pose (real wheel odometry that errs by degrees in a step), ICP starts
from there instead, and keeps that result only if it fits the local map better than ICP from
the prediction (``seed_window``, ``seed_verify``). Readings in space that a scan a few steps
earlier saw free (walking people) are left out (:func:`.scan_points.free_space_violations`);
a new keyframe is taken every ``keyframe_dist_m`` / ``keyframe_angle_rad``. Loop closure and
the pose graph over the keyframes are :mod:`.loop_closure`; :mod:`.first_run` composes the
two.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Annotated

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from dynmap_sim import se2
from dynmap_sim.agent.grid import points_on_segments
from dynmap_sim.agent.mapping.correlative_matcher import (
    LikelihoodTable,
    angular_step,
    correlative_match,
)
from dynmap_sim.agent.mapping.scan_matcher import MatchResult, PointMap, match_scan
from dynmap_sim.agent.mapping.scan_points import (
    BeamDirections,
    free_space_violations,
    range_discontinuities,
    range_weights,
    scan_points_base,
    voxel_downsample,
)
from dynmap_sim.agent.params import (
    AsTuple,
    Int,
    NonNegative,
    Positive,
    PositiveInt,
    params_dataclass,
)
from dynmap_sim.types import LaserSpec, Odometry, PoseEstimate, Scan

FloatArray = NDArray[np.float64]

#: Accepted values of :attr:`KeyframeSLAMConfig.drop_edges`.
DROP_EDGES = ("none", "isolated", "all")


@params_dataclass()
class KeyframeSLAMConfig:
    """Parameters of the scan-to-map front end (lengths in m, angles in rad)."""

    #: A new keyframe once the robot moved this far from the last one [m]: close enough that
    #: consecutive keyframes share most of their view (URG-04LX: 5.6 m range).
    keyframe_dist_m: float = 0.3
    #: ... or turned this much [rad] (~17 degrees).
    keyframe_angle_rad: float = 0.3
    #: The local map a scan is matched against: the points of the last this many keyframes
    #: (~3.6 m of path at the default spacing): recent, so hardly drifted.
    local_map_keyframes: Int = 12
    #: ... plus every keyframe within this distance [m] of the newest one (0: none), when no
    #: walls anchor the front end. Off: without an anchor, older keyframes nearby carry the
    #: drift gathered since, and ICP would follow it.
    local_map_radius_m: float = 0.0
    #: The same radius [m] when the prior's walls anchor the front end (``anchor_walls``
    #: with walls granted). The older keyframes were then held to the walls themselves, so
    #: their drift is bounded, and they bring back what the robot saw of this place before:
    #: along an aisle whose walls lie out of range, the last keyframes alone let the heading
    #: drift and a second pass come back beside the first. 3 m: a keyframe that near shares
    #: most of the view of a 5.6 m scan.
    anchored_local_map_radius_m: float = 3.0
    #: Keyframe points and the local map are thinned to one point per square cell of this
    #: side [m] (3 cm: a few times the URG-04LX's 1 cm range noise).
    voxel_m: float = 0.03
    #: The local map keeps each cell's centroid (averages the range noise; ``False``: the
    #: first, least drifted point).
    voxel_mean: bool = True
    #: Keyframe points farther than this from the robot [m] are left out (100: all).
    map_max_range_m: float = 100.0
    #: Neighbours that fit a point's line in point-to-line ICP (:class:`.scan_matcher.PointMap`).
    k_normal: Int = 6
    #: ICP correspondence gate [m]: the odometry prediction is within a few cm of the truth.
    max_correspondence_m: float = 0.3
    #: Huber threshold of the ICP residuals [m]: twice the range noise (1 cm).
    huber_m: float = 0.02
    #: The scan's information in ICP is divided by this (>= 1): neighbouring residuals are
    #: not independent (Censi 2007: ICP's covariance is optimistic), so that the odometry
    #: prior keeps its say where the scan constrains the pose only weakly.
    info_inflation: float = 5.0
    #: Weight points by their range noise (:func:`.scan_points.range_weights`); off: the
    #: Huber loss already tames far points.
    range_weighting: bool = False
    #: Add the odometry prior ``(x - x̂⁻)ᵀ C_O⁻¹ (x - x̂⁻)`` (B&D eq. 9 with κ = 1) to ICP: keeps
    #: matches along featureless corridors where odometry says.
    odom_prior: bool = True
    #: ``C_O`` of one odometry increment of length ``d`` [m] and turn ``a`` [rad], as standard
    #: deviations ``(s_xy0, k_xy_d, k_xy_a, s_th0, k_th_a, k_th_d)``:
    #: ``sigma_xy = s_xy0 + k_xy_d d + k_xy_a a`` [m], ``sigma_th = s_th0 + k_th_a a + k_th_d d``
    #: [rad]. Tight (5 % of the distance): the wheel odometry drifts 1-2 %. The constant
    #: ``s_xy0`` is paid on every scan and sets how loose the prior is per metre at a given
    #: scan rate: 1 mm keeps the scan-to-map ICP's small forward bias from stretching long
    #: corridors (measurements: docs/tuning/slam.md).
    odom_sigma: Annotated[tuple[float, float, float, float, float, float], AsTuple] = (
        0.001,
        0.05,
        0.01,
        0.002,
        0.05,
        0.02,
    )
    #: Leave beams at range discontinuities (mixed pixels) out of matching:
    #: ``"none"``, ``"isolated"`` (beams that jump from both neighbours) or ``"all"``
    #: (:func:`.scan_points.range_discontinuities`). Off: it helped one simulated world and
    #: hurt another (docs/tuning/slam.md).
    drop_edges: str = "none"
    #: Leave out readings in space that the scans this many steps earlier saw free (walking
    #: people; :func:`.scan_points.free_space_violations`); ``()`` off. 0.3 s and 0.8 s at
    #: 10 Hz: a walking leg has moved on, the robot has hardly moved.
    dynamic_filter_lags: Annotated[tuple[Int, ...], AsTuple] = (3, 8)
    #: Seed ICP by a correlative search around the odometry prediction (Olson 2009; the
    #: real-time correlative matcher of Hess et al. 2016 §IV, whose result is then the prior
    #: of the fine matcher): half-windows ``(xy [m], theta [rad])``, each widened by the
    #: odometry step itself (a step odometry reports late, in one jump, is not trusted),
    #: the translation rounded to whole cells of the seed's grid; ``(0, 0)`` off. Real
    #: wheel odometry errs by up to 20 degrees in a step, beyond ICP's 0.3 m basin; in
    #: translation a slipping wheel over-reports at most the step it reports, so only the
    #: step is searched (a robot crawling or standing is searched in heading alone): a
    #: wider translation window found the grid's aliases along aisles between shelf rows,
    #: 0.3 m jumps that nothing pulled back. ``seed_verify`` keeps near-exact odometry from
    #: being overruled by the seed's grid (docs/tuning/slam.md).
    seed_window: Annotated[tuple[float, float], AsTuple] = (0.0, 0.4)
    #: > 0: the seed's heading half-window is this many times the 95th percentile of the
    #: heading corrections ``|theta - theta_pred|`` of the last ``seed_theta_scans`` accepted
    #: scans, at most ``seed_window[1]`` (then widened by the step's turn as above): the
    #: window follows the odometry's own heading error, measured on the log, instead of
    #: one bound for every robot. Wheel odometry that errs by degrees a step keeps the wide
    #: search; odometry good to a fraction of a degree is not overruled by a grid alias
    #: degrees away, which a view of few or noisy points can score higher. 4: the 95th
    #: percentile is 2 sigma of a Gaussian error, so the window holds 8 sigma, and heavy
    #: tails (slips) lift the percentile itself. 0: always ``seed_window[1]``.
    seed_theta_gain: NonNegative = 4.0
    #: ... over this many accepted scans (fewer: ``seed_window[1]``, nothing is known yet
    #: of the odometry): 25 corrections lie beyond the percentile, enough for a stable
    #: estimate, and a change of floor is followed within a minute of a 10 Hz scan.
    seed_theta_scans: PositiveInt = 500
    #: The seed's likelihood grid: cell side and Gaussian width [m], and the range [m]
    #: within which map and scan points take part.
    seed_resolution_m: float = 0.1
    seed_range_m: float = 15.0
    #: The seed replaces the odometry prediction only if its score (mean likelihood per
    #: point) is at least this much higher than the prediction's.
    seed_min_gain: float = 0.05
    #: ... than the best score within this many grid cells (``seed_resolution_m``) and
    #: angular steps (:func:`.correlative_matcher.angular_step`) of the prediction; 0: the
    #: prediction's own score. The search's grid is its resolution (Olson 2009 §IV-A): a
    #: pose one cell or one step off a correct prediction can score higher by aliasing alone
    #: (points crossing cell borders), and then the seed moves ICP off a right answer.
    #: With 1, the seed is taken only when it finds a distinctly different pose; not the
    #: default: it also drops the small real corrections, which ``seed_verify`` sorts out.
    seed_compare_steps: Int = 0
    #: When the seed replaces the prediction, the odometry prior centred on it gets the
    #: seed's own quantization variance added (uniform over a cell and an angular step:
    #: ``res**2 / 12``, ``step**2 / 12``), so that ICP may refine within the seed's
    #: resolution. Off: the prior keeps odometry's covariance (mm over a 10 cm grid), as
    #: if the seed were exact, and holds ICP on the grid (Hess et al. 2016 §IV weigh the
    #: fine matcher's prior against the scan instead). Not the default: ``seed_verify``
    #: decides better between the seed and the prediction.
    seed_prior_quantization: bool = False
    #: When the seed replaces the prediction, also run ICP from the prediction (with the
    #: odometry prior) and keep the seed's result only if its point-to-line RMS residual is
    #: lower by more than the RMS's standard error, ``rmse / sqrt(2 n)`` with ``n`` the
    #: matched points divided by ``info_inflation`` (the residuals are not independent,
    #: Censi 2007): two local optima of ICP compared under one score, as Karto/slam_toolbox
    #: check a correlative match's response before trusting it. The seed's score is its
    #: 10 cm grid's (aliasing, see ``seed_compare_steps``), ICP's is the continuous
    #: point-to-line fit, which tells the right optimum from a grid alias.
    seed_verify: bool = True
    #: Match every scan against the walls the prior grants too (when it grants them), as
    #: localization in an architectural floor plan does (Boniardi et al. 2017): walls do not
    #: drift, so the front end's drift stays bounded where it sees one, instead of growing
    #: with the path until a loop closes (B&D §4 map without a plan; this is off without
    #: one). The furniture in front of walls is in the keyframes, nearer than the wall. An
    #: anchored first run's back end ties the keyframes to the walls instead of closing
    #: loops (:attr:`.loop_closure.LoopClosureConfig.wall_factors`).
    anchor_walls: bool = True
    #: Only the walls the local map has seen take part: a wall point counts when a keyframe
    #: point lies within this distance [m] of it. A wall hidden behind furniture (shelves
    #: and desks against it, in view of a scan where the keyframes do not yet hold them)
    #: would otherwise pull those readings onto itself; 0.1 m is ten times the range noise
    #: and more than the front end drifts between two keyframes.
    anchor_seen_m: Positive = 0.1

    def __post_init__(self) -> None:
        if self.drop_edges not in DROP_EDGES:
            raise ValueError(f"drop_edges must be none, isolated or all, got {self.drop_edges!r}")


@dataclass(frozen=True)
class Keyframe:
    """A keyframe: robot pose ``(3,)`` in the map frame and its raw scan (REP-117 ranges)."""

    pose: FloatArray
    ranges_m: NDArray[np.float32]
    scan_index: int = 0


class KeyframeSLAM:
    """Online scan-to-local-map ICP with keyframes (the first run's front end)."""

    def __init__(
        self,
        laser: LaserSpec,
        initial_pose: ArrayLike,
        config: KeyframeSLAMConfig,
        walls: FloatArray | None = None,
    ) -> None:
        self.laser = laser
        self.config = config
        #: The prior's wall segments ``(N, 4)`` when they anchor the front end
        #: (``anchor_walls``), else none; and as map-frame points, matched with the keyframes.
        self.wall_segments = (
            np.asarray(walls, dtype=np.float64).reshape(-1, 4)
            if config.anchor_walls and walls is not None
            else np.zeros((0, 4))
        )
        self.wall_points = (
            points_on_segments(self.wall_segments, config.voxel_m)
            if len(self.wall_segments)
            else np.zeros((0, 2))
        )
        self._beams = BeamDirections(laser)
        self.initial_pose = np.asarray(initial_pose, dtype=np.float64).reshape(3).copy()
        self._kf_maps: dict[int, PointMap | None] | None = None
        self._history: list[tuple[FloatArray, NDArray[np.float32]]] = []  # recent (pose, scan)
        self.n_dynamic = 0
        self.pose = self.initial_pose.copy()
        self.cov = np.diag([1e-6, 1e-6, 1e-6])
        self._last_odom: FloatArray | None = None
        self.keyframes: list[Keyframe] = []
        #: base-frame points of each keyframe (thinned, dynamic readings left out)
        self.keyframe_points: list[FloatArray] = []
        #: each keyframe's pose in the previous one's frame as the front end measured it
        #: (the sequential edges of a pose graph, whatever later moves the keyframes)
        self.keyframe_steps: list[FloatArray] = []
        self._seq_cov: list[FloatArray] = []  # front-end covariance at each keyframe
        self._ref: list[tuple[int, FloatArray]] = []  # per scan: (keyframe, pose in it)
        self.stamps_s: list[float] = []
        self._local: PointMap | None = None
        self._seed_table: LikelihoodTable | None = None
        self.n_scans = 0
        self.n_rejected = 0
        #: scans on which the correlative seed replaced the odometry prediction
        self.n_seeded = 0
        #: ... and on which ICP from the prediction then fit better (``seed_verify``)
        self.n_seed_refuted = 0
        #: heading corrections [rad] of the last accepted scans (``seed_theta_gain``)
        self._corrections: deque[float] = deque(maxlen=config.seed_theta_scans)

    # -- keyframes -----------------------------------------------------------------------
    def _add_keyframe(self, ranges: NDArray[np.float32], pts: FloatArray) -> None:
        c = self.config
        if self.keyframes:
            self.keyframe_steps.append(se2.between(self.keyframes[-1].pose, self.pose))
        self.keyframes.append(
            Keyframe(self.pose.copy(), np.asarray(ranges, np.float32).copy(), self.n_scans)
        )
        near = np.hypot(pts[:, 0], pts[:, 1]) <= c.map_max_range_m
        self.keyframe_points.append(voxel_downsample(pts[near], c.voxel_m))
        self._seq_cov.append(self.cov.copy())
        self._rebuild_local_map()

    def move_keyframes(self, poses: FloatArray) -> None:
        """Put the keyframes at ``poses`` ``(K, 3)`` (a pose graph's answer); the current pose
        and the recent scans' poses move rigidly with the newest keyframe, and the local map
        is made again from the moved keyframes."""
        last = self.keyframes[-1].pose
        shift = se2.compose(poses[-1], se2.inverse(last))  # map-frame correction
        self.keyframes = [
            Keyframe(np.asarray(p, dtype=np.float64).copy(), k.ranges_m, k.scan_index)
            for p, k in zip(poses, self.keyframes, strict=True)
        ]
        self.pose = se2.compose(shift, self.pose)
        self._history = [(se2.compose(shift, p), r) for p, r in self._history]
        self._rebuild_local_map()

    def local_keyframes(self) -> list[int]:
        """Indices of the keyframes the local map holds, oldest first: the last
        ``local_map_keyframes`` and those within the radius of the newest one
        (``anchored_local_map_radius_m`` when walls anchor the front end, else
        ``local_map_radius_m``)."""
        c = self.config
        n = len(self.keyframes)
        chosen = set(range(max(0, n - c.local_map_keyframes), n))
        radius = c.anchored_local_map_radius_m if len(self.wall_points) else c.local_map_radius_m
        if radius > 0 and n:
            kp = np.array([k.pose[:2] for k in self.keyframes])
            chosen |= set(np.nonzero(np.hypot(*(kp - kp[-1]).T) < radius)[0].tolist())
        return sorted(chosen)

    def _rebuild_local_map(self) -> None:
        c = self.config
        # Oldest first: the voxel filter keeps the first point, i.e. the least drifted one.
        sel = self.local_keyframes()
        pts = np.concatenate(
            [se2.transform_points(self.keyframes[k].pose, self.keyframe_points[k]) for k in sel]
        )
        pts = voxel_downsample(pts, c.voxel_m, mean=c.voxel_mean)
        if len(self.wall_points):
            here = self.keyframes[-1].pose[:2]
            reach = self.laser.range_max_m + c.max_correspondence_m
            walls = self.wall_points[np.hypot(*(self.wall_points - here).T) <= reach]
            if len(walls):
                gap, _ = cKDTree(pts).query(walls, distance_upper_bound=c.anchor_seen_m)
                pts = np.concatenate([pts, walls[np.isfinite(gap)]])
        self._local = PointMap(pts, k_normal=c.k_normal) if len(pts) >= 3 else None
        self._seed_table = None
        if c.seed_window[0] > 0 or c.seed_window[1] > 0:
            here = self.keyframes[-1].pose[:2]
            near = pts[np.hypot(*(pts - here).T) <= c.seed_range_m]
            if len(near) >= 20:
                self._seed_table = LikelihoodTable(
                    voxel_downsample(near, c.seed_resolution_m),
                    c.seed_resolution_m,
                    c.seed_resolution_m,
                    margin_m=c.seed_window[0] + 1.0,
                )

    def keyframe_map(self, k: int) -> PointMap | None:
        """Point map of keyframe ``k`` in its own frame (built once, cached; None below 20
        points)."""
        if self._kf_maps is None:
            self._kf_maps = {}
        if k not in self._kf_maps:
            pts = self.keyframe_points[k]
            self._kf_maps[k] = (
                PointMap(pts, k_normal=self.config.k_normal) if len(pts) >= 20 else None
            )
        return self._kf_maps[k]

    def trajectory(self, keyframe_poses: FloatArray) -> FloatArray:
        """Every scan's pose ``(n_scans, 3)``, re-attached rigidly to its reference keyframe
        at ``keyframe_poses`` (e.g. after the pose graph moved them)."""
        return np.array([se2.compose(keyframe_poses[k], rel) for k, rel in self._ref])

    # -- matching ------------------------------------------------------------------------
    def _dynamic_mask(self, ranges: NDArray[np.float32], pose: FloatArray) -> NDArray[np.bool_]:
        """Readings in space free in the scans ``dynamic_filter_lags`` steps ago."""
        dyn = np.zeros(len(ranges), dtype=bool)
        for lag in self.config.dynamic_filter_lags:
            if len(self._history) >= lag:
                ref_pose, ref_ranges = self._history[-lag]
                dyn |= free_space_violations(self.laser, ranges, pose, ref_ranges, ref_pose)
        return dyn

    def seed_theta_window(self) -> float:
        """The seed's heading half-window [rad] before the step's turn is added
        (:attr:`KeyframeSLAMConfig.seed_theta_gain`)."""
        c = self.config
        if c.seed_theta_gain <= 0 or len(self._corrections) < self._corrections.maxlen:
            return c.seed_window[1]
        q95 = float(np.percentile(np.fromiter(self._corrections, float), 95.0))
        return min(c.seed_window[1], c.seed_theta_gain * q95)

    def _seed(
        self, sub: FloatArray, pred: FloatArray, d: float, a: float, q: FloatArray
    ) -> tuple[FloatArray, FloatArray, bool]:
        """ICP's start and prior ``(pose, covariance, seeded)``: the odometry prediction
        ``pred`` with its covariance ``q``, or the correlative seed when it finds a clearly
        better pose (:attr:`KeyframeSLAMConfig.seed_window`); ``d``, ``a``: the odometry
        step."""
        c = self.config
        if self._seed_table is None:
            return pred, q, False
        near = sub[np.hypot(sub[:, 0], sub[:, 1]) <= c.seed_range_m]
        if len(near) < 20:
            return pred, q, False
        thin = voxel_downsample(near, c.seed_resolution_m)
        step = angular_step(thin, c.seed_resolution_m)
        found = correlative_match(
            thin,
            self._seed_table,
            pred,
            window_xy_m=c.seed_resolution_m
            * math.floor((c.seed_window[0] + d) / c.seed_resolution_m + 0.5),
            window_theta_rad=self.seed_theta_window() + a,
            theta_step_rad=step,
        )
        at_pred = correlative_match(
            thin,
            self._seed_table,
            pred,
            window_xy_m=c.seed_compare_steps * c.seed_resolution_m,
            window_theta_rad=c.seed_compare_steps * step,
            theta_step_rad=step,
        )
        # Move off odometry only for a clearly better fit (Karto's response test): an
        # ambiguous view (corridor, turn in place) keeps odometry.
        if found.score < at_pred.score + c.seed_min_gain:
            return pred, q, False
        self.n_seeded += 1
        if c.seed_prior_quantization:
            cell = np.array([c.seed_resolution_m, c.seed_resolution_m, step])
            return found.pose, q + np.diag(cell**2 / 12.0), True
        return found.pose, q, True

    def _icp(self, sub: FloatArray, start: FloatArray, q: FloatArray) -> MatchResult:
        """Scan-to-local-map ICP of ``sub`` from ``start``, with the prior ``(start, q)``."""
        c = self.config
        assert self._local is not None
        return match_scan(
            sub,
            self._local,
            start,
            prior_mean=start,
            prior_info=np.linalg.inv(q) if c.odom_prior else None,
            max_correspondence_m=c.max_correspondence_m,
            max_iterations=20,
            weights=range_weights(sub) if c.range_weighting else None,
            info_inflation=c.info_inflation,
            huber_m=c.huber_m,
        )

    def update(self, odom: Odometry, scan: Scan) -> PoseEstimate:
        """Fuse one odometry reading and scan; return the front end's pose estimate."""
        c = self.config
        opose = np.asarray(odom.pose, dtype=np.float64)
        ranges = np.asarray(scan.ranges_m, dtype=np.float32)
        if self._last_odom is None:
            self._last_odom = opose.copy()
            first = ranges
            if c.drop_edges != "none":
                first = np.where(
                    range_discontinuities(ranges, isolated_only=c.drop_edges == "isolated"),
                    np.nan,
                    ranges,
                )
            self._add_keyframe(ranges, scan_points_base(self.laser, first, self._beams))
        else:
            delta = se2.between(self._last_odom, opose)
            self._last_odom = opose.copy()
            pred = se2.compose(self.pose, delta)
            dyn = self._dynamic_mask(ranges, pred)
            self.n_dynamic += int(dyn.sum())
            if c.drop_edges != "none":
                dyn |= range_discontinuities(ranges, isolated_only=c.drop_edges == "isolated")
            pts = scan_points_base(self.laser, np.where(dyn, np.nan, ranges), self._beams)
            d = float(np.hypot(delta[0], delta[1]))
            a = abs(float(delta[2]))
            sig_xy = c.odom_sigma[0] + c.odom_sigma[1] * d + c.odom_sigma[2] * a
            sig_th = c.odom_sigma[3] + c.odom_sigma[4] * a + c.odom_sigma[5] * d
            q = np.diag([sig_xy**2, sig_xy**2, sig_th**2])
            accepted = False
            if self._local is not None and len(pts) >= 20:
                sub = pts[:: max(1, len(pts) // 400)]
                seed, q_seed, seeded = self._seed(sub, pred, d, a, q)
                res = self._icp(sub, seed, q_seed)
                if seeded and c.seed_verify:
                    # Keep the seed's result only if it fits the local map better than ICP
                    # from the prediction, by more than the RMS residual's standard error
                    # (rmse / sqrt(2 n) for n independent residuals; n / info_inflation of
                    # them are, as in ICP's covariance).
                    alt = self._icp(sub, pred, q)
                    n_indep = max(alt.n_matched, 1) / max(c.info_inflation, 1.0)
                    margin = 1.0 - 1.0 / np.sqrt(2.0 * n_indep)
                    if not res.rmse_m < alt.rmse_m * margin:
                        res = alt
                        self.n_seed_refuted += 1
                if res.n_matched >= max(15, 0.3 * len(sub)) and res.rmse_m < 0.08:
                    self.pose = res.pose
                    self.cov = res.cov
                    accepted = True
                    self._corrections.append(float(abs(se2.wrap_angle(res.pose[2] - pred[2]))))
            if not accepted:
                self.n_rejected += 1
                self.pose = pred
                self.cov = self.cov + q
            kf = self.keyframes[-1].pose
            rel = se2.between(kf, self.pose)
            if np.hypot(rel[0], rel[1]) > c.keyframe_dist_m or abs(rel[2]) > c.keyframe_angle_rad:
                self._add_keyframe(ranges, pts)
        if c.dynamic_filter_lags:
            self._history.append((self.pose.copy(), ranges))
            del self._history[: -max(c.dynamic_filter_lags)]
        kf_idx = len(self.keyframes) - 1
        self._ref.append((kf_idx, se2.between(self.keyframes[kf_idx].pose, self.pose)))
        self.stamps_s.append(float(scan.stamp_s))
        self.n_scans += 1
        return PoseEstimate(mean=self.pose.copy(), cov=self.cov.copy())
