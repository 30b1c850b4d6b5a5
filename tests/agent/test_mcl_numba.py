"""The MCL core's kernels give the numpy code's numbers exactly, on random inputs: the
likelihood field's end-point values, the ray casting of expected ranges and the particle
clusters (:mod:`.mcl_numba`), and the occupancy grid's distance field
(:mod:`dynmap_sim.agent.grid_numba`, against scipy)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from dynmap_sim.agent import grid_numba
from dynmap_sim.agent.grid import OCCUPIED, OccupancyGrid
from dynmap_sim.agent.localization import mcl_numba
from dynmap_sim.agent.localization.distance_filter import cast_rays
from dynmap_sim.agent.localization.likelihood_field import endpoint_cells, endpoint_values
from dynmap_sim.agent.localization.particle_filter import bin_clusters

needs_numba = pytest.mark.skipif(
    not mcl_numba.numba_available(), reason="numba (extra 'fast') not installed"
)
KERNELS = ["python", pytest.param("numba", marks=needs_numba)]


@pytest.mark.parametrize("kernel", KERNELS)
def test_endpoint_values_of_the_kernel_equal_numpy(kernel: str) -> None:
    rng = np.random.default_rng(21)
    for _ in range(30 if kernel == "python" else 200):
        h, w = (int(v) for v in rng.integers(1, 120, 2))
        res = float(rng.choice([0.05, 0.1, 0.033]))
        grid = OccupancyGrid(np.zeros((h, w), np.int8), rng.uniform(-3, 3, 2), res, 1.0)
        n_p, n_b = int(rng.integers(1, 200)), int(rng.integers(1, 70))
        span = np.array([w, h]) * res
        xy = grid.origin_xy_m + rng.uniform(-0.3, 1.3, (n_p, 2)) * span  # some outside
        particles = np.column_stack([xy, rng.uniform(-4, 4, n_p)])
        ranges = rng.uniform(0.0, 6.0, n_b)
        angles = np.sort(rng.uniform(-2.1, 2.1, n_b))
        mount = [rng.normal(0, 0.2), rng.normal(0, 0.1), rng.normal(0, 0.5)]
        if rng.random() < 0.1:
            particles[rng.integers(n_p)] = np.nan  # a lost particle is outside, as in numpy
        with np.errstate(invalid="ignore"):  # NaN to int: outside
            cells = endpoint_cells(particles, ranges, angles, mount, grid)
        table = rng.normal(0, 1, h * w + 1).astype(np.float32)
        for values, ref in ((table, np.take(table, cells)), (np.arange(h * w + 1), cells)):
            got = endpoint_values(values, particles, ranges, angles, mount, grid, backend=kernel)
            assert got.dtype == ref.dtype
            assert got.tobytes() == ref.tobytes()


@pytest.mark.parametrize("kernel", KERNELS)
def test_bin_clusters_of_the_kernel_equal_scipy(kernel: str) -> None:
    rng = np.random.default_rng(22)
    n_th = 36
    for _ in range(60 if kernel == "python" else 300):
        n = int(rng.integers(1, 400))
        bx = rng.integers(0, rng.integers(1, 15), n)
        by = rng.integers(0, rng.integers(1, 15), n)
        bt = rng.integers(0, n_th, n)
        ny = int(by.max()) + 3
        ukeys = np.unique((bx * ny + by) * n_th + bt)
        ref = bin_clusters(ukeys, ny, n_th, backend="numpy")
        np.testing.assert_array_equal(bin_clusters(ukeys, ny, n_th, backend=kernel), ref)


@pytest.mark.parametrize("kernel", KERNELS)
def test_distances_of_the_kernel_equal_scipy(kernel: str) -> None:
    rng = np.random.default_rng(31)
    for _ in range(60 if kernel == "python" else 400):
        h, w = (int(v) for v in rng.integers(1, 90, 2))
        occ = rng.random((h, w)) < rng.choice([0.001, 0.01, 0.1, 0.5, 0.95])
        occ[rng.integers(h), rng.integers(w)] = True
        ref = ndimage.distance_transform_edt(~occ)
        got = np.sqrt(grid_numba.squared_distances(occ, python=kernel == "python"))
        assert got.tobytes() == ref.tobytes()
        cells = np.where(occ, OCCUPIED, rng.choice([-1, 0], (h, w))).astype(np.int8)
        origin, res, max_d = rng.uniform(-3, 3, 2), float(rng.choice([0.05, 0.1])), 1.3
        grid = OccupancyGrid(cells, origin, res, max_d, backend=kernel)
        ref_grid = OccupancyGrid(cells, origin, res, max_d, backend="numpy")
        assert grid.dist_m.tobytes() == ref_grid.dist_m.tobytes()


@pytest.mark.parametrize("kernel", KERNELS)
def test_cast_rays_of_the_kernel_equal_numpy(kernel: str) -> None:
    rng = np.random.default_rng(23)
    for _ in range(30 if kernel == "python" else 200):
        h, w = (int(v) for v in rng.integers(1, 80, 2))
        occupied = rng.random((h, w)) < rng.choice([0.0, 0.01, 0.1, 0.5])
        origin, res = rng.uniform(-3, 3, 2), float(rng.choice([0.05, 0.1]))
        span = np.array([w, h]) * res
        pose = [*(origin + rng.uniform(-0.2, 1.2, 2) * span), rng.uniform(-4, 4)]
        angles = rng.uniform(-2.1, 2.1, int(rng.integers(1, 70)))
        range_max = float(rng.uniform(0.01, 6.0))
        t_ref, ref = cast_rays(occupied, origin, res, pose, angles, range_max, backend="numpy")
        t, got = cast_rays(occupied, origin, res, pose, angles, range_max, backend=kernel)
        assert t.tobytes() == t_ref.tobytes()
        np.testing.assert_array_equal(got, ref)
