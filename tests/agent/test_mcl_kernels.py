"""The MCL core's compiled kernels against independent references: the likelihood field's
end-point lookup (a float64 projection per particle and beam), the particle clusters (a
breadth-first search over the bins), the occupancy grid's distance field (the distance to the
nearest occupied cell, by brute force and in closed form) and the ray casting of expected
ranges (the crossing of a wall, in closed form)."""

from __future__ import annotations

import math
from collections import deque

import numpy as np
import pytest

from dynmap_sim.agent.grid import OCCUPIED, OccupancyGrid, squared_distances
from dynmap_sim.agent.localization.distance_filter import cast_rays, expected_ranges
from dynmap_sim.agent.localization.likelihood_field import endpoint_values
from dynmap_sim.agent.localization.particle_filter_kernels import bin_clusters


def _endpoint_cell(grid: OccupancyGrid, pose, r: float, a: float, mount) -> tuple[int, float]:
    """The flat cell of a beam's end point in float64 (``H * W`` outside) and its distance
    [cells] to the nearest cell border."""
    x, y, th = pose
    mx, my, myaw = mount
    lx = x + math.cos(th) * mx - math.sin(th) * my
    ly = y + math.sin(th) * mx + math.cos(th) * my
    fx = (lx + r * math.cos(th + a + myaw) - grid.origin_xy_m[0]) / grid.resolution_m
    fy = (ly + r * math.sin(th + a + myaw) - grid.origin_xy_m[1]) / grid.resolution_m
    border = min(abs(fx - round(fx)), abs(fy - round(fy)))
    h, w = grid.shape
    ix, iy = math.floor(fx), math.floor(fy)
    return (iy * w + ix if 0 <= ix < w and 0 <= iy < h else h * w), border


@pytest.mark.parametrize("seed", range(8))
def test_endpoint_values_are_the_table_at_the_end_point_cell(seed: int) -> None:
    """Each beam's value is the table's at the cell of its end point (the float32 projection
    may pick the neighbour only within 1e-3 cells of a border)."""
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(1, 60, 2))
    res = float(rng.choice([0.05, 0.1, 0.033]))
    grid = OccupancyGrid(np.zeros((h, w), np.int8), rng.uniform(-3, 3, 2), res, 1.0)
    n_p, n_b = int(rng.integers(1, 40)), int(rng.integers(1, 30))
    span = np.array([w, h]) * res
    xy = grid.origin_xy_m + rng.uniform(-0.3, 1.3, (n_p, 2)) * span  # some outside
    particles = np.column_stack([xy, rng.uniform(-4, 4, n_p)])
    ranges = rng.uniform(0.0, 3.0, n_b)
    angles = np.sort(rng.uniform(-2.1, 2.1, n_b))
    mount = (float(rng.normal(0, 0.2)), float(rng.normal(0, 0.1)), float(rng.normal(0, 0.5)))
    got = endpoint_values(np.arange(h * w + 1), particles, ranges, angles, mount, grid)
    assert got.shape == (n_p, n_b) and got.dtype == np.int64
    for i in range(n_p):
        for j in range(n_b):
            want, border = _endpoint_cell(grid, particles[i], ranges[j], angles[j], mount)
            assert got[i, j] == want or border < 1e-3


def test_endpoint_values_keep_the_table_dtype_and_the_outside_value() -> None:
    grid = OccupancyGrid(np.zeros((3, 4), np.int8), [0.0, 0.0], 0.1, 1.0)
    table = np.arange(13, dtype=np.float32) / 2
    far = endpoint_values(table, np.array([[0.15, 0.15, 0.0]]), np.array([0.1, 5.0]),
                          np.zeros(2), (0, 0, 0), grid)  # fmt: skip
    assert far.dtype == np.float32
    assert far.tolist() == [[table[1 * 4 + 2], table[12]]]


def _brute_clusters(ukeys: np.ndarray, ny: int, n_th: int) -> np.ndarray:
    """Connected components of the bins (26 neighbours, theta wrapping) by breadth-first
    search from each unlabelled bin in key order."""
    bins = [(int(k) // (ny * n_th), int(k) % (ny * n_th) // n_th, int(k) % n_th) for k in ukeys]
    index = {b: u for u, b in enumerate(bins)}
    label = np.full(len(bins), -1)
    n = 0
    for u0 in range(len(bins)):
        if label[u0] >= 0:
            continue
        label[u0] = n
        todo = deque([u0])
        while todo:
            bx, by, bt = bins[todo.popleft()]
            for dx in (-1, 0, 1):
                for dy in (-1, 0, 1):
                    for dt in (-1, 0, 1):
                        v = index.get((bx + dx, by + dy, (bt + dt) % n_th))
                        if v is not None and label[v] < 0:
                            label[v] = n
                            todo.append(v)
        n += 1
    return label


@pytest.mark.parametrize("seed", range(40))
def test_bin_clusters_are_the_connected_components(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n_th = int(rng.choice([3, 4, 36]))
    n = int(rng.integers(1, 120))
    bx = rng.integers(0, rng.integers(1, 10), n)
    by = rng.integers(0, rng.integers(1, 10), n)
    bt = rng.integers(0, n_th, n)
    ny = int(by.max()) + 3
    ukeys = np.unique((bx * ny + by) * n_th + bt)
    np.testing.assert_array_equal(bin_clusters(ukeys, ny, n_th), _brute_clusters(ukeys, ny, n_th))


def test_bin_clusters_join_across_the_theta_wrap() -> None:
    n_th, ny = 36, 4
    ukeys = np.array([(0 * ny + 1) * n_th + 0, (0 * ny + 1) * n_th + 35, (3 * ny + 1) * n_th])
    assert bin_clusters(np.sort(ukeys), ny, n_th).tolist() == [0, 0, 1]


@pytest.mark.parametrize("seed", range(30))
def test_squared_distances_are_the_nearest_occupied_cell(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(1, 25, 2))
    occ = rng.random((h, w)) < rng.choice([0.005, 0.05, 0.3, 0.9])
    occ[rng.integers(h), rng.integers(w)] = True
    oy, ox = np.nonzero(occ)
    yy, xx = np.mgrid[0:h, 0:w]
    want = ((yy[..., None] - oy) ** 2 + (xx[..., None] - ox) ** 2).min(axis=-1)
    np.testing.assert_array_equal(squared_distances(occ), want.astype(np.float64))


def test_the_distance_field_of_one_occupied_cell_is_the_euclidean_distance() -> None:
    """One occupied cell at (iy, ix) = (7, 12): every cell centre's distance is
    ``res * hypot(x - 12, y - 7)``, clipped at ``max_dist_m``."""
    occ = np.zeros((20, 31), np.int8)
    occ[7, 12] = OCCUPIED
    grid = OccupancyGrid(occ, [-1.0, 2.0], 0.05, max_dist_m=0.6)
    yy, xx = np.mgrid[0:20, 0:31]
    want = np.minimum(0.05 * np.hypot(xx - 12, yy - 7), 0.6).astype(np.float32)
    np.testing.assert_allclose(grid.dist_m, want, rtol=1e-6, atol=1e-7)
    assert grid.dist_m[7, 12] == 0.0 and grid.dist_m.max() == np.float32(0.6)
    empty = OccupancyGrid(np.zeros((3, 3), np.int8), [0.0, 0.0], 0.1, max_dist_m=1.5)
    assert (empty.dist_m == np.float32(1.5)).all()


@pytest.mark.parametrize("seed", range(10))
def test_expected_ranges_end_where_the_beam_enters_a_wall(seed: int) -> None:
    """A wall of occupied columns from x = 3 m: a beam from (x0, y0) at angle ``a`` enters it
    after ``(3 - x0) / cos a``; the cast, sampling every half cell, stops within half a cell
    beyond (inf for beams that miss it within range)."""
    rng = np.random.default_rng(seed)
    res = float(rng.choice([0.05, 0.1]))
    occ = np.zeros((int(6 / res), int(5 / res)), np.int8)
    occ[:, int(round(3 / res)) :] = OCCUPIED
    grid = OccupancyGrid(occ, [0.0, 0.0], res)
    pose = np.array([rng.uniform(0.2, 2.8), rng.uniform(2.0, 4.0), rng.uniform(-0.5, 0.5)])
    angles = rng.uniform(-1.0, 1.0, 50)
    range_max = 4.0
    got = expected_ranges(grid, pose, angles, range_max)
    a = pose[2] + angles
    entry = (3.0 - pose[0]) / np.cos(a)
    y_entry = pose[1] + entry * np.sin(a)
    hits = (entry <= range_max - res) & (y_entry > 0.0) & (y_entry < 6.0 - 1e-9)
    assert hits.sum() > 10
    assert np.all(got[hits] >= entry[hits] - 1e-9)
    assert np.all(got[hits] <= entry[hits] + 0.5 * res + 1e-9)
    assert np.all(np.isinf(got[entry > range_max + 1e-9]))


def test_cast_rays_samples_every_half_cell_and_off_grid_never_hits() -> None:
    occ = np.zeros((4, 4), bool)
    occ[1, 3] = True
    t, first = cast_rays(occ, np.zeros(2), 0.1, [0.07, 0.15, 0.0], [0.0, np.pi], 1.0)
    np.testing.assert_allclose(t, 0.05 * np.arange(1, 21))
    assert first.tolist() == [4, -1]  # 0.07 + 0.25 m is in column 3; backwards: off the grid
