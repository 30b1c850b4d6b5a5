"""The broad phase of the people model lists every segment a person may feel, and the
geometry queries of goal choice (free space, inside, line of sight) agree with brute force."""

import numpy as np

from dynmap_sim.world.people import Obstacles, SegmentGrid
from dynmap_sim.world.people.params import CELL_M, REACH_M
from dynmap_sim.world.polygons import point_segment_distance


def _cell_index(grid, z):
    """The grid cell of each point (truncated, clipped to the grid), computed here."""
    nx, ny = grid.shape
    i = np.clip(((z.real - grid.origin[0]) / CELL_M).astype(np.int64), 0, nx - 1)
    j = np.clip(((z.imag - grid.origin[1]) / CELL_M).astype(np.int64), 0, ny - 1)
    return i * ny + j


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
    listed = grid.cells[_cell_index(grid, z)]  # (P, K) segment indices, padded with len(segs)
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
    idx = grid.cells[_cell_index(grid, z)]
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


def _inside_reference(outlines, pts):
    """Crossing parity of a ray toward +x, point by point and outline by outline."""
    out = []
    for px, py in pts.tolist():
        inside = False
        for outline in outlines:
            odd = False
            for x0, y0, x1, y1 in outline:
                if (y0 > py) != (y1 > py) and x0 + (py - y0) / (y1 - y0) * (x1 - x0) > px:
                    odd = not odd
            inside |= odd
        out.append(inside)
    return np.array(out)


def test_inside_any_is_the_crossing_parity_per_outline():
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
    for k in range(20):
        pts = rng.uniform(-1.0, 12.0, (int(rng.integers(1, 60)), 2))
        j = rng.integers(len(segs), size=len(pts))
        on = rng.random(len(pts)) < 0.3
        pts[on] = segs[j[on], :2]  # on a corner
        on = rng.random(len(pts)) < 0.2
        t = rng.random(on.sum())[:, None]
        pts[on] = segs[j[on], :2] + t * (segs[j[on], 2:] - segs[j[on], :2])  # on an edge
        np.testing.assert_array_equal(obs.inside_any(pts), _inside_reference(outlines, pts), str(k))


def test_free_mask_is_the_distance_to_every_segment_and_not_inside():
    rng = np.random.default_rng(5)
    segs = _random_segments(rng, 30)
    box = np.array([[4.0, 4.0, 6.0, 4.0], [6.0, 4.0, 6.0, 6.0], [6.0, 6.0, 4.0, 6.0]])
    box = np.vstack([box, [[4.0, 6.0, 4.0, 4.0]]])
    obs = Obstacles(np.vstack([box, segs]), outline_starts=np.array([0, 4]))
    pts = rng.uniform(-1.0, 13.0, (1500, 2))
    for r in (0.22, 1.2):  # within the grid's reach, and wider than it
        want = point_segment_distance(pts, obs.segments).min(axis=1) > r + 0.05
        inside = _inside_reference([box, segs], pts)
        np.testing.assert_array_equal(obs.free_mask(pts, r), want & ~inside)


def _crosses(a, b, s):
    """Brute force: the segments a-b and s properly cross (each one's ends strictly on
    opposite sides of the other)."""

    def side(p, q, r):
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])

    p0, p1 = s[:2], s[2:]
    return side(a, b, p0) * side(a, b, p1) < 0 and side(p0, p1, a) * side(p0, p1, b) < 0


def test_line_of_sight_is_no_proper_crossing():
    rng = np.random.default_rng(6)
    segs = _random_segments(rng, 25)
    obs = Obstacles(segs)
    a = np.array([6.0, 6.0])
    bs = rng.uniform(0.0, 12.0, (300, 2))
    want = [not any(_crosses(a, b, s) for s in segs) for b in bs]
    assert obs.visible_many(a, bs).tolist() == want
    assert 0 < sum(want) < len(want)
