"""Scan points and the thinning of a point set to one point per cell, against plain references."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim.agent.mapping.scan_points import (
    BeamDirections,
    first_per_cell,
    scan_points_base,
    voxel_downsample,
)
from dynmap_sim.types import LaserSpec


@pytest.mark.parametrize("seed", range(20))
def test_first_per_cell_keeps_the_lowest_index_of_each_cell(seed):
    """The first point of each cell, in order (cells with many points, negative coordinates,
    points on cell borders, a single point, spread-out points), against a dictionary."""
    rng = np.random.default_rng(seed)
    n = int(rng.choice([1, 2, 50, 400, 3000]))
    cell = float(rng.choice([0.05, 0.1, 0.3]))
    # small boxes (the dense table of cells) and spread-out points (the sort of the keys)
    pts = rng.uniform(-6.0, 6.0, (n, 2)) * (1.0 if seed % 4 else 1e4)
    pts[: n // 4] = np.round(pts[: n // 4] / cell) * cell  # on the borders
    pts[n // 2 :: 3] = pts[n // 2 :: 3].round(1)  # repeated cells and points
    first: dict[tuple[int, int], int] = {}
    for i, (x, y) in enumerate(pts):
        first.setdefault((int(np.floor(x / cell)), int(np.floor(y / cell))), i)
    want = np.array(sorted(first.values()))
    assert np.array_equal(first_per_cell(pts, cell), want)
    assert np.array_equal(voxel_downsample(pts, cell), pts[want])


@pytest.mark.parametrize("seed", range(12))
def test_scan_points_are_the_polar_readings_in_the_robot_frame(seed):
    """Valid readings (not NaN, inf, below the minimum or at the maximum) as ``r (cos, sin)``
    moved by the laser's mount pose, with and without cached beam directions."""
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
    rr = r.astype(np.float64)
    ok = np.isfinite(rr) & (rr >= 0.02) & (rr < 5.6)
    a = laser.angle_min_rad + laser.angle_increment_rad * np.arange(laser.n_beams)
    x, y, th = mount
    want = np.column_stack([x + rr[ok] * np.cos(th + a[ok]), y + rr[ok] * np.sin(th + a[ok])])
    for beams in (None, BeamDirections(laser)):
        got = scan_points_base(laser, r, beams)
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
