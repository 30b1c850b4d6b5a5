"""The simulated world: world files, calendar and schedule, people (docs/architecture.md §2-3).

```python
from dynmap_sim.world import load_world, resolve_world_path, World
spec = load_world(resolve_world_path("lab"))
world = World(spec, seed=0)
world.reset(day=4, run=2)
world.step(0.1, robot_pose=(x, y, theta))
world.geometry.segments  # (N, 4) for the lidar
```
"""

from dynmap_sim.world.calendar import Calendar, RunSlot
from dynmap_sim.world.geometry import GeometryView
from dynmap_sim.world.loader import (
    WorldFileError,
    load_world,
    parse_world,
    resolve_world_path,
    world_json_schema,
)
from dynmap_sim.world.route import (
    ROUTE_CLEARANCE_M,
    route_blocked,
    route_clearance_m,
    route_clearances,
)
from dynmap_sim.world.schedule import ObjectState, Snapshot
from dynmap_sim.world.spec import WorldSpec
from dynmap_sim.world.world import (
    CATEGORY_PERSON,
    CATEGORY_STATIC,
    COLLISION_PERSON,
    COLLISION_STATIC,
    World,
)

__all__ = [
    "CATEGORY_PERSON",
    "CATEGORY_STATIC",
    "COLLISION_PERSON",
    "COLLISION_STATIC",
    "ROUTE_CLEARANCE_M",
    "Calendar",
    "GeometryView",
    "ObjectState",
    "RunSlot",
    "Snapshot",
    "World",
    "WorldFileError",
    "WorldSpec",
    "load_world",
    "parse_world",
    "resolve_world_path",
    "route_blocked",
    "route_clearance_m",
    "route_clearances",
    "world_json_schema",
]
