"""Loop closure keyframe by keyframe, as an online graph SLAM does it (Karto / slam_toolbox,
Konolige et al. 2010 "Efficient sparse pose adjustment for 2D mapping"; Cartographer, Hess
et al. 2016 §V), replayed over the first run's keyframes when the run ends.

Why: searching closures only once, at the end, against the front end's whole drift fails
when the drift between revisits exceeds the search window. An online mapper closes each
loop as soon as it comes back, so the drift it must bridge is only the drift **since its
last closure**, and every closure shrinks the drift of what follows.

Here keyframes are visited in order. The search window of keyframe ``i`` grows with the path
driven since the last accepted closure (``drift_window``), candidates are the nearest
earlier keyframes in the current estimate, each is verified by the correlative search and
ICP of :class:`~.loop_closure.LoopClosure` (score, residual, overlap, conditioning). A
closure is accepted when it agrees with the current estimate (implied correction within
``accept_m`` / ``accept_rad``) or when another verified closure within ``confirm_keyframes``
implies the same correction (Olson 2009's single-cluster idea in its simplest pairwise form:
a false match from perceptual aliasing stands alone). Each accepted closure enters the pose
graph, optimized with a Huber loss (Cartographer's robust back end) when its correction is
worth it; the keyframes not yet visited follow rigidly, so the next searches start from the
corrected estimate.

Off by default (``LoopClosureConfig.incremental_loops``; measurements: docs/tuning/slam.md).
"""

from __future__ import annotations

from typing import Annotated, Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim import se2
from dynmap_sim.agent.mapping.pose_graph import Edge, optimize_pose_graph
from dynmap_sim.agent.params import AsTuple, Int, params_dataclass

FloatArray = NDArray[np.float64]


@params_dataclass()
class IncrementalLoopConfig:
    """Parameters of the incremental closure search (lengths in m, angles in rad).

    General values, not fitted to one log: the windows assume the front end drifts at most
    5 % of the distance and 0.6 degrees per metre between closures."""

    #: Search half-window in x and y after driving ``s`` m since the last closure:
    #: ``min(a + b s, cap)`` as ``(a, b, cap)``.
    drift_window_m: Annotated[tuple[float, float, float], AsTuple] = (0.3, 0.05, 4.0)
    #: ... and in theta [rad, rad/m, rad].
    drift_window_rad: Annotated[tuple[float, float, float], AsTuple] = (0.1, 0.01, 0.6)
    #: A verified closure whose implied correction is within this [m] / [rad] of the
    #: current estimate is accepted at once (it agrees with what is already known).
    accept_m: float = 0.15
    accept_rad: float = 0.05
    #: Otherwise it waits for another verified closure within this many keyframes that
    #: implies the same correction (within ``agree_m`` / ``agree_rad``).
    confirm_keyframes: Int = 20
    agree_m: float = 0.25
    agree_rad: float = 0.05
    #: Re-optimize the graph after an accepted closure whose correction exceeds this [m]
    #: (smaller ones are added and optimized with the next).
    reoptimize_m: float = 0.05


def _candidates(cur: FloatArray, i: int, lcc: Any, w_xy: float) -> list[int] | None:
    """The earlier keyframes to verify as closures of keyframe ``i``: the nearest in the
    current estimate ``cur`` ``(n, 3)`` within the loop radius widened by the drift window
    ``w_xy`` [m], at most ``lcc.loop_candidates``, no two within twice the loop gap of each
    other (None: none is near); ``lcc``: the :class:`~.loop_closure.LoopClosureConfig`."""
    cand = np.arange(0, i - lcc.loop_min_gap)
    dist = np.hypot(*(cur[cand, :2] - cur[i, :2]).T)
    near = dist < 0.5 * lcc.loop_radius_m + w_xy
    if not np.any(near):
        return None
    cand, dist = cand[near], dist[near]
    chosen: list[int] = []
    for m in np.argsort(dist):
        if len(chosen) >= lcc.loop_candidates:
            break
        if all(abs(int(cand[m]) - o) > 2 * lcc.loop_min_gap for o in chosen):
            chosen.append(int(cand[m]))
    return chosen


def incremental_closures(
    lc,  # noqa: ANN001  # LoopClosure (circular import)
    slam,  # noqa: ANN001  # KeyframeSLAM
    seq: list[Edge],
    config: IncrementalLoopConfig | None = None,
) -> tuple[FloatArray, list[Edge]]:
    """The keyframe poses after closing loops in order, and the accepted closure edges."""
    c = IncrementalLoopConfig() if config is None else config
    lcc = lc.config
    fe = np.array([k.pose for k in slam.keyframes], dtype=np.float64)
    n = len(fe)
    cur = fe.copy()
    path = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(fe[:, :2], axis=0).T))])
    since = 0.0  # path length at the last accepted closure
    tables: dict = {}
    loops: list[Edge] = []
    pending: list[tuple[int, Edge, FloatArray]] = []
    dirty = False
    stats = {"searched": 0, "verified": 0, "agreed": 0, "confirmed": 0, "no_candidate": 0}
    lc.stats = stats  # _verified_loop counts its rejections here too
    for i in range(lcc.loop_min_gap + 1, n, lcc.loop_stride):
        src = slam.keyframe_points[i]
        if len(src) < 30:
            continue
        s = path[i] - since
        w_xy = min(c.drift_window_m[0] + c.drift_window_m[1] * s, c.drift_window_m[2])
        w_th = min(c.drift_window_rad[0] + c.drift_window_rad[1] * s, c.drift_window_rad[2])
        chosen = _candidates(cur, i, lcc, w_xy)
        if chosen is None:
            stats["no_candidate"] += 1
            continue
        accepted: list[Edge] = []
        pending = [p for p in pending if i - p[0] <= c.confirm_keyframes]
        for j in chosen:
            edge = lc._verified_loop(cur, slam, tables, j, i, w_xy, 0.0, w_theta_rad=w_th)
            stats["searched"] += 1
            if edge is None:
                continue
            stats["verified"] += 1
            corr = se2.between(cur[i], se2.compose(cur[j], edge.z))
            if np.hypot(corr[0], corr[1]) < c.accept_m and abs(corr[2]) < c.accept_rad:
                accepted.append(edge)
                stats["agreed"] += 1
                continue
            mates = [
                p
                for p in pending
                if np.hypot(*(p[2][:2] - corr[:2])) < c.agree_m
                and abs(se2.wrap_angle(p[2][2] - corr[2])) < c.agree_rad
            ]
            if mates:
                stats["confirmed"] += 1
                accepted.append(edge)
                accepted.extend(p[1] for p in mates)
                pending = [p for p in pending if all(p is not q for q in mates)]
            else:
                pending.append((i, edge, corr))
        if not accepted:
            continue
        loops.extend(accepted)
        since = path[i]
        big = max(
            float(np.hypot(*se2.between(cur[e.j], se2.compose(cur[e.i], e.z))[:2]))
            for e in accepted
        )
        if big > c.reoptimize_m or dirty:
            cur = optimize_pose_graph(cur, seq + loops, anchor=0, loss="huber", f_scale=3.0)
            pending = []  # their corrections were relative to the estimate before
            dirty = False
        else:
            dirty = True
    if dirty and loops:
        cur = optimize_pose_graph(cur, seq + loops, anchor=0, loss="huber", f_scale=3.0)
    return cur, loops
