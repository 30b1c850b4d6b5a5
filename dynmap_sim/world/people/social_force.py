"""The facade the world uses: :class:`SocialForce` spawns and steps the people of one run."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.world.people import legs as _legs
from dynmap_sim.world.people import spawning
from dynmap_sim.world.people.correction import correct
from dynmap_sim.world.people.crowd import Crowd
from dynmap_sim.world.people.dynamics import (
    StepConstants,
    goals_due,
    max_move_m,
    move,
    social_force,
)
from dynmap_sim.world.people.obstacles import Obstacles
from dynmap_sim.world.people.params import STRIDE_M
from dynmap_sim.world.polygons import FloatArray
from dynmap_sim.world.spec import PeopleSpec


class SocialForce:
    """Social force stepping for the people of one run among fixed ``segments`` ``(N, 4)``."""

    def __init__(
        self,
        populations: tuple[PeopleSpec, ...],
        segments: FloatArray,
        rng: np.random.Generator,
        broad_phase: bool = True,
        outline_starts: NDArray[np.int64] | None = None,
    ) -> None:
        self.populations = populations
        self.rng = rng
        self.obstacles = Obstacles(segments, broad_phase, outline_starts)
        self._consts: StepConstants | None = None
        self._views: tuple[NDArray[Any], ...] | None = None

    def __getstate__(self) -> dict[str, Any]:
        """Pickle without the step's caches: the complex views (a pickled view would be a
        copy, no longer writing through to the crowd's arrays) and the constants; both are
        made again on the next step."""
        state = self.__dict__.copy()
        state["_views"] = state["_consts"] = None
        return state

    @property
    def segments(self) -> FloatArray:
        """The fixed segments ``(N, 4)`` people walk among."""
        return self.obstacles.segments

    @property
    def broad_phase(self) -> bool:
        """Whether nearby segments come from the grid (else all are candidates)."""
        return self.obstacles.broad_phase

    @property
    def outline_starts(self) -> NDArray[np.int64] | None:
        """First segment of each closed outline in ``segments`` (for inside tests), or None."""
        return self.obstacles.outline_starts

    def pick_goal(
        self,
        pop: PeopleSpec,
        frm: FloatArray,
        r: float,
        avoid: tuple[FloatArray, float] | None = None,
    ) -> FloatArray:
        """A goal in line of sight of ``frm``: an attraction point or a free point of the areas,
        not within ``avoid = (centre, radius_m) + r`` (the robot's disc)."""
        return spawning.pick_goal(self.obstacles, self.rng, pop, frm, r, avoid)

    def spawn(
        self,
        time_s: float,
        day_active: list[bool],
        keep_away: FloatArray | None = None,
        weekday: int | None = None,
    ) -> Crowd:
        """Place the people present at ``time_s`` (profile x count, the profile of
        ``weekday`` where a population has one) on free spots of their areas."""
        return spawning.spawn(
            self.populations, self.obstacles, self.rng, time_s, day_active, keep_away, weekday
        )

    def _constants(self, crowd: Crowd, robot_radius_m: float) -> StepConstants:
        """Per-crowd constants of :meth:`step` (radii, speeds), rebuilt when they change."""
        c = self._consts
        if (
            c is not None
            and c.radius is crowd.radius
            and c.v0 is crowd.v0
            and c.robot_radius_m == robot_radius_m
            and c.n == crowd.n
        ):
            return c
        c = StepConstants.build(crowd.radius, crowd.v0, robot_radius_m)
        self._consts = c
        return c

    def _complex_views(
        self, crowd: Crowd
    ) -> tuple[NDArray[np.complex128], NDArray[np.complex128], NDArray[np.complex128]]:
        """Complex views ``x + iy`` of ``crowd.pos``, ``vel`` and ``goal`` (in-place updates
        write through), made C-contiguous float64 first; kept while the arrays stay."""
        c = self._views
        if c is not None and c[0] is crowd.pos and c[1] is crowd.vel and c[2] is crowd.goal:
            return c[3], c[4], c[5]
        for name in ("pos", "vel", "goal"):
            a = getattr(crowd, name)
            if not (a.flags.c_contiguous and a.dtype == np.float64):
                setattr(crowd, name, np.ascontiguousarray(a, dtype=np.float64))
        views = tuple(getattr(crowd, n).view(np.complex128)[:, 0] for n in ("pos", "vel", "goal"))
        self._views = (crowd.pos, crowd.vel, crowd.goal, *views)
        return views[0], views[1], views[2]

    def step(
        self,
        crowd: Crowd,
        dt_s: float,
        robot_xy: FloatArray | None = None,
        robot_radius_m: float = 0.2,
    ) -> None:
        """Advance ``crowd`` by ``dt_s`` seconds in place (explicit Euler + position correction).

        Positions and velocities are handled as complex numbers ``x + iy`` (views of
        ``crowd.pos`` / ``crowd.vel``).
        """
        if crowd.n == 0:
            return
        z, v, goal = self._complex_views(crowd)
        rows = self.obstacles.rows(z)  # candidate segments (static geometry within REACH_M)
        k = self._constants(crowd, robot_radius_m)
        rz = None if robot_xy is None else complex(float(robot_xy[0]), float(robot_xy[1]))
        force, pair_gap, wall_gap, robot_gap = social_force(z, v, goal, rows, rz, k)
        old = move(z, v, force, dt_s, k)
        # a move is at most dt * vmax (plus rounding): the robot's disc, other bodies and
        # walls are checked only when someone was that close to them
        moved_max_m = max_move_m(dt_s, k.vmax_max)
        gaps = (pair_gap, wall_gap, robot_gap)
        disp = correct(z, v, rows, rz, k, old, gaps, moved_max_m)
        crowd.phase += disp * (2 * np.pi / STRIDE_M)
        redo = goals_due(crowd, goal, z, dt_s, rz, k)
        if redo is None:
            return
        avoid = None if robot_xy is None else spawning.goal_avoid(robot_xy, robot_radius_m)
        spawning.renew_goals(crowd, redo, self.populations, self.obstacles, self.rng, avoid)

    @staticmethod
    def legs(crowd: Crowd) -> tuple[FloatArray, NDArray[np.int32]]:
        """Two leg circles per person ``(2P, 3)`` and the person index of each."""
        return _legs.legs(crowd)

    @staticmethod
    def poses(crowd: Crowd) -> FloatArray:
        """People poses ``(P, 3)``: position and heading of motion [m, rad]."""
        return _legs.poses(crowd)
