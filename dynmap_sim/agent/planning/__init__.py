"""Planning (agent role): paths on a clearance grid.

* :mod:`.planner` — the Planner role and its registry;
* :mod:`.clearance_grid` — distance to the nearest obstacle on a grid;
* :mod:`.grid_dijkstra` — ``grid-dijkstra``: Dijkstra over free cells, string-pulled;
* :mod:`.grid_astar` — ``grid-astar``: A* (octile heuristic) over the same graph, and
  ``plan_around`` (H&W §6.3 replanning around a block back onto the path);
* :mod:`.costmap` — the stack's own costmap (nav2 ``costmap_2d`` style): static layer (prior
  walls or a localizer's grid), obstacle layer (scans mark and clear), inflation as a
  :class:`.clearance_grid.ClearanceGrid`.
"""
