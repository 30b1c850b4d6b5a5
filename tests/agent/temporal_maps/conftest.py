"""Synthetic runs for the temporal-map localizers: an L-shaped room, a route round a box."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_scans import LASER, box, drifting_stream, polyline_path, room_segments

from dynmap_sim.agent.grid import OCCUPIED
from dynmap_sim.types import Prior

PTS = np.array([[0, 0], [8, 0], [8, 3], [5, 3], [5, 6], [0, 6]], float)
WALLS = np.concatenate([PTS, np.roll(PTS, -1, axis=0)], axis=1)
#: A box inside the route's loop: there in the morning runs, gone in the evening ones.
BOX = box(2.6, 2.2, 3.2, 2.8)
TRUTH = polyline_path(np.array([[1.0, 1.0], [4.2, 1.0], [4.0, 3.8], [1.0, 3.6]]), 0.1, 0.3)


def run_day(loc, day, rng, with_box, both_runs=False):
    """Two runs, 08:00 and 20:00; the box there ``with_box`` in the first run (in both
    with ``both_runs``); the position errors [m]."""
    errs = []
    for run in (1, 2):
        segs = room_segments(cupboard=False)
        if with_box and (run == 1 or both_runs):
            segs = np.concatenate([segs, BOX])
        loc.begin_run(Prior(initial_pose=TRUTH[0].copy(), walls=WALLS, day=day, run=run))
        for (odom, scan), pose in zip(drifting_stream(TRUTH, segs, LASER, rng), TRUTH, strict=True):
            errs.append(np.hypot(*(loc.update(odom, scan).mean[:2] - pose[:2])))
        loc.end_run()
    loc.end_day()
    return np.array(errs)


def box_share(loc, t_s):
    """Share of the box's boundary points that have an occupied cell within one cell (the
    edges lie on cell borders) in the map predicted for ``t_s``."""
    grid = loc.predicted_grid(t_s)
    u = np.arange(0.05, 0.6, 0.05)
    edge = np.concatenate([np.stack([2.6 + u, np.full_like(u, 2.2)], 1),
                           np.stack([2.6 + u, np.full_like(u, 2.8)], 1),
                           np.stack([np.full_like(u, 2.6), 2.2 + u], 1),
                           np.stack([np.full_like(u, 3.2), 2.2 + u], 1)])  # fmt: skip
    ix, iy = grid.cell_of(edge)
    occ = grid.occupancy == OCCUPIED
    near = np.zeros(len(edge), bool)
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            near |= occ[iy + dy, ix + dx]
    return float(np.mean(near))


@pytest.fixture
def walls():
    """The room's walls: the prior."""
    return WALLS


@pytest.fixture
def day_runs():
    return run_day


@pytest.fixture
def box_cells_share():
    return box_share
