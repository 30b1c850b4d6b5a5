"""Static SLAM of the first run: scan-matching front end, loop closure, pose-graph back end.

Biber & Duckett §4: "an initial map is built from the first run ... by a classical static
SLAM algorithm ... based on scan matching". This is that algorithm:

* **front end** (online, :meth:`FirstRunMapper.update`): each scan is matched by
  point-to-line ICP (:mod:`.scan_matcher`, Huber 2 cm) against a local map made of the last
  keyframes, seeded by odometry, with an odometry prior (B&D eq. 9) that grows with the
  motion; readings in space that a scan 3 or 8 steps earlier saw free (walking people) are
  left out (:func:`free_space_violations`); a new keyframe is taken every
  ``keyframe_dist_m`` / ``keyframe_angle_rad``;
* **loop closure** (:meth:`FirstRunMapper.finish`): first, drift-tolerant closures -- for
  keyframes far apart in sequence, a correlative search (:mod:`.correlative_matcher`,
  Olson 2009) whose window grows with the path length between them, verified by ICP, a
  conditioning test and a consistency vote -- are optimized by plain least squares; then
  keyframes near each other in that estimate are matched by ICP; a match is accepted only
  if it converges with a small residual and a high inlier fraction;
* **back end**: the keyframe pose graph (sequential + loop edges) is optimized by
  :func:`.pose_graph.optimize_pose_graph`, anchored at the first keyframe so that the map
  frame is the frame of the initial pose the prior grants;
* the optimized keyframe scans are rendered into a 5 cm
  :class:`~dynmap_sim.agent.grid.OccupancyGrid`, and every scan's pose is re-attached
  rigidly to its reference keyframe.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim import se2
from dynmap_sim.agent.grid import OccupancyGrid
from dynmap_sim.agent.mapping.correlative_matcher import LikelihoodTable, correlative_match
from dynmap_sim.agent.mapping.pose_graph import Edge, optimize_pose_graph
from dynmap_sim.agent.mapping.scan_matcher import MatchResult, PointMap, match_scan
from dynmap_sim.types import LaserSpec, Odometry, PoseEstimate, Scan

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Keyframe:
    """A keyframe: robot pose ``(3,)`` in the map frame and its raw scan (REP-117 ranges)."""

    pose: FloatArray
    ranges_m: NDArray[np.float32]
    scan_index: int = 0


@dataclass
class StaticMap:
    """The first run's map: every scan's pose, the grid, and the keyframes (optimized)."""

    trajectory: FloatArray
    grid: OccupancyGrid
    keyframes: list[Keyframe]
    stamps_s: FloatArray = field(default_factory=lambda: np.zeros(0))
    n_loop_closures: int = 0


class BeamDirections:
    """Cosines and sines of a laser's beam angles, computed once for many scans."""

    def __init__(self, laser: LaserSpec) -> None:
        angles = laser.angles()
        self.laser = laser
        self.cos = np.cos(angles)
        self.sin = np.sin(angles)


def scan_points_base(
    laser: LaserSpec, ranges_m: ArrayLike, beams: BeamDirections | None = None
) -> FloatArray:
    """Valid readings of a scan as points ``(N, 2)`` in the robot (``base_link``) frame.

    ``beams`` (the laser's :class:`BeamDirections`, optional) saves recomputing the beam
    directions for every scan; the points are the same.
    """
    r = np.asarray(ranges_m, dtype=np.float64)
    ok = np.isfinite(r) & (r >= laser.range_min_m) & (r < laser.range_max_m)
    if beams is None:
        pts = se2.scan_to_points(np.where(ok, r, np.nan), laser.angles())
    else:
        rr = r[ok]
        pts = np.empty((len(rr), 2))
        np.multiply(rr, beams.cos[ok], out=pts[:, 0])
        np.multiply(rr, beams.sin[ok], out=pts[:, 1])
    return se2.transform_points(np.asarray(laser.mount_pose, dtype=np.float64), pts)


def range_discontinuities(
    ranges_m: ArrayLike, jump_m: float = 0.1, jump_rel: float = 0.03, isolated_only: bool = False
) -> NDArray[np.bool_]:
    """Beams whose range jumps from a neighbour's by more than ``jump_m + jump_rel * r``.

    At a depth edge the laser spot straddles two surfaces and may read a range in between
    (a *mixed pixel*, cf. the lidar model's ``p_mixed``); such points lie on no surface and
    pull ICP. Dropping every beam next to a jump removes them (and the edge beams proper,
    a small loss); ``isolated_only`` drops only beams that jump from *both* neighbours
    (isolated points: most mixed pixels and spurious short returns). Non-finite readings
    count as jumps. Returns ``(n_beams,)``.
    """
    r = np.asarray(ranges_m, dtype=np.float64)
    fin = np.where(np.isfinite(r), r, 1e9)
    gap = np.abs(np.diff(fin)) > jump_m + jump_rel * np.minimum(fin[1:], fin[:-1])
    left = np.concatenate([[False], gap])  # a jump to the previous beam
    right = np.concatenate([gap, [False]])
    return (left & right) if isolated_only else (left | right)


def free_space_violations(
    laser: LaserSpec,
    ranges_m: NDArray[np.float32],
    pose: FloatArray,
    ref_ranges_m: NDArray[np.float32],
    ref_pose: FloatArray,
    gate_m: float = 0.15,
    gate_rel: float = 0.05,
) -> NDArray[np.bool_]:
    """Readings of a scan that lie in space an earlier scan saw free: moving obstacles.

    The end point of each valid reading (scan at robot ``pose``) is projected into the
    earlier scan (at ``ref_pose``); if the earlier beams around that direction (the beam and
    its two neighbours, to be safe at edges) all reached farther than the point by more than
    ``gate_m + gate_rel * range``, or returned nothing, the point sits in space that was
    free a moment ago -- a person's legs, not the static world (the free-space consistency
    test behind dynamic-object filtering, e.g. Hähnel et al. 2003). Returns ``(n_beams,)``.
    """
    r = np.asarray(ranges_m, dtype=np.float64)
    ok = np.isfinite(r) & (r >= laser.range_min_m) & (r < laser.range_max_m)
    out = np.zeros(len(r), dtype=bool)
    if not ok.any():
        return out
    mount = np.asarray(laser.mount_pose, dtype=np.float64)
    lp = se2.compose(pose, mount)
    ref_lp = se2.compose(ref_pose, mount)
    ang = laser.angles()
    th = lp[2] + ang[ok]
    pts = lp[:2] + r[ok, None] * np.stack([np.cos(th), np.sin(th)], axis=1)
    rel = se2.transform_points(se2.inverse(ref_lp), pts)
    rho = np.hypot(rel[:, 0], rel[:, 1])
    b = np.rint(
        (np.arctan2(rel[:, 1], rel[:, 0]) - laser.angle_min_rad) / laser.angle_increment_rad
    )
    b = b.astype(np.intp)
    inside = (b >= 1) & (b < laser.n_beams - 1)
    ref = np.asarray(ref_ranges_m, dtype=np.float64)
    ref = np.where(np.isnan(ref) | (ref < laser.range_min_m), 0.0, ref)  # unknown: not free
    ref = np.where(ref >= laser.range_max_m, np.inf, ref)
    bc = np.clip(b, 1, laser.n_beams - 2)
    reach = np.minimum(np.minimum(ref[bc - 1], ref[bc]), ref[bc + 1])
    free = inside & (reach > rho + gate_m + gate_rel * rho) & (rho < laser.range_max_m - 0.5)
    out[np.nonzero(ok)[0][free]] = True
    return out


def range_weights(points_base: FloatArray, rel_noise: float = 0.01, min_sigma_m: float = 0.01):
    """Relative inverse variances ``(sigma_min / sigma(r))^2`` of points for ICP, with the
    range noise ``sigma(r) = max(min_sigma_m, rel_noise * r)`` (URG-04LX datasheet)."""
    r = np.hypot(points_base[:, 0], points_base[:, 1])
    return (min_sigma_m / np.maximum(min_sigma_m, rel_noise * r)) ** 2


def voxel_downsample(points: FloatArray, voxel_m: float, mean: bool = False) -> FloatArray:
    """One point per ``voxel_m`` square cell: the first one, or (``mean``) the centroid."""
    if len(points) == 0:
        return points
    key = np.floor(points / voxel_m).astype(np.int64)
    _, idx, inv = np.unique(
        key[:, 0] * 1_000_003 + key[:, 1], return_index=True, return_inverse=True
    )
    if not mean:
        return points[np.sort(idx)]
    cnt = np.bincount(inv)
    cx = np.bincount(inv, weights=points[:, 0]) / cnt
    cy = np.bincount(inv, weights=points[:, 1]) / cnt
    return np.column_stack([cx, cy])


class FirstRunMapper:
    """Online scan-matching front end with keyframes; :meth:`finish` closes loops and maps."""

    def __init__(
        self,
        laser: LaserSpec,
        initial_pose: ArrayLike,
        keyframe_dist_m: float = 0.3,
        keyframe_angle_rad: float = 0.3,
        local_map_keyframes: int = 12,
        local_map_radius_m: float = 0.0,
        voxel_m: float = 0.03,
        max_correspondence_m: float = 0.3,
        loop_radius_m: float = 3.0,
        loop_min_gap: int = 15,
        loop_max_angle_rad: float = 2.0,
        loop_min_overlap: float = 0.35,
        resolution_m: float = 0.05,
        range_weighting: bool = False,
        voxel_mean: bool = True,
        odom_prior: bool = True,
        max_neighbours: int = 8,
        info_inflation: float = 5.0,
        map_max_hit_range_m: float = 3.0,
        graph_rounds: int = 1,
        map_max_range_m: float = 100.0,
        k_normal: int = 6,
        global_loops: bool = True,
        loop_candidates: int = 3,
        edge_info_inflation: float = 0.0,
        huber_m: float = 0.02,
        edge_huber_m: float = 0.02,
        drop_edges: str = "none",
        seq_sigma: tuple[float, float, float, float, float] = (0.01, 0.03, 0.005, 0.02, 0.02),
        dynamic_filter_lags: tuple[int, ...] = (3, 8),
        loop_stride: int = 2,
        loop_window_m: tuple[float, float, float] = (0.3, 0.025, 3.0),
        loop_window_rad: tuple[float, float, float] = (0.05, 0.004, 0.5),
        loop_submap_half: int = 4,
        loop_min_score: float = 0.45,
        loop_max_sigma_m: float = 0.03,
        odom_sigma: tuple[float, float, float, float, float, float] = (
            0.005,
            0.05,
            0.01,
            0.002,
            0.05,
            0.02,
        ),
    ) -> None:
        self.laser = laser
        self._beams = BeamDirections(laser)
        self.initial_pose = np.asarray(initial_pose, dtype=np.float64).reshape(3).copy()
        self.keyframe_dist_m = float(keyframe_dist_m)
        self.keyframe_angle_rad = float(keyframe_angle_rad)
        self.local_map_keyframes = int(local_map_keyframes)
        self.local_map_radius_m = float(local_map_radius_m)
        self.voxel_m = float(voxel_m)
        self.max_correspondence_m = float(max_correspondence_m)
        self.loop_radius_m = float(loop_radius_m)
        self.loop_min_gap = int(loop_min_gap)
        self.loop_max_angle_rad = float(loop_max_angle_rad)
        self.loop_min_overlap = float(loop_min_overlap)
        self.resolution_m = float(resolution_m)
        self.range_weighting = bool(range_weighting)
        self.voxel_mean = bool(voxel_mean)
        self.odom_prior = bool(odom_prior)
        self.max_neighbours = int(max_neighbours)
        self.info_inflation = float(info_inflation)
        self.map_max_hit_range_m = float(map_max_hit_range_m)
        self.graph_rounds = int(graph_rounds)
        self._kf_maps: dict[int, PointMap | None] | None = None
        self.map_max_range_m = float(map_max_range_m)
        self.k_normal = int(k_normal)
        self.global_loops = bool(global_loops)
        self.loop_candidates = int(loop_candidates)
        self.edge_info_inflation = float(edge_info_inflation)
        self.huber_m = float(huber_m)
        self.edge_huber_m = float(edge_huber_m)
        if drop_edges not in ("none", "isolated", "all"):
            raise ValueError(f"drop_edges must be none, isolated or all, got {drop_edges!r}")
        self.drop_edges = str(drop_edges)
        self.seq_sigma = tuple(float(v) for v in seq_sigma)
        self.dynamic_filter_lags = tuple(int(v) for v in dynamic_filter_lags)
        self._history: list[tuple[FloatArray, NDArray[np.float32]]] = []  # recent (pose, scan)
        self.n_dynamic = 0
        self.loop_stride = max(1, int(loop_stride))
        self.loop_window_m = tuple(float(v) for v in loop_window_m)
        self.loop_window_rad = tuple(float(v) for v in loop_window_rad)
        self.loop_submap_half = int(loop_submap_half)
        self.loop_min_score = float(loop_min_score)
        self.loop_max_sigma_m = float(loop_max_sigma_m)
        self.odom_sigma = tuple(float(v) for v in odom_sigma)
        self.pose = self.initial_pose.copy()
        self.cov = np.diag([1e-6, 1e-6, 1e-6])
        self._last_odom: FloatArray | None = None
        self.keyframes: list[Keyframe] = []
        self._kf_points: list[FloatArray] = []  # base-frame points per keyframe
        self._seq_cov: list[FloatArray] = []  # front-end covariance at each keyframe
        self._ref: list[tuple[int, FloatArray]] = []  # per scan: (keyframe, pose in it)
        self._stamps: list[float] = []
        self._local: PointMap | None = None
        self.n_scans = 0
        self.n_rejected = 0

    # -- front end -----------------------------------------------------------------------
    def _add_keyframe(self, ranges: NDArray[np.float32], pts: FloatArray) -> None:
        self.keyframes.append(
            Keyframe(self.pose.copy(), np.asarray(ranges, np.float32).copy(), self.n_scans)
        )
        near = np.hypot(pts[:, 0], pts[:, 1]) <= self.map_max_range_m
        self._kf_points.append(voxel_downsample(pts[near], self.voxel_m))
        self._seq_cov.append(self.cov.copy())
        self._rebuild_local_map()

    def _rebuild_local_map(self) -> None:
        n = len(self.keyframes)
        recent = set(range(max(0, n - self.local_map_keyframes), n))
        if self.local_map_radius_m > 0:
            kp = np.array([k.pose[:2] for k in self.keyframes])
            near = np.nonzero(np.hypot(*(kp - kp[-1]).T) < self.local_map_radius_m)[0]
            recent |= set(near.tolist())
        # Oldest first: the voxel filter keeps the first point, i.e. the least drifted one.
        sel = sorted(recent)
        pts = np.concatenate(
            [se2.transform_points(self.keyframes[k].pose, self._kf_points[k]) for k in sel]
        )
        pts = voxel_downsample(pts, self.voxel_m, mean=self.voxel_mean)
        self._local = PointMap(pts, k_normal=self.k_normal) if len(pts) >= 3 else None

    def _dynamic_mask(self, ranges: NDArray[np.float32], pose: FloatArray) -> NDArray[np.bool_]:
        """Readings in space free in the scans ``dynamic_filter_lags`` steps ago."""
        dyn = np.zeros(len(ranges), dtype=bool)
        for lag in self.dynamic_filter_lags:
            if len(self._history) >= lag:
                ref_pose, ref_ranges = self._history[-lag]
                dyn |= free_space_violations(self.laser, ranges, pose, ref_ranges, ref_pose)
        return dyn

    def update(self, odom: Odometry, scan: Scan) -> PoseEstimate:
        """Fuse one odometry reading and scan; return the front end's pose estimate."""
        opose = np.asarray(odom.pose, dtype=np.float64)
        ranges = np.asarray(scan.ranges_m, dtype=np.float32)
        if self._last_odom is None:
            self._last_odom = opose.copy()
            first = ranges
            if self.drop_edges != "none":
                first = np.where(
                    range_discontinuities(ranges, isolated_only=self.drop_edges == "isolated"),
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
            if self.drop_edges != "none":
                dyn |= range_discontinuities(ranges, isolated_only=self.drop_edges == "isolated")
            pts = scan_points_base(self.laser, np.where(dyn, np.nan, ranges), self._beams)
            d = float(np.hypot(delta[0], delta[1]))
            a = abs(float(delta[2]))
            sig_xy = self.odom_sigma[0] + self.odom_sigma[1] * d + self.odom_sigma[2] * a
            sig_th = self.odom_sigma[3] + self.odom_sigma[4] * a + self.odom_sigma[5] * d
            q = np.diag([sig_xy**2, sig_xy**2, sig_th**2])
            accepted = False
            if self._local is not None and len(pts) >= 20:
                sub = pts[:: max(1, len(pts) // 400)]
                res = match_scan(
                    sub,
                    self._local,
                    pred,
                    prior_mean=pred,
                    prior_info=np.linalg.inv(q) if self.odom_prior else None,
                    max_correspondence_m=self.max_correspondence_m,
                    max_iterations=20,
                    weights=range_weights(sub) if self.range_weighting else None,
                    info_inflation=self.info_inflation,
                    huber_m=self.huber_m,
                )
                n_used = len(pts[:: max(1, len(pts) // 400)])
                if res.n_matched >= max(15, 0.3 * n_used) and res.rmse_m < 0.08:
                    self.pose = res.pose
                    self.cov = res.cov
                    accepted = True
            if not accepted:
                self.n_rejected += 1
                self.pose = pred
                self.cov = self.cov + q
            kf = self.keyframes[-1].pose
            rel = se2.between(kf, self.pose)
            if np.hypot(rel[0], rel[1]) > self.keyframe_dist_m or abs(rel[2]) > (
                self.keyframe_angle_rad
            ):
                self._add_keyframe(ranges, pts)
        if self.dynamic_filter_lags:
            self._history.append((self.pose.copy(), ranges))
            del self._history[: -max(self.dynamic_filter_lags)]
        kf_idx = len(self.keyframes) - 1
        self._ref.append((kf_idx, se2.between(self.keyframes[kf_idx].pose, self.pose)))
        self._stamps.append(float(scan.stamp_s))
        self.n_scans += 1
        return PoseEstimate(mean=self.pose.copy(), cov=self.cov.copy())

    # -- back end ------------------------------------------------------------------------
    def _sequential_edges(self, poses: FloatArray) -> list[Edge]:
        edges = []
        for k in range(len(poses) - 1):
            z = se2.between(poses[k], poses[k + 1])
            d = float(np.hypot(z[0], z[1]))
            a_xy, b_xy, a_th, b_th, c_th = self.seq_sigma
            sxy = a_xy + b_xy * d
            sth = a_th + b_th * d + c_th * abs(float(z[2]))
            edges.append(Edge(k, k + 1, z, np.diag([1 / sxy**2, 1 / sxy**2, 1 / sth**2])))
        return edges

    def _edge_info(self, res: MatchResult, fixed: FloatArray) -> FloatArray:
        """Information of an ICP edge: the fixed one, or (``edge_info_inflation`` > 0) the
        ICP's own (Gauss-Newton) information divided by that factor -- so weakly constrained
        directions weigh little -- but never more than the fixed one in any direction."""
        if self.edge_info_inflation <= 0:
            return fixed
        icp_cov = res.cov * self.edge_info_inflation
        cov = icp_cov + np.linalg.inv(fixed)
        info = np.linalg.inv(cov)
        return 0.5 * (info + info.T)

    def _keyframe_map(self, k: int) -> PointMap | None:
        """Point map of keyframe ``k`` in its own frame (built once, cached)."""
        if self._kf_maps is None:
            self._kf_maps = {}
        if k not in self._kf_maps:
            pts = self._kf_points[k]
            self._kf_maps[k] = PointMap(pts, k_normal=self.k_normal) if len(pts) >= 20 else None
        return self._kf_maps[k]

    def _match_edges(self, poses: FloatArray) -> list[Edge]:
        """Pairwise ICP edges between keyframes near each other in the current estimate.

        Every keyframe is matched against up to ``max_neighbours`` earlier keyframes within
        ``loop_radius_m`` (spread over the sequence; those far back in the sequence are loop
        closures). A match is kept if it converges with a small residual and enough overlap.
        """
        edges: list[Edge] = []
        info = np.diag([1 / 0.01**2, 1 / 0.01**2, 1 / 0.005**2])
        for i in range(1, len(poses)):
            cand = np.arange(0, i)
            dist = np.hypot(*(poses[cand, :2] - poses[i, :2]).T)
            dth = np.abs(se2.wrap_angle(poses[cand, 2] - poses[i, 2]))
            cand = cand[(dist < self.loop_radius_m) & (dth < self.loop_max_angle_rad)]
            if len(cand) > self.max_neighbours:
                pick = np.linspace(0, len(cand) - 1, self.max_neighbours).round().astype(int)
                cand = cand[np.unique(pick)]
            src = self._kf_points[i]
            if len(src) < 20:
                continue
            for j in cand:
                target = self._keyframe_map(int(j))
                if target is None:
                    continue
                init = se2.between(poses[j], poses[i])
                if i - j > self.loop_min_gap:  # a loop closure: allow for more drift
                    res = match_scan(
                        src,
                        target,
                        init,
                        max_correspondence_m=0.5,
                        max_iterations=30,
                        huber_m=self.edge_huber_m,
                    )
                    init_fine = res.pose
                else:
                    init_fine = init
                res = match_scan(
                    src,
                    target,
                    init_fine,
                    max_correspondence_m=0.15,
                    max_iterations=20,
                    huber_m=self.edge_huber_m,
                )
                moved = float(np.hypot(*(res.pose[:2] - init[:2])))
                if (
                    res.converged
                    and res.n_matched >= max(60, self.loop_min_overlap * len(src))
                    and res.rmse_m < 0.03
                    and moved < 1.0
                ):
                    edges.append(Edge(int(j), i, res.pose, self._edge_info(res, info)))
        return edges

    def _submap_points(self, poses: FloatArray, j: int) -> FloatArray:
        """Points of keyframes ``j +- loop_submap_half`` in keyframe ``j``'s frame."""
        lo, hi = max(0, j - self.loop_submap_half), min(len(poses), j + self.loop_submap_half + 1)
        pts = np.concatenate(
            [
                se2.transform_points(se2.between(poses[j], poses[k]), self._kf_points[k])
                for k in range(lo, hi)
            ]
        )
        return voxel_downsample(pts, 0.04, mean=True)

    def _global_loop_edges(self, poses: FloatArray) -> list[Edge]:
        """Loop closures robust to large drift: correlative search, then ICP verification.

        For keyframe ``i`` (every ``loop_stride``-th) and earlier keyframes ``j`` more than
        ``loop_min_gap`` keyframes back, the search window grows with the path length
        ``s`` [m] between them, ``w = min(a + b s, cap)`` (``loop_window_m`` for x and y,
        ``loop_window_rad`` for theta): the drift the front end may have gathered. The
        ``loop_candidates`` nearest such candidates (in the current estimate, from distinct
        stretches of the sequence) are matched by
        :func:`.correlative_matcher.correlative_match` against the submap around ``j``; the
        result is refined by ICP and kept if the correlative score, the ICP residual and
        overlap are good and the ICP pose is well constrained in every direction (no
        corridor-like ambiguity: largest position standard deviation <= ``loop_max_sigma_m``).
        """
        n = len(poses)
        step = np.hypot(*np.diff(poses[:, :2], axis=0).T)
        path = np.concatenate([[0.0], np.cumsum(step)])
        a_m, b_m, cap_m = self.loop_window_m
        tables: dict[int, tuple[LikelihoodTable, PointMap] | None] = {}
        edges: list[Edge] = []
        for i in range(self.loop_min_gap + 1, n, self.loop_stride):
            src = self._kf_points[i]
            if len(src) < 30:
                continue
            cand = np.arange(0, i - self.loop_min_gap)
            s = path[i] - path[cand]
            w_xy = np.minimum(a_m + b_m * s, cap_m)
            dist = np.hypot(*(poses[cand, :2] - poses[i, :2]).T)
            near = dist < 0.5 * self.loop_radius_m + w_xy
            if not np.any(near):
                continue
            cand, w_xy, s, dist = cand[near], w_xy[near], s[near], dist[near]
            chosen: list[int] = []
            for m in np.argsort(dist):  # nearest first, one per stretch of the sequence
                if len(chosen) >= self.loop_candidates:
                    break
                if all(abs(int(cand[m]) - int(cand[c])) > 2 * self.loop_min_gap for c in chosen):
                    chosen.append(int(m))
            for m in chosen:
                edge = self._verified_loop(poses, tables, int(cand[m]), i, w_xy[m], s[m])
                if edge is not None:
                    edges.append(edge)
        return self._consistent_loops(poses, edges)

    def _verified_loop(
        self,
        poses: FloatArray,
        tables: dict[int, tuple[LikelihoodTable, PointMap] | None],
        j: int,
        i: int,
        w_xy_m: float,
        path_m: float,
    ) -> Edge | None:
        """Correlative search of keyframe ``i`` around ``j``'s submap, verified by ICP."""
        if j not in tables:
            sub = self._submap_points(poses, j)
            tables[j] = (
                (LikelihoodTable(sub, 0.05, 0.05, margin_m=0.5), PointMap(sub))
                if len(sub) >= 30
                else None
            )
        entry = tables[j]
        if entry is None:
            return None
        table, pmap = entry
        src = self._kf_points[i]
        a_r, b_r, cap_r = self.loop_window_rad
        cres = correlative_match(
            voxel_downsample(src, 0.1),
            table,
            se2.between(poses[j], poses[i]),
            window_xy_m=float(w_xy_m),
            window_theta_rad=float(min(a_r + b_r * path_m, cap_r)),
        )
        if cres.score < self.loop_min_score:
            return None
        res = match_scan(
            src,
            pmap,
            cres.pose,
            max_correspondence_m=0.15,
            max_iterations=30,
            huber_m=self.edge_huber_m,
        )
        sig = float(np.sqrt(np.max(np.linalg.eigvalsh(res.cov[:2, :2]))))
        if (
            res.converged
            and res.n_matched >= max(60, self.loop_min_overlap * len(src))
            and res.rmse_m < 0.03
            and sig <= self.loop_max_sigma_m
        ):
            info = np.diag([1 / 0.01**2, 1 / 0.01**2, 1 / 0.005**2])
            return Edge(j, i, res.pose, info)
        return None

    def _consistent_loops(
        self,
        poses: FloatArray,
        edges: list[Edge],
        window: int = 40,
        tol_m: float = 0.25,
        tol_rad: float = 0.05,
    ) -> list[Edge]:
        """Keep loop edges whose implied drift correction is confirmed by another.

        An edge ``(j, i, z)`` says keyframe ``i`` is at ``x_j ⊕ z``; its correction
        ``x_j ⊕ z ⊖ x_i`` (map frame) is the drift gathered between ``j`` and ``i``. Drift
        is smooth, so true closures whose ``i`` and ``j`` both lie within ``window`` of each
        other agree (within ``tol_m`` / ``tol_rad``), while a false match (perceptual
        aliasing) stands alone: an edge is kept if at least one other edge and a majority
        of those nearby agree with it (a simple form of Olson's single-cluster test).
        """
        if len(edges) < 2:
            return []
        jj = np.array([e.i for e in edges])
        ii = np.array([e.j for e in edges])
        implied = se2.compose(poses[jj], np.array([e.z for e in edges]))
        corr = implied - poses[ii]
        corr[:, 2] = se2.wrap_angle(corr[:, 2])
        near = (np.abs(ii[:, None] - ii[None, :]) <= window) & (
            np.abs(jj[:, None] - jj[None, :]) <= window
        )
        agree = (
            near
            & (np.hypot(*(corr[:, None, :2] - corr[None, :, :2]).transpose(2, 0, 1)) < tol_m)
            & (np.abs(se2.wrap_angle(corr[:, None, 2] - corr[None, :, 2])) < tol_rad)
        )
        n_agree = agree.sum(axis=1)
        keep = (n_agree >= 2) & (2 * n_agree > near.sum(axis=1))
        return [e for e, k in zip(edges, keep, strict=True) if k]

    def finish(self) -> StaticMap:
        """Close loops, optimize the pose graph, render the grid; return the static map."""
        if not self.keyframes:
            raise ValueError("FirstRunMapper.finish() before any update()")
        poses = np.array([k.pose for k in self.keyframes])
        seq = self._sequential_edges(poses)
        n_loops = 0
        if self.global_loops:
            loops = self._global_loop_edges(poses)
            if loops:  # verified and mutually consistent: least squares without robust loss
                poses = optimize_pose_graph(poses, seq + loops, anchor=0, loss="linear")
        for _ in range(self.graph_rounds):
            matches = self._match_edges(poses)
            n_loops = sum(1 for e in matches if e.j - e.i > self.loop_min_gap)
            if not matches:
                break
            poses = optimize_pose_graph(poses, seq + matches, anchor=0)
        kfs = [Keyframe(poses[m], k.ranges_m, k.scan_index) for m, k in enumerate(self.keyframes)]
        traj = np.array([se2.compose(poses[k], rel) for k, rel in self._ref])
        grid = OccupancyGrid.from_scans(
            poses,
            np.array([k.ranges_m for k in self.keyframes]),
            self.laser,
            resolution_m=self.resolution_m,
            max_hit_range_m=self.map_max_hit_range_m,
        )
        return StaticMap(
            trajectory=traj,
            grid=grid,
            keyframes=kfs,
            stamps_s=np.array(self._stamps),
            n_loop_closures=n_loops,
        )
