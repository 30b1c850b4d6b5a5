"""The shipped worlds never put two objects into each other, at any run."""

import numpy as np
import pytest

from dynmap_sim.world import World, load_world
from dynmap_sim.world.polygons import sat_separation

TOL_M = 0.01


@pytest.mark.parametrize("name", ["lab", "apartment", "apartment-hw", "office", "corridor", "hall"])
def test_no_two_objects_overlap_at_any_run(name):
    w = World(load_world(name), seed=0)
    for slot in w.calendar.slots:
        objs = w.snapshot(slot.day, slot.run).objects
        boxes = np.array([np.concatenate([o.polygon.min(0), o.polygon.max(0)]) for o in objs])
        for i, a in enumerate(objs):
            near = np.flatnonzero(
                (boxes[i + 1 :, 0] < boxes[i, 2])
                & (boxes[i + 1 :, 2] > boxes[i, 0])
                & (boxes[i + 1 :, 1] < boxes[i, 3])
                & (boxes[i + 1 :, 3] > boxes[i, 1])
            )
            for j in near + i + 1:
                b = objs[j]
                if a.kind == "wall" and b.kind == "wall":
                    continue  # wall pieces overlap at their joints by design
                depth = -sat_separation(a.polygon, b.polygon)
                assert depth <= TOL_M, (slot.day, slot.run, a.id, b.id, depth)
