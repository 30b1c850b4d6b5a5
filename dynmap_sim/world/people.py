"""Pedestrians steered by the social force model (Helbing & Molnár 1995, Phys. Rev. E 51).

Each person ``i`` (unit mass) is driven toward a goal and repelled by the others, by static
geometry and by the robot:

* driving term ``(v0_i e_i - v_i) / tau``  (H&M eq. 2, relaxation time ``tau``);
* person-person ``A exp((r_i + r_j - d_ij) / B) n_ij``  (H&M eq. 3-4, in the circular form
  of Helbing, Farkas & Vicsek 2000);
* obstacle ``A_w exp((r_i - d_iW) / B_w) n_iW`` from the closest point of every segment
  within reach (H&M eq. 5);
* robot: the same exponential from a disc of the robot's radius plus a comfort margin, and
  a sideways evasion term when the robot is ahead (people step aside early, to the right
  when it is dead ahead), which keeps head-on corridor meetings from ending in a stand-off.

The speed is capped at ``1.3 v0_i`` (H&M eq. 8). After the explicit Euler step a position
correction keeps bodies out of walls and furniture and at least ``ROBOT_GAP_M`` away from
the robot's body, so the simulation never shows a person inside a wall whatever the forces.
A person who reaches a goal, gets no closer to it by ``PROGRESS_M`` for ``STUCK_S``, or finds
the robot standing on it picks a new one in line of sight,
or, for a population with a ``route``, heads for the route's next waypoint (closed loop).
People are seen by the laser as two legs whose fore-aft offset follows the gait phase.

Cost: for the crowds of the shipped worlds (<= ~30 people) a step is bound by the number of
numpy calls, not by arithmetic, so :meth:`SocialForce.step` works on complex numbers
(``x + iy`` views of the crowd arrays) and evaluates every repulsion — people, robot and the
closest points of the candidate segments from a 0.5 m grid (broad phase) — as one
exponential over a single ``(P, P + 1 + K)`` matrix of source-to-person vectors. The forces
are those of the formulas above, evaluated exactly (no precomputed field), and the same seed
gives the same trajectories.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.world.polygons import FloatArray, point_segment_distance
from dynmap_sim.world.spec import PeopleSpec

TAU_S = 0.5
A_PEOPLE = 2.1
B_PEOPLE = 0.3
A_WALL = 4.0
B_WALL = 0.12
A_ROBOT = 6.0
B_ROBOT = 0.25
ROBOT_GAP_M = 0.10
A_EVADE = 1.5
KEEP_RIGHT_M = 0.15
B_EVADE = 0.8
REACH_M = 1.0
CELL_M = 0.5
GOAL_TOL_M = 0.4
STUCK_S = 4.0
PROGRESS_M = 0.2
PAUSE_S = 2.0
LEG_RADIUS_M = 0.06
LEG_SPREAD_M = 0.10
STRIDE_M = 1.2
LEG_SWING_M = 0.12
_FAR = complex(1e9, 1e9)  # stands in for an absent robot (its force underflows to 0)


def profile_fraction(profile: tuple[tuple[float, float], ...], time_s: float) -> float:
    """Fraction of a population present at ``time_s`` seconds since midnight."""
    hours = np.array([h for h, _ in profile])
    frac = np.array([f for _, f in profile])
    return float(np.interp(time_s / 3600.0, hours, frac))


@dataclass
class Crowd:
    """Live state of all people of a run. Arrays have one row per person."""

    pos: FloatArray
    vel: FloatArray
    goal: FloatArray
    v0: FloatArray
    radius: FloatArray
    population: NDArray[np.int64]
    phase: FloatArray
    stuck_s: FloatArray
    ids: tuple[str, ...]
    waypoint: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    """Index of the route waypoint each person heads for (-1: no route, free goals)."""
    best_goal_m: FloatArray = field(default_factory=lambda: np.zeros(0))
    """Closest each person has come to its current goal [m] (progress for stuck detection)."""

    @property
    def n(self) -> int:
        """Number of people."""
        return len(self.pos)


@dataclass(frozen=True)
class _StepConstants:
    """Per-crowd constants of :meth:`SocialForce.step`; ``*_log_a`` fold a force's amplitude
    and the bodies' radii into the exponent (``A exp((r - d) / B) = exp(log_a - d / B)``)."""

    n: int
    radius: FloatArray
    v0: FloatArray
    robot_radius_m: float
    v0_tau: FloatArray
    vmax: FloatArray
    rsum_masked: FloatArray
    """``r_i + r_j`` with ``-inf`` on the diagonal (a body never overlaps itself)."""
    pair_log_a: FloatArray
    """``ln A + (r_i + r_j) / B`` with ``-inf`` on the diagonal (no self-force)."""
    wall_log_a: FloatArray
    robot_log_a: FloatArray
    evade_log_a: FloatArray
    robot_need: FloatArray
    robot_goal_reach: FloatArray
    k_cols: int
    log_a: FloatArray
    """``(P, P + 1 + K)``: the ``*_log_a`` of the people, the robot and ``K`` candidate
    segments, laid out like the source points in :meth:`SocialForce.step`."""
    inv_b: FloatArray
    """``(P, P + 1 + K)``: ``1 / B`` of the same interactions [1/m]."""

    @classmethod
    def build(
        cls, radius: FloatArray, v0: FloatArray, robot_radius_m: float, k_cols: int
    ) -> _StepConstants:
        n = len(radius)
        rsum = radius[:, None] + radius[None, :]
        diag = np.eye(n, dtype=bool)
        reach = radius + robot_radius_m + ROBOT_GAP_M
        pair_log_a = np.where(diag, -np.inf, np.log(A_PEOPLE) + rsum / B_PEOPLE)
        wall_log_a = np.log(A_WALL) + radius / B_WALL
        robot_log_a = np.log(A_ROBOT) + reach / B_ROBOT
        log_a = np.empty((n, n + 1 + k_cols))
        inv_b = np.empty((n, n + 1 + k_cols))
        log_a[:, :n], inv_b[:, :n] = pair_log_a, 1.0 / B_PEOPLE
        log_a[:, n], inv_b[:, n] = robot_log_a, 1.0 / B_ROBOT
        log_a[:, n + 1 :], inv_b[:, n + 1 :] = wall_log_a[:, None], 1.0 / B_WALL
        return cls(
            n=n,
            radius=radius,
            v0=v0,
            robot_radius_m=robot_radius_m,
            v0_tau=v0 / TAU_S,
            vmax=1.3 * v0,
            rsum_masked=np.where(diag, -np.inf, rsum),
            pair_log_a=pair_log_a,
            wall_log_a=wall_log_a,
            robot_log_a=robot_log_a,
            evade_log_a=np.log(A_EVADE) + reach / B_EVADE,
            robot_need=reach,
            robot_goal_reach=reach + 0.1,
            k_cols=k_cols,
            log_a=log_a,
            inv_b=inv_b,
        )


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
        self.segments = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
        self.broad_phase = broad_phase
        #: first segment of each closed outline in ``segments`` (for inside tests), or None
        self.outline_starts = outline_starts
        self._consts: _StepConstants | None = None
        self._build_grid()

    def _build_grid(self) -> None:
        """Uniform grid (cell ``CELL_M``) listing, per cell, the segments within ``REACH_M``.

        Rows are padded with a far-away dummy segment so that a step gathers a dense
        ``(P, K)`` block of candidate segments per person (broad phase).
        """
        s = self.segments
        far = np.array([[1e6, 1e6, 1e6 + 1.0, 1e6]])
        ext = np.concatenate([s, far])
        d = ext[:, 2:4] - ext[:, 0:2]
        inv = 1.0 / np.maximum(np.sum(d * d, axis=1), 1e-18)
        self._seg_p0 = s[:, 0] + 1j * s[:, 1]
        self._seg_d = (s[:, 2] - s[:, 0]) + 1j * (s[:, 3] - s[:, 1])
        self._seg_dc = self._seg_d.conjugate()
        # per segment, complex: p0, conj(d), 1 / |d|^2 (gathered per person each step)
        self._segrows = np.column_stack(
            [ext[:, 0] + 1j * ext[:, 1], d[:, 0] - 1j * d[:, 1], inv + 0j]
        )
        if len(s) == 0:
            self._origin = np.zeros(2)
            self._origin_c = 0j
            self._cell_hi = np.zeros(2, dtype=np.int64)
            self._cell_stride = np.array([1, 1], dtype=np.int64)
            self._shape = (1, 1)
            self._cells = np.zeros((1, 1), dtype=np.int64)
            return
        lo = np.minimum(s[:, :2], s[:, 2:]).min(axis=0) - REACH_M
        hi = np.maximum(s[:, :2], s[:, 2:]).max(axis=0) + REACH_M
        nx, ny = (np.ceil((hi - lo) / CELL_M).astype(int) + 1).tolist()
        self._origin, self._shape = lo, (nx, ny)
        self._origin_c = complex(lo[0], lo[1])
        self._cell_hi = np.array([nx - 1, ny - 1], dtype=np.int64)
        self._cell_stride = np.array([ny, 1], dtype=np.int64)
        smin = np.minimum(s[:, :2], s[:, 2:]) - REACH_M - lo
        smax = np.maximum(s[:, :2], s[:, 2:]) + REACH_M - lo
        i0 = np.clip(np.floor(smin / CELL_M).astype(np.int64), 0, [nx - 1, ny - 1])
        i1 = np.clip(np.floor(smax / CELL_M).astype(np.int64), 0, [nx - 1, ny - 1])
        ncx = i1[:, 0] - i0[:, 0] + 1
        ncy = i1[:, 1] - i0[:, 1] + 1
        npairs = ncx * ncy
        seg = np.repeat(np.arange(len(s)), npairs)
        j = np.arange(int(npairs.sum())) - np.repeat(np.cumsum(npairs) - npairs, npairs)
        cell = (i0[seg, 0] + j // ncy[seg]) * ny + (i0[seg, 1] + j % ncy[seg])
        order = np.argsort(cell, kind="stable")
        cell_sorted = cell[order]
        counts = np.bincount(cell, minlength=nx * ny)
        first = np.cumsum(counts) - counts
        rank = np.arange(len(cell)) - first[cell_sorted]
        cells = np.full((nx * ny, max(1, int(counts.max()))), len(s), dtype=np.int64)
        cells[cell_sorted, rank] = seg[order]
        self._cells = cells

    # -- sampling -----------------------------------------------------------------------
    def _inside_any(self, points: FloatArray) -> NDArray[np.bool_]:
        """True where points ``(P, 2)`` lie inside a closed outline (crossing-number parity of
        a ray toward +x, counted per outline)."""
        if self.outline_starts is None or len(self.segments) == 0:
            return np.zeros(len(points), dtype=bool)
        s = self.segments
        y0, y1 = s[None, :, 1], s[None, :, 3]
        py = points[:, 1:2]
        straddle = (y0 > py) != (y1 > py)
        t = (py - y0) / np.where(y1 == y0, 1.0, y1 - y0)
        x_cross = s[None, :, 0] + t * (s[None, :, 2] - s[None, :, 0])
        hits = (straddle & (x_cross > points[:, 0:1])).astype(np.int64)
        per_outline = np.add.reduceat(hits, self.outline_starts, axis=1)
        return np.any(per_outline % 2 == 1, axis=1)

    def _free_mask(self, points: FloatArray, r: float) -> NDArray[np.bool_]:
        """True where a body of radius ``r`` fits at ``points`` ``(P, 2)`` (clear of outlines
        by 5 cm and not inside any)."""
        if len(self.segments) == 0:
            return np.ones(len(points), dtype=bool)
        if self.broad_phase and r + 0.05 < REACH_M:  # the grid lists every segment that near
            pts = np.ascontiguousarray(points, dtype=np.float64)
            z = pts.view(np.complex128)[:, 0]
            rows = self._segment_rows(z)
            a = z[:, None] - rows[..., 0]
            cd = rows[..., 1]
            t = (a * cd).real * rows[..., 2].real
            np.minimum(np.maximum(t, 0.0, out=t), 1.0, out=t)
            clear = np.abs(a - t * cd.conjugate()).min(axis=1) > r + 0.05
        else:
            clear = point_segment_distance(points, self.segments).min(axis=1) > r + 0.05
        return clear & ~self._inside_any(points)

    def _free(self, xy: FloatArray, r: float) -> bool:
        return bool(self._free_mask(xy[None, :], r)[0])

    def _visible(self, a: FloatArray, b: FloatArray) -> bool:
        if len(self.segments) == 0:
            return True
        # proper crossings of a-b with each segment p0 + s d: the endpoints of each lie on
        # opposite sides of the other (signs of 2-D cross products, Im(conj(u) w) = u x w)
        za, ab = complex(a[0], a[1]), complex(b[0] - a[0], b[1] - a[1])
        w0 = self._seg_p0 - za  # p0 - a
        o1 = (ab.conjugate() * w0).imag
        o2 = (ab.conjugate() * (w0 + self._seg_d)).imag
        o3 = (self._seg_dc * w0).imag  # = -(d x (a - p0))
        o4 = (self._seg_dc * (w0 - ab)).imag  # = -(d x (b - p0))
        return not bool(((o1 * o2 < 0.0) & (o3 * o4 < 0.0)).any())

    def _random_point(self, pop: PeopleSpec, r: float) -> FloatArray | None:
        """A uniformly drawn free point of the population's areas (up to 8 batches of 8)."""
        boxes = np.array(pop.areas, dtype=np.float64)
        for _ in range(8):
            k = self.rng.integers(len(boxes), size=8)
            u = self.rng.uniform(0.0, 1.0, size=(8, 2))
            cand = boxes[k, :2] + u * (boxes[k, 2:] - boxes[k, :2])
            if len(self.segments) == 0:
                return cand[0]
            idx = np.flatnonzero(self._free_mask(cand, r))
            if len(idx):
                return cand[idx[0]].copy()
        return None

    def pick_goal(
        self,
        pop: PeopleSpec,
        frm: FloatArray,
        r: float,
        avoid: tuple[FloatArray, float] | None = None,
    ) -> FloatArray:
        """A goal in line of sight of ``frm``: an attraction point or a free point of the areas,
        not within ``avoid = (centre, radius_m) + r`` (the robot's disc)."""
        for _ in range(20):
            if pop.goals:
                g = np.array(pop.goals[int(self.rng.integers(len(pop.goals)))], dtype=float)
            else:
                g = self._random_point(pop, r)
                if g is None:
                    continue
            gx, gy = float(g[0]), float(g[1])
            if avoid is not None and math.hypot(gx - avoid[0][0], gy - avoid[0][1]) < avoid[1] + r:
                continue
            if math.hypot(gx - frm[0], gy - frm[1]) > GOAL_TOL_M and self._visible(frm, g):
                return g
        return frm.copy()

    def spawn(
        self, time_s: float, day_active: list[bool], keep_away: FloatArray | None = None
    ) -> Crowd:
        """Place the people present at ``time_s`` (profile x count) on free spots of their areas."""
        pos, goal, v0, rad, popi, ids, wps = [], [], [], [], [], [], []
        for k, pop in enumerate(self.populations):
            if not day_active[k]:
                continue
            n = int(round(pop.count * profile_fraction(pop.profile, time_s)))
            for j in range(n):
                xy = None
                wp = int(self.rng.integers(len(pop.route))) if pop.route else -1
                for _ in range(30):
                    if wp >= 0:  # on a route: somewhere along the leg toward waypoint wp
                        a = np.array(pop.route[wp - 1], dtype=float)
                        b = np.array(pop.route[wp], dtype=float)
                        c = a + self.rng.uniform(0.0, 1.0) * (b - a)
                        if not self._free(c, pop.radius_m):
                            continue
                    else:
                        c = self._random_point(pop, pop.radius_m)
                    if c is None:
                        break
                    ok = all(
                        np.hypot(*(c - p)) > r + pop.radius_m + 0.1
                        for p, r in zip(pos, rad, strict=True)
                    )
                    if keep_away is not None:
                        ok = ok and np.hypot(*(c - keep_away)) > 1.0
                    if ok:
                        xy = c
                        break
                if xy is None:
                    continue
                pos.append(xy)
                rad.append(pop.radius_m)
                v0.append(self.rng.uniform(*pop.speed_mps))
                if wp >= 0:
                    goal.append(np.array(pop.route[wp], dtype=float))
                else:
                    goal.append(self.pick_goal(pop, xy, pop.radius_m))
                wps.append(wp)
                popi.append(k)
                ids.append(f"person:{pop.id}:{j}")
        n = len(pos)
        return Crowd(
            pos=np.array(pos, dtype=np.float64).reshape(n, 2),
            vel=np.zeros((n, 2)),
            goal=np.array(goal, dtype=np.float64).reshape(n, 2),
            v0=np.array(v0, dtype=np.float64),
            radius=np.array(rad, dtype=np.float64),
            population=np.array(popi, dtype=np.int64),
            phase=self.rng.uniform(0, 2 * np.pi, n),
            stuck_s=np.zeros(n),
            ids=tuple(ids),
            waypoint=np.array(wps, dtype=np.int64),
            best_goal_m=np.hypot(*(np.reshape(goal, (n, 2)) - np.reshape(pos, (n, 2))).T),
        )

    # -- dynamics -------------------------------------------------------------------------
    def _constants(self, crowd: Crowd, robot_radius_m: float, k_cols: int) -> _StepConstants:
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
        c = _StepConstants.build(crowd.radius, crowd.v0, robot_radius_m, k_cols)
        self._consts = c
        return c

    def _segment_rows(self, z: NDArray[np.complex128]) -> NDArray[np.complex128]:
        """Candidate segments near each person as ``(P, K, 3)`` complex rows
        ``p0, conj(d), 1/|d|^2`` (padded with a far dummy).

        Without ``broad_phase`` every segment is a candidate (the naive reference).
        """
        if not self.broad_phase:
            rows = self._segrows  # all segments and the far dummy (never empty)
            return np.broadcast_to(rows, (len(z), *rows.shape))
        return self._segrows[self._cells[self._cell_index(z)]]

    def _cell_index(self, z: NDArray[np.complex128]) -> NDArray[np.int64]:
        """Index of the grid cell holding each point ``z`` (clipped to the grid)."""
        ij = ((z - self._origin_c) * (1.0 / CELL_M)).view(np.float64).reshape(-1, 2)
        ij = ij.astype(np.int64)  # truncation: negative cells clip to 0 as with floor
        np.minimum(np.maximum(ij, 0, out=ij), self._cell_hi, out=ij)
        return ij @ self._cell_stride

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
        n = crowd.n
        if n == 0:
            return
        for name in ("pos", "vel", "goal"):
            a = getattr(crowd, name)
            if not (a.flags.c_contiguous and a.dtype == np.float64):
                setattr(crowd, name, np.ascontiguousarray(a, dtype=np.float64))
        z = crowd.pos.view(np.complex128)[:, 0]  # views: in-place updates write through
        v = crowd.vel.view(np.complex128)[:, 0]
        goal = crowd.goal.view(np.complex128)[:, 0]
        rows = self._segment_rows(z)  # candidate segments (static geometry within REACH_M)
        k = self._constants(crowd, robot_radius_m, rows.shape[1])
        to_goal = goal - z
        e = to_goal / np.maximum(np.abs(to_goal), 1e-9)
        # driving term (H&M eq. 2)
        force = k.v0_tau * e - v * (1.0 / TAU_S)
        # repulsion: one exponential per (person, source) from the vectors source -> person
        # of all sources at once: the other people (H&M eq. 3-4; the diagonal is masked by
        # the constants), the robot, and the closest point of each candidate segment (H&M
        # eq. 5; only those within REACH_M count)
        rz = None if robot_xy is None else complex(float(robot_xy[0]), float(robot_xy[1]))
        diff = np.empty((n, n + 1 + rows.shape[1]), dtype=np.complex128)
        np.subtract(z[:, None], z[None, :], out=diff[:, :n])
        np.subtract(z, _FAR if rz is None else rz, out=diff[:, n])
        a = z[:, None] - rows[..., 0]
        cd = rows[..., 1]  # conj(d)
        t = (a * cd).real
        t *= rows[..., 2].real
        np.minimum(np.maximum(t, 0.0, out=t), 1.0, out=t)
        np.subtract(a, t * cd.conjugate(), out=diff[:, n + 1 :])  # closest point -> person
        d = np.abs(diff)
        # smallest gaps before the move [m]: between two bodies, and per person to a segment
        pair_gap = float((d[:, :n] - k.rsum_masked).min())
        wall_gap = d[:, n + 1 :].min(axis=1) - crowd.radius
        w = np.exp(k.log_a - d * k.inv_b)
        w /= np.maximum(d, 1e-9)
        w_wall = w[:, n + 1 :]
        w_wall[d[:, n + 1 :] > REACH_M] = 0.0
        force += (w * diff).sum(axis=1)
        if rz is not None:
            rd = diff[:, n]
            dr = np.maximum(d[:, n], 1e-9)
            # evasion: a robot ahead makes people step aside early (to their right when it is
            # dead ahead), so a head-on meeting in a corridor does not end in a stand-off.
            # conj(e) rd: real part -(robot ahead), imaginary part > 0: robot on the right
            er = e.conjugate() * rd
            mag = np.exp(k.evade_log_a - dr * (1.0 / B_EVADE)) * (er.real < 0.0)
            # step right (keep-right convention), unless the robot is clearly on the right
            force += mag * np.where(er.imag > KEEP_RIGHT_M, 1j, -1j) * e
        v += dt_s * force
        v *= np.minimum(1.0, k.vmax / np.maximum(np.abs(v), 1e-9))  # H&M eq. 8
        old = z.copy()
        z += dt_s * v
        self._correct(crowd, z, v, rows, rz, k, old, pair_gap, wall_gap)
        crowd.phase += np.abs(z - old) * (2 * np.pi / STRIDE_M)
        # goals: arrival, no progress for STUCK_S, or the robot standing on the goal -> new goal
        gd = np.abs(goal - z)
        progress = gd < crowd.best_goal_m - PROGRESS_M
        crowd.best_goal_m = np.where(progress, gd, crowd.best_goal_m)
        crowd.stuck_s = np.where(progress, 0.0, crowd.stuck_s + dt_s)
        redo = (gd < GOAL_TOL_M) | (crowd.stuck_s > STUCK_S)
        avoid = None
        if rz is not None:
            redo |= np.abs(goal - rz) < k.robot_goal_reach
            avoid = (robot_xy, robot_radius_m + ROBOT_GAP_M + 0.1)
        redo &= crowd.stuck_s >= 0.0  # negative: pausing after a failed goal search
        if not redo.any():
            return
        pos = crowd.pos
        for i in np.flatnonzero(redo):
            pop = self.populations[int(crowd.population[i])]
            if pop.route:  # next waypoint of the (closed) route
                crowd.waypoint[i] = (crowd.waypoint[i] + 1) % len(pop.route)
                crowd.goal[i] = pop.route[int(crowd.waypoint[i])]
            else:
                crowd.goal[i] = self.pick_goal(pop, pos[i], float(crowd.radius[i]), avoid)
            crowd.stuck_s[i] = 0.0
            if np.array_equal(crowd.goal[i], pos[i]):  # no goal found: pause, then retry
                crowd.stuck_s[i] = -PAUSE_S
            crowd.best_goal_m[i] = float(np.hypot(*(crowd.goal[i] - pos[i])))

    def _correct(
        self,
        crowd: Crowd,
        z: NDArray[np.complex128],
        v: NDArray[np.complex128],
        rows: NDArray[np.complex128],
        rz: complex | None,
        k: _StepConstants,
        old: NDArray[np.complex128],
        pair_gap: float,
        wall_gap: FloatArray,
    ) -> None:
        """Push bodies out of the robot's comfort disc, each other, then walls (walls win).

        ``z``, ``v`` are complex views of positions and velocities (updated in place).
        Distances are 1-Lipschitz in position, so a body that moved less than its gap before
        the move (``pair_gap``, ``wall_gap`` [m]) cannot overlap: those checks are skipped.
        """
        if rz is not None:
            rd = z - rz
            dr = np.maximum(np.abs(rd), 1e-9)
            push = k.robot_need - dr
            if push.max() > 0.0:
                np.maximum(push, 0.0, out=push)
                z += push / dr * rd
        disp = np.abs(z - old)
        if crowd.n > 1 and 2.0 * disp.max() >= pair_gap:
            diff = z[:, None] - z[None, :]
            d = np.abs(diff)
            over = np.maximum(k.rsum_masked - d, 0.0)
            z += 0.5 * ((over / np.maximum(d, 1e-9)) * diff).sum(axis=1)
            disp = np.abs(z - old)
        if not bool((disp >= wall_gap).any()):
            return
        p0 = rows[..., 0]
        cd = rows[..., 1]
        inv = rows[..., 2].real
        idx = np.arange(crowd.n)
        for _ in range(2):
            a = z[:, None] - p0
            t = (a * cd).real * inv
            np.minimum(np.maximum(t, 0.0, out=t), 1.0, out=t)
            q = a - t * cd.conjugate()
            dist = np.abs(q)
            over = crowd.radius[:, None] - dist
            j = np.argmax(over, axis=1)
            depth = over[idx, j]
            if not (depth > 0.0).any():
                break
            np.maximum(depth, 0.0, out=depth)
            nv = q[idx, j] / np.maximum(dist[idx, j], 1e-9)
            z += depth * nv
            # remove the velocity component into the obstacle
            vn = (v * nv.conjugate()).real
            hit = (depth > 0) & (vn < 0)
            v -= np.where(hit, vn, 0.0) * nv

    @staticmethod
    def legs(crowd: Crowd) -> tuple[FloatArray, NDArray[np.int32]]:
        """Two leg circles per person ``(2P, 3)`` and the person index of each."""
        out = np.empty((2 * crowd.n, 3))
        SocialForce.legs_into(crowd, out)
        return out, np.repeat(np.arange(crowd.n, dtype=np.int32), 2)

    @staticmethod
    def legs_into(crowd: Crowd, out: FloatArray) -> None:
        """Write the two leg circles of each person into rows of ``out`` ``(2P, 3)``.

        The legs stand ``LEG_SPREAD_M`` to either side of the heading of motion (``+x`` for
        a person standing still), offset fore and aft by ``LEG_SWING_M sin(phase)`` (scaled
        down below 0.5 m/s).
        """
        if crowd.n == 0:
            return
        vel = np.ascontiguousarray(crowd.vel, dtype=np.float64)
        pos = np.ascontiguousarray(crowd.pos, dtype=np.float64)
        v = vel.view(np.complex128)[:, 0]
        z = pos.view(np.complex128)[:, 0]
        sp = np.abs(v)
        h = np.where(sp > 1e-3, v / np.maximum(sp, 1e-9), 1.0)
        swing = np.sin(crowd.phase)
        swing *= np.minimum(sp * (LEG_SWING_M / 0.5), LEG_SWING_M)
        off = h * (swing + 1j * LEG_SPREAD_M)
        legs = out[:, :2].view(np.complex128)[:, 0]
        np.add(z, off, out=legs[0::2])
        np.subtract(z, off, out=legs[1::2])
        out[:, 2] = LEG_RADIUS_M

    @staticmethod
    def poses(crowd: Crowd) -> FloatArray:
        """People poses ``(P, 3)``: position and heading of motion [m, rad]."""
        th = np.arctan2(crowd.vel[:, 1], crowd.vel[:, 0])
        return np.column_stack([crowd.pos, th])
