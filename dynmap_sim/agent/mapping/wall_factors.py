"""Factors that tie the first run's keyframes to the prior's walls.

Where a scenario grants the walls, the keyframe pose graph of the first run gets, beside its
sequential edges, one absolute factor per keyframe whose scan fits the walls: the keyframe's
points matched by ICP against the walls *visible* from its pose, with the match's
covariance. This is the floor-plan constraint of Boniardi, Caselitz, Kümmerle & Burgard
(2017, "A pose graph-based localization system for long-term navigation in CAD floor
plans"): the plan holds the map frame wherever a scan sees a wall, and the sequential edges
carry it through the stretches where none is in range, so a heading error gathered in an
open hall is taken out of the keyframes before and after it instead of staying in the map.
The graph is optimized during the run as keyframes come, as Boniardi et al. do, so that the
front end goes on from corrected keyframes, and once more at its end
(:meth:`.loop_closure.LoopClosure.optimize_on_walls`).

Visibility matters because a wall of the plan is a closed outline: both faces of a
partition are in it, and a keyframe that drifted by more than half the wall's thickness is
pulled onto the face it cannot see. :meth:`WallPlan.visible_from` keeps the outline points
that no other segment hides from the keyframe's position.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.grid import sample_segments
from dynmap_sim.agent.mapping.scan_matcher import PointMap, match_scan
from dynmap_sim.agent.planning.route_graph import project_onto_segments

if TYPE_CHECKING:
    from dynmap_sim.agent.mapping.loop_closure import LoopClosureConfig

FloatArray = NDArray[np.float64]

#: Floor of a wall factor's covariance: 1 cm in x and y, 0.005 rad in theta (the fixed
#: information of a verified loop closure, :data:`.loop_closure.EDGE_INFO`).
_FLOOR_COV = np.diag([0.01**2, 0.01**2, 0.005**2])


@dataclass(frozen=True)
class WallPlan:
    """The prior's wall outline ``segments`` ``(N, 4)`` sampled as ``points`` ``(M, 2)``
    [m], with the segment each point lies on (``segment_of``, ``(M,)``)."""

    segments: FloatArray
    points: FloatArray
    segment_of: NDArray[np.intp]

    @classmethod
    def from_segments(cls, segments: ArrayLike, spacing_m: float) -> WallPlan:
        """Points every ``spacing_m`` [m] or closer along each segment, both ends included."""
        seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
        pts, of = sample_segments(seg, spacing_m)
        return cls(seg, pts, of)

    def visible_from(self, xy: ArrayLike, reach_m: float) -> FloatArray:
        """The points within ``reach_m`` of ``xy`` that no other segment hides: the ray from
        ``xy`` to the point crosses no segment but its own short of the last 2 cm (the
        points on a corner's far segment are not hidden by its near one)."""
        o = np.asarray(xy, dtype=np.float64)[:2]
        d = self.points - o
        dist = np.hypot(d[:, 0], d[:, 1])
        near = dist <= reach_m
        if not near.any():
            return np.zeros((0, 2))
        d, dist, own = d[near], dist[near], self.segment_of[near]
        a, b = self.segments[:, :2], self.segments[:, 2:]
        cand = np.nonzero(project_onto_segments(o, a, b)[2] <= reach_m)[0]
        a, ab = a[cand], b[cand] - a[cand]
        # the ray o + u d (0 < u < 1) against each segment a + v ab (0 <= v <= 1)
        den = d[:, None, 0] * ab[None, :, 1] - d[:, None, 1] * ab[None, :, 0]
        den = np.where(den == 0.0, np.nan, den)
        w = a[None, :, :] - o
        u = (w[..., 0] * ab[None, :, 1] - w[..., 1] * ab[None, :, 0]) / den
        v = (w[..., 0] * d[:, None, 1] - w[..., 1] * d[:, None, 0]) / den
        short = 1.0 - 0.02 / np.maximum(dist, 1e-6)
        hidden = (u > 1e-6) & (u < short[:, None]) & (v >= 0.0) & (v <= 1.0)
        hidden &= cand[None, :] != own[:, None]
        return self.points[np.nonzero(near)[0][~hidden.any(axis=1)]]


def wall_factor(
    plan: WallPlan,
    points: FloatArray,
    pose: FloatArray,
    reach_m: float,
    huber_m: float,
    config: LoopClosureConfig,
) -> tuple[FloatArray, FloatArray] | None:
    """``(pose, information)`` of a keyframe whose ``points`` ``(N, 2)`` (its own frame),
    at ``pose``, fit the walls visible from it, or None: ICP with the gates ``wall_gate_m``
    (coarse, then fine), kept if it converges with at least ``wall_min_points`` points
    within the fine gate at an RMS residual below ``wall_max_rmse_m``. The information is
    the inverse of ICP's covariance (scan information divided by ``wall_info_inflation``)
    plus a floor of 1 cm and 0.005 rad."""
    walls = plan.visible_from(pose, reach_m)
    if len(points) < config.wall_min_points or len(walls) < config.wall_min_points:
        return None
    target = PointMap(walls)
    start = pose
    for gate in config.wall_gate_m:
        res = match_scan(
            points,
            target,
            start,
            max_correspondence_m=gate,
            max_iterations=30,
            huber_m=huber_m,
            info_inflation=config.wall_info_inflation,
        )
        start = res.pose
    fits = res.n_matched >= config.wall_min_points and res.rmse_m < config.wall_max_rmse_m
    if not (res.converged and fits):
        return None
    info = np.linalg.inv(res.cov + _FLOOR_COV)
    return res.pose, 0.5 * (info + info.T)
