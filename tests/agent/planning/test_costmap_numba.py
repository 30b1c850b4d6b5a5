"""The costmap's kernels (:mod:`.costmap_numba`) give the numpy / scipy code's numbers exactly."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import ndimage
from synthetic_scans import LASER, box, raycast

from dynmap_sim import se2
from dynmap_sim.agent.planning import costmap_numba
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid
from dynmap_sim.agent.planning.costmap import Costmap, CostmapParams
from dynmap_sim.types import Scan

needs_numba = pytest.mark.skipif(
    not costmap_numba.numba_available(), reason="numba (extra 'fast') not installed"
)
MOUNTED = dataclasses.replace(LASER, mount_pose=(0.10, 0.05, 0.2))


def random_world(rng: np.random.Generator) -> np.ndarray:
    """A 6 m x 4 m room with a few random boxes (segments ``(S, 4)``)."""
    segs = [box(0.0, 0.0, 6.0, 4.0)]
    for _ in range(rng.integers(0, 6)):
        x, y = rng.uniform(0.3, 5.3), rng.uniform(0.3, 3.3)
        s = rng.uniform(0.05, 0.6)
        segs.append(box(x, y, x + s, y + s))
    return np.concatenate(segs)


def random_scan(rng: np.random.Generator, segs: np.ndarray, pose: np.ndarray) -> Scan:
    """Ranges with noise and the odd NaN / +-inf / too-short / max-range reading."""
    lp = se2.compose(pose, np.asarray(MOUNTED.mount_pose))
    r = raycast(lp, MOUNTED.angles(), segs, MOUNTED.range_max_m)
    r = r + rng.normal(0.0, 0.01, r.shape)
    bad = rng.random(r.shape)
    r[bad < 0.01] = np.nan
    r[(bad >= 0.01) & (bad < 0.02)] = -np.inf
    r[(bad >= 0.02) & (bad < 0.03)] = np.inf
    r[(bad >= 0.03) & (bad < 0.04)] = 0.001
    r[(bad >= 0.04) & (bad < 0.05)] = MOUNTED.range_max_m
    return Scan(r.astype(np.float32))


def costmaps(backends: tuple[str, ...], **params: float) -> list[Costmap]:
    out = []
    for backend in backends:
        cm = Costmap(CostmapParams(**params), (0.0, 0.0, 6.0, 4.0))  # type: ignore[arg-type]
        cm.set_static_segments(box(0.0, 0.0, 6.0, 4.0))
        cm.backend = backend
        out.append(cm)
    return out


@needs_numba
@pytest.mark.parametrize("seed", range(4))
def test_scan_updates_of_numba_equal_numpy(seed: int) -> None:
    """Sequences of scans (the robot partly outside the grid too) leave identical marks, the
    same ``changed`` flags and identical clearances and window clearances."""
    rng = np.random.default_rng(seed)
    segs = random_world(rng)
    fast, ref = costmaps(("numba", "numpy"), max_persistence_scans=int(rng.integers(1, 4)))
    # scattered marks too: rays through blocks with and without marks, skipped or not
    marks = (rng.random(fast.shape) < [0.0, 0.002, 0.01, 0.05][seed]).astype(np.int8)
    fast.marks, ref.marks = marks, marks.copy()
    for _ in range(25):
        pose = np.array([rng.uniform(-0.5, 6.5), rng.uniform(-0.5, 4.5), rng.uniform(-4, 4)])
        scan = random_scan(rng, segs, pose)
        assert fast.update(pose, scan, MOUNTED) == ref.update(pose, scan, MOUNTED)
        np.testing.assert_array_equal(fast.marks, ref.marks)
        np.testing.assert_array_equal(fast.clearance().clearance_m, ref.clearance().clearance_m)
        base = ref.clearance()
        for window_m, margin_m in ((1.6, 0.8), (0.3, 0.2), (10.0, 0.5)):
            a = fast.window_clearance(base, pose[:2], window_m, margin_m)
            b = ref.window_clearance(base, pose[:2], window_m, margin_m)
            np.testing.assert_array_equal(a.clearance_m, b.clearance_m)
        if rng.random() < 0.1:
            fast.clear_obstacles()
            ref.clear_obstacles()


def test_python_kernel_of_the_scan_update_equals_numpy() -> None:
    """The uncompiled kernel (what numba compiles) marks as numpy does."""
    rng = np.random.default_rng(7)
    segs = random_world(rng)
    (ref,) = costmaps(("numpy",))
    marks = ref.marks.copy()
    seen = np.zeros(marks.size, np.uint8)
    for _ in range(3):
        pose = np.array([rng.uniform(0.5, 5.5), rng.uniform(0.5, 3.5), rng.uniform(-4, 4)])
        scan = random_scan(rng, segs, pose)
        lp = se2.compose(pose, np.asarray(MOUNTED.mount_pose))
        th = lp[2] + MOUNTED.angles()
        p = ref.params
        changed = costmap_numba.mark_scan(
            marks,
            *ref.origin.tolist(),
            ref.resolution_m,
            *lp[:2].tolist(),
            np.cos(th),
            np.sin(th),
            np.asarray(scan.ranges_m, np.float64),
            MOUNTED.range_min_m,
            MOUNTED.range_max_m,
            p.raytrace_range_m,
            p.inf_clear_range_m,
            p.obstacle_range_m,
            p.max_persistence_scans,
            *pose[:2].tolist(),
            ref._footprint,
            seen,
            python=True,
        )
        assert changed == ref.update(pose, scan, MOUNTED)
        np.testing.assert_array_equal(marks, ref.marks)
        assert not seen.any()  # the scratch is left zero


@pytest.mark.parametrize("python", [False, True])
def test_distance_transform_equals_scipy_bit_for_bit(python: bool) -> None:
    """Random layers and windows: the kernel's clearance is scipy's EDT times the cell size
    (inf without an obstacle), exactly."""
    if not python and not costmap_numba.numba_available():
        pytest.skip("numba (extra 'fast') not installed")
    rng = np.random.default_rng(3)
    for _ in range(150 if python else 600):
        h, w = (int(v) for v in rng.integers(1, 30, 2))
        static = rng.random((h, w)) < rng.choice([0.0, 0.005, 0.05, 0.4])
        marks = (rng.random((h, w)) < rng.choice([0.0, 0.02])).astype(np.int8)
        r0, c0 = int(rng.integers(0, h)), int(rng.integers(0, w))
        r1, c1 = int(rng.integers(r0 + 1, h + 1)), int(rng.integers(c0 + 1, w + 1))
        occ = (static | (marks > 0))[r0:r1, c0:c1]
        ref = ndimage.distance_transform_edt(~occ) * 0.05 if occ.any() else np.inf + 0 * occ
        got = costmap_numba.clearance_window(static, marks, (r0, r1), (c0, c1), 0.05, python)
        np.testing.assert_array_equal(got, ref)


def test_window_clearance_keeps_the_base_outside_the_window() -> None:
    (cm,) = costmaps(("numpy",))
    base = ClearanceGrid(cm.origin, cm.resolution_m, np.full(cm.shape, 7.0))
    out = cm.window_clearance(base, np.array([3.0, 2.0]), 0.5, 0.4)
    i, j = base.cell_of(np.array([3.0, 2.0]))
    assert np.all(base.clearance_m == 7.0)  # not changed
    assert out.clearance_m[i, j] == 7.0 and out.clearance_m[0, 0] == 7.0
    inner = out.clearance_m[i - 10 : i + 11, j - 10 : j + 11]
    assert np.all(inner == 7.0)  # no obstacle within the window's reach: the base's value


@needs_numba
def test_window_clearance_of_numba_equals_numpy_on_random_layers() -> None:
    """Random obstacle layers, bases, centres (the grid's edges too), windows and margins:
    the kernel's window clearance (its obstacles capped at the margin) equals numpy's."""
    rng = np.random.default_rng(11)
    fast, ref = costmaps(("numba", "numpy"))
    h, w = fast.shape
    for _ in range(200):
        static = rng.random((h, w)) < rng.choice([0.0, 0.002, 0.02, 0.2])
        marks = (rng.random((h, w)) < rng.choice([0.0, 0.01])).astype(np.int8)
        for cm in (fast, ref):
            cm.static, cm.marks = static, marks.copy()
            cm._changed()
        base = ClearanceGrid(fast.origin, fast.resolution_m, rng.uniform(0.0, 2.0, (h, w)))
        kept = base.clearance_m.copy()
        for _ in range(3):  # the kernel reuses its array while the base is the same
            centre = rng.uniform(-0.5, [6.5, 4.5])
            window_m, margin_m = rng.uniform(0.05, 2.0), rng.uniform(0.05, 1.2)
            a = fast.window_clearance(base, centre, window_m, margin_m)
            b = ref.window_clearance(base, centre, window_m, margin_m)
            np.testing.assert_array_equal(a.clearance_m, b.clearance_m)
        np.testing.assert_array_equal(base.clearance_m, kept)  # the base is not changed


@pytest.mark.parametrize("python", [False, True])
def test_chessboard_distance_is_the_brute_force_minimum(python: bool) -> None:
    """The block distances the scan kernel skips by: ``min_q dist[q] + chessboard(p, q)``
    for random starts (zeros, a border ramp, large values), as a brute force finds."""
    if not python and not costmap_numba.numba_available():
        pytest.skip("numba (extra 'fast') not installed")
    fn = costmap_numba._chessboard_distance_py if python else costmap_numba._chessboard_distance
    rng = np.random.default_rng(5)
    for _ in range(60):
        h, w = (int(v) for v in rng.integers(1, 14, 2))
        start = rng.integers(0, 2 * max(h, w), (h, w))
        start[rng.random((h, w)) < rng.choice([0.0, 0.05, 0.3])] = 0
        ii, jj = np.mgrid[:h, :w]
        cheb = np.maximum(
            np.abs(ii.reshape(-1, 1) - ii.reshape(1, -1)),
            np.abs(jj.reshape(-1, 1) - jj.reshape(1, -1)),
        )
        want = (start.reshape(1, -1) + cheb).min(axis=1).reshape(h, w)
        got = start.astype(np.int64)
        fn(got)
        np.testing.assert_array_equal(got, want)


@needs_numba
@pytest.mark.parametrize("density", [0.03, 0.002])
def test_rays_along_cell_and_block_edges_update_as_numpy(density: float) -> None:
    """Axis-aligned and diagonal beams from laser poses on cell edges (where a ray grazes
    the blocks the kernel skips), in dense marks and in sparse ones (long skips across
    squares of free blocks): identical marks."""
    rng = np.random.default_rng(4)
    segs = random_world(rng)
    fast, ref = costmaps(("numba", "numpy"))
    marks = (rng.random(fast.shape) < density).astype(np.int8)
    fast.marks, ref.marks = marks, marks.copy()
    res = fast.resolution_m
    angles = MOUNTED.angles()
    for _ in range(40):
        k = int(rng.integers(0, MOUNTED.n_beams))
        heading = float(rng.choice([0.0, 0.5, 1.0, 1.5, 0.25, 0.75])) * np.pi
        theta = heading - angles[k] - MOUNTED.mount_pose[2]  # beam k along ``heading``
        cell = rng.integers(8, 70, 2) + rng.choice([0.0, 0.5, 0.4999999, 0.25], 2)
        lp_xy = fast.origin + cell * res
        c, s = np.cos(theta), np.sin(theta)
        mx, my = MOUNTED.mount_pose[:2]
        pose = np.array([lp_xy[0] - (c * mx - s * my), lp_xy[1] - (s * mx + c * my), theta])
        scan = random_scan(rng, segs, pose)
        assert fast.update(pose, scan, MOUNTED) == ref.update(pose, scan, MOUNTED)
        np.testing.assert_array_equal(fast.marks, ref.marks)
