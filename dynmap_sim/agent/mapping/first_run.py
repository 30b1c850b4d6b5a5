"""Static SLAM of the first run: the keyframe front end, loop closure, and the grid.

Biber & Duckett §4: "an initial map is built from the first run ... by a classical static
SLAM algorithm ... based on scan matching". :class:`FirstRunMapper` is that algorithm, made
of two parts:

* **front end** (online, :meth:`FirstRunMapper.update`): scan-to-map ICP against the recent
  keyframes, :class:`~.keyframe_slam.KeyframeSLAM`;
* **loop closure and back end** (:meth:`FirstRunMapper.finish`): drift-tolerant closures,
  pairwise ICP edges and the keyframe pose graph, :class:`~.loop_closure.LoopClosure`;

then the optimized keyframe scans are rendered into a 5 cm
:class:`~dynmap_sim.agent.grid.OccupancyGrid`, and every scan's pose is re-attached rigidly
to its reference keyframe. Its parameters are one :class:`FirstRunConfig`, which a scenario's
flat ``mapper_params`` table fills (:meth:`FirstRunConfig.from_params`).

Where the scenario's prior grants the walls, the front end matches them too
(:attr:`~.keyframe_slam.KeyframeSLAMConfig.anchor_walls`): the map is then registered to the
plan as it is built, and the back end ties the keyframes to the walls they see instead of
closing loops (:mod:`.wall_factors`; B&D had no plan; without one, or with ``anchor_walls =
false``, this is their first run).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.agent.grid import OccupancyGrid
from dynmap_sim.agent.mapping.keyframe_slam import Keyframe, KeyframeSLAM, KeyframeSLAMConfig
from dynmap_sim.agent.mapping.loop_closure import LoopClosure, LoopClosureConfig
from dynmap_sim.agent.params import Positive, build, params_dataclass
from dynmap_sim.types import LaserSpec, Odometry, PoseEstimate, Scan

FloatArray = NDArray[np.float64]


@params_dataclass("mapper_params")
class FirstRunConfig:
    """Parameters of the first run's SLAM: its two parts and the rendered grid."""

    #: The front end (:class:`~.keyframe_slam.KeyframeSLAMConfig`).
    slam: KeyframeSLAMConfig = field(default_factory=KeyframeSLAMConfig)
    #: Loop closure and pose graph (:class:`~.loop_closure.LoopClosureConfig`).
    loops: LoopClosureConfig = field(default_factory=LoopClosureConfig)
    #: Cell side of the rendered grid [m] (5 cm: the URG-04LX's noise is 1 cm at 1 m).
    resolution_m: Positive = 0.05
    #: Readings farther than this [m] only clear free space in the grid (the range noise is
    #: 1 % of the range: far hits blur the walls). ``static-mcl`` raises it to the sensor's
    #: range (:func:`~dynmap_sim.agent.maps.map_source.make_map_source`).
    map_max_hit_range_m: Positive = 3.0

    @classmethod
    def from_params(cls, **params: Any) -> FirstRunConfig:
        """The config of a flat table of field names of this class and its two parts (a
        scenario's ``mapper_params``, e.g. ``{"global_loops": False, "voxel_m": 0.05}``);
        an unknown name is a :class:`TypeError` that lists them."""
        who = "mapper_params"
        slam = {f.name for f in fields(KeyframeSLAMConfig)}
        loops = {f.name for f in fields(LoopClosureConfig)}
        own = {f.name for f in fields(cls)} - {"slam", "loops"}
        unknown = sorted(set(params) - own - slam - loops)
        if unknown:
            known = ", ".join(sorted(own | slam | loops))
            raise TypeError(f"{who}: unknown parameters {unknown}; known: {known}")
        return cls(
            slam=build(KeyframeSLAMConfig, {k: params[k] for k in slam & set(params)}, who),
            loops=build(LoopClosureConfig, {k: params[k] for k in loops & set(params)}, who),
            **{k: v for k, v in params.items() if k in own},
        )


@dataclass
class StaticMap:
    """The first run's map: every scan's pose, the grid, and the keyframes (optimized)."""

    trajectory: FloatArray
    grid: OccupancyGrid
    keyframes: list[Keyframe]
    stamps_s: FloatArray = field(default_factory=lambda: np.zeros(0))
    n_loop_closures: int = 0


class FirstRunMapper:
    """Online keyframe SLAM; :meth:`finish` closes loops and renders the map."""

    def __init__(
        self,
        laser: LaserSpec,
        initial_pose: ArrayLike,
        config: FirstRunConfig | None = None,
        walls: FloatArray | None = None,
    ) -> None:
        self.laser = laser
        self.config = FirstRunConfig() if config is None else config
        self.slam = KeyframeSLAM(laser, initial_pose, self.config.slam, walls)
        self.loop_closure = LoopClosure(self.config.loops)

    def update(self, odom: Odometry, scan: Scan) -> PoseEstimate:
        """Fuse one odometry reading and scan; return the front end's pose estimate (on an
        anchored run, every ``wall_graph_every`` keyframes after the keyframes were optimized
        on the walls)."""
        slam = self.slam
        n = len(slam.keyframes)
        est = slam.update(odom, scan)
        every = self.config.loops.wall_graph_every
        k = len(slam.keyframes)
        if k > n and every and k % every == 0 and self._on_walls:
            slam.move_keyframes(self.loop_closure.optimize_on_walls(slam))
            est = PoseEstimate(slam.pose.copy(), est.cov, est.extras)
        return est

    @property
    def _on_walls(self) -> bool:
        """The keyframes are optimized on the prior's walls (anchored, ``wall_factors``)."""
        return bool(len(self.slam.wall_points)) and self.config.loops.wall_factors

    def finish(self) -> StaticMap:
        """Close loops, optimize the pose graph, render the grid; return the static map."""
        slam = self.slam
        if not slam.keyframes:
            raise ValueError("FirstRunMapper.finish() before any update()")
        if len(slam.wall_points):
            # The prior's walls hold the map frame (KeyframeSLAMConfig.anchor_walls): the
            # keyframes are optimized against them (LoopClosureConfig.wall_factors), or kept.
            n_loops = 0
            if self._on_walls:
                poses = self.loop_closure.optimize_on_walls(slam, refresh=True)
            else:
                poses = np.array([k.pose for k in slam.keyframes])
        else:
            poses, n_loops = self.loop_closure.optimize(slam)
        kfs = [Keyframe(poses[m], k.ranges_m, k.scan_index) for m, k in enumerate(slam.keyframes)]
        grid = OccupancyGrid.from_scans(
            poses,
            np.array([k.ranges_m for k in slam.keyframes]),
            self.laser,
            resolution_m=self.config.resolution_m,
            max_hit_range_m=self.config.map_max_hit_range_m,
        )
        return StaticMap(
            trajectory=slam.trajectory(poses),
            grid=grid,
            keyframes=kfs,
            stamps_s=np.array(slam.stamps_s),
            n_loop_closures=n_loops,
        )
