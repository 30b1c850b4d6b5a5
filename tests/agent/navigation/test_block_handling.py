"""The corridor cut check (H&W §6.3): the kernel's stations and cuts against the clearance
grid's own look-ups, and the check of the path's first ``cut_check_m`` against the check of
the whole path."""

from __future__ import annotations

import math

import numpy as np

from dynmap_sim.agent.navigation.block_handling import (
    _clamped_projection,
    cut_probe,
    first_cut_stretch,
)
from dynmap_sim.agent.navigation.stack import NavigationStack
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid
from dynmap_sim.types import LaserSpec

LASER = LaserSpec("test", 181, -math.pi / 2, math.pi / 180, 0.05, 8.0, 0.1, 0.0)


def cut_whole_path(stack, path, hw, grid, pose, seg0):
    """The check on every segment of the remaining path (no cut-off of far segments)."""
    p = stack.params
    seg0 = min(seg0, len(path) - 2)
    verts = path[seg0:]
    a = verts[0] + _clamped_projection(verts[0], verts[1], pose[:2])
    verts = np.concatenate([a[None], verts[1:]])
    hw_seg = np.minimum(hw[seg0:-1], hw[seg0 + 1 :])
    lin = np.linspace(-1.0, 1.0, p.cut_offsets)
    res = grid.resolution_m
    ox, oy = grid.origin.tolist()
    pts, cut = cut_probe(
        verts, hw_seg, res, p.cut_check_m, lin, grid.clearance_m, ox, oy, res, stack.min_clearance_m
    )
    return first_cut_stretch(pts, cut)


def test_the_cut_check_equals_the_check_of_the_whole_path():
    stack = NavigationStack(LASER, 0.17)
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
        got = stack.blocks.cut_ahead(path, hw, grid, pose, seg0)
        assert (got is None) == (want is None)
        if got is not None:
            np.testing.assert_array_equal(got, want)
            found += 1
    assert found > 20  # cuts were found, not only free corridors


def test_the_cut_kernel_samples_the_path_and_looks_the_offsets_up_in_the_grid():
    """Each station lies on its segment every ``step`` from the segment's start, within
    ``max_along`` of the first along the polyline; it is cut exactly when every lateral
    offset's cell (:meth:`ClearanceGrid.clearance_at`) is below the hard clearance."""
    rng = np.random.default_rng(1)
    grid = ClearanceGrid(np.array([-1.0, -1.5]), 0.05, rng.uniform(0.0, 0.5, (60, 80)))
    lin = np.linspace(-1, 1, 9)
    n_cut = 0
    for _ in range(30):
        verts = np.cumsum(rng.normal(0.0, 0.5, (int(rng.integers(2, 12)), 2)), axis=0)
        hw = rng.uniform(0.05, 0.4, len(verts) - 1)
        pts, cut = cut_probe(verts, hw, 0.05, 2.0, lin, grid.clearance_m, -1.0, -1.5, 0.05, 0.2)
        want_pts, want_cut = [], []
        for i in range(len(verts) - 1):
            d = verts[i + 1] - verts[i]
            length = math.hypot(*d)
            normal = np.array([-d[1], d[0]]) / max(length, 1e-12)
            for m in range(max(1, math.ceil(length / 0.05))):
                q = verts[i] + (m * 0.05 / length if length > 0 else 0.0) * d
                want_pts.append(q)
                probe = q + (lin * hw[i])[:, None] * normal
                want_cut.append(bool(np.all(grid.clearance_at(probe) < 0.2)))
        want_pts = np.array(want_pts)
        along = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(want_pts, axis=0).T))])
        keep = int(np.count_nonzero(along <= 2.0 + 1e-9))
        assert len(pts) in (keep, keep - 1)  # a station exactly at 2 m may round either way
        np.testing.assert_allclose(pts, want_pts[: len(pts)], atol=1e-12)
        assert cut.tolist() == want_cut[: len(pts)]
        n_cut += int(cut.sum())
    assert n_cut > 0


def test_first_cut_stretch_is_the_first_run_of_cut_stations():
    pts = np.arange(16.0).reshape(8, 2)
    cut = np.array([0, 1, 1, 0, 1, 1, 1, 0], bool)
    np.testing.assert_array_equal(first_cut_stretch(pts, cut), pts[1:3])
    assert first_cut_stretch(pts, np.zeros(8, bool)) is None
