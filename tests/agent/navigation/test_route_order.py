"""Route planning keeps a loop's route order: reverse edges never take the robot back over a
via point it has passed (they would close the loop backwards); elsewhere they still serve."""

import numpy as np

from dynmap_sim.agent.navigation import RouteMemory, RouteMemoryParams
from dynmap_sim.agent.navigation.route_planning import RoutePlanning, Targets
from dynmap_sim.agent.navigation.stack_params import StackParams
from dynmap_sim.agent.planning.grid_astar import GridAStar

REVERSE = RouteMemoryParams(reverse_cost_factor=1.5)
#: A 4 m square loop: waypoints 0-4 (4 is the end, on the start); via points 1, 2 and 3.
LOOP = [(0.0, 0.0), (4.0, 0.0), (4.0, 4.0), (0.0, 4.0), (0.0, 0.0)]


def planning(route, via_k: int) -> tuple[RouteMemory, RoutePlanning, Targets]:
    params = StackParams(speed_mps=0.2, loop_via_spacing_m=4.0)
    mem = RouteMemory.from_prior(route, 0.2, 0.35, 0.0, REVERSE, densify=False)
    # a route from the start joins the loop's start and its end: a way round backwards
    mem.add_route([(0.0, 0.0), (0.0, -2.0)], 0.2, 0.35, 0.0)
    targets = Targets(params)
    targets.set_route(mem.routes[0], np.asarray(route[-1]))
    targets.via_k, targets.armed = via_k, True
    return mem, RoutePlanning(params, 0.22, GridAStar(0.22, 0.32)), targets


def test_a_blocked_loop_is_not_closed_backwards_over_the_passed_via_points():
    mem, routing, targets = planning(LOOP, via_k=2)
    assert [wid for _, wid in targets.vias] == [1, 2, 3]
    mem.block((2, 3))  # between the passed via point 2 and the target 3
    back = routing._route_plan_on(mem.graph(), np.array([3.0, 4.0, np.pi]), None, targets)
    assert back is not None and 1 in back.node_ids  # back round through via point 1
    plan, n = routing.route_plan(mem.graph(), np.array([3.0, 4.0, np.pi]), None, targets)
    assert plan is None and n == 2  # forwards the way is blocked: the stack goes round it
    mem.unblock((2, 3))
    plan, _ = routing.route_plan(mem.graph(), np.array([3.0, 4.0, np.pi]), None, targets)
    assert plan is not None and plan.node_ids[1:] == (3,)


def test_a_route_that_is_no_loop_is_still_driven_backwards():
    route = [(0.0, 0.0), (4.0, 0.0), (4.0, 4.0)]  # out of the room: no via points
    mem, routing, targets = planning(route, via_k=0)
    targets.goal_xy, targets.goal_id = np.array([0.0, -2.0]), None  # back out and away
    plan, n = routing.route_plan(mem.graph(), np.array([4.0, 3.0, 0.0]), None, targets)
    assert n == 1 and plan is not None and plan.edges[0] == (1, 0)  # segment 0 -> 1 back
