"""First-run static SLAM on a synthetic room: trajectory and map accuracy against truth."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dynmap_sim import se2
from dynmap_sim.agent.grid import OCCUPIED
from dynmap_sim.agent.mapping.first_run import FirstRunConfig, FirstRunMapper
from dynmap_sim.agent.mapping.keyframe_slam import Keyframe, KeyframeSLAMConfig
from dynmap_sim.agent.mapping.loop_closure import REJECTIONS, LoopClosureConfig
from dynmap_sim.agent.mapping.scan_points import (
    BeamDirections,
    free_space_violations,
    range_discontinuities,
    scan_points_base,
)
from dynmap_sim.types import Odometry, Scan


def _segment_distance(points: np.ndarray, segs: np.ndarray) -> np.ndarray:
    a = segs[None, :, :2]
    b = segs[None, :, 2:]
    p = points[:, None, :]
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, -1) / np.sum(ab * ab, -1), 0.0, 1.0)
    return np.min(np.linalg.norm(p - (a + t[..., None] * ab), axis=-1), axis=1)


def test_first_run_map_and_trajectory(segments, laser, cast, path_fn, odo_fn):
    rng = np.random.default_rng(0)
    truth = path_fn(step_m=0.05, laps=2)
    odo = odo_fn(truth, rng)
    mapper = FirstRunMapper(laser, truth[0])
    est = []
    for k in range(len(truth)):
        r = cast(truth[k], laser.angles(), segments, laser.range_max_m)
        r = (r + rng.normal(0, 0.01, r.shape)).astype(np.float32)
        e = mapper.update(Odometry(odo[k], 0.1 * k), Scan(r, 0.1 * k))
        est.append(e.mean)
    est = np.array(est)
    dead = np.array([se2.compose(truth[0], se2.between(odo[0], o)) for o in odo])
    smap = mapper.finish()
    assert smap.trajectory.shape == truth.shape
    ate = np.sqrt(np.mean(np.sum((smap.trajectory[:, :2] - truth[:, :2]) ** 2, axis=1)))
    ate_dead = np.sqrt(np.mean(np.sum((dead[:, :2] - truth[:, :2]) ** 2, axis=1)))
    assert ate_dead > 0.15  # the odometry really drifts
    assert ate < 0.03
    assert smap.n_loop_closures >= 1
    # The closure search's counts add up: every candidate searched is rejected for one
    # reason or verified, and the consistent ones are among the verified.
    stats = mapper.loop_closure.stats
    rejected = sum(stats[k] for k in REJECTIONS)
    assert stats["searched"] == rejected + stats["verified"] > 0
    assert 1 <= stats["consistent"] <= stats["verified"]
    # Online estimates are already good; the map frame is the initial pose's frame.
    assert np.max(np.hypot(*(est[:, :2] - truth[:, :2]).T)) < 0.1
    assert np.allclose(smap.trajectory[0], truth[0], atol=1e-6)
    # The grid: occupied cells lie on the true geometry.
    occ = smap.grid.occupied_points()
    assert len(occ) > 300
    d = _segment_distance(occ, segments)
    assert np.mean(d <= 0.05) > 0.95
    assert smap.grid.occupancy.dtype == np.int8
    assert (smap.grid.occupancy == OCCUPIED).sum() == len(occ)
    assert len(smap.keyframes) > 20
    assert all(k.ranges_m.shape == (laser.n_beams,) for k in smap.keyframes)


def test_free_space_violations_flag_a_moving_leg_only(segments, laser, cast):
    """A leg that appears where the earlier scan saw the wall: flagged; walls are not."""
    pose0 = np.array([3.0, 1.5, 0.2])
    pose1 = np.array([3.1, 1.52, 0.22])  # the robot moved a little
    r0 = cast(pose0, laser.angles(), segments, laser.range_max_m).astype(np.float32)
    leg = np.array([4.2, 1.9, 0.06])  # a 6 cm "leg" in front of the robot in scan 1 only
    r1 = cast(pose1, laser.angles(), segments, laser.range_max_m)
    th = pose1[2] + laser.angles()
    d = np.stack([np.cos(th), np.sin(th)], axis=1)
    w = leg[:2] - pose1[:2]
    b = d @ w
    disc = b**2 - (w @ w - leg[2] ** 2)
    t_leg = np.where(disc > 0, b - np.sqrt(np.maximum(disc, 0)), np.inf)
    on_leg = (t_leg > 0) & (t_leg < r1)
    r1 = np.where(on_leg, t_leg, r1).astype(np.float32)
    assert on_leg.sum() >= 2
    dyn = free_space_violations(laser, r1, pose1, r0, pose0)
    assert np.all(dyn[on_leg])
    assert not np.any(dyn[~on_leg])
    # The same scan against itself: nothing is dynamic.
    assert not free_space_violations(laser, r1, pose1, r1, pose1).any()


def test_range_discontinuities_flag_both_sides_of_a_jump():
    r = np.array([2.0, 2.01, 2.02, 1.2, 3.0, 3.01, np.inf, 3.0], dtype=np.float32)
    flags = range_discontinuities(r, jump_m=0.1, jump_rel=0.0)
    # 2.02 -> 1.2 -> 3.0: the mixed pixel (1.2) and its neighbours; inf counts as a jump.
    assert flags.tolist() == [False, False, True, True, True, True, True, True]
    isolated = range_discontinuities(r, jump_m=0.1, jump_rel=0.0, isolated_only=True)
    assert isolated.tolist() == [False, False, False, True, False, False, True, False]
    assert not range_discontinuities(np.linspace(1.0, 1.5, 50)).any()


def test_scan_points_with_cached_beam_directions_are_the_same(laser):
    rng = np.random.default_rng(2)
    r = rng.uniform(0.0, 7.0, laser.n_beams)
    r[::7] = np.inf
    r[::11] = np.nan
    beams = BeamDirections(laser)
    assert np.array_equal(scan_points_base(laser, r, beams), scan_points_base(laser, r))


def test_flat_mapper_params_fill_both_parts_of_the_config():
    """A scenario's flat ``mapper_params`` go to the front end, loop closure or the grid,
    typed like the defaults; an unknown name is an error that names it."""
    cfg = FirstRunConfig.from_params(
        voxel_m=0.05, global_loops=False, map_max_hit_range_m=5, loop_stride=0, seq_sigma=[1] * 5
    )
    assert cfg.slam == replace(KeyframeSLAMConfig(), voxel_m=0.05)
    loops = replace(LoopClosureConfig(), global_loops=False, loop_stride=1, seq_sigma=(1.0,) * 5)
    assert cfg.loops == loops
    assert cfg.map_max_hit_range_m == 5.0 and isinstance(cfg.map_max_hit_range_m, float)
    assert FirstRunConfig.from_params() == FirstRunConfig()
    with pytest.raises(TypeError, match=r"unknown parameters \['voxel'\]"):
        FirstRunConfig.from_params(voxel=0.05)
    with pytest.raises(ValueError, match="drop_edges"):
        FirstRunConfig.from_params(drop_edges="some")


def _run_mapper(walls, segments, laser, cast, path_fn, odo_fn):
    """Four laps of the loop on drifting odometry; (online errors, finished map) [m]."""
    rng = np.random.default_rng(0)
    truth = path_fn(laps=4)
    odo = odo_fn(truth, rng)
    mapper = FirstRunMapper(laser, truth[0], walls=walls)
    est = []
    for k in range(len(truth)):
        r = cast(truth[k], laser.angles(), segments, laser.range_max_m)
        r = (r + rng.normal(0, 0.01, r.shape)).astype(np.float32)
        est.append(mapper.update(Odometry(odo[k], 0.1 * k), Scan(r, 0.1 * k)).mean)
    online = np.hypot(*(np.array(est)[:, :2] - truth[:, :2]).T)
    smap = mapper.finish()
    return online, smap, truth


def test_prior_walls_bound_the_front_end_drift(segments, laser, cast, path_fn, odo_fn):
    """Granted the room's six outer walls (not the pillar or the cupboards), the front end
    matches them too: its online error stays at the range noise's scale instead of growing
    lap by lap, and the finished map, tied to the walls it sees instead of closed in loops,
    stays as close to the truth."""
    free, _, _ = _run_mapper(None, segments, laser, cast, path_fn, odo_fn)
    anchored, smap, truth = _run_mapper(segments[:6], segments, laser, cast, path_fn, odo_fn)
    assert free.max() > 0.03  # without the plan, drift builds up between closures
    assert anchored.max() < 0.02
    assert np.sqrt(np.mean(anchored**2)) < 0.5 * np.sqrt(np.mean(free**2))
    assert smap.n_loop_closures == 0
    final = np.hypot(*(smap.trajectory[:, :2] - truth[:, :2]).T)
    assert final.max() < 0.02
    assert np.sqrt(np.mean(final**2)) < np.sqrt(np.mean(anchored**2))


def test_anchor_walls_off_ignores_the_prior(segments, laser):
    """``anchor_walls = False`` is B&D's first run: walls given or not, nothing is matched."""
    config = FirstRunConfig(slam=KeyframeSLAMConfig(anchor_walls=False))
    mapper = FirstRunMapper(laser, np.zeros(3), config, walls=segments)
    assert len(mapper.slam.wall_points) == 0
    on = FirstRunMapper(laser, np.zeros(3), walls=segments[:1])
    spacing = np.hypot(*np.diff(on.slam.wall_points, axis=0).T)
    assert len(on.slam.wall_points) >= 8 / 0.03 and spacing.max() <= 0.03 + 1e-12


def test_local_map_takes_nearby_keyframes_only_where_walls_anchor(segments, laser):
    """A second pass of a place matches the first pass's keyframes when walls hold the
    map frame (``anchored_local_map_radius_m``); without walls only the last keyframes."""
    x = np.r_[np.arange(0.0, 9.0, 0.3), np.arange(9.0, 0.0, -0.3)]  # out and back, 60 keyframes
    poses = np.c_[x, np.zeros_like(x), np.zeros_like(x)]
    free = FirstRunMapper(laser, poses[0]).slam
    anchored = FirstRunMapper(laser, poses[0], walls=segments).slam
    for slam in (free, anchored):
        slam.keyframes = [Keyframe(p, np.zeros(laser.n_beams, np.float32)) for p in poses]
    last12 = list(range(len(poses) - 12, len(poses)))
    assert free.local_keyframes() == last12
    near_start = [k for k in range(len(poses)) if abs(x[k] - x[-1]) < 3.0]
    assert anchored.local_keyframes() == sorted(set(near_start) | set(last12))
    assert min(anchored.local_keyframes()) == 0  # the first pass's start is back in view
