"""The thinning of a point set to one point per cell (scan_points.first_per_cell)."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim.agent.mapping.scan_points import BeamDirections, first_per_cell, scan_points_base
from dynmap_sim.types import LaserSpec
from tests.agent.maps.test_sample_set import UPDATE_KERNELS as BACKENDS  # python, numba


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", range(20))
def test_first_per_cell_kernel_gives_the_numpy_indices(backend, seed):
    """The kernel keeps the numpy code's points: the first of each cell, in order (cells
    with many points, negative coordinates, points on cell borders, a single point)."""
    rng = np.random.default_rng(seed)
    n = int(rng.choice([1, 2, 50, 400, 3000]))
    cell = float(rng.choice([0.05, 0.1, 0.3]))
    # small boxes (the dense table of cells) and spread-out points (the sort of the keys)
    pts = rng.uniform(-6.0, 6.0, (n, 2)) * (1.0 if seed % 4 else 1e4)
    pts[: n // 4] = np.round(pts[: n // 4] / cell) * cell  # on the borders
    pts[n // 2 :: 3] = pts[n // 2 :: 3].round(1)  # repeated cells and points
    want = first_per_cell(pts, cell, backend="numpy")
    got = first_per_cell(pts, cell, backend=backend)
    assert np.array_equal(want, got)
    assert np.array_equal(np.unique(np.floor(pts[got] / cell), axis=0).shape, (len(got), 2))


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", range(12))
def test_scan_points_kernel_gives_the_numpy_points(backend, seed):
    """scan_points_base's loop (with beam directions) gives the numpy points bit for bit:
    invalid readings (NaN, inf, below the minimum, at the maximum), a mounted laser."""
    rng = np.random.default_rng(seed)
    mount = (0.0, 0.0, 0.0) if seed % 3 == 0 else tuple(rng.normal(0.0, 0.3, 3))
    laser = LaserSpec(
        name="t", n_beams=683, angle_min_rad=-2.0862, angle_increment_rad=2 * np.pi / 1024,
        range_min_m=0.02, range_max_m=5.6, scan_period_s=0.1, time_increment_s=0.0,
        mount_pose=mount,
    )  # fmt: skip
    r = rng.uniform(0.0, 6.0, laser.n_beams).astype(np.float32)
    r[rng.integers(0, laser.n_beams, 40)] = np.nan
    r[rng.integers(0, laser.n_beams, 20)] = np.inf
    r[rng.integers(0, laser.n_beams, 10)] = 5.6
    r[rng.integers(0, laser.n_beams, 10)] = 0.01
    beams = BeamDirections(laser)
    want = scan_points_base(laser, r, beams, backend="numpy")
    got = scan_points_base(laser, r, beams, backend=backend)
    assert want.shape == got.shape and want.tobytes() == got.tobytes()
