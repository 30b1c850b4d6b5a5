"""Route checks: how much room the operator's route leaves at a given run.

The shipped worlds keep every waypoint leg at least ``ROUTE_CLEARANCE_M`` from every wall and
object at every run (room for a 0.2 m-radius robot and its controller), except objects the
schedule puts on the route on purpose (``blocks_route = true`` on the event).
"""

from __future__ import annotations

import numpy as np

from dynmap_sim.world.polygons import FloatArray, polyline_clearance
from dynmap_sim.world.schedule import Snapshot

#: Clearance [m] the shipped worlds promise along the route polyline.
ROUTE_CLEARANCE_M = 0.45


def route_clearances(snapshot: Snapshot, route: FloatArray) -> dict[str, float]:
    """Clearance [m] of ``route`` ``(K, 2)`` from every object of ``snapshot``, keyed by id."""
    objs = snapshot.objects
    c = polyline_clearance(np.asarray(route, dtype=np.float64), [o.polygon for o in objs])
    return {o.id: float(v) for o, v in zip(objs, c, strict=True)}


def route_clearance_m(snapshot: Snapshot, route: FloatArray) -> float:
    """Smallest clearance [m] of ``route`` from objects not marked ``blocks_route``."""
    c = route_clearances(snapshot, route)
    blocking = {o.id for o in snapshot.objects if o.blocks_route}
    vals = [v for k, v in c.items() if k not in blocking]
    return min(vals) if vals else float("inf")


def route_blocked(snapshot: Snapshot) -> bool:
    """True if the schedule intentionally blocks the route at this run."""
    return any(o.blocks_route for o in snapshot.objects)
