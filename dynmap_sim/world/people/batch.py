"""The people of many runs stepped as one array (a vector env's worlds, one crowd each).

:class:`CrowdBatch` steps ``E`` crowds, each among its own segments, with its own robot and
its own generator, with the numbers :meth:`SocialForce.step` gives each of them alone, bit
for bit: the people of all crowds are the rows of one set of arrays, so the numpy calls of
the social force, the speed cap, the move and the goal progress are paid once for all
crowds instead of once per crowd.

Layout: row ``r`` is person ``j`` of crowd ``e``. Its sources are ``Pmax`` people columns
(crowd ``e``'s people first, then padding), the robot, and ``Kmax`` candidate segments
(crowd ``e``'s grid cell list, padded with its far dummy); padding has ``ln A = -inf`` (no
force). Element by element this is :func:`~.dynamics.social_force`'s arithmetic; the sums
over a row are taken over exactly the single crowd's ``P + 1 + K`` sources in its order (rows
grouped by that width), since a floating-point sum depends on its length and order. The
rare corrections (a body in the robot's disc, overlapping bodies, a body in a wall) and new
goals run per crowd on that crowd's rows, through the single crowd's own functions.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.world.people import spawning
from dynmap_sim.world.people.correction import (
    _clear_robot,
    _push_out_of_walls,
    _separate_pairs,
)
from dynmap_sim.world.people.crowd import Crowd
from dynmap_sim.world.people.dynamics import (
    StepConstants,
    driving_force,
    evasion,
    goals_due,
    max_move_m,
    repulsion_terms,
    segment_vectors_into,
    speed_factor,
)
from dynmap_sim.world.people.legs import leg_centres_into
from dynmap_sim.world.people.params import CELL_M, STRIDE_M
from dynmap_sim.world.people.social_force import NUMPY_OPS, SocialForce
from dynmap_sim.world.polygons import FloatArray

IntArray = NDArray[np.int64]


@dataclass
class _Layout:
    """The constants of a batch of crowds (rebuilt when a crowd's constants change)."""

    ks: tuple[StepConstants, ...]
    starts: IntArray
    """First row of each crowd (``E + 1`` entries, the last the number of rows)."""
    n: int
    """``Pmax``: the people columns of a row (named as :class:`StepConstants` ``n``)."""
    people_src: IntArray
    """``(N, Pmax)``: the row of each people column (the crowd's own people, then its first)."""
    log_a: FloatArray
    inv_b: FloatArray
    rsum_masked: FloatArray
    v0_tau: FloatArray
    vmax: FloatArray
    radius: FloatArray
    evade_log_a: FloatArray
    robot_need: FloatArray
    robot_goal_reach: FloatArray
    vmax_max: FloatArray
    """Per crowd: the largest speed of anyone [m/s] (bounds a step's move)."""
    sum_groups: list[tuple[IntArray, IntArray]]
    """Rows of equal width ``P + 1 + K`` and their sources' flat indices ``(rows, width)``."""
    segrows: NDArray[np.complex128]
    """Every crowd's grid rows (p0, conj(d), 1/|d|^2), end to end."""
    cells: IntArray
    """Every crowd's cell lists (into ``segrows``, padded with its far dummy), end to end."""
    origin_c: NDArray[np.complex128]
    cell_hi: IntArray
    """Per row: the largest cell index along x and y (``(N, 2)``)."""
    cell_ny: IntArray
    cell_first: IntArray
    """Per row: the first cell of its crowd in ``cells``."""


class CrowdBatch:
    """Steps many crowds at once (see the module docstring); keeps the batch's constants
    between steps, rebuilt when a crowd changes (a new run)."""

    def __init__(self) -> None:
        self._layout: _Layout | None = None
        self._moved: _Moved | None = None
        self._state: _State | None = None

    @staticmethod
    def batchable(forces: SocialForce) -> bool:
        """True if :meth:`step` can take this crowd's forces (numpy backend, broad phase)."""
        return forces.backend_ops() is NUMPY_OPS and forces.broad_phase

    def step(
        self,
        forces: Sequence[SocialForce],
        crowds: Sequence[Crowd],
        dt_s: float,
        robot_xy: Sequence[FloatArray],
        robot_radius_m: Sequence[float],
    ) -> None:
        """:meth:`SocialForce.step` of each ``forces[e]`` on ``crowds[e]`` (not empty; each
        :meth:`batchable`), with robot ``robot_xy[e]`` (``(2,)`` float array) of radius
        ``robot_radius_m[e]``; the same numbers as one by one."""
        ks = tuple(
            f._constants(c, float(rr), f.obstacles.grid.cells.shape[1])
            for f, c, rr in zip(forces, crowds, robot_radius_m, strict=True)
        )
        lay = self._layout
        if lay is None or len(lay.ks) != len(ks) or any(map(_differ, lay.ks, ks)):
            lay = self._layout = _build_layout(forces, ks, lay)
        state = self._state
        if state is None or not state.holds(crowds):
            state = self._state = _State(crowds)
        pos, vel, goal_xy = state.pos, state.vel, state.goal
        z = pos.view(np.complex128)[:, 0]
        v = vel.view(np.complex128)[:, 0]
        goal = goal_xy.view(np.complex128)[:, 0]
        starts = lay.starts
        counts = starts[1:] - starts[:-1]
        rz_e = [complex(float(p[0]), float(p[1])) for p in robot_xy]
        rz = np.array(rz_e, dtype=np.complex128).repeat(counts)
        rows = _candidate_rows(lay, z)
        # the social force (dynamics.social_force, row by row)
        e, force = driving_force(z, v, goal, lay)  # type: ignore[arg-type]
        n = lay.n
        diff = np.empty((z.shape[0], n + 1 + rows.shape[1]), dtype=np.complex128)
        np.subtract(z[:, None], z.take(lay.people_src), out=diff[:, :n])
        np.subtract(z, rz, out=diff[:, n])
        segment_vectors_into(z, rows, diff[:, n + 1 :])
        d = np.abs(diff)
        first = starts[:-1]
        pair_gap = np.minimum.reduceat((d[:, :n] - lay.rsum_masked).min(axis=1), first)
        wall_gap = d[:, n + 1 :].min(axis=1) - lay.radius
        terms = repulsion_terms(diff, d, lay).ravel()
        for which, idx in lay.sum_groups:
            force[which] += terms[idx].sum(axis=1)
        force += evasion(e, diff[:, n], d[:, n], lay)  # type: ignore[arg-type]
        robot_gap = np.minimum.reduceat(d[:, n] - lay.robot_need, first)
        # the move (SocialForce.step)
        v += dt_s * force
        v *= speed_factor(v, lay)  # type: ignore[arg-type]
        old = z.copy()
        z += dt_s * v
        moved_max = max_move_m(dt_s, lay.vmax_max)
        # the position correction (correction.correct), crowd by crowd where needed
        rows_at = starts.tolist()
        for i in (robot_gap <= moved_max).nonzero()[0].tolist():
            s = slice(rows_at[i], rows_at[i + 1])
            _clear_robot(z[s], rz_e[i], ks[i])
        disp = np.abs(z - old)
        pairs = (counts > 1) & (2.0 * np.maximum.reduceat(disp, first) >= pair_gap)
        for i in pairs.nonzero()[0].tolist():
            s = slice(rows_at[i], rows_at[i + 1])
            _separate_pairs(z[s], ks[i])
            disp[s] = np.abs(z[s] - old[s])
        walls = np.logical_or.reduceat(disp >= wall_gap, first)
        for i in walls.nonzero()[0].tolist():
            s = slice(rows_at[i], rows_at[i + 1])
            _push_out_of_walls(crowds[i], z[s], v[s], rows[s, : ks[i].k_cols])
            disp[s] = np.abs(z[s] - old[s])
        phase = state.phase
        phase += disp * (2 * np.pi / STRIDE_M)
        progress = _Progress(state.best_goal_m, state.stuck_s)
        redo = goals_due(progress, goal, z, dt_s, rz, lay)  # type: ignore[arg-type]
        due = np.logical_or.reduceat(redo, first)
        self._moved = _Moved(pos, vel, phase)
        state.progressed(progress.best_goal_m, progress.stuck_s)
        for i in due.nonzero()[0].tolist():
            f = forces[i]
            avoid = spawning.goal_avoid(robot_xy[i], float(robot_radius_m[i]))
            s = slice(rows_at[i], rows_at[i + 1])
            spawning.renew_goals(crowds[i], redo[s], f.populations, f.obstacles, f.rng, avoid)

    def positions(self) -> NDArray[np.complex128]:
        """The positions ``x + iy`` of every person after the last :meth:`step`, crowd
        after crowd."""
        assert self._moved is not None
        return self._moved.pos.view(np.complex128)[:, 0]

    def leg_centres(self) -> NDArray[np.complex128]:
        """The centres ``x + iy`` of the legs of every person after the last :meth:`step`,
        crowd after crowd (:func:`~.legs.leg_centres_into` of each crowd, in one pass)."""
        m = self._moved
        assert m is not None
        out = np.empty(2 * m.pos.shape[0], dtype=np.complex128)
        leg_centres_into(m, out)  # type: ignore[arg-type]
        return out


def _differ(a: object, b: object) -> bool:
    return a is not b


@dataclass
class _Moved:
    """Positions, velocities and gait phases of all rows after a step (what the legs read)."""

    pos: FloatArray
    vel: FloatArray
    phase: FloatArray


class _State:
    """The per-person state of a batch's crowds as the rows of joint arrays, crowd after
    crowd, each crowd's arrays being views of its rows: a step reads and moves everyone in
    place, with nothing to gather before or to write back after (what a crowd's own
    functions change in place, a new goal say, lands in the joint rows too)."""

    def __init__(self, crowds: Sequence[Crowd]) -> None:
        self.crowds = tuple(crowds)
        at = np.cumsum([0, *(c.n for c in crowds)]).tolist()
        self.rows = [slice(a, b) for a, b in zip(at[:-1], at[1:], strict=True)]
        self.pos = np.concatenate([c.pos for c in crowds])
        self.vel = np.concatenate([c.vel for c in crowds])
        self.goal = np.concatenate([c.goal for c in crowds])
        self.phase = np.concatenate([c.phase for c in crowds])
        self.best_goal_m = np.concatenate([c.best_goal_m for c in crowds])
        self.stuck_s = np.concatenate([c.stuck_s for c in crowds])
        self._given: list[list[FloatArray]] = []  # each crowd's views, in _FIELDS order
        for c, s in zip(self.crowds, self.rows, strict=True):
            c.pos, c.vel, c.goal = self.pos[s], self.vel[s], self.goal[s]
            c.phase, c.best_goal_m, c.stuck_s = self.phase[s], self.best_goal_m[s], self.stuck_s[s]
            self._given.append([c.pos, c.vel, c.goal, c.phase, c.best_goal_m, c.stuck_s])

    def holds(self, crowds: Sequence[Crowd]) -> bool:
        """True if these are this state's crowds, in order, with the arrays it gave them
        (a new run, or a crowd stepped on its own since, needs a new state)."""
        return len(crowds) == len(self.crowds) and all(
            c is mine
            and c.pos is g[0]
            and c.vel is g[1]
            and c.goal is g[2]
            and c.phase is g[3]
            and c.best_goal_m is g[4]
            and c.stuck_s is g[5]
            for c, mine, g in zip(crowds, self.crowds, self._given, strict=True)
        )

    def progressed(self, best_goal_m: FloatArray, stuck_s: FloatArray) -> None:
        """Take the new goal progress (:func:`~.dynamics.goals_due` replaces its arrays)."""
        self.best_goal_m, self.stuck_s = best_goal_m, stuck_s
        for c, s, g in zip(self.crowds, self.rows, self._given, strict=True):
            c.best_goal_m = g[4] = best_goal_m[s]
            c.stuck_s = g[5] = stuck_s[s]


@dataclass
class _Progress:
    """The goal-progress state :func:`~.dynamics.goals_due` reads and replaces."""

    best_goal_m: FloatArray
    stuck_s: FloatArray


def _candidate_rows(lay: _Layout, z: NDArray[np.complex128]) -> NDArray[np.complex128]:
    """Each row's candidate segments (its crowd's :meth:`SegmentGrid.rows`, padded)."""
    ij = ((z - lay.origin_c) * (1.0 / CELL_M)).view(np.float64).reshape(-1, 2)
    ij = ij.astype(np.int64)
    np.minimum(np.maximum(ij, 0, out=ij), lay.cell_hi, out=ij)  # (np.clip, without its overhead)
    cell = lay.cell_first + ij[:, 0] * lay.cell_ny + ij[:, 1]
    return lay.segrows.take(lay.cells.take(cell, axis=0), axis=0)  # (see SegmentGrid.rows)


def _build_layout(
    forces: Sequence[SocialForce], ks: tuple[StepConstants, ...], old: _Layout | None = None
) -> _Layout:
    """The batch's constants from each crowd's :class:`StepConstants` and grid. The joint
    cell lists (megabytes for a few large worlds: a fresh array of them costs more in page
    faults than the copy) are written into ``old``'s, the layout this one replaces, when
    they have the same shape."""
    counts = np.array([k.n for k in ks], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)])
    n_rows = int(starts[-1])
    pmax = int(counts.max())
    grids = [f.obstacles.grid for f in forces]
    kmax = max(g.cells.shape[1] for g in grids)
    width = pmax + 1 + kmax
    log_a = np.full((n_rows, width), -np.inf)
    inv_b = np.ones((n_rows, width))
    rsum = np.full((n_rows, pmax), -np.inf)
    people_src = np.empty((n_rows, pmax), dtype=np.int64)
    by_width: dict[int, tuple[list[IntArray], list[IntArray]]] = {}
    seg_at = cell_at = 0
    segrows, cell_first, origin, hi, ny = [], [], [], [], []
    # every grid's cell lists (into the joint segrows), padded with its far dummy
    shape = (sum(g.cells.shape[0] for g in grids), kmax)
    cells = old.cells if old is not None and old.cells.shape == shape else np.empty(shape, np.int64)
    for k, g, r0 in zip(ks, grids, starts[:-1].tolist(), strict=True):
        p, kk = k.n, k.k_cols
        rs = slice(r0, r0 + p)
        log_a[rs, :p] = k.log_a[:, :p]
        inv_b[rs, :p] = k.inv_b[:, :p]
        log_a[rs, pmax : pmax + 1 + kk] = k.log_a[:, p:]
        inv_b[rs, pmax : pmax + 1 + kk] = k.inv_b[:, p:]
        rsum[rs, :p] = k.rsum_masked
        people_src[rs] = r0
        people_src[rs, :p] = r0 + np.arange(p)
        # the single crowd's sources in its order: its people, the robot, its segments
        cols = np.concatenate([np.arange(p), pmax + np.arange(1 + kk)])
        rows_i, idx_i = by_width.setdefault(p + 1 + kk, ([], []))
        rows_i.append(np.arange(r0, r0 + p))
        idx_i.append(np.arange(r0, r0 + p)[:, None] * width + cols[None, :])
        n_cells, w = g.cells.shape
        mine = cells[cell_at : cell_at + n_cells]
        np.add(g.cells, seg_at, out=mine[:, :w])
        mine[:, w:] = seg_at + g.segrows.shape[0] - 1  # the far dummy
        segrows.append(g.segrows)
        cell_first.append(np.full(p, cell_at, dtype=np.int64))
        origin.append(np.full(p, g.origin_c, dtype=np.complex128))
        hi.append(np.repeat(g.cell_hi[None, :], p, axis=0))
        ny.append(np.full(p, g.shape[1], dtype=np.int64))
        seg_at += g.segrows.shape[0]
        cell_at += g.cells.shape[0]
    cat: Any = np.concatenate
    return _Layout(
        ks=ks,
        starts=starts,
        n=pmax,
        people_src=people_src,
        log_a=log_a,
        inv_b=inv_b,
        rsum_masked=rsum,
        v0_tau=cat([k.v0_tau for k in ks]),
        vmax=cat([k.vmax for k in ks]),
        radius=cat([k.radius for k in ks]),
        evade_log_a=cat([k.evade_log_a for k in ks]),
        robot_need=cat([k.robot_need for k in ks]),
        robot_goal_reach=cat([k.robot_goal_reach for k in ks]),
        vmax_max=np.array([k.vmax_max for k in ks]),
        sum_groups=[(cat(r), cat(i)) for r, i in by_width.values()],
        segrows=cat(segrows),
        cells=cells,
        origin_c=cat(origin),
        cell_hi=cat(hi),
        cell_ny=cat(ny),
        cell_first=cat(cell_first),
    )
