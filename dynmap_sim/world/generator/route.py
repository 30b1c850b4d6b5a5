"""The operator's route: through the rooms in one round, each room entered and left (through
the same doorway where it is a dead end), with a small loop inside larger rooms, and back to
the start. Legs between places are grid A* paths round everything the schedule ever puts
down, straightened into few waypoints.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import label

from dynmap_sim.world.generator.furnish import Furnished, inner_box
from dynmap_sim.world.generator.grid import Grid, astar, path_cost, simplify
from dynmap_sim.world.generator.params import GeneratorError
from dynmap_sim.world.generator.plan import Plan, Room
from dynmap_sim.world.polygons import FloatArray

#: Rooms the route passes through rather than visits.
HUBS = ("corridor", "lobby", "lab", "warehouse")
#: Clearance [m] the route's straight legs aim for.
WANT_M = 0.6


def room_places(grid: Grid, plan: Plan, room: Room, n: int, need: float) -> list[tuple]:
    """Up to ``n`` well-spread points of ``room`` with the most clearance (at least ``need``)."""
    x0, y0, x1, y1 = inner_box(plan, room)
    i0, j0 = grid.index(x0, y0)
    i1, j1 = grid.index(x1, y1)
    sub = grid.clearance[i0 : i1 + 1, j0 : j1 + 1]
    ii, jj = np.nonzero(sub >= need)
    if not len(ii):
        return []
    pts = np.stack(
        [grid.x0 + (jj + j0 + 0.5) * grid.cell, grid.y0 + (ii + i0 + 0.5) * grid.cell], 1
    )
    score = np.minimum(sub[ii, jj], 1.0)
    picked = [int(np.argmax(score))]
    while len(picked) < n:
        d = np.min(np.hypot(*(pts[:, None, :] - pts[picked][None]).transpose(2, 0, 1)), axis=1)
        k = int(np.argmax(np.minimum(d, 6.0) * score))
        if d[k] < 1.5:
            break
        picked.append(k)
    return [tuple(np.round(pts[k], 2)) for k in picked]


def _order(points: list[tuple], centre) -> list[tuple]:
    return sorted(points, key=lambda q: np.arctan2(q[1] - centre[1], q[0] - centre[0]))


def visits(grid: Grid, plan: Plan, fur: Furnished, rooms: list[Room], need: float) -> list[tuple]:
    """Places the route visits in order: round the building by angle about its centre, the
    places of each room together; the hall's aisles in a snake."""
    centre = (0.5 * plan.width, 0.5 * plan.depth)
    groups = []
    for room in rooms:
        if room.use == "warehouse":
            continue
        small = room.area_m2 < 12 or room.use == "corridor"
        n = 1 if small else 2 if room.area_m2 < 30 else 4
        pts = room_places(grid, plan, room, n, need)
        if pts:
            rc = (0.5 * (room.box[0] + room.box[2]), 0.5 * (room.box[1] + room.box[3]))
            groups.append((np.arctan2(rc[1] - centre[1], rc[0] - centre[0]), _order(pts, rc)))
    out = [q for _, pts in sorted(groups) for q in pts]
    if plan.kind == "hall":
        snake = []
        for k, (xw, y, xe) in enumerate(fur.aisles):
            ends = [(round(xw + 0.3, 2), round(y, 2)), (round(xe, 2), round(y, 2))]
            snake += ends if k % 2 else ends[::-1]
        out = snake + out
    return out


def draw_route(grid: Grid, plan: Plan, fur: Furnished, rooms: list[Room], radius: float):
    """Waypoints ``(K, 2)`` of a closed route through ``rooms`` (start = end)."""
    cost = path_cost(grid, radius + 0.1)
    labels, _ = label(np.isfinite(cost), structure=np.ones((3, 3)))
    places = [q for q in visits(grid, plan, fur, rooms, radius + 0.35) if labels[grid.index(*q)]]
    # the places the robot can reach from one another: the free region holding most of them
    region = np.bincount([labels[grid.index(*q)] for q in places]).argmax()
    places = [q for q in places if labels[grid.index(*q)] == region]
    if len(places) < 2:
        raise GeneratorError(
            f"fewer than two places of this {plan.kind} can be reached by a robot of radius "
            f"{radius:g} m; try a smaller robot_radius_m or wider doorways"
        )
    route: list[FloatArray] = []
    for a, b in zip(places, places[1:] + places[:1], strict=True):
        path = astar(grid, cost, a, b)
        assert path is not None  # same free region
        route.append(simplify(grid, path, WANT_M))
    pts = np.concatenate([route[0][:1], *[leg[1:] for leg in route]])
    pts = np.round(pts, 2)
    keep = [0]  # a waypoint close to the last one kept goes if the leg past it stays clear
    for k in range(1, len(pts)):
        close = np.hypot(*(pts[k] - pts[keep[-1]])) <= 0.25
        if (
            close
            and k + 1 < len(pts)
            and grid.segment_clearance(pts[keep[-1]], pts[k + 1]) > radius + 0.1
        ):
            continue
        if not np.array_equal(pts[k], pts[keep[-1]]):
            keep.append(k)
    return pts[keep]
