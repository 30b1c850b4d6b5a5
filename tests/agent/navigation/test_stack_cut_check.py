"""The corridor cut check (H&W §6.3) looks only at the path's first ``cut_check_m``: samples
beyond it are not generated, and what it finds (numpy or the numba kernel) is what the check
of the whole path finds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dynmap_sim.agent.navigation.route_numba import cut_probe
from dynmap_sim.agent.navigation.stack import (
    NavigationStack,
    _clamped_projection,
    cut_stations,
    first_cut_stretch,
)
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid
from dynmap_sim.types import LaserSpec

LASER = LaserSpec("test", 181, -math.pi / 2, math.pi / 180, 0.05, 8.0, 0.1, 0.0)


def cut_whole_path(stack, path, hw, grid, pose, seg0):
    """The check sampling the whole remaining path (the code before the cut-off): the same
    stations, on every segment of the path."""
    p = stack.params
    seg0 = min(seg0, len(path) - 2)
    verts = path[seg0:]
    a = verts[0] + _clamped_projection(verts[0], verts[1], pose[:2])
    verts = np.concatenate([a[None], verts[1:]])
    hw_seg = np.minimum(hw[seg0:-1], hw[seg0 + 1 :])
    lin = np.linspace(-1.0, 1.0, p.cut_offsets)
    pts, cut = cut_stations(verts, hw_seg, grid, p.cut_check_m, lin, stack.min_clearance_m)
    return first_cut_stretch(pts, cut)


@pytest.mark.parametrize("backend", ["numpy", "auto"])
def test_the_cut_check_equals_the_check_of_the_whole_path(backend):
    stack = NavigationStack(LASER, 0.17)
    stack.backend = backend
    rng = np.random.default_rng(7)
    found = 0
    for _ in range(150):
        clearance = rng.uniform(0.0, 1.0, (120, 120))
        clearance[rng.random((120, 120)) < 0.5] = 0.0
        grid = ClearanceGrid(np.array([-3.0, -3.0]), 0.05, clearance)
        n = int(rng.integers(2, 40))
        steps = rng.normal(0.0, 0.4, (n - 1, 2)) * (rng.random((n - 1, 1)) > 0.1)  # some 0 m
        path = np.concatenate([[[0.0, 0.0]], np.cumsum(steps, axis=0)])
        hw = rng.uniform(0.05, 0.4, n)
        pose = np.array([*rng.uniform(-0.3, 0.3, 2), 0.0])
        seg0 = int(rng.integers(0, n))
        want = cut_whole_path(stack, path, hw, grid, pose, seg0)
        got = stack._cut_ahead(path, hw, grid, pose, seg0=seg0)
        assert (got is None) == (want is None)
        if got is not None:
            np.testing.assert_array_equal(got, want)
            found += 1
    assert found > 20  # cuts were found, not only free corridors


def test_the_cut_kernel_uncompiled_equals_compiled():
    rng = np.random.default_rng(1)
    clearance = rng.uniform(0.0, 0.5, (60, 80))
    for _ in range(30):
        verts = np.cumsum(rng.normal(0.0, 0.5, (int(rng.integers(2, 12)), 2)), axis=0)
        hw = rng.uniform(0.05, 0.4, len(verts) - 1)
        args = (verts, hw, 0.05, 2.0, np.linspace(-1, 1, 9), clearance, -1.0, -1.5, 0.05, 0.2)
        (p1, c1), (p2, c2) = cut_probe(*args, python=True), cut_probe(*args)
        np.testing.assert_array_equal(p1, p2)
        np.testing.assert_array_equal(c1, c2)
