"""Loop closure over the first run's keyframes: candidate search, verification, pose graph.

B&D §4: the first run's static SLAM outputs "a set of selected laser scans with relations
between them" -- the keyframes of :mod:`.keyframe_slam` and the pose-graph edges made here:

* **sequential edges** between consecutive keyframes (the front end's relative poses, with a
  standard deviation that grows with the step, ``seq_sigma``);
* **drift-tolerant closures** (:meth:`LoopClosure.global_loop_edges`): for keyframes far apart
  in sequence, a correlative search (:mod:`.correlative_matcher`, Olson 2009) whose window
  grows with the path length between them, verified by ICP, a conditioning test and a
  consistency vote (a simple single-cluster test); they are optimized by plain least squares;
* **pairwise ICP edges** (:meth:`LoopClosure.match_edges`) between keyframes near each other
  in that estimate, accepted only if ICP converges with a small residual and a high inlier
  fraction, optimized with a robust loss;
* the graph is optimized by :func:`.pose_graph.optimize_pose_graph` (Grisetti et al. 2010),
  anchored at the first keyframe so that the map frame is the frame of the initial pose.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from numpy.typing import NDArray

from dynmap_sim import se2
from dynmap_sim.agent.mapping.correlative_matcher import LikelihoodTable, correlative_match
from dynmap_sim.agent.mapping.incremental_loops import incremental_closures
from dynmap_sim.agent.mapping.keyframe_slam import KeyframeSLAM
from dynmap_sim.agent.mapping.pose_graph import (
    Edge,
    optimize_pose_graph,
    optimize_pose_graph_dcs,
)
from dynmap_sim.agent.mapping.scan_matcher import MatchResult, PointMap, match_scan
from dynmap_sim.agent.mapping.scan_points import voxel_downsample
from dynmap_sim.agent.mapping.wall_factors import WallPlan, wall_factor
from dynmap_sim.agent.params import (
    AsTuple,
    Int,
    NonNegativeInt,
    Positive,
    PositiveInt,
    params_dataclass,
)

FloatArray = NDArray[np.float64]


@params_dataclass()
class LoopClosureConfig:
    """Parameters of loop closure and the pose graph (lengths in m, angles in rad)."""

    #: Search drift-tolerant closures by correlative matching before the ICP rounds: a long
    #: loop drifts beyond ICP's basin.
    global_loops: bool = True
    #: Keyframes more than this many apart in sequence may close a loop (nearer ones are
    #: sequential neighbours, matched anyway).
    loop_min_gap: Int = 15
    #: Closures are searched for every this-many-th keyframe (at least 1): neighbouring
    #: keyframes see the same, half of them suffice.
    loop_stride: Int = 2
    #: At most this many closure candidates per keyframe, nearest first, from distinct
    #: stretches of the sequence (more than ``2 loop_min_gap`` keyframes apart).
    loop_candidates: Int = 3
    #: Correlative search half-window in x and y: ``min(a + b s, cap)`` [m] for a path length
    #: ``s`` [m] between the two keyframes, as ``(a, b, cap)``: 2.5 % of the path, the drift
    #: the front end may gather, at most 9 m, the default submap's length (``2
    #: loop_submap_half`` x ``keyframe_dist_m``; a number of its own, which changing either
    #: leaves as it is): a scan displaced farther than that from the prediction is off the
    #: submap it is matched against, and the search cost grows with the window's area.
    loop_window_m: Annotated[tuple[float, float, float], AsTuple] = (0.3, 0.025, 9.0)
    #: ... and in theta, ``(a, b, cap)`` [rad, rad/m, rad].
    loop_window_rad: Annotated[tuple[float, float, float], AsTuple] = (0.05, 0.004, 0.5)
    #: A closure's target is the submap of keyframes ``j +- loop_submap_half``: 15, about
    #: 4.5 m of path either side at the front end's 0.3 m spacing. A place revisited in the
    #: opposite direction is seen, by a laser of 180 deg or less, only from keyframes metres
    #: before or after ``j``; and a submap must be small enough to stay locally correct
    #: and large enough to be distinct (Cartographer's submaps, Hess et al. 2016): over such
    #: a stretch the front end errs by about 3 cm (real logs' relations under 30 s), within
    #: the correlative table's 5 cm cells.
    loop_submap_half: Int = 15
    #: Least correlative score (share of points on the submap) of a closure candidate.
    loop_min_score: float = 0.45
    #: Largest position standard deviation [m] of a verified closure's ICP pose: rejects
    #: corridor-like matches that slide along the corridor.
    loop_max_sigma_m: float = 0.03
    #: Pairwise ICP edges join keyframes within this distance [m] in the current estimate
    #: (global candidates: within half of it plus the search window).
    loop_radius_m: float = 3.0
    #: ... whose headings differ by less than this [rad].
    loop_max_angle_rad: float = 2.0
    #: An ICP edge needs at least this share of the keyframe's points matched (and 60).
    loop_min_overlap: float = 0.35
    #: At most this many earlier keyframes per keyframe get a pairwise ICP edge (spread over
    #: the sequence).
    max_neighbours: Int = 8
    #: Huber threshold [m] of the edges' ICP (2 cm, as the front end).
    edge_huber_m: float = 0.02
    #: > 0: a pairwise edge's information is the ICP's own divided by this factor (weakly
    #: constrained directions weigh little), capped by the fixed 1 cm / 0.005 rad one; 0: the
    #: fixed one.
    edge_info_inflation: float = 0.0
    #: Standard deviations of a sequential edge of length ``d`` [m] and turn ``a`` [rad] as
    #: ``(s_xy0, k_xy_d, s_th0, k_th_d, k_th_a)``: ``sigma_xy = s_xy0 + k_xy_d d`` [m],
    #: ``sigma_th = s_th0 + k_th_d d + k_th_a |a|`` [rad] (the front end drifts ~3 % of the
    #: distance).
    seq_sigma: Annotated[tuple[float, float, float, float, float], AsTuple] = (
        0.01,
        0.03,
        0.005,
        0.02,
        0.02,
    )
    #: Rounds of pairwise ICP edges + robust optimization after the global closures (one:
    #: the same quality as two in half the back-end time).
    graph_rounds: Int = 1
    #: Close loops keyframe by keyframe with a window that grows with the path since the
    #: last closure (:mod:`.incremental_loops`) instead of once over the whole drift.
    incremental_loops: bool = False
    #: Keep the correlative closures in the graph of the ICP rounds: a verified, mutually
    #: consistent closure is evidence the pose graph keeps (Olson 2009, Mangelson et al.
    #: 2018). Off: the ICP round optimizes the sequential edges and its own pairwise edges
    #: only, so where those find no loop edge (a long loop whose ends lie beyond
    #: ``loop_radius_m`` in the front end's estimate) the graph relaxes back to the front
    #: end's shape and the closures are lost.
    keep_closures: bool = True
    #: The robust treatment of loop-closure and pairwise ICP edges in the pose graph:
    #: ``"dcs"`` dynamic covariance scaling (Agarwal et al. 2013: an edge whose error is far
    #: beyond its covariance loses its weight, so one wrong closure cannot bend the graph),
    #: ``"huber"`` the Huber loss at ``3`` standard deviations on the ICP rounds and plain
    #: least squares on the correlative closures.
    robust_kernel: str = "dcs"
    #: DCS's ``phi`` [squared standard deviations]: an edge with ``chi2 <= phi`` keeps its
    #: full weight; Agarwal et al. 2013 (§V) find results insensitive over 0.1-10 and use 1.
    dcs_phi: float = 1.0
    #: Closures are compared for consistency when both their ends lie within this many
    #: keyframes (~12 m of path at the default spacing): the legs between them are short
    #: enough for the front end's drift to be small.
    consistency_window: Int = 40
    #: The consistency test's bound in standard deviations of the legs' drift
    #: (``seq_sigma``); 3: a true pair passes with ~99 % probability per direction.
    consistency_gate: float = 3.0
    #: Where the prior grants the walls (an anchored first run): optimize the keyframes
    #: under their sequential edges and one factor per keyframe that sees a wall
    #: (:mod:`.wall_factors`, Boniardi et al. 2017), instead of keeping the front end's
    #: poses. Loop closures are not searched then: the walls bound the drift, and in halls
    #: of identical aisles a closure aliases to the next aisle.
    wall_factors: bool = True
    #: ICP correspondence gates [m] of a wall factor, coarse then fine: the front end's
    #: ``max_correspondence_m``, then its ``anchor_seen_m`` (readings of furniture in front
    #: of a wall stay out of the fit).
    wall_gate_m: Annotated[tuple[Positive, Positive], AsTuple] = (0.3, 0.1)
    #: A wall factor needs this many of the keyframe's points within the fine gate (the
    #: fewest a closure's source may have).
    wall_min_points: PositiveInt = 30
    #: ... at an RMS residual below this [m] (a verified closure's bound).
    wall_max_rmse_m: Positive = 0.03
    #: The scan's information in a wall factor is divided by this: the keyframe's points
    #: are not independent (Censi 2007) and neighbouring keyframes see the same wall, so
    #: that the factors of one wall do not outweigh the sequential edges that tie them
    #: together. 20: on the development worlds the maps varied by millimetres over 20-60,
    #: and came out worse at the front end's 5 (docs/tuning/slam.md).
    wall_info_inflation: Positive = 20.0
    #: The keyframes are optimized on the walls every this many keyframes during the run
    #: (0: only at its end), so that the front end's local map and pose go on from
    #: corrected keyframes: 10 keyframes, about 3 m of path, less than the laser's reach.
    wall_graph_every: NonNegativeInt = 10

    def __post_init__(self) -> None:
        if self.robust_kernel not in ("dcs", "huber"):
            raise ValueError(f"robust_kernel must be dcs or huber, got {self.robust_kernel!r}")
        object.__setattr__(self, "loop_stride", max(1, self.loop_stride))


#: Why a closure candidate was rejected, first failed check first (:attr:`LoopClosure.stats`):
#: an empty submap, a correlative score below ``loop_min_score``, ICP not converged, too few
#: points matched (``loop_min_overlap``), an RMS residual of 3 cm or more, or a pose sliding
#: in some direction (``loop_max_sigma_m``).
REJECTIONS = (
    "empty_submap",
    "low_score",
    "not_converged",
    "low_overlap",
    "high_rmse",
    "sliding",
)

#: Information of a verified ICP edge: 1 cm in x and y, 0.005 rad in theta.
EDGE_INFO = np.diag([1 / 0.01**2, 1 / 0.01**2, 1 / 0.005**2])
EDGE_INFO.flags.writeable = False


class LoopClosure:
    """Edges of the keyframe pose graph and its optimization (see the module docstring)."""

    def __init__(self, config: LoopClosureConfig) -> None:
        self.config = config
        #: Counts of the last closure search: keyframes without a candidate, candidates
        #: searched, rejected by each of :data:`REJECTIONS`, verified and kept as consistent
        #: (:mod:`.incremental_loops` keeps its own counts here).
        self.stats: dict[str, int] = {}
        self._walls: WallPlan | None = None  # the prior's walls (optimize_on_walls)
        #: each keyframe's wall factor ``(pose, information)`` or None, in keyframe order
        self._wall_cache: list[tuple[FloatArray, FloatArray] | None] = []

    def optimize(self, slam: KeyframeSLAM) -> tuple[FloatArray, int]:
        """The keyframe poses ``(K, 3)`` after closing loops, and the number of loop-closing
        edges of the last ICP round."""
        c = self.config
        poses = np.array([k.pose for k in slam.keyframes])
        seq = self.sequential_edges(
            [se2.between(poses[k], poses[k + 1]) for k in range(len(poses) - 1)]
        )
        n_loops = 0
        kept: list[Edge] = []  # closures that stay in the graph of the ICP rounds
        if c.global_loops and c.incremental_loops:
            poses, kept = incremental_closures(self, slam, seq)
            if not c.keep_closures:
                kept = []
        elif c.global_loops:
            loops = self.global_loop_edges(poses, slam)
            if loops:  # verified and mutually consistent
                poses = self._optimize(poses, seq, loops, "linear")
                kept = loops if c.keep_closures else []
        for _ in range(c.graph_rounds):
            matches = self.match_edges(poses, slam)
            n_loops = sum(1 for e in matches if e.j - e.i > c.loop_min_gap)
            if not matches:
                break
            poses = self._optimize(poses, seq, kept + matches, "huber")
        return poses, n_loops

    def optimize_on_walls(self, slam: KeyframeSLAM, refresh: bool = False) -> FloatArray:
        """The keyframe poses ``(K, 3)`` of an anchored first run, optimized under the
        sequential edges (the front end's steps between keyframes as measured) and the wall
        factors (:func:`.wall_factors.wall_factor`), the latter robust (DCS): a virtual node
        at the map origin holds the factors, and it and the first keyframe (the known
        initial pose) stay fixed. A keyframe's factor is found once, at its pose of the
        first call that sees it; ``refresh`` finds every factor again at today's poses."""
        poses = np.array([k.pose for k in slam.keyframes])
        if self._walls is None:
            self._walls = WallPlan.from_segments(slam.wall_segments, slam.config.voxel_m)
        if refresh:
            self._wall_cache.clear()
        reach = slam.laser.range_max_m + self.config.wall_gate_m[0]
        for k in range(len(self._wall_cache), len(poses)):
            self._wall_cache.append(
                wall_factor(
                    self._walls,
                    slam.keyframe_points[k],
                    poses[k],
                    reach,
                    slam.config.huber_m,
                    self.config,
                )
            )
        v = len(poses)
        walls = [Edge(v, k, *f) for k, f in enumerate(self._wall_cache) if f is not None]
        self.stats = {"wall_factors": len(walls)}
        if not walls:
            return poses
        seq = self.sequential_edges(slam.keyframe_steps)
        robust = np.r_[np.zeros(len(seq), bool), np.ones(len(walls), bool)]
        nodes = np.vstack([poses, np.zeros(3)])
        out = optimize_pose_graph_dcs(nodes, seq + walls, robust, self.config.dcs_phi, (0, v))
        return out[:-1]

    def _optimize(self, poses: FloatArray, seq: list[Edge], loops: list[Edge], loss: str):
        """The graph of sequential edges ``seq`` and loop/ICP edges ``loops`` optimized, the
        latter robust as ``robust_kernel`` says (``loss``: the Huber variant's loss)."""
        if self.config.robust_kernel == "dcs":
            robust = np.r_[np.zeros(len(seq), bool), np.ones(len(loops), bool)]
            return optimize_pose_graph_dcs(poses, seq + loops, robust, self.config.dcs_phi)
        return optimize_pose_graph(poses, seq + loops, anchor=0, loss=loss)

    # -- edges ---------------------------------------------------------------------------
    def sequential_edges(self, steps: list[FloatArray]) -> list[Edge]:
        """Edges between consecutive keyframes measuring ``steps``, each keyframe's pose in
        the previous one's frame."""
        edges = []
        for k, z in enumerate(steps):
            d = float(np.hypot(z[0], z[1]))
            a_xy, b_xy, a_th, b_th, c_th = self.config.seq_sigma
            sxy = a_xy + b_xy * d
            sth = a_th + b_th * d + c_th * abs(float(z[2]))
            edges.append(Edge(k, k + 1, z, np.diag([1 / sxy**2, 1 / sxy**2, 1 / sth**2])))
        return edges

    def _edge_info(self, res: MatchResult, fixed: FloatArray) -> FloatArray:
        """Information of an ICP edge: the fixed one, or (``edge_info_inflation`` > 0) the
        ICP's own (Gauss-Newton) information divided by that factor -- so weakly constrained
        directions weigh little -- but never more than the fixed one in any direction."""
        if self.config.edge_info_inflation <= 0:
            return fixed
        icp_cov = res.cov * self.config.edge_info_inflation
        cov = icp_cov + np.linalg.inv(fixed)
        info = np.linalg.inv(cov)
        return 0.5 * (info + info.T)

    def match_edges(self, poses: FloatArray, slam: KeyframeSLAM) -> list[Edge]:
        """Pairwise ICP edges between keyframes near each other in the current estimate.

        Every keyframe is matched against up to ``max_neighbours`` earlier keyframes within
        ``loop_radius_m`` (spread over the sequence; those far back in the sequence are loop
        closures). A match is kept if it converges with a small residual and enough overlap.
        """
        c = self.config
        edges: list[Edge] = []
        info = EDGE_INFO
        for i in range(1, len(poses)):
            cand = np.arange(0, i)
            dist = np.hypot(*(poses[cand, :2] - poses[i, :2]).T)
            dth = np.abs(se2.wrap_angle(poses[cand, 2] - poses[i, 2]))
            cand = cand[(dist < c.loop_radius_m) & (dth < c.loop_max_angle_rad)]
            if len(cand) > c.max_neighbours:
                pick = np.linspace(0, len(cand) - 1, c.max_neighbours).round().astype(int)
                cand = cand[np.unique(pick)]
            src = slam.keyframe_points[i]
            if len(src) < 20:
                continue
            for j in cand:
                target = slam.keyframe_map(int(j))
                if target is None:
                    continue
                init = se2.between(poses[j], poses[i])
                if i - j > c.loop_min_gap:  # a loop closure: allow for more drift
                    res = match_scan(
                        src,
                        target,
                        init,
                        max_correspondence_m=0.5,
                        max_iterations=30,
                        huber_m=c.edge_huber_m,
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
                    huber_m=c.edge_huber_m,
                )
                moved = float(np.hypot(*(res.pose[:2] - init[:2])))
                if (
                    res.converged
                    and res.n_matched >= max(60, c.loop_min_overlap * len(src))
                    and res.rmse_m < 0.03
                    and moved < 1.0
                ):
                    edges.append(Edge(int(j), i, res.pose, self._edge_info(res, info)))
        return edges

    def _submap_points(self, poses: FloatArray, slam: KeyframeSLAM, j: int) -> FloatArray:
        """Points of keyframes ``j +- loop_submap_half`` in keyframe ``j``'s frame."""
        half = self.config.loop_submap_half
        lo, hi = max(0, j - half), min(len(poses), j + half + 1)
        pts = np.concatenate(
            [
                se2.transform_points(se2.between(poses[j], poses[k]), slam.keyframe_points[k])
                for k in range(lo, hi)
            ]
        )
        return voxel_downsample(pts, 0.04, mean=True)

    def global_loop_edges(self, poses: FloatArray, slam: KeyframeSLAM) -> list[Edge]:
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
        c = self.config
        n = len(poses)
        step = np.hypot(*np.diff(poses[:, :2], axis=0).T)
        path = np.concatenate([[0.0], np.cumsum(step)])
        a_m, b_m, cap_m = c.loop_window_m
        tables: dict[int, tuple[LikelihoodTable, PointMap] | None] = {}
        edges: list[Edge] = []
        self.stats = dict.fromkeys(REJECTIONS + ("no_candidate",), 0)
        for i in range(c.loop_min_gap + 1, n, c.loop_stride):
            src = slam.keyframe_points[i]
            if len(src) < 30:
                continue
            cand = np.arange(0, i - c.loop_min_gap)
            s = path[i] - path[cand]
            w_xy = np.minimum(a_m + b_m * s, cap_m)
            dist = np.hypot(*(poses[cand, :2] - poses[i, :2]).T)
            near = dist < 0.5 * c.loop_radius_m + w_xy
            if not np.any(near):
                self.stats["no_candidate"] += 1
                continue
            cand, w_xy, s, dist = cand[near], w_xy[near], s[near], dist[near]
            chosen: list[int] = []
            for m in np.argsort(dist):  # nearest first, one per stretch of the sequence
                if len(chosen) >= c.loop_candidates:
                    break
                if all(abs(int(cand[m]) - int(cand[o])) > 2 * c.loop_min_gap for o in chosen):
                    chosen.append(int(m))
            for m in chosen:
                edge = self._verified_loop(poses, slam, tables, int(cand[m]), i, w_xy[m], s[m])
                if edge is not None:
                    edges.append(edge)
        self.stats["searched"] = sum(self.stats[k] for k in REJECTIONS) + len(edges)
        self.stats["verified"] = len(edges)
        kept = self._consistent_loops(poses, edges)
        self.stats["consistent"] = len(kept)
        return kept

    def _verified_loop(
        self,
        poses: FloatArray,
        slam: KeyframeSLAM,
        tables: dict[int, tuple[LikelihoodTable, PointMap] | None],
        j: int,
        i: int,
        w_xy_m: float,
        path_m: float,
        w_theta_rad: float | None = None,
    ) -> Edge | None:
        """Correlative search of keyframe ``i`` around ``j``'s submap, verified by ICP."""
        c = self.config
        if j not in tables:
            sub = self._submap_points(poses, slam, j)
            tables[j] = (
                (LikelihoodTable(sub, 0.05, 0.05, margin_m=0.5), PointMap(sub))
                if len(sub) >= 30
                else None
            )
        entry = tables[j]
        if entry is None:
            self._reject("empty_submap")
            return None
        table, pmap = entry
        src = slam.keyframe_points[i]
        a_r, b_r, cap_r = c.loop_window_rad
        cres = correlative_match(
            voxel_downsample(src, 0.1),
            table,
            se2.between(poses[j], poses[i]),
            window_xy_m=float(w_xy_m),
            window_theta_rad=float(
                min(a_r + b_r * path_m, cap_r) if w_theta_rad is None else w_theta_rad
            ),
        )
        if cres.score < c.loop_min_score:
            self._reject("low_score")
            return None
        res = match_scan(
            src,
            pmap,
            cres.pose,
            max_correspondence_m=0.15,
            max_iterations=30,
            huber_m=c.edge_huber_m,
        )
        sig = float(np.sqrt(np.max(np.linalg.eigvalsh(res.cov[:2, :2]))))
        for reason, failed in (
            ("not_converged", not res.converged),
            ("low_overlap", res.n_matched < max(60, c.loop_min_overlap * len(src))),
            ("high_rmse", not res.rmse_m < 0.03),
            ("sliding", sig > c.loop_max_sigma_m),
        ):
            if failed:
                self._reject(reason)
                return None
        return Edge(j, i, res.pose, EDGE_INFO)

    def _reject(self, reason: str) -> None:
        """Count a closure candidate rejected for ``reason`` (one of :data:`REJECTIONS`)."""
        self.stats[reason] = self.stats.get(reason, 0) + 1

    def _consistent_loops(self, poses: FloatArray, edges: list[Edge]) -> list[Edge]:
        """Keep loop edges that are pairwise consistent with others nearby.

        Two closures ``a = (j_a, i_a, z_a)`` and ``b`` close one cycle with the front end's
        legs ``j_a -> j_b`` and ``i_b -> i_a``: if both are true, ``x_ja ⊕ z_a`` and ``x_jb ⊕
        z_b ⊕ (x_ib^-1 ⊕ x_ia)`` are the same pose up to the drift along the two legs (the
        pairwise consistency test of Olson 2009 and Mangelson et al. 2018, PCM), whatever
        drift lies between the closures and the map frame. The test's bound grows with the
        legs' path ``s`` as the sequential edges' deviation does (``seq_sigma``):
        ``consistency_gate * (2 s_xy0 + k_xy_d s)`` [m] and ``consistency_gate * (2 s_th0 +
        k_th_d s)`` [rad]. Closures whose ends both lie within ``consistency_window``
        keyframes are compared; a false match (perceptual aliasing) stands alone: an edge is
        kept if at least one other edge and a majority of those compared agree with it.
        """
        c = self.config
        if len(edges) < 2:
            return []
        jj = np.array([e.i for e in edges])  # the earlier keyframe (the edge's i)
        ii = np.array([e.j for e in edges])
        step = np.hypot(*np.diff(poses[:, :2], axis=0).T)
        path = np.concatenate([[0.0], np.cumsum(step)])
        z = np.array([e.z for e in edges])
        via_a = se2.compose(poses[jj], z)  # pose of i_a by closure a
        n = len(edges)
        a_idx, b_idx = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        a_idx, b_idx = a_idx.ravel(), b_idx.ravel()
        leg = se2.between(poses[ii[b_idx]], poses[ii[a_idx]])  # i_b -> i_a, front end
        via_b = se2.compose(via_a[b_idx], leg)
        err = se2.between(via_a[a_idx], via_b)
        s = np.abs(path[jj[a_idx]] - path[jj[b_idx]]) + np.abs(path[ii[a_idx]] - path[ii[b_idx]])
        s_xy0, k_xy_d, s_th0, k_th_d, _ = c.seq_sigma
        g = c.consistency_gate
        ok = (np.hypot(err[:, 0], err[:, 1]) <= g * (2 * s_xy0 + k_xy_d * s)) & (
            np.abs(se2.wrap_angle(err[:, 2])) <= g * (2 * s_th0 + k_th_d * s)
        )
        w = c.consistency_window
        near = (np.abs(ii[a_idx] - ii[b_idx]) <= w) & (np.abs(jj[a_idx] - jj[b_idx]) <= w)
        agree = (near & ok).reshape(n, n)  # includes the edge itself
        n_agree = agree.sum(axis=1)
        keep = (n_agree >= 2) & (2 * n_agree > near.reshape(n, n).sum(axis=1))
        return [e for e, k in zip(edges, keep, strict=True) if k]
