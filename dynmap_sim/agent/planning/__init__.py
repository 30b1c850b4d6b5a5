"""Planning (agent role): paths on a clearance grid.

* :mod:`.planner` — the Planner role and its registry;
* :mod:`.clearance_grid` — distance to the nearest obstacle on a grid;
* :mod:`.grid_dijkstra` — ``grid-dijkstra``: Dijkstra over free cells, string-pulled.
"""
