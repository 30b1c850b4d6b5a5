"""Route blocks: an object closing the passage the route takes, for a day or two, marked
``blocks_route``; some leave a way round (the grid A* finds another path between the
neighbouring waypoints), some none."""

from __future__ import annotations

from typing import Any

import numpy as np

from dynmap_sim.world.generator.grid import Grid, astar, path_cost, with_polygons
from dynmap_sim.world.generator.place import Placer, outline, rounded_pose
from dynmap_sim.world.polygons import (
    ccw,
    points_in_convex,
    polygon_edges,
    segment_pair_distances,
)


def polyline_legs_clearance(route: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Clearance [m] of each leg of ``route`` from the convex ``poly`` (0 where it enters)."""
    legs = np.concatenate([route[:-1], route[1:]], axis=1)
    d = segment_pair_distances(legs, polygon_edges(poly)).min(axis=1)
    inside = points_in_convex(route, ccw(poly))
    d[inside[:-1] | inside[1:]] = 0.0
    return d


#: Widest passage [m] one object closes.
MAX_SPAN_M = 3.2


def _span(grid: Grid, p, n) -> tuple[float, float]:
    """Free distance [m] from ``p`` along ``+n`` and ``-n`` to the first occupied cell."""
    out = []
    for s in (1.0, -1.0):
        d = 0.0
        while d < MAX_SPAN_M:
            q = p + s * (d + 0.5 * grid.cell) * n
            i, j = grid.index(*q)
            if grid.occupied[i, j]:
                break
            d += 0.5 * grid.cell
        out.append(d)
    return out[0], out[1]


def _candidates(route: np.ndarray, rng) -> list[tuple[np.ndarray, np.ndarray]]:
    """Points on the route's legs, away from the waypoints: ``(point, unit along)``."""
    out = []
    for k in range(len(route) - 1):
        a, b = route[k], route[k + 1]
        length = float(np.hypot(*(b - a)))
        if length < 3.0:
            continue
        u = (b - a) / length
        for s in np.arange(1.2, length - 1.2, 0.6):
            out.append((a + s * u, u))
    order = rng.permutation(len(out))
    return [out[i] for i in order]


def _joined(grid: Grid, radius: float, route: np.ndarray, legs) -> bool:
    """True where grid A* joins the two waypoints of every leg in ``legs``."""
    cost = path_cost(grid, radius)
    return all(astar(grid, cost, route[j], route[j + 1]) is not None for j in legs)


def draw_blocks(
    grid: Grid,
    walls: Grid,
    placer: Placer,
    route: np.ndarray,
    rng,
    p: dict,
    days: int,
    n_runs: int,
):
    """Blocking objects and their add/remove events: ``blocks_with_way_round`` of one sort and
    ``blocks_without_way_round`` of the other; the counts placed and, per block, which sort.
    A block leaves a way round where, for every leg it obstructs, grid A* still joins the
    leg's two waypoints round everything the schedule ever puts down (``grid``: so at every
    run); it leaves none where A* finds no way even between the bare ``walls``."""
    want = {True: int(p["blocks_with_way_round"]), False: int(p["blocks_without_way_round"])}
    got = {True: 0, False: 0}
    radius = float(p["robot_radius_m"])
    objects: list[dict[str, Any]] = []
    events: list[dict[str, Any]] = []
    notes: dict[str, str] = {}
    day = 2  # day 1 stays as drawn: the route is checked feasible on it
    for q, u in _candidates(route, rng)[:120]:
        if got[True] >= want[True] and got[False] >= want[False]:
            break
        n = np.array([-u[1], u[0]])
        lp, ln = _span(grid, q, n)
        if lp + ln > MAX_SPAN_M or lp + ln < 2 * radius + 0.1:
            continue
        centre = q + 0.5 * (lp - ln) * n
        obj = {
            "id": f"route_block_{len(objects)}",
            "kind": "furniture",
            "size": [round(lp + ln - 0.04, 3), round(float(rng.uniform(0.6, 1.0)), 3)],
            "pose": rounded_pose(centre[0], centre[1], float(np.arctan2(n[1], n[0]))),
            "present": False,
        }
        poly = outline(obj)
        if not placer.free(poly, 0.0, {"keepout", "lane"}):
            continue
        legs = np.flatnonzero(polyline_legs_clearance(route, poly) < radius + 0.05)
        way = _joined(with_polygons(grid, [poly]), radius + 0.05, route, legs)
        if not way and _joined(with_polygons(walls, [poly]), radius, route, legs):
            continue  # a way round between the walls, but not past everything ever put down
        if got[way] >= want[way] or day > days:
            continue
        placer.add(poly, obj["id"])
        start = int(rng.integers(day, days + 1))
        run = int(rng.integers(1, n_runs + 1))
        end = min(days + 1, start + int(rng.integers(1, 3)))
        notes[obj["id"]] = "a way round" if way else "no way round"
        objects.append(obj)
        events.append(
            {"action": "add", "target": obj["id"], "at": start, "run": run, "blocks_route": True}
        )
        if end <= days:
            events.append({"action": "remove", "target": obj["id"], "at": end})
        day = end
        got[way] += 1
    counts = {"block_way_round": got[True], "block_no_way_round": got[False]}
    return objects, events, counts, notes
