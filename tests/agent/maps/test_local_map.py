"""Local maps (§4.1, Table 1), dynamic-map learning (§4.4) and current-map synthesis (§4.3)."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim.agent.maps import local_map_numba
from dynmap_sim.agent.maps.current_map import synthesize_current_map
from dynmap_sim.agent.maps.dynamic_map import DynamicMap
from dynmap_sim.agent.maps.local_map import TABLE1, LocalMap
from tests.agent.maps.test_sample_set import UPDATE_KERNELS  # python, numba


def test_table1_memory():
    lm = LocalMap([0, 0])
    assert [ts.n_rays for ts in TABLE1] == [360, 360, 720, 1440, 1440]
    assert [ts.n_samples for ts in TABLE1] == [5, 10, 50, 100, 100]
    assert [ts.update_ratio for ts in TABLE1] == [0.2, 0.8, 0.8, 0.2, 0.05]
    assert lm.n_samples_capacity == 329_400
    assert lm.sample_bytes == 658_800 <= 0.66e6
    assert TABLE1[4].half_life_steps == pytest.approx(13.5, abs=0.05)  # Table 1: ≈ 13.5 days
    assert TABLE1[1].half_life_steps == pytest.approx(0.43, abs=0.01)


def test_projection_to_closest_ray():
    lm = LocalMap([1.0, 2.0])
    a = np.deg2rad([0.2, 0.6, 90.0, 359.7, 180.4])
    r = np.array([1.0, 2.0, 3.0, 1.5, 2.5])
    pts = np.array([1.0, 2.0]) + r[:, None] * np.stack([np.cos(a), np.sin(a)], axis=1)
    ang, dist = lm.polar(pts)
    assert np.allclose(dist, r)
    assert list(LocalMap.ray_index(ang, 360)) == [0, 1, 90, 0, 180]
    assert list(LocalMap.ray_index(ang, 1440)) == [1, 2, 360, 1439, 722]


def test_learned_medians_reproduce_the_room(room, scan_fn):
    rng = np.random.default_rng(0)
    dmap = DynamicMap(max_range_m=8.0)
    centre = np.array([2.0, 2.0, 0.0])
    i = dmap.add_local_map(centre[:2], scan_fn(centre, room, rng), rng)
    poses = [centre + [dx, dy, 0] for dx in (-0.3, 0, 0.3) for dy in (-0.3, 0, 0.3)]
    for _ in range(3):
        pts = [scan_fn(p, room, rng) for p in poses]
        dmap.learn_offline([1, 2, 3, 4], np.array(poses), pts, rng)
    for level in range(5):
        p = dmap.local_maps[i].points(level)
        assert len(p) > 0.5 * TABLE1[level].n_rays
        # every point lies on a wall of the 6 x 4 room or on the pillar
        on_wall = np.minimum.reduce(
            [np.abs(p[:, 0]), np.abs(p[:, 0] - 6), np.abs(p[:, 1]), np.abs(p[:, 1] - 4)]
        )
        on_pillar = (p[:, 0] > 3.95) & (p[:, 0] < 4.45) & (p[:, 1] > 2.45) & (p[:, 1] < 2.95)
        assert np.mean((on_wall < 0.05) | on_pillar) > 0.97, level


def test_online_learning_creates_and_updates_local_maps(room, scan_fn):
    rng = np.random.default_rng(1)
    dmap = DynamicMap()
    pose = np.array([1.0, 1.0, 0.0])
    assert dmap.learn_online(pose, scan_fn(pose, room, rng), rng) == [0]
    assert len(dmap) == 1
    before_ltm = [s.samples_mm.copy() for s in dmap.local_maps[0].sub]
    assert dmap.learn_online(pose + [1.0, 0, 0], scan_fn(pose + [1, 0, 0], room, rng), rng) == [0]
    after = dmap.local_maps[0].sub
    assert not np.array_equal(after[0].samples_mm, before_ltm[0])  # λ1 learned
    for level in range(1, 5):  # the long-term maps did not
        assert np.array_equal(after[level].samples_mm, before_ltm[level])
    far = np.array([4.5, 1.0, 0.0])  # 3.5 m away: a new local map
    assert dmap.learn_online(far, scan_fn(far, room, rng), rng) == [1]
    assert list(dmap.near([4.0, 1.0], 2.5)) == [1]


def _trained_map(room, scan_fn, rng, n=6):
    dmap = DynamicMap()
    pose = np.array([2.0, 2.0, 0.0])
    dmap.add_local_map(pose[:2], scan_fn(pose, room, rng), rng)
    for _ in range(n):
        poses = np.array([pose + [rng.normal(0, 0.2), rng.normal(0, 0.2), 0] for _ in range(8)])
        dmap.learn_offline([1, 2, 3, 4], poses, [scan_fn(p, room, rng) for p in poses], rng)
        for p in poses:
            dmap.learn_online(p, scan_fn(p, room, rng), rng)
    return dmap, pose


def test_selection_prefers_short_term_memory_after_a_change(room, scan_fn, box_fn):
    rng = np.random.default_rng(2)
    dmap, pose = _trained_map(room, scan_fn, rng)
    changed = np.concatenate([room, box_fn(0.6, 0.5, 1.4, 3.5)])  # a cupboard on the left
    static = synthesize_current_map(dmap, pose, scan_fn(pose, room, rng), range(5))
    assert not static.safe_mode
    assert static.n_explained > 0.8 * static.n_readings
    for _ in range(8):  # the short-term memory learns the cupboard within a few scans
        dmap.learn_online(pose, scan_fn(pose, changed, rng), rng)
    cur = synthesize_current_map(dmap, pose, scan_fn(pose, changed, rng), range(5))
    assert cur.timescale == 0
    assert not cur.safe_mode
    # the chosen model explains the scan better than the long-term one alone
    ltm = synthesize_current_map(dmap, pose, scan_fn(pose, changed, rng), [4])
    assert cur.scan_loglik > ltm.scan_loglik
    # the current map contains the cupboard's front face x = 1.4
    assert np.sum(np.abs(cur.points[:, 0] - 1.4) < 0.05) > 20


def test_safe_mode_when_nothing_fits(room, scan_fn, box_fn):
    rng = np.random.default_rng(3)
    dmap, pose = _trained_map(room, scan_fn, rng, n=2)
    other = box_fn(1.5, 1.5, 2.5, 2.5)  # the robot is boxed in: nothing the map knows
    cur = synthesize_current_map(dmap, pose + [0.0, 0.0, 0.0], scan_fn(pose, other, rng), range(5))
    assert cur.safe_mode
    assert cur.selections == [(0, 4)]
    assert cur.n_explained < 0.5 * cur.n_readings


@pytest.mark.parametrize("sigma_min_m", [0.0, 0.01])
def test_all_levels_at_once_equal_one_level_at_a_time(room, scan_fn, sigma_min_m):
    rng = np.random.default_rng(5)
    dmap = DynamicMap(max_range_m=8.0)
    pose = np.array([2.0, 2.0, 0.0])
    i = dmap.add_local_map(pose[:2], scan_fn(pose, room, rng), rng)
    lm = dmap.local_maps[i]
    dmap.learn_offline([1, 2, 3, 4], pose[None], [scan_fn(pose, room, rng)], rng)
    for step in range(3):  # the stacked tables must follow every update
        scan = scan_fn(pose + [0.1 * step, 0.0, 0.0], room, rng)
        polar = lm.polar(np.concatenate([scan, [[30.0, 30.0]]]))  # one reading out of range
        levels = [0, 1, 2, 3, 4] if step != 1 else [1, 3, 4]
        both = lm.log_likelihoods(levels, polar, sigma_min_m=sigma_min_m, min_outlier_ratio=0.01)
        for b, level in enumerate(levels):
            one = lm.log_likelihood(level, polar, sigma_min_m=sigma_min_m, min_outlier_ratio=0.01)
            assert np.array_equal(both[b], one)
        dmap.learn_online(pose, scan, rng, levels=[0])


@pytest.mark.skipif(not local_map_numba.numba_available(), reason="numba not installed")
def test_compiled_scan_log_likelihoods_agree_with_numpy(room, scan_fn):
    rng = np.random.default_rng(8)
    dmap = DynamicMap(max_range_m=8.0)
    pose = np.array([2.0, 2.0, 0.0])
    i = dmap.add_local_map(pose[:2], scan_fn(pose, room, rng), rng)
    lm = dmap.local_maps[i]
    dmap.learn_offline([1, 2, 3, 4], pose[None], [scan_fn(pose, room, rng)], rng)
    for step in range(3):
        pts = np.concatenate([scan_fn(pose + [0.2 * step, 0.1, 0.0], room, rng), [[30.0, 2.0]]])
        kw = {"sigma_min_m": 0.01, "min_outlier_ratio": 0.01}
        a = lm.scan_log_likelihoods([0, 1, 2, 3, 4], pts, backend="numba", **kw)
        b = lm.scan_log_likelihoods([0, 1, 2, 3, 4], pts, backend="numpy", **kw)
        assert np.allclose(a, b, rtol=1e-12, atol=1e-12)
        dmap.learn_online(pose, pts, rng, levels=[0])


def test_snapshot_points_are_the_sub_map_medians(room, scan_fn):
    """A day snapshot (uint16 mm medians of λ2–λ5) reproduces LocalMap.points within 1 mm."""
    rng = np.random.default_rng(3)
    dmap, _ = _trained_map(room, scan_fn, rng, n=3)
    dmap.add_local_map(np.array([4.5, 1.5]), scan_fn(np.array([4.5, 1.5, 0.0]), room, rng), rng)
    snap = dmap.snapshot(sigma_max_m=0.10)
    assert snap.levels == (1, 2, 3, 4) and snap.centres.shape == (2, 2)
    for level in snap.levels:
        assert snap.medians_mm[snap.levels.index(level)].shape == (2, TABLE1[level].n_rays)
        for i, lm in enumerate(dmap.local_maps):
            want = lm.points(level, 0.10)
            got = snap.points(i, level)
            assert got.shape == want.shape and len(got) > 0
            assert np.abs(got - want).max() < 1e-3


@pytest.mark.parametrize("backend", UPDATE_KERNELS)
@pytest.mark.parametrize("seed", range(6))
def test_compiled_projection_learns_the_numpy_samples(backend, seed):
    """learn_levels with the compiled projection (local_map_numba.polar_rays) leaves every
    sub-map's samples and the generator as the numpy projection does: points beyond the
    maximum range, on ray boundaries and at 2π, ranges past 65.535 m, levels sharing rays."""
    rng = np.random.default_rng(seed)
    a = LocalMap(rng.normal(0, 1, 2), max_range_m=float(rng.choice([4.0, 80.0])))
    b = LocalMap(a.centre, max_range_m=a.max_range_m)
    ra, rb = np.random.default_rng(seed), np.random.default_rng(seed)
    for step in range(8):
        n = int(rng.integers(0, 900))
        ang = rng.uniform(0, 2 * np.pi, n)
        ang[: n // 4] = np.round(ang[: n // 4] * 720 / np.pi) * np.pi / 720  # on the rays
        r = rng.uniform(0.0, 6.0, n) * (1.0 + 12.0 * (rng.random(n) < 0.05))
        pts = a.centre + r[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])
        levels = [[0], [1], [2, 3, 4], [0, 1, 2, 3, 4]][step % 4]
        fill = step == 0
        a.learn_levels(levels, pts, ra, fill=fill, backend="numpy")
        b.learn_levels(levels, pts, rb, fill=fill, backend=backend)
        for sa, sb in zip(a.sub, b.sub, strict=True):
            assert np.array_equal(sa.samples_mm, sb.samples_mm)
            assert np.array_equal(sa.count, sb.count)
    assert ra.random() == rb.random()
