"""Where people appear and where they head: spawning, goal choice and goal renewal.

Random draws come from the run's generator in a fixed order (the same seed gives the same
people and the same goals).
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.world.people.crowd import Crowd, profile_fraction
from dynmap_sim.world.people.params import GOAL_TOL_M, PAUSE_S, ROBOT_GAP_M
from dynmap_sim.world.polygons import FloatArray
from dynmap_sim.world.spec import PeopleSpec

#: Tries of :func:`pick_goal` before a person gives up (and pauses).
GOAL_TRIES = 20
#: Tries of :func:`pick_goal` evaluated in one pass.
SPECULATE = 4


class GoalQueries(Protocol):
    """What spawning and goal choice ask of the static geometry (:class:`.Obstacles`)."""

    segments: FloatArray

    def free_mask(self, points: FloatArray, r: float) -> NDArray[np.bool_]: ...

    def visible(self, a: FloatArray, b: FloatArray) -> bool: ...

    def visible_many(self, a: FloatArray, bs: FloatArray) -> NDArray[np.bool_]: ...


@lru_cache(maxsize=64)
def _boxes(areas: tuple[tuple[float, float, float, float], ...]) -> tuple[FloatArray, FloatArray]:
    """Lower corners ``(B, 2)`` and sizes ``(B, 2)`` of the areas (read-only; a point of box
    ``k`` is ``lo[k] + u * span[k]``, the same numbers as ``box[:2] + u * (box[2:] -
    box[:2])``)."""
    boxes = np.array(areas, dtype=np.float64).reshape(-1, 4)
    lo = boxes[:, :2].copy()
    span = boxes[:, 2:] - boxes[:, :2]
    lo.setflags(write=False)
    span.setflags(write=False)
    return lo, span


def random_point(
    obstacles: GoalQueries, rng: np.random.Generator, pop: PeopleSpec, r: float
) -> FloatArray | None:
    """A uniformly drawn free point of the population's areas (up to 8 batches of 8)."""
    lo, span = _boxes(pop.areas)
    for _ in range(8):
        k = rng.integers(len(lo), size=8)
        u = rng.uniform(0.0, 1.0, size=(8, 2))
        cand = lo[k] + u * span[k]
        if len(obstacles.segments) == 0:
            return cand[0]
        idx = np.flatnonzero(obstacles.free_mask(cand, r))
        if len(idx):
            return cand[idx[0]].copy()
    return None


def pick_goal(
    obstacles: GoalQueries,
    rng: np.random.Generator,
    pop: PeopleSpec,
    frm: FloatArray,
    r: float,
    avoid: tuple[FloatArray, float] | None = None,
) -> FloatArray:
    """A goal in line of sight of ``frm``: an attraction point or a free point of the areas,
    not within ``avoid = (centre, radius_m) + r`` (the robot's disc); ``frm`` if none.

    Up to ``GOAL_TRIES`` tries, each drawing a goal (see :func:`_try_goal`). Tries for a
    free point of the areas (after the first, with several areas) are evaluated
    ``SPECULATE`` at a time: their draws are made in the order one try after another makes
    them, their candidates tested in one pass, and the generator is then put back to where
    the first accepted try left it, so the goals and the draws are those of the
    one-at-a-time loop, number for number.
    """
    # every try for attraction points (one draw and one line of sight each: nothing to
    # gain), and the first alone for several areas (it is often accepted, and speculative
    # tries there cost a draw of area indices each)
    left = GOAL_TRIES
    while left > 0 and (pop.goals or (left == GOAL_TRIES and len(pop.areas) > 1)):
        left -= 1
        g = _try_goal(obstacles, rng, pop, r)
        if g is not None and _accept_one(obstacles, g, frm, r, avoid):
            return g
    while left > 0:
        n = min(SPECULATE, left)
        state = rng.bit_generator.state
        goals, done = _draw_tries(obstacles, rng, pop, r, n)
        ok = _accept(obstacles, goals, frm, r, avoid)
        if ok.any():
            s = int(ok.argmax())  # the first accepted try: replay the draws up to it
            rng.bit_generator.state = state
            _draw_tries(obstacles, rng, pop, r, s + 1, test=False)
            return goals[s].copy()
        left -= done
        if done < n:  # try ``done`` needs more than one batch of points: one at a time
            rng.bit_generator.state = state
            _draw_tries(obstacles, rng, pop, r, done, test=False)
            left -= 1
            g = _try_goal(obstacles, rng, pop, r)
            if g is not None and _accept_one(obstacles, g, frm, r, avoid):
                return g
    return frm.copy()


def _try_goal(
    obstacles: GoalQueries, rng: np.random.Generator, pop: PeopleSpec, r: float
) -> FloatArray | None:
    """One try of :func:`pick_goal`: an attraction point, or a free point of the areas."""
    if pop.goals:
        return np.array(pop.goals[int(rng.integers(len(pop.goals)))], dtype=float)
    return random_point(obstacles, rng, pop, r)


def _draw_tries(
    obstacles: GoalQueries,
    rng: np.random.Generator,
    pop: PeopleSpec,
    r: float,
    n: int,
    test: bool = True,
) -> tuple[FloatArray, int]:
    """The draws of ``n`` tries of :func:`pick_goal` for free points of the areas (no
    attraction points) in their order, assuming each try's
    :func:`random_point` finds a free point in its first batch of 8 (``test``: check that
    with one :meth:`Obstacles.free_mask` of all candidates). Returns the goals ``(m, 2)`` of
    the first ``m <= n`` tries for which that holds, and ``m``."""
    lo, span = _boxes(pop.areas)
    if n == 0:
        return np.zeros((0, 2)), 0
    if len(lo) == 1:  # integers(1) draws nothing: the uniforms follow one another
        u = rng.uniform(0.0, 1.0, size=(8 * n, 2))
        if not test:
            return np.zeros((0, 2)), n
        cand = lo[0] + u * span[0]
    else:
        ks, us = [], []
        for _ in range(n):
            ks.append(rng.integers(len(lo), size=8))
            us.append(rng.uniform(0.0, 1.0, size=(8, 2)))
        if not test:
            return np.zeros((0, 2)), n
        k, u = np.concatenate(ks), np.concatenate(us)
        cand = lo[k] + u * span[k]
    if len(obstacles.segments) == 0:
        return cand[::8].copy(), n
    free = obstacles.free_mask(cand, r).reshape(n, 8)
    found = free.any(axis=1)
    m = n if found.all() else int(found.argmin())
    first = free[:m].argmax(axis=1)
    return cand.reshape(n, 8, 2)[np.arange(m), first], m


def _accept_one(
    obstacles: GoalQueries,
    g: FloatArray,
    frm: FloatArray,
    r: float,
    avoid: tuple[FloatArray, float] | None,
) -> bool:
    """:func:`_accept` for one goal ``g``."""
    gx, gy = float(g[0]), float(g[1])
    if avoid is not None and math.hypot(gx - avoid[0][0], gy - avoid[0][1]) < avoid[1] + r:
        return False
    return math.hypot(gx - frm[0], gy - frm[1]) > GOAL_TOL_M and obstacles.visible(frm, g)


def _accept(
    obstacles: GoalQueries,
    goals: FloatArray,
    frm: FloatArray,
    r: float,
    avoid: tuple[FloatArray, float] | None,
) -> NDArray[np.bool_]:
    """Per goal ``(m, 2)``: not within ``avoid`` (+ ``r``), farther than ``GOAL_TOL_M`` from
    ``frm``, and in its line of sight."""
    near = np.zeros(len(goals), dtype=bool)
    for i, (gx, gy) in enumerate(goals.tolist()):
        if avoid is not None and math.hypot(gx - avoid[0][0], gy - avoid[0][1]) < avoid[1] + r:
            continue
        near[i] = math.hypot(gx - frm[0], gy - frm[1]) > GOAL_TOL_M
    if not near.any():
        return near
    seen = np.zeros(len(goals), dtype=bool)
    seen[near] = obstacles.visible_many(frm, goals[near])
    return seen


def spawn(
    populations: tuple[PeopleSpec, ...],
    obstacles: GoalQueries,
    rng: np.random.Generator,
    time_s: float,
    day_active: list[bool],
    keep_away: FloatArray | None = None,
    weekday: int | None = None,
) -> Crowd:
    """Place the people present at ``time_s`` (profile x count) on free spots of their areas;
    ``weekday`` (0 Monday .. 6 Sunday) picks a population's profile for that day, if any."""
    pos, goal, v0, rad, popi, ids, wps = [], [], [], [], [], [], []
    for k, pop in enumerate(populations):
        if not day_active[k]:
            continue
        profile = pop.profile if weekday is None else pop.profile_on(weekday)
        n = int(round(pop.count * profile_fraction(profile, time_s)))
        for j in range(n):
            wp = int(rng.integers(len(pop.route))) if pop.route else -1
            xy = _free_spot(obstacles, rng, pop, wp, pos, rad, keep_away)
            if xy is None:
                continue
            pos.append(xy)
            rad.append(pop.radius_m)
            v0.append(rng.uniform(*pop.speed_mps))
            if wp >= 0:
                goal.append(np.array(pop.route[wp], dtype=float))
            else:
                goal.append(pick_goal(obstacles, rng, pop, xy, pop.radius_m))
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
        phase=rng.uniform(0, 2 * np.pi, n),
        stuck_s=np.zeros(n),
        ids=tuple(ids),
        waypoint=np.array(wps, dtype=np.int64),
        best_goal_m=np.hypot(*(np.reshape(goal, (n, 2)) - np.reshape(pos, (n, 2))).T),
    )


def _free_spot(
    obstacles: GoalQueries,
    rng: np.random.Generator,
    pop: PeopleSpec,
    wp: int,
    pos: list[FloatArray],
    rad: list[float],
    keep_away: FloatArray | None,
) -> FloatArray | None:
    """A spot for a new person (up to 30 draws): on the route leg toward waypoint ``wp``
    (``-1``: in the areas), clear of the people placed at ``pos`` and 1 m from ``keep_away``."""
    for _ in range(30):
        if wp >= 0:  # on a route: somewhere along the leg toward waypoint wp
            a = np.array(pop.route[wp - 1], dtype=float)
            b = np.array(pop.route[wp], dtype=float)
            c = a + rng.uniform(0.0, 1.0) * (b - a)
            if not obstacles.free(c, pop.radius_m):
                continue
        else:
            c = random_point(obstacles, rng, pop, pop.radius_m)
        if c is None:
            break
        ok = all(np.hypot(*(c - p)) > r + pop.radius_m + 0.1 for p, r in zip(pos, rad, strict=True))
        if keep_away is not None:
            ok = ok and np.hypot(*(c - keep_away)) > 1.0
        if ok:
            return c
    return None


def goal_avoid(robot_xy: FloatArray, robot_radius_m: float) -> tuple[FloatArray, float]:
    """The disc new goals keep clear of (``avoid`` of :func:`renew_goals`): the robot's
    comfort disc (``ROBOT_GAP_M`` beyond its radius) and 0.1 m more."""
    return robot_xy, robot_radius_m + ROBOT_GAP_M + 0.1


def renew_goals(
    crowd: Crowd,
    redo: NDArray[np.bool_],
    populations: tuple[PeopleSpec, ...],
    obstacles: GoalQueries,
    rng: np.random.Generator,
    avoid: tuple[FloatArray, float] | None,
) -> None:
    """New goals for the people in ``redo``: the next waypoint of a (closed) route, or a goal
    in sight (not in ``avoid``); who finds none pauses ``PAUSE_S`` before trying again."""
    pos = crowd.pos
    for i in np.flatnonzero(redo):
        pop = populations[int(crowd.population[i])]
        if pop.route:  # next waypoint of the (closed) route
            crowd.waypoint[i] = (crowd.waypoint[i] + 1) % len(pop.route)
            crowd.goal[i] = pop.route[int(crowd.waypoint[i])]
        else:
            crowd.goal[i] = pick_goal(obstacles, rng, pop, pos[i], float(crowd.radius[i]), avoid)
        crowd.stuck_s[i] = 0.0
        (gx, gy), (px, py) = crowd.goal[i].tolist(), pos[i].tolist()
        if gx == px and gy == py:  # no goal found: pause, then retry
            crowd.stuck_s[i] = -PAUSE_S
        crowd.best_goal_m[i] = float(np.hypot(*(crowd.goal[i] - pos[i])))
