"""The facade the world uses: :class:`SocialForce` spawns and steps the people of one run."""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import Any, NamedTuple

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
    social_force,
    speed_factor,
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
        backend: str = "numpy",
    ) -> None:
        self.populations = populations
        self.rng = rng
        self.obstacles = Obstacles(segments, broad_phase, outline_starts)
        self._consts: StepConstants | None = None
        self._views: tuple[NDArray[Any], ...] | None = None
        self._ops: StepOps | None = None
        self.backend = check_backend(backend)

    def __getstate__(self) -> dict[str, Any]:
        """Pickle without the step's caches: the complex views (a pickled view would be a
        copy, no longer writing through to the crowd's arrays) and the constants; both are
        made again on the next step (and the backend's operations)."""
        state = self.__dict__.copy()
        state["_views"] = state["_consts"] = state["_ops"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        """Restore, dropping the caches of states pickled before they were left out."""
        self.__dict__.update(state)
        self._views = self._consts = self._ops = None
        self.__dict__.setdefault("backend", "numpy")

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
        ``crowd.pos`` / ``crowd.vel``), and the exponentials fold their prefactors in
        (``A exp((r - d) / B) = exp(ln A + r / B - d / B)``), so one step is a few dozen
        numpy calls whatever the crowd size (the cost of a step is call overhead for the
        crowds of the shipped worlds).
        """
        if crowd.n == 0:
            return
        z, v, goal = self._complex_views(crowd)
        ops = self.backend_ops()
        rows = ops.rows(self.obstacles, z)  # candidate segments (static geometry within REACH_M)
        k = self._constants(crowd, robot_radius_m, rows.shape[1])
        rz = None if robot_xy is None else complex(float(robot_xy[0]), float(robot_xy[1]))
        force, pair_gap, wall_gap, robot_gap = ops.social_force(crowd, z, v, goal, rows, rz, k)
        v += dt_s * force
        v *= ops.speed_factor(v, k)  # H&M eq. 8
        old = z.copy()
        z += dt_s * v
        # a move is at most dt * vmax (plus rounding): the robot's disc is checked only when
        # someone was that close to it
        moved_max_m = max_move_m(dt_s, k.vmax_max)
        gaps = (pair_gap, wall_gap, robot_gap)
        disp = correct(crowd, z, v, rows, rz, k, old, gaps, moved_max_m, ops.pair_push)
        crowd.phase += disp * (2 * np.pi / STRIDE_M)
        redo = ops.goals_due(crowd, goal, z, dt_s, rz, k)
        if redo is None or not redo.any():
            return
        avoid = None if robot_xy is None else spawning.goal_avoid(robot_xy, robot_radius_m)
        queries = ops.queries(self.obstacles)
        spawning.renew_goals(crowd, redo, self.populations, queries, self.rng, avoid)

    def backend_ops(self) -> StepOps:
        """The backend's operations: numpy's (:mod:`.dynamics`) or, with the numba backend
        (``auto`` when numba is installed), the kernels of :mod:`.dynamics_numba` (the same
        numbers)."""
        if self._ops is None:
            self._ops = NUMPY_OPS if _runs_numpy(self.backend) else compiled_ops()
        return self._ops

    @staticmethod
    def legs(crowd: Crowd) -> tuple[FloatArray, NDArray[np.int32]]:
        """Two leg circles per person ``(2P, 3)`` and the person index of each."""
        return _legs.legs(crowd)

    @staticmethod
    def poses(crowd: Crowd) -> FloatArray:
        """People poses ``(P, 3)``: position and heading of motion [m, rad]."""
        return _legs.poses(crowd)


#: People backends: numpy, numba (extra ``fast``; the same numbers), or auto (numba when it
#: is installed, else numpy; resolved when the people step, so a pickled world resumes on
#: either install).
BACKENDS = ("numpy", "numba", "auto")


def check_backend(backend: str) -> str:
    """``backend`` if it is one of :data:`BACKENDS` and usable; ValueError otherwise."""
    if backend not in BACKENDS:
        raise ValueError(f"people backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "numba":
        from dynmap_sim.jit import numba_available

        if not numba_available():
            raise ValueError('people backend "numba" needs numba: pip install "dynmap-sim[fast]"')
    return backend


def _runs_numpy(backend: str) -> bool:
    """True where a checked ``backend`` steps with numpy's operations on this install
    (``auto`` without numba: :func:`dynmap_sim.jit.kernel_backend`)."""
    if backend == "numpy":  # (numba is not even imported)
        return True
    from dynmap_sim.jit import kernel_backend

    return kernel_backend(backend) is None


class StepOps(NamedTuple):
    """What differs between the backends in a step of :meth:`SocialForce.step` and in
    placing the legs."""

    rows: Callable[[Obstacles, NDArray[np.complex128]], NDArray[np.complex128]]
    social_force: Callable[..., tuple[NDArray[np.complex128], float, FloatArray, float]]
    speed_factor: Callable[[NDArray[np.complex128], StepConstants], FloatArray]
    #: who needs a new goal (a mask, or None when nobody does)
    goals_due: Callable[..., NDArray[np.bool_] | None]
    #: the compiled weights of the pair separation (None: numpy's)
    pair_push: Callable[..., bool] | None
    #: the compiled heading and swing of the legs (None: numpy's;
    #: :func:`.legs.leg_centres_into`)
    legs: Callable[..., None] | None
    #: the obstacles' queries goal choice asks (free space, line of sight): the obstacles
    #: themselves, or their compiled twin (:func:`.obstacles_numba.queries`)
    queries: Callable[[Obstacles], spawning.GoalQueries]


def _own_queries(obstacles: Obstacles) -> Obstacles:
    """numpy's queries: the obstacles' own methods."""
    return obstacles


NUMPY_OPS = StepOps(Obstacles.rows, social_force, speed_factor, goals_due, None, None, _own_queries)


def compiled_ops(python: bool = False) -> StepOps:
    """:class:`StepOps` of the numba backend: :mod:`.dynamics_numba`'s functions with its
    compiled kernels (imported on first use; ``python=True``: the plain-Python kernels, for
    tests)."""
    from dynmap_sim.world.people import dynamics_numba as dn
    from dynmap_sim.world.people import obstacles_numba

    kern = dn.Kernels(python=python)
    return StepOps(
        partial(dn.candidate_rows, kern),
        partial(dn.social_force, kern),
        partial(dn.speed_factor, kern),
        partial(dn.goals_due, kern),
        kern.pair_push,
        kern.legs,
        partial(obstacles_numba.queries, python=python),
    )
