"""The broad phase of the people model lists every segment a person may feel."""

import numpy as np

from dynmap_sim.world.people import Obstacles, SegmentGrid
from dynmap_sim.world.people.params import REACH_M
from dynmap_sim.world.polygons import point_segment_distance


def _random_segments(rng, n):
    a = rng.uniform(0.0, 12.0, (n, 2))
    b = a + rng.uniform(-2.0, 2.0, (n, 2))
    return np.hstack([a, b])


def test_grid_lists_every_segment_within_reach():
    rng = np.random.default_rng(0)
    segs = _random_segments(rng, 40)
    grid = SegmentGrid(segs)
    pts = rng.uniform(-2.0, 14.0, (3000, 2))
    z = np.ascontiguousarray(pts).view(np.complex128)[:, 0]
    listed = grid.cells[grid.cell_index(z)]  # (P, K) segment indices, padded with len(segs)
    assert listed.max() == len(segs)  # the far dummy pads the rows
    near = point_segment_distance(pts, segs) <= REACH_M
    assert near.any()
    for i in np.flatnonzero(near.any(axis=1)):
        assert set(np.flatnonzero(near[i])) <= set(listed[i]), i


def test_grid_rows_are_the_listed_segments():
    rng = np.random.default_rng(1)
    segs = _random_segments(rng, 10)
    grid = SegmentGrid(segs)
    z = np.array([3.0 + 4.0j, 20.0 - 5.0j])
    rows = grid.rows(z)
    idx = grid.cells[grid.cell_index(z)]
    p0 = np.append(segs[:, 0] + 1j * segs[:, 1], 1e6 + 1e6j)
    np.testing.assert_array_equal(rows[..., 0], p0[idx])
    assert grid.all_rows(2).shape == (2, len(segs) + 1, 3)


def test_broad_phase_and_naive_agree_on_free_space():
    rng = np.random.default_rng(2)
    segs = _random_segments(rng, 30)
    pts = rng.uniform(-1.0, 13.0, (2000, 2))
    fast = Obstacles(segs, broad_phase=True).free_mask(pts, 0.22)
    naive = Obstacles(segs, broad_phase=False).free_mask(pts, 0.22)
    np.testing.assert_array_equal(fast, naive)
    assert fast.any() and not fast.all()


def test_empty_geometry_has_no_candidates_but_the_dummy():
    grid = SegmentGrid(np.zeros((0, 4)))
    rows = grid.rows(np.array([0j, 5.0 + 5.0j]))
    assert rows.shape == (2, 1, 3)
    assert np.all(rows[..., 0] == 1e6 + 1e6j)


def _inside_all_pairs(obs, pts):
    """The crossing-parity test of every point against every segment (the reference)."""
    s = obs.segments
    py = pts[:, 1:2]
    straddle = (s[:, 1] > py) != (s[:, 3] > py)
    x_cross = s[:, 0] + (py - s[:, 1]) / obs._cross_den * obs._cross_dx
    hits = straddle & (x_cross > pts[:, 0:1])
    return np.logical_xor.reduceat(hits, obs.outline_starts, axis=1).any(axis=1)


def test_inside_any_near_outlines_is_the_all_pairs_test():
    # squares, a triangle and an open chain as outlines; points random, on corners, on edges
    rng = np.random.default_rng(2)
    outlines = []
    for x, y, w in rng.uniform([0, 0, 0.3], [10, 10, 2.0], (12, 3)):
        c = [(x, y), (x + w, y), (x + w, y + w), (x, y + w), (x, y)]
        outlines.append([(*a, *b) for a, b in zip(c[:-1], c[1:], strict=True)])
    outlines.append([(1.0, 1.0, 4.0, 2.0), (4.0, 2.0, 2.0, 5.0), (2.0, 5.0, 1.0, 1.0)])
    outlines.append([(0.0, 3.0, 5.0, 3.0), (5.0, 3.0, 5.0, 8.0)])
    segs = np.array([s for o in outlines for s in o])
    starts = np.cumsum([0] + [len(o) for o in outlines[:-1]])
    obs = Obstacles(segs, outline_starts=starts)
    for k in range(50):
        pts = rng.uniform(-1.0, 12.0, (int(rng.integers(1, 60)), 2))
        j = rng.integers(len(segs), size=len(pts))
        on = rng.random(len(pts)) < 0.3
        pts[on] = segs[j[on], :2]  # on a corner
        on = rng.random(len(pts)) < 0.2
        t = rng.random(on.sum())[:, None]
        pts[on] = segs[j[on], :2] + t * (segs[j[on], 2:] - segs[j[on], :2])  # on an edge
        np.testing.assert_array_equal(obs.inside_any(pts), _inside_all_pairs(obs, pts), str(k))
