"""Navigation memory (agent role): the routes a robot has driven, Hentschel & Wagner 2011 §5.

* :mod:`.route_memory` — routes as directed waypoint sequences (H&W eqs. 16-17), the robot's
  position relative to them (§5.1), their learning and forgetting (§5.2), and the directed
  route graph that :mod:`dynmap_sim.agent.planning.route_astar` plans on (§6.2).
* :mod:`.stack` — the navigation stack: costmap, route memory, route A*, the corridor
  follower, global replanning around blocks (§6.3), recovery and the collision monitor,
  composed per scan (``begin_run`` / ``step`` / ``end_run``).
* :mod:`.policy` — the stack and a localizer as a Gymnasium policy (``reset`` / ``act``).

Everything here sees only the agent's own pose estimate, never the truth.
"""

from dynmap_sim.agent.navigation.route_memory import (
    Edge,
    Route,
    RouteGraph,
    RouteMemory,
    RouteMemoryParams,
    RoutePosition,
    Waypoint,
)

__all__ = [
    "Edge",
    "Route",
    "RouteGraph",
    "RouteMemory",
    "RouteMemoryParams",
    "RoutePosition",
    "Waypoint",
]
