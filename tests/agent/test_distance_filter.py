"""Distance filter (Fox et al. 1999): expected ranges in a grid, short readings, and its use in
static-mcl's recovery signal."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from synthetic_scans import LASER, raycast
from synthetic_scans import room_segments as room

from dynmap_sim.agent.grid import OccupancyGrid
from dynmap_sim.agent.localization.distance_filter import expected_ranges, short_readings
from dynmap_sim.agent.localization.particle_filter import TUNED, AMCLFilter


def test_expected_ranges_match_the_true_walls_within_a_cell():
    segs = room()
    grid = OccupancyGrid.from_segments(segs, free_seed_xy_m=(1, 1))
    pose = np.array([1.2, 1.1, 0.4])
    angles = LASER.angles()
    truth = raycast(pose, angles, segs, LASER.range_max_m)
    exp = expected_ranges(grid, pose, angles, LASER.range_max_m)
    both = np.isfinite(truth) & np.isfinite(exp)
    assert both.mean() > 0.8
    # rasterized walls and half-cell steps: within two cells of the segment, except beams
    # that graze a wall and enter its rasterized cells early (never later than the wall)
    err = exp[both] - truth[both]
    assert np.mean(np.abs(err) <= 2 * grid.resolution_m) > 0.8
    assert np.median(np.abs(err)) <= grid.resolution_m
    assert err.max() <= 2 * grid.resolution_m
    # nothing to hit within the range: inf
    far = expected_ranges(grid, pose, angles, 0.05)
    assert np.all(np.isinf(far))


def test_short_readings():
    mask = short_readings([1.0, 2.0, np.inf, 0.5], [2.0, 2.1, 3.0, np.inf], margin_m=0.3)
    assert mask.tolist() == [True, False, False, True]


def test_a_crowd_in_front_does_not_look_like_a_kidnapping():
    """Two beams in five cut short (people in front): with the distance filter the per-beam
    recovery average stays where it was; without it, it falls below the ratio at which
    ``tuned`` starts injecting random poses."""
    segs = room()
    grid = OccupancyGrid.from_segments(segs, free_seed_xy_m=(1, 1))
    pose = np.array([1.2, 1.1, 0.4])
    good = raycast(pose, LASER.angles(), segs, LASER.range_max_m)
    crowd = good.copy()
    used = AMCLFilter(grid, LASER, TUNED).beams  # the beams the filter looks at
    cut = used[np.arange(len(used)) % 5 < 2]
    crowd[cut] = np.minimum(crowd[cut], 0.6)
    ratios = {}
    for margin in (0.0, TUNED.recovery_distance_filter_m):
        cfg = replace(TUNED, recovery_distance_filter_m=margin, distance_filter_weights=margin > 0)
        f = AMCLFilter(grid, LASER, cfg)
        rng = np.random.default_rng(7)
        f.init_gaussian(pose, np.diag([0.02**2, 0.02**2, 0.01**2]), rng)
        for _ in range(20):
            f.correct(good)
            f.resample(rng)
        before = f.w_fast
        for _ in range(20):
            f.correct(crowd)
            f.resample(rng)
        ratios[margin] = f.w_fast / before
    assert ratios[TUNED.recovery_distance_filter_m] > 0.8
    assert ratios[0.0] < TUNED.recovery_ratio_threshold


def test_a_scan_mostly_shorter_than_the_map_is_not_filtered():
    """``recovery_occluded = "all-beams"``: more than half of the readings short (a
    kidnapping into a smaller room looks like that): the recovery average uses every
    reading."""
    segs = room()
    grid = OccupancyGrid.from_segments(segs, free_seed_xy_m=(1, 1))
    pose = np.array([1.2, 1.1, 0.4])
    f = AMCLFilter(grid, LASER, replace(TUNED, recovery_occluded="all-beams"))
    f.init_gaussian(pose, np.diag([0.02**2, 0.02**2, 0.01**2]), np.random.default_rng(0))
    good = raycast(pose, LASER.angles(), segs, LASER.range_max_m)
    r, a = f._beams_of(good)
    assert len(f._distance_filter_beams(f.weights, r, a)) == len(r)  # nothing short
    few = r.copy()
    few[: len(r) // 3] = 0.3
    assert len(f._distance_filter_beams(f.weights, few, a)) == len(r) - len(r) // 3
    most = r.copy()
    most[: 2 * len(r) // 3] = 0.3
    assert len(f._distance_filter_beams(f.weights, most, a)) == len(r)


def test_hold_leaves_the_recovery_averages_of_an_occluded_scan_alone():
    """``recovery_occluded = "hold"`` (``tuned``): a scan mostly shorter than the map predicts
    feeds neither ``w_slow`` nor ``w_fast`` (nor local resetting's ``w_last``) while the
    global gate is not counting; once it counts, such a scan feeds them with all its beams;
    a scan with few short readings feeds them as before."""
    segs = room()
    grid = OccupancyGrid.from_segments(segs, free_seed_xy_m=(1, 1))
    pose = np.array([1.2, 1.1, 0.4])
    assert TUNED.recovery_occluded == "hold"
    f = AMCLFilter(grid, LASER, TUNED)
    rng = np.random.default_rng(3)
    f.init_gaussian(pose, np.diag([0.02**2, 0.02**2, 0.01**2]), rng)
    good = raycast(pose, LASER.angles(), segs, LASER.range_max_m)
    for _ in range(10):
        f.correct(good)
        f.resample(rng)
    r, a = f._beams_of(good)
    occluded = good.copy()
    occluded[f.beams[: 2 * len(f.beams) // 3]] = 0.3
    assert f._distance_filter_beams(f.weights, *f._beams_of(occluded)) is None
    held = (f.w_slow, f.w_fast, f.w_last, f.n_low_updates)
    for _ in range(10):
        f.correct(occluded)
        f.resample(rng)
    assert (f.w_slow, f.w_fast, f.w_last, f.n_low_updates) == held
    few = good.copy()
    few[f.beams[: len(f.beams) // 3]] = 0.3
    kept = f._distance_filter_beams(f.weights, *f._beams_of(few))
    assert kept is not None and len(r) // 2 <= len(kept) < len(r)
    f.correct(few)
    assert f.w_fast != held[1]
    f.n_low_updates = 1  # the gate counts: the fit had fallen before
    ro, ao = f._beams_of(occluded)
    assert len(f._distance_filter_beams(f.weights, ro, ao)) == len(ro)


def test_recovery_occluded_and_min_share_are_checked():
    for bad in ({"recovery_occluded": "skip"}, {"recovery_min_beam_share": 1.5}):
        try:
            replace(TUNED, **bad)
        except ValueError as exc:
            assert "static-mcl" in str(exc) and next(iter(bad)) in str(exc)
        else:
            raise AssertionError(f"{bad} accepted")


def test_random_poses_the_scan_contradicts_are_not_injected():
    """``recovery_through_max_share``: at the true pose no reading passes through a wall of
    the map, at most random poses (random headings) many do; with the option the global
    recovery injects only the random poses at or below the share: fewer than without it, from
    the same draws."""
    segs = room()
    grid = OccupancyGrid.from_segments(segs, free_seed_xy_m=(1, 1))
    pose = np.array([1.0, 2.5, 0.0])
    scan = raycast(pose, LASER.angles(), segs, LASER.range_max_m)
    injected = {}
    for share in (0.0, 0.5):
        cfg = replace(TUNED, recovery_through_max_share=share, recovery_max_fraction=0.5)
        f = AMCLFilter(grid, LASER, cfg)
        rng = np.random.default_rng(11)
        f.init_gaussian(pose, np.diag([0.02**2, 0.02**2, 0.01**2]), rng)
        f.correct(scan)
        # the gate forced open: half of the draws are random pose candidates
        f.w_slow, f.w_fast, f.n_low_updates = 1.0, 1e-6, cfg.recovery_min_updates
        f.resample(rng)
        injected[share] = f.n_random_injected
        if share:
            assert f.through_shares(pose[None, :])[0] == 0.0
            shares = f.through_shares(f.random_poses(300, rng))
            assert 0.05 < np.mean(shares <= share) < 0.95
    assert 0 < injected[0.5] < 0.95 * injected[0.0]


def test_recovery_through_fields_are_checked():
    for bad in ({"recovery_through_max_share": 1.5}, {"recovery_through_margin_m": -0.1}):
        try:
            replace(TUNED, **bad)
        except ValueError as exc:
            assert next(iter(bad)) in str(exc)
        else:
            raise AssertionError(f"{bad} accepted")
