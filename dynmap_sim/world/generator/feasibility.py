"""Can a robot of a given radius follow a world's route on a given day? (world side: truth)

In each run's geometry (walls and the objects present, doors as they stand) a leg whose
straight line comes within the robot's radius of an obstacle (exact distances from points
every 2.5 cm) is a problem unless the schedule put that obstacle there on purpose
(``blocks_route``); then grid A* (:mod:`~dynmap_sim.world.generator.grid`) says whether the
robot can get round it at all. A doorway
narrower than the robot and a route with no length are named as such.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dynmap_sim.world.calendar import Calendar
from dynmap_sim.world.generator.grid import CELL_M, Grid, astar, path_cost, rasterize
from dynmap_sim.world.polygons import (
    ccw,
    point_segment_distance,
    points_in_convex,
    polygon_edges,
)
from dynmap_sim.world.schedule import ObjectState, Schedule
from dynmap_sim.world.spec import PeriodicEvent, WorldSpec

#: Most cells along the longer side of a check grid (a larger world gets coarser cells).
MAX_CELLS = 1600


@dataclass(frozen=True)
class RouteProblem:
    """One problem of the route at ``(day, run)``: the field, the place [m] and what."""

    day: int
    run: int
    field: str
    x: float
    y: float
    message: str


def _nearest(objs: tuple[ObjectState, ...], p: np.ndarray) -> list[tuple[float, ObjectState]]:
    """Objects by distance [m] from point ``p`` (0 inside)."""
    out = []
    for o in objs:
        d = float(point_segment_distance(p[None], polygon_edges(o.polygon)).min())
        if points_in_convex(p[None], o.polygon).any():
            d = 0.0
        out.append((d, o))
    out.sort(key=lambda t: t[0])
    return out


def _gap_walls(objs, p: np.ndarray, radius: float) -> str | None:
    """A message when ``p`` lies in a gap between two walls narrower than the robot."""
    near = [(d, o) for d, o in _nearest(objs, p)[:6] if d <= radius + 0.05]
    walls = [(d, o) for d, o in near if o.kind == "wall"]
    if len(walls) < 2:
        return None
    (d0, a), (d1, b) = walls[0], walls[1]
    width = d0 + d1
    if width < 2 * radius:
        return (
            f"passes a gap of {width:.2f} m between {a.id!r} and {b.id!r}, narrower than the "
            f"robot ({2 * radius:.2f} m)"
        )
    return None


def grid_cell(spec: WorldSpec) -> float:
    """The check grid's cell [m]: :data:`CELL_M`, coarser for very large worlds."""
    x0, y0, x1, y1 = spec.bounds
    return max(CELL_M, max(x1 - x0, y1 - y0) / MAX_CELLS)


def _static_problems(spec: WorldSpec) -> list[RouteProblem]:
    route = spec.robot.route
    out = []
    for k in range(len(route) - 1):
        if np.hypot(*(route[k + 1] - route[k])) < 1e-9:
            x, y = route[k]
            out.append(
                RouteProblem(
                    0,
                    0,
                    f"robot.route.{k}",
                    float(x),
                    float(y),
                    f"leg {k}->{k + 1} has no length (a repeated waypoint)",
                )
            )
    if spec.robot.route_length_m < 1e-9:
        x, y = route[0]
        out.append(
            RouteProblem(
                0,
                0,
                "robot.route",
                float(x),
                float(y),
                "the route ends where it starts with nothing between",
            )
        )
    return out


def _clearances(pts: np.ndarray, objs: tuple[ObjectState, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Exact distance [m] from each point ``(P, 2)`` to the nearest object (0 inside one) and
    that object's index."""
    edges = [polygon_edges(o.polygon) for o in objs]
    owner = np.repeat(np.arange(len(objs)), [len(e) for e in edges])
    d = point_segment_distance(pts, np.concatenate(edges))  # (P, E)
    for k, o in enumerate(objs):  # a point inside an outline is at 0
        lo, hi = o.polygon.min(axis=0), o.polygon.max(axis=0)
        cand = np.flatnonzero(np.all((pts >= lo) & (pts <= hi), axis=1))
        if len(cand):
            inside = cand[points_in_convex(pts[cand], ccw(o.polygon))]
            d[np.ix_(inside, np.flatnonzero(owner == k))] = 0.0
    best = np.argmin(d, axis=1)
    return d[np.arange(len(pts)), best], owner[best]


def leg_problems(
    spec: WorldSpec, objs: tuple[ObjectState, ...], day: int, run: int, radius: float
) -> list[RouteProblem]:
    """Problems of the route's legs in one run's geometry ``objs``; grid A* (built only when
    a leg is obstructed) says whether there is a way round."""
    route = spec.robot.route
    out: list[RouteProblem] = []
    grid: Grid | None = None
    step = 0.5 * CELL_M
    boxes = np.array([[*o.polygon.min(axis=0), *o.polygon.max(axis=0)] for o in objs])
    for k in range(len(route) - 1):
        a, b = route[k], route[k + 1]
        lo, hi = np.minimum(a, b) - radius - 0.05, np.maximum(a, b) + radius + 0.05
        near = np.flatnonzero(
            (boxes[:, 0] <= hi[0])
            & (boxes[:, 2] >= lo[0])
            & (boxes[:, 1] <= hi[1])
            & (boxes[:, 3] >= lo[1])
        )
        if not len(near):
            continue
        n = max(2, int(np.hypot(*(b - a)) / step) + 1)
        pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        clear, who_near = _clearances(pts, tuple(objs[i] for i in near))
        who = near[who_near]
        bad = clear <= radius
        if not bad.any() or all(objs[i].blocks_route for i in np.unique(who[bad])):
            continue  # clear, or blocked on purpose (the driver knows)
        mine = bad & np.array([not objs[i].blocks_route for i in who])
        worst = int(np.flatnonzero(mine)[np.argmin(clear[mine])])
        culprit = objs[who[worst]]
        x, y = float(pts[worst][0]), float(pts[worst][1])
        gap = _gap_walls(objs, pts[worst], radius)
        if grid is None:
            grid = rasterize(spec.bounds, [o.polygon for o in objs], grid_cell(spec))
            cost = path_cost(grid, radius)
        way = astar(grid, cost, a, b) is not None
        if gap is not None:
            msg = f"leg {k}->{k + 1} {gap}"
        elif not way:
            msg = (
                f"leg {k}->{k + 1} is blocked by {culprit.id!r} ({culprit.kind}) and there is "
                f"no way round for a robot of radius {radius:.2f} m"
            )
        else:
            msg = (
                f"leg {k}->{k + 1} goes through {culprit.id!r} ({culprit.kind}); the robot "
                "must find a way round"
            )
        out.append(RouteProblem(day, run, f"robot.route.{k}", x, y, msg))
    return out


def _has_periodic(spec: WorldSpec) -> bool:
    """True when a periodic event changes the world between the runs of a day."""
    return any(isinstance(ev, PeriodicEvent) for ev in spec.schedule)


def route_problems(
    spec: WorldSpec,
    seed: int = 0,
    radius: float = 0.2,
    slots: list[tuple[int, int]] | None = None,
) -> list[RouteProblem]:
    """Problems of the route at the runs ``slots`` (default: run 1 of every day, every run of
    every day with a periodic event in the schedule, and every run where an event takes
    effect), each distinct geometry checked once and a problem
    reported at the first run it is seen."""
    cal = Calendar(spec.calendar)
    sched = Schedule(spec, cal)
    if slots is None:
        extra = {(cal.day_of(ev.at), ev.run) for ev in spec.schedule if getattr(ev, "run", 1) > 1}
        runs = range(1, (cal.runs_per_day if _has_periodic(spec) else 1) + 1)
        every = {(d, r) for d in range(1, cal.n_days + 1) for r in runs}
        slots = sorted(every | {s for s in extra if s[0]})
    out = _static_problems(spec)
    seen_geometry: set = set()
    seen_problem: set = set()
    for day, run in slots:
        objs = sched.object_states(seed, cal.slot_index(day, run))
        key = tuple((o.id, o.polygon.round(3).tobytes()) for o in objs if o.kind != "wall")
        if key in seen_geometry:
            continue
        seen_geometry.add(key)
        for pr in leg_problems(spec, objs, day, run, radius):
            if (pr.field, pr.message) not in seen_problem:
                seen_problem.add((pr.field, pr.message))
                out.append(pr)
    return out
