"""The facade the world uses: :class:`SocialForce` spawns and steps the people of one run."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.world.people import legs as _legs
from dynmap_sim.world.people import spawning
from dynmap_sim.world.people.correction import correct
from dynmap_sim.world.people.crowd import Crowd
from dynmap_sim.world.people.dynamics import StepConstants, goals_due, social_force
from dynmap_sim.world.people.obstacles import Obstacles
from dynmap_sim.world.people.params import ROBOT_GAP_M, STRIDE_M
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
        self, time_s: float, day_active: list[bool], keep_away: FloatArray | None = None
    ) -> Crowd:
        """Place the people present at ``time_s`` (profile x count) on free spots of their areas."""
        return spawning.spawn(
            self.populations, self.obstacles, self.rng, time_s, day_active, keep_away
        )

    def _constants(self, crowd: Crowd, robot_radius_m: float, k_cols: int) -> StepConstants:
        """Per-crowd constants of :meth:`step` (radii, speeds), rebuilt when they change."""
        c = self._consts
        if (
            c is not None
            and c.radius is crowd.radius
            and c.v0 is crowd.v0
            and c.robot_radius_m == robot_radius_m
            and c.n == crowd.n
            and c.k_cols == k_cols
        ):
            return c
        c = StepConstants.build(crowd.radius, crowd.v0, robot_radius_m, k_cols)
        self._consts = c
        return c

    def step(
        self,
        crowd: Crowd,
        dt_s: float,
        robot_xy: FloatArray | None = None,
        robot_radius_m: float = 0.2,
    ) -> None:
        """Advance ``crowd`` by ``dt_s`` seconds in place (explicit Euler + position correction).

        Positions and velocities are handled as complex numbers ``x + iy`` (views of
        ``crowd.pos`` / ``crowd.vel``), and the exponentials fold their prefactors in
        (``A exp((r - d) / B) = exp(ln A + r / B - d / B)``), so one step is a few dozen
        numpy calls whatever the crowd size (the cost of a step is call overhead for the
        crowds of the shipped worlds).
        """
        if crowd.n == 0:
            return
        for name in ("pos", "vel", "goal"):
            a = getattr(crowd, name)
            if not (a.flags.c_contiguous and a.dtype == np.float64):
                setattr(crowd, name, np.ascontiguousarray(a, dtype=np.float64))
        z = crowd.pos.view(np.complex128)[:, 0]  # views: in-place updates write through
        v = crowd.vel.view(np.complex128)[:, 0]
        goal = crowd.goal.view(np.complex128)[:, 0]
        rows = self.obstacles.rows(z)  # candidate segments (static geometry within REACH_M)
        k = self._constants(crowd, robot_radius_m, rows.shape[1])
        rz = None if robot_xy is None else complex(float(robot_xy[0]), float(robot_xy[1]))
        force, pair_gap, wall_gap = social_force(crowd, z, v, goal, rows, rz, k)
        v += dt_s * force
        v *= np.minimum(1.0, k.vmax / np.maximum(np.abs(v), 1e-9))  # H&M eq. 8
        old = z.copy()
        z += dt_s * v
        correct(crowd, z, v, rows, rz, k, old, pair_gap, wall_gap)
        crowd.phase += np.abs(z - old) * (2 * np.pi / STRIDE_M)
        redo = goals_due(crowd, goal, z, dt_s, rz, k)
        if not redo.any():
            return
        avoid = None if rz is None else (robot_xy, robot_radius_m + ROBOT_GAP_M + 0.1)
        spawning.renew_goals(crowd, redo, self.populations, self.obstacles, self.rng, avoid)

    @staticmethod
    def legs(crowd: Crowd) -> tuple[FloatArray, NDArray[np.int32]]:
        """Two leg circles per person ``(2P, 3)`` and the person index of each."""
        return _legs.legs(crowd)

    @staticmethod
    def legs_into(crowd: Crowd, out: FloatArray) -> None:
        """Write the two leg circles of each person into rows of ``out`` ``(2P, 3)``."""
        _legs.legs_into(crowd, out)

    @staticmethod
    def poses(crowd: Crowd) -> FloatArray:
        """People poses ``(P, 3)``: position and heading of motion [m, rad]."""
        return _legs.poses(crowd)
