"""Navigation memory (agent role): the routes a robot has driven, Hentschel & Wagner 2011 §5.

* :mod:`.route_memory` — the route memory (H&W §5): :mod:`.routes` (directed waypoint
  sequences, eqs. 16-17, and the route graph :mod:`dynmap_sim.agent.planning.route_astar`
  plans on, §6.2), :mod:`.route_tracking` (the robot's position relative to them and what
  driving them teaches, §5.1-5.2), :mod:`.route_learning` (new routes and forgetting, §5.2).
* :mod:`.stack` — the navigation stack: costmap, route memory, route A*, the corridor
  follower, global replanning around blocks (§6.3), recovery and the collision monitor,
  composed per scan (``begin_run`` / ``step`` / ``end_run``).
* :mod:`.policy` — the stack and a localizer as a Gymnasium policy (``reset`` / ``act``).

Everything here sees only the agent's own pose estimate, never the truth.
"""

from dynmap_sim.agent.navigation.route_memory import RouteMemory
from dynmap_sim.agent.navigation.route_tracking import RoutePosition
from dynmap_sim.agent.navigation.routes import Route, RouteMemoryParams, Waypoint
from dynmap_sim.agent.planning.route_graph import Edge, RouteGraph

__all__ = [
    "Edge",
    "Route",
    "RouteGraph",
    "RouteMemory",
    "RouteMemoryParams",
    "RoutePosition",
    "Waypoint",
]
