"""The costmap's layers: static walls, scans marking and clearing at the estimated laser pose."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest
from synthetic_scans import LASER, box, raycast

from dynmap_sim import se2
from dynmap_sim.agent.grid import OccupancyGrid
from dynmap_sim.agent.planning.clearance_grid import ClearanceGrid
from dynmap_sim.agent.planning.costmap import Costmap, CostmapParams, laser_pose, samples_along
from dynmap_sim.types import Prior, Scan

ROOM = box(0.0, 0.0, 6.0, 4.0)
BLOCK = box(2.5, 1.6, 2.9, 2.0)  # a 40 cm box 1.5 m ahead of the robot
#: a laser mounted 10 cm ahead, 5 cm left and turned 0.2 rad on the robot
MOUNTED = dataclasses.replace(LASER, mount_pose=(0.10, 0.05, 0.2))
POSE = np.array([1.0, 1.7, 0.1])


def scan_of(segs: np.ndarray, pose: np.ndarray = POSE, laser=MOUNTED) -> Scan:
    """Exact ranges from the laser mounted on a robot at ``pose`` (+inf: no return)."""
    lp = se2.compose(pose, np.asarray(laser.mount_pose))
    return Scan(raycast(lp, laser.angles(), segs, laser.range_max_m).astype(np.float32))


def dist_to_segments(xy: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """Distance [m] of points ``(N, 2)`` to the nearest of the segments ``(S, 4)``."""
    a, b = segs[None, :, :2], segs[None, :, 2:]
    ab = b - a
    t = np.clip(((xy[:, None] - a) * ab).sum(-1) / (ab * ab).sum(-1), 0.0, 1.0)
    return np.hypot(*(a + t[..., None] * ab - xy[:, None]).transpose(2, 0, 1)).min(axis=1)


def marked_xy(cm: Costmap) -> np.ndarray:
    ii, jj = np.nonzero(cm.obstacle_mask())
    return cm.origin + np.stack([jj, ii], axis=1) * cm.resolution_m


def block_cells(cm: Costmap) -> np.ndarray:
    """Marks within 10 cm of the block."""
    xy = marked_xy(cm)
    return xy[dist_to_segments(xy, BLOCK) < 0.1] if len(xy) else xy


@pytest.fixture
def cm() -> Costmap:
    c = Costmap(CostmapParams(), (0.0, 0.0, 6.0, 4.0))
    c.set_static_segments(ROOM)
    return c


def test_samples_along_covers_each_segment() -> None:
    pts, seg = samples_along(
        np.array([[0.0, 0.0], [1.0, 1.0]]), np.array([[1.0, 0.0], [1.0, 1.0]]), 0.1, True
    )
    assert np.allclose(pts[seg == 0][:, 1], 0.0) and pts[seg == 0][:, 0].max() == 1.0
    assert len(pts[seg == 0]) == 11 and len(pts[seg == 1]) == 2  # a zero-length one: twice


def test_wall_segment_appears_in_clearance() -> None:
    cm = Costmap(None, (0.0, 0.0, 4.0, 4.0))
    cm.set_static_segments(np.array([[1.0, 2.0, 3.0, 2.0]]))
    g = cm.clearance()
    assert g.shape == cm.shape and np.allclose(g.origin, [-1.0, -1.0])
    assert g.clearance_at(np.array([2.0, 2.0])) == 0.0
    for y, want in ((2.5, 0.5), (3.5, 1.5), (0.4, 1.6)):
        assert g.clearance_at(np.array([2.0, y])) == pytest.approx(want, abs=0.03)
    assert g.clearance_at(np.array([4.0, 2.0])) == pytest.approx(1.0, abs=0.03)  # past the end
    assert not cm.obstacle_mask().any()


def test_scan_of_a_box_marks_it_at_the_laser_pose(cm: Costmap) -> None:
    assert cm.update(POSE, scan_of(np.concatenate([ROOM, BLOCK])), MOUNTED)
    xy = marked_xy(cm)
    # every mark lies on the box or the room's walls (to within the cell's half diagonal) ...
    d = np.minimum(dist_to_segments(xy, BLOCK), dist_to_segments(xy, ROOM))
    assert d.max() <= 0.5 * np.sqrt(2) * cm.resolution_m + 1e-9
    # ... no farther than obstacle_range_m from the laser, and the box's near face is covered
    lp = se2.compose(POSE, MOUNTED.mount_pose)
    assert np.hypot(*(xy - lp[:2]).T).max() <= cm.params.obstacle_range_m + cm.resolution_m
    face = np.stack([np.full(9, 2.5), np.linspace(1.6, 2.0, 9)], axis=1)
    cells = block_cells(cm)
    gap = np.hypot(*(face[:, None] - cells[None]).transpose(2, 0, 1)).min(axis=1)
    assert gap.max() <= cm.resolution_m
    # the box is now an obstacle in the clearance the planners see
    assert cm.clearance().clearance_at(np.array([2.5, 1.8])) == 0.0
    # the same scan read at the robot pose without the mount offset lands elsewhere
    wrong = Costmap(cm.params, (0.0, 0.0, 6.0, 4.0))
    wrong.update(POSE, scan_of(np.concatenate([ROOM, BLOCK])), LASER)
    assert len(block_cells(wrong)) < 0.5 * len(block_cells(cm))


def test_a_later_scan_through_the_cells_clears_them(cm: Costmap) -> None:
    cm.update(POSE, scan_of(np.concatenate([ROOM, BLOCK])), MOUNTED)
    assert len(block_cells(cm)) > 5
    assert cm.update(POSE, scan_of(ROOM), MOUNTED)  # the box is gone: its cells are seen through
    assert len(block_cells(cm)) == 0
    assert cm.clearance().clearance_at(np.array([2.5, 1.8])) > 0.5
    assert cm.static[cm.occupied_mask()].sum() >= cm.static.sum()  # walls stay


def test_marks_seen_often_persist_for_a_few_clearing_scans(cm: Costmap) -> None:
    for _ in range(5):
        cm.update(POSE, scan_of(np.concatenate([ROOM, BLOCK])), MOUNTED)
    n = cm.params.max_persistence_scans
    for _ in range(n - 1):
        cm.update(POSE, scan_of(ROOM), MOUNTED)
        assert len(block_cells(cm)) > 0
    cm.update(POSE, scan_of(ROOM), MOUNTED)
    assert len(block_cells(cm)) == 0


def test_only_marks_that_have_stood_long_enough_are_lasting(cm: Costmap) -> None:
    """``persistent_clearance``: the walls and the marks at least ``min_age_s`` old; a mark
    seen through and marked again starts its age anew."""
    face = np.array([2.5, 1.8])  # on the box's near face
    for k in range(4):  # the box seen at t = 0, 1, 2, 3 s
        cm.update(POSE, scan_of(np.concatenate([ROOM, BLOCK])), MOUNTED, t_s=float(k))
    assert cm.clearance().clearance_at(face) == 0.0
    assert cm.persistent_clearance(3.0, 5.0).clearance_at(face) > 0.5  # 3 s < 5 s
    assert cm.persistent_clearance(5.0, 5.0).clearance_at(face) == 0.0
    assert cm.persistent_clearance(3.0, 0.0).clearance_at(face) == 0.0
    wall = np.array([3.0, 0.0])
    assert cm.persistent_clearance(3.0, 5.0).clearance_at(wall) == 0.0  # static: always
    for k in range(cm.params.max_persistence_scans):  # seen through until cleared
        cm.update(POSE, scan_of(ROOM), MOUNTED, t_s=4.0 + k)
    assert len(block_cells(cm)) == 0
    cm.update(POSE, scan_of(np.concatenate([ROOM, BLOCK])), MOUNTED, t_s=10.0)
    assert cm.persistent_clearance(12.0, 5.0).clearance_at(face) > 0.5  # 2 s old again
    assert cm.persistent_clearance(15.0, 5.0).clearance_at(face) == 0.0
    cm.clear_obstacles()
    assert np.isnan(cm.marked_since_s).all()


def test_the_marks_ages_are_those_of_the_whole_grid_rule(cm: Costmap) -> None:
    """Ages are kept only where a scan reaches; a reference kept over the whole grid (a
    mark's age starts when it appears and ends when it goes) agrees after every scan of a
    drive past a box that comes and goes."""
    ref = np.full(cm.shape, np.nan)
    rng = np.random.default_rng(4)
    for k in range(60):
        pose = np.array([0.5 + 0.08 * k, 1.7 + rng.uniform(-0.3, 0.3), rng.uniform(-1.0, 1.0)])
        walls = np.concatenate([ROOM, BLOCK]) if (k // 10) % 2 == 0 else ROOM
        cm.update(pose, scan_of(walls, pose), MOUNTED, t_s=float(k))
        on = cm.marks > 0
        ref[on & np.isnan(ref)] = float(k)
        ref[~on] = np.nan
        np.testing.assert_array_equal(cm.marked_since_s, ref)
    assert np.isfinite(ref).sum() > 50  # marks were kept, of several ages
    assert len(np.unique(ref[np.isfinite(ref)])) > 5


def test_a_scan_s_stamp_is_the_default_time_of_its_marks(cm: Costmap) -> None:
    scan = scan_of(np.concatenate([ROOM, BLOCK]))
    cm.update(POSE, Scan(scan.ranges_m, 7.5), MOUNTED)
    assert np.nanmin(cm.marked_since_s) == np.nanmax(cm.marked_since_s) == 7.5


@pytest.mark.parametrize("inf_clear_range_m", [3.0, 0.0])
def test_inf_readings_clear_up_to_the_clearing_range(inf_clear_range_m: float) -> None:
    params = CostmapParams(inf_clear_range_m=inf_clear_range_m)
    cm = Costmap(params, (0.0, 0.0, 6.0, 4.0))
    cm.update(POSE, scan_of(BLOCK), MOUNTED)
    assert len(block_cells(cm)) > 5
    nothing = Scan(np.full(MOUNTED.n_beams, np.inf, dtype=np.float32))
    cm.update(POSE, nothing, MOUNTED)
    assert (len(block_cells(cm)) == 0) == (inf_clear_range_m > 0)


def test_too_close_nan_and_max_range_readings_do_not_mark(cm: Costmap) -> None:
    r = np.full(MOUNTED.n_beams, -np.inf, dtype=np.float32)
    r[::3] = np.nan
    r[1::3] = MOUNTED.range_max_m
    assert not cm.update(POSE, Scan(r), MOUNTED)
    assert not cm.obstacle_mask().any()


def test_footprint_is_cleared_and_static_layer_is_not(cm: Costmap) -> None:
    cm.update(POSE, scan_of(np.concatenate([ROOM, BLOCK])), MOUNTED)
    far = np.array([2.2, 1.8, 0.0])  # 0.3 m before the box: the footprint reaches into it
    cm.update(far, Scan(np.full(MOUNTED.n_beams, np.inf, np.float32)), MOUNTED)
    xy = marked_xy(cm)
    assert len(xy) == 0 or np.hypot(*(xy - far[:2]).T).min() > cm.params.footprint_clear_radius_m
    near_wall = np.array([0.1, 2.0, np.pi])  # standing on the static wall clears nothing of it
    cm.update(near_wall, Scan(np.full(MOUNTED.n_beams, np.inf, np.float32)), MOUNTED)
    assert cm.clearance().clearance_at(np.array([0.0, 2.0])) == 0.0


def test_static_grid_of_a_localizer() -> None:
    grid = OccupancyGrid.from_segments(ROOM, resolution_m=0.1, free_seed_xy_m=(1, 1))
    cm = Costmap(CostmapParams(), (0.0, 0.0, 6.0, 4.0))
    cm.set_static_grid(grid)
    g = cm.clearance()
    wall = np.stack([np.linspace(0.2, 5.8, 40), np.zeros(40)], axis=1)
    assert np.all(g.clearance_at(wall) <= 0.05 + 1e-9)  # a coarser map's wall stays closed
    assert g.clearance_at(np.array([3.0, 2.0])) == pytest.approx(1.95, abs=0.1)
    # unknown space (outside the room) counts as an obstacle only when asked
    blocked = Costmap(CostmapParams(unknown_is_obstacle=True), (0.0, 0.0, 6.0, 4.0))
    blocked.set_static_grid(grid)
    assert blocked.occupied_mask()[0, 0] and not cm.occupied_mask()[0, 0]


def test_clearance_is_cached_until_a_layer_changes(cm: Costmap) -> None:
    g = cm.clearance()
    assert cm.clearance() is g
    cm.update(POSE, scan_of(np.concatenate([ROOM, BLOCK])), MOUNTED)
    g2 = cm.clearance()
    assert g2 is not g
    assert not cm.update(POSE, scan_of(np.concatenate([ROOM, BLOCK])), MOUNTED)
    assert cm.clearance() is g2
    cm.clear_obstacles()
    assert not cm.obstacle_mask().any() and cm.clearance() is not g2


def test_pickle_round_trip(cm: Costmap) -> None:
    cm.update(POSE, scan_of(np.concatenate([ROOM, BLOCK])), MOUNTED)
    cm.clearance()
    back = pickle.loads(pickle.dumps(cm))
    assert np.array_equal(back.occupied_mask(), cm.occupied_mask())
    assert np.array_equal(back.clearance().clearance_m, cm.clearance().clearance_m)


def test_for_prior() -> None:
    cm = Costmap.for_prior(Prior(initial_pose=None, walls=ROOM))
    assert cm.clearance().clearance_at(np.array([0.0, 2.0])) == 0.0
    assert np.allclose(cm.origin, [-1.0, -1.0])
    bare = Costmap.for_prior(Prior(initial_pose=np.array([1.0, 2.0, 0.0])))
    assert not bare.occupied_mask().any() and bare.shape == (441, 441)
    with pytest.raises(ValueError):
        Costmap.for_prior(Prior(initial_pose=None))


def test_laser_pose_is_se2_compose_bit_for_bit() -> None:
    """The scan update's laser pose on floats equals :func:`se2.compose` exactly."""
    rng = np.random.default_rng(2)
    poses = np.concatenate([rng.uniform(-20.0, 20.0, (3000, 3)), rng.uniform(-4, 4, (3000, 3))])
    for mount in ((0.1, 0.05, 0.2), (0.0, 0.0, 0.0), (-0.13, 0.02, np.pi)):
        for pose in poses:
            want = se2.compose(pose, np.asarray(mount, dtype=np.float64))
            assert laser_pose(pose, mount) == tuple(want.tolist())


def test_cell_index_is_cell_of() -> None:
    """The one-point cell index equals :meth:`ClearanceGrid.cell_of` (ties, outside points)."""
    rng = np.random.default_rng(3)
    grid = ClearanceGrid(np.array([-1.3, 2.7]), 0.05, np.zeros((50, 70)))
    pts = np.concatenate(
        [rng.uniform(-5.0, 8.0, (3000, 2)), np.round(rng.uniform(-3.0, 8.0, (3000, 2)) * 40) / 40]
    )
    got = np.array([grid.cell_index(x, y) for x, y in pts.tolist()])
    np.testing.assert_array_equal(got, grid.cell_of(pts))


def test_window_of_an_unchanged_costmap_is_its_clearance() -> None:
    """On the costmap's own clearance with no change since, the window clearance is that
    clearance (returned as is), as computed on a copy of it."""
    rng = np.random.default_rng(4)
    cm = Costmap(CostmapParams(), (0.0, 0.0, 6.0, 4.0))
    cm.set_static_segments(box(0.0, 0.0, 6.0, 4.0))
    for _ in range(20):
        cm.marks = (rng.random(cm.shape) < rng.choice([0.0, 0.002, 0.02])).astype(np.int8)
        cm._changed()
        base = cm.clearance()
        copy = ClearanceGrid(base.origin, base.resolution_m, base.clearance_m.copy())
        centre = rng.uniform(-0.5, [6.5, 4.5])
        window_m, margin_m = rng.uniform(0.05, 2.0), rng.uniform(0.05, 1.2)
        assert cm.window_clearance(base, centre, window_m, margin_m) is base
        got = cm.window_clearance(copy, centre, window_m, margin_m)
        np.testing.assert_array_equal(got.clearance_m, base.clearance_m)
