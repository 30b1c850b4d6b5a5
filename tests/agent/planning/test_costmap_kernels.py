"""The costmap's kernels (:mod:`.costmap_kernels`) against independent references: the scan
update against what its rays surely pass and surely miss, the distance transforms against
scipy's exact EDT, the block distances against a brute-force minimum."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import ndimage
from synthetic_scans import LASER, box, raycast

from dynmap_sim import se2
from dynmap_sim.agent.planning import costmap_kernels
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid
from dynmap_sim.agent.planning.costmap import Costmap, CostmapParams
from dynmap_sim.types import Scan

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


def costmap(**params: float) -> Costmap:
    cm = Costmap(CostmapParams(**params), (0.0, 0.0, 6.0, 4.0))  # type: ignore[arg-type]
    cm.set_static_segments(box(0.0, 0.0, 6.0, 4.0))
    return cm


def ray_geometry(cm: Costmap, pose: np.ndarray, ranges: np.ndarray):
    """Per beam: the laser position [m], unit direction, clearing length [m] (module doc of
    :mod:`.costmap`) and the flat hit cell (-1: none); and the cells marked (hits within the
    obstacle range)."""
    p = cm.params
    lp = se2.compose(pose, np.asarray(MOUNTED.mount_pose))
    th = lp[2] + MOUNTED.angles()
    d = np.stack([np.cos(th), np.sin(th)], axis=1)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(ranges) & (ranges >= MOUNTED.range_min_m)
        hit = valid & (ranges < MOUNTED.range_max_m)
        no_return = (ranges == np.inf) | (valid & ~hit)
    clear = np.where(hit, np.minimum(ranges, p.raytrace_range_m), 0.0)
    clear = np.where(no_return, min(p.inf_clear_range_m, p.raytrace_range_m), clear)
    h, w = cm.shape
    end = lp[:2] + d * np.where(hit, ranges, 0.0)[:, None]
    ij = np.rint((end[:, ::-1] - cm.origin[::-1]) / cm.resolution_m).astype(np.int64)
    inside = hit & (ij[:, 0] >= 0) & (ij[:, 0] < h) & (ij[:, 1] >= 0) & (ij[:, 1] < w)
    own = np.where(inside, ij[:, 0] * w + ij[:, 1], -1)
    marked = own[inside & (ranges <= p.obstacle_range_m)]
    return lp[:2], d, clear, own, np.unique(marked)


def check_update(cm: Costmap, pose: np.ndarray, scan: Scan) -> None:
    """One :meth:`Costmap.update` against what its rays say: hit cells marked (one more scan,
    up to the persistence), marked cells that a ray crosses within 0.2 cells of their centre
    (a cell inside its clearing length, not its own hit cell) one scan less, cells no ray
    comes within 0.75 cells of unchanged, the footprint cleared, and ``changed`` true exactly
    when a cell's obstacle state changed."""
    res, maxp = cm.resolution_m, cm.params.max_persistence_scans
    before = cm.marks.copy().reshape(-1).astype(np.int64)
    ranges = np.asarray(scan.ranges_m, np.float64)
    changed = cm.update(pose, scan, MOUNTED)
    after = cm.marks.reshape(-1).astype(np.int64)
    assert changed == bool(np.any((before > 0) != (after > 0)))
    lp, d, clear, own, marked = ray_geometry(cm, pose, ranges)
    h, w = cm.shape
    cells = np.arange(h * w)
    centres = cm.origin + np.stack([cells % w, cells // w], axis=1) * res
    dist_robot = np.hypot(*(centres - pose[:2]).T)
    foot = dist_robot <= cm.params.footprint_clear_radius_m - res  # surely in the footprint
    maybe_foot = dist_robot <= cm.params.footprint_clear_radius_m + res
    assert not after[foot].any()
    look = np.flatnonzero(((before > 0) | np.isin(cells, marked)) & ~maybe_foot)
    rel = centres[look, None, :] - lp  # (C, B, 2)
    t = np.einsum("cbi,bi->cb", rel, d)  # along each ray [m]
    off = np.abs(rel[..., 0] * d[:, 1] - rel[..., 1] * d[:, 0]) / res  # across it [cells]
    on_ray = (t >= -0.75 * res) & (t <= clear + 0.75 * res)
    near = np.any(on_ray & (off <= 0.75), axis=1)
    crossed = np.any(
        (t >= res) & (t <= clear - res) & (off <= 0.2) & (own[None, :] != look[:, None]), axis=1
    )
    is_marked = np.isin(look, marked)
    got, old = after[look], before[look]
    dec = np.maximum(old - 1, 0)
    m = is_marked
    up = np.minimum(old[m] + 1, maxp)
    assert np.all((got[m] == up) | (got[m] == np.minimum(dec[m] + 1, maxp)))
    c = crossed & ~is_marked
    np.testing.assert_array_equal(got[c], dec[c])
    u = ~near & ~is_marked
    np.testing.assert_array_equal(got[u], old[u])
    rest = ~is_marked
    assert np.all((got[rest] == old[rest]) | (got[rest] == dec[rest]))  # at most one less
    others = np.setdiff1d(cells[~maybe_foot], look)
    assert not after[others].any()  # no mark appears but at a hit cell
    assert np.count_nonzero(c) + np.count_nonzero(m) > 0 or not len(look)


@pytest.mark.parametrize("seed", range(4))
def test_scan_updates_mark_and_clear_as_the_rays_say(seed: int) -> None:
    """Sequences of scans (the robot partly outside the grid too) over scattered marks (rays
    through blocks with and without marks, skipped or not); the scratch is left zero."""
    rng = np.random.default_rng(seed)
    segs = random_world(rng)
    cm = costmap(max_persistence_scans=int(rng.integers(1, 4)))
    cm.marks = (rng.random(cm.shape) < [0.0, 0.002, 0.01, 0.05][seed]).astype(np.int8)
    for _ in range(25):
        pose = np.array([rng.uniform(-0.5, 6.5), rng.uniform(-0.5, 4.5), rng.uniform(-4, 4)])
        check_update(cm, pose, random_scan(rng, segs, pose))
        assert not cm._seen.any()
        if rng.random() < 0.1:
            cm.clear_obstacles()
            assert not cm.marks.any()


@pytest.mark.parametrize("density", [0.03, 0.002])
def test_rays_along_cell_and_block_edges_clear_what_they_pass(density: float) -> None:
    """Axis-aligned and diagonal beams from laser poses on cell edges (where a ray grazes
    the blocks the kernel skips), in dense marks and in sparse ones (long skips across
    squares of free blocks)."""
    rng = np.random.default_rng(4)
    segs = random_world(rng)
    cm = costmap()
    cm.marks = (rng.random(cm.shape) < density).astype(np.int8)
    res = cm.resolution_m
    angles = MOUNTED.angles()
    for _ in range(40):
        k = int(rng.integers(0, MOUNTED.n_beams))
        heading = float(rng.choice([0.0, 0.5, 1.0, 1.5, 0.25, 0.75])) * np.pi
        theta = heading - angles[k] - MOUNTED.mount_pose[2]  # beam k along ``heading``
        cell = rng.integers(8, 70, 2) + rng.choice([0.0, 0.5, 0.4999999, 0.25], 2)
        lp_xy = cm.origin + cell * res
        c, s = np.cos(theta), np.sin(theta)
        mx, my = MOUNTED.mount_pose[:2]
        pose = np.array([lp_xy[0] - (c * mx - s * my), lp_xy[1] - (s * mx + c * my), theta])
        check_update(cm, pose, random_scan(rng, segs, pose))


def test_distance_transform_equals_scipy_bit_for_bit() -> None:
    """Random layers and windows: the kernel's clearance is scipy's EDT times the cell size
    (inf without an obstacle), exactly."""
    rng = np.random.default_rng(3)
    for _ in range(600):
        h, w = (int(v) for v in rng.integers(1, 30, 2))
        static = rng.random((h, w)) < rng.choice([0.0, 0.005, 0.05, 0.4])
        marks = (rng.random((h, w)) < rng.choice([0.0, 0.02])).astype(np.int8)
        r0, c0 = int(rng.integers(0, h)), int(rng.integers(0, w))
        r1, c1 = int(rng.integers(r0 + 1, h + 1)), int(rng.integers(c0 + 1, w + 1))
        occ = (static | (marks > 0))[r0:r1, c0:c1]
        ref = ndimage.distance_transform_edt(~occ) * 0.05 if occ.any() else np.inf + 0 * occ
        got = costmap_kernels.clearance_window(static, marks, (r0, r1), (c0, c1), 0.05)
        np.testing.assert_array_equal(got, ref)


def test_window_clearance_keeps_the_base_outside_the_window() -> None:
    cm = costmap()
    base = ClearanceGrid(cm.origin, cm.resolution_m, np.full(cm.shape, 7.0))
    out = cm.window_clearance(base, np.array([3.0, 2.0]), 0.5, 0.4)
    i, j = base.cell_of(np.array([3.0, 2.0]))
    assert np.all(base.clearance_m == 7.0)  # not changed
    assert out.clearance_m[i, j] == 7.0 and out.clearance_m[0, 0] == 7.0
    inner = out.clearance_m[i - 10 : i + 11, j - 10 : j + 11]
    assert np.all(inner == 7.0)  # no obstacle within the window's reach: the base's value


def window_reference(cm: Costmap, base: ClearanceGrid, centre, window_m, margin_m):
    """:meth:`Costmap.window_clearance` by its definition, with scipy's EDT of the window
    grown by the margin: the exact distance where below the margin, else at least it."""
    res = cm.resolution_m
    h, w = cm.shape
    i, j = base.cell_index(float(centre[0]), float(centre[1]))
    k_in = int(np.ceil(window_m / res))
    k_out = k_in + int(np.ceil(margin_m / res))
    r0, r1 = max(i - k_out, 0), min(i + k_out + 1, h)
    c0, c1 = max(j - k_out, 0), min(j + k_out + 1, w)
    a0, a1 = max(i - k_in, 0), min(i + k_in + 1, h)
    b0, b1 = max(j - k_in, 0), min(j + k_in + 1, w)
    occ = (cm.static | (cm.marks > 0))[r0:r1, c0:c1]
    if occ.any():
        local = ndimage.distance_transform_edt(~occ) * res
    else:
        local = np.full(occ.shape, np.inf)
    win = local[a0 - r0 : a1 - r0, b0 - c0 : b1 - c0]
    out = base.clearance_m.copy()
    out[a0:a1, b0:b1] = np.where(win < margin_m, win, np.maximum(out[a0:a1, b0:b1], margin_m))
    return out


def test_window_clearance_on_random_layers_is_its_definition() -> None:
    """Random obstacle layers, bases, centres (the grid's edges too), windows and margins:
    the kernel's window clearance (its obstacles capped at the margin) is the definition's."""
    rng = np.random.default_rng(11)
    cm = costmap()
    h, w = cm.shape
    for _ in range(200):
        cm.static = rng.random((h, w)) < rng.choice([0.0, 0.002, 0.02, 0.2])
        cm.marks = (rng.random((h, w)) < rng.choice([0.0, 0.01])).astype(np.int8)
        cm._changed()
        base = ClearanceGrid(cm.origin, cm.resolution_m, rng.uniform(0.0, 2.0, (h, w)))
        kept = base.clearance_m.copy()
        for _ in range(3):  # the kernel reuses its array while the base is the same
            centre = rng.uniform(-0.5, [6.5, 4.5])
            window_m, margin_m = rng.uniform(0.05, 2.0), rng.uniform(0.05, 1.2)
            want = window_reference(cm, base, centre, window_m, margin_m)
            got = cm.window_clearance(base, centre, window_m, margin_m)
            np.testing.assert_array_equal(got.clearance_m, want)
        np.testing.assert_array_equal(base.clearance_m, kept)  # the base is not changed


def test_chessboard_distance_is_the_brute_force_minimum() -> None:
    """The block distances the scan kernel skips by: ``min_q dist[q] + chessboard(p, q)``
    for random starts (zeros, a border ramp, large values), as a brute force finds."""
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
        costmap_kernels.chessboard_distance(got)
        np.testing.assert_array_equal(got, want)
