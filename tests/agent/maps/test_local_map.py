"""Local maps (§4.1, Table 1), dynamic-map learning (§4.4) and current-map synthesis (§4.3)."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim.agent.maps.current_map import synthesize_current_map
from dynmap_sim.agent.maps.dynamic_map import DynamicMap
from dynmap_sim.agent.maps.local_map import TABLE1, LocalMap
from dynmap_sim.agent.maps.sample_set import mixture_log_likelihood


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
def test_scan_log_likelihoods_are_the_mixture_model(room, scan_fn, sigma_min_m):
    """The per-reading log-likelihoods of several levels at once (compiled with a floor,
    the stacked tables following every update) are eq. 6–8 level by level
    (:func:`mixture_log_likelihood` on the readings' polar coordinates); a reading beyond
    the maximum range has none."""
    rng = np.random.default_rng(5)
    dmap = DynamicMap(max_range_m=8.0)
    pose = np.array([2.0, 2.0, 0.0])
    i = dmap.add_local_map(pose[:2], scan_fn(pose, room, rng), rng)
    lm = dmap.local_maps[i]
    dmap.learn_offline([1, 2, 3, 4], pose[None], [scan_fn(pose, room, rng)], rng)
    for step in range(3):
        scan = scan_fn(pose + [0.1 * step, 0.0, 0.0], room, rng)
        pts = np.concatenate([scan, [[30.0, 30.0]]])  # one reading out of range
        levels = [0, 1, 2, 3, 4] if step != 1 else [1, 3, 4]
        kw = {"sigma_min_m": sigma_min_m, "min_outlier_ratio": 0.01}
        got = lm.scan_log_likelihoods(levels, pts, **kw)
        ang, dist = lm.polar(pts)
        for b, level in enumerate(levels):
            ray = lm.ray_index(ang, TABLE1[level].n_rays)
            want = mixture_log_likelihood(lm.sub[level].estimates(), ray, dist, 8.0, **kw)
            fin = np.isfinite(want)
            assert np.array_equal(fin, np.isfinite(got[b])) and not fin[-1]
            np.testing.assert_allclose(got[b][fin], want[fin], rtol=1e-9, atol=1e-9)
        dmap.learn_online(pose, scan, rng, levels=[0])


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


@pytest.mark.parametrize("seed", range(6))
def test_learning_puts_each_point_on_its_closest_ray(seed):
    """A filling step puts each point within the maximum range on the closest ray of every
    level (ray ``j`` at ``j·2π/R``) with its distance in millimetres (clipped at 65.535 m);
    points beyond the maximum range are left out."""
    rng = np.random.default_rng(seed)
    lm = LocalMap(rng.normal(0, 1, 2), max_range_m=float(rng.choice([4.0, 80.0])))
    n = int(rng.integers(1, 300))
    ang = rng.uniform(0, 2 * np.pi, n)
    r = rng.uniform(0.0, 6.0, n) * (1.0 + 12.0 * (rng.random(n) < 0.05))
    pts = lm.centre + r[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])
    lm.learn_levels(range(5), pts, rng, fill=True)
    near = np.hypot(*(pts - lm.centre).T) <= lm.max_range_m
    for level, ts in enumerate(TABLE1):
        want: list[list[int]] = [[] for _ in range(ts.n_rays)]
        for a, d in zip(ang[near], r[near], strict=True):
            want[int(np.rint(a * ts.n_rays / (2 * np.pi))) % ts.n_rays].append(
                min(int(np.rint(d * 1000.0)), 65535)
            )
        sub = lm.sub[level]
        for j in range(ts.n_rays):
            got = sorted(sub.samples_mm[j, : sub.count[j]].tolist())
            assert len(got) == min(len(want[j]), ts.n_samples)
            assert all(v in want[j] for v in got)
