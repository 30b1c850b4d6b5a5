"""The thinning of a point set to one point per cell (scan_points.first_per_cell)."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim.agent.mapping.scan_points import first_per_cell
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
