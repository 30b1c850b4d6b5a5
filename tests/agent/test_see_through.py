"""The see-through test (:mod:`dynmap_sim.agent.localization.see_through`) and its use in
static-mcl's sensor update (``see_through_margin_m``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dynmap_sim.agent.grid import OCCUPIED, OccupancyGrid
from dynmap_sim.agent.localization.distance_filter import expected_ranges
from dynmap_sim.agent.localization.particle_filter import TUNED, AMCLFilter
from dynmap_sim.agent.localization.see_through import see_through_logp, wall_depths
from dynmap_sim.types import LaserSpec


@pytest.mark.parametrize("seed", range(10))
def test_the_walk_stops_within_half_a_cell_of_where_the_beam_enters_a_wall(seed: int) -> None:
    """A wall of occupied columns from x = 3 m: a beam from laser (x0, y0) at angle ``a``
    enters it after ``(3 - x0) / cos a``; the walk's safe steps never jump over it, so the
    depth lies within half a cell beyond (inf when the reading ends before it, less the
    margin)."""
    rng = np.random.default_rng(seed)
    res = float(rng.choice([0.05, 0.1]))
    occ = np.zeros((int(6 / res), int(5 / res)), np.int8)
    occ[:, int(round(3 / res)) :] = OCCUPIED
    g = OccupancyGrid(occ, [0.0, 0.0], res)
    n = 20
    particles = np.column_stack([rng.uniform(0.2, 2.8, n), rng.uniform(2.0, 4.0, n),
                                 rng.uniform(-0.5, 0.5, n)])  # fmt: skip
    mount = (float(rng.uniform(-0.1, 0.1)), 0.0, float(rng.uniform(-0.2, 0.2)))
    angles = rng.uniform(-0.8, 0.8, 15)
    ranges = rng.uniform(0.5, 5.0, 15)
    depth = wall_depths(g, particles, ranges, angles, mount, 0.3)
    th = particles[:, 2:3]
    lx = particles[:, 0:1] + np.cos(th) * mount[0]
    ly = particles[:, 1:2] + np.sin(th) * mount[0]
    a = th + mount[2] + angles[None, :]
    entry = (3.0 - lx) / np.cos(a)
    y_entry = ly + entry * np.sin(a)
    inside = (y_entry > 0.0) & (y_entry < 6.0 - 1e-9)
    through = inside & (entry + 0.5 * res < ranges - 0.3)
    short = entry >= ranges - 0.3
    assert through.sum() > 20 and short.sum() > 20
    assert np.all(depth[through] >= entry[through] - 1e-9)
    assert np.all(depth[through] <= entry[through] + 0.5 * res + 1e-9)
    assert np.all(np.isinf(depth[short]))


def test_it_agrees_with_ray_casting_away_from_the_margin() -> None:
    """Against the half-cell ray caster of the distance filter: a reading that ends 8 cm past
    ``first hit + margin`` sees through, one 8 cm short of it does not; both walks sample, so
    a beam that grazes a corner can differ (a few in a hundred)."""
    segs = np.array([[0, 0, 10, 0], [10, 0, 10, 8], [10, 8, 0, 8], [0, 8, 0, 0], [5, 0, 5, 5],
                     [2, 6, 3, 6.5], [7, 2, 8, 3]], float)  # fmt: skip
    g = OccupancyGrid.from_segments(segs, free_seed_xy_m=[1, 1])
    rng = np.random.default_rng(0)
    angles = np.linspace(-2.0, 2.0, 41)
    occupied = g.occupancy == OCCUPIED
    agree = {True: [], False: []}
    for _ in range(40):
        pose = np.array([rng.uniform(0.5, 9.5), rng.uniform(0.5, 7.5), rng.uniform(-3, 3)])
        first = expected_ranges(g, pose, angles, 30.0, occupied)
        ok = np.isfinite(first)
        for offset, expect in ((0.3 + 0.08, True), (0.3 - 0.08, False)):
            depth = wall_depths(g, pose[None], first[ok] + offset, angles[ok], (0, 0, 0), 0.3)
            agree[expect].extend(np.isfinite(depth[0]) == expect)
    assert len(agree[True]) > 1000
    assert np.mean(agree[True]) > 0.98
    assert np.mean(agree[False]) > 0.98


def _two_wall_filter(margin: float) -> tuple[AMCLFilter, np.ndarray]:
    """Walls at x = 5 m and x = 6 m (up to y = 3 m), a room around them; a laser facing +x."""
    segs = np.array([[0, -3, 9, -3], [9, -3, 9, 3], [9, 3, 0, 3], [0, 3, 0, -3],
                     [5, -1, 5, 1], [6, -1, 6, 1]], float)  # fmt: skip
    g = OccupancyGrid.from_segments(segs, free_seed_xy_m=[1, 0])
    laser = LaserSpec("test", 5, -0.1, 0.05, 0.02, 5.6, 0.1, 0.0)
    cfg = replace(TUNED, see_through_margin_m=margin, do_beamskip=False)
    return AMCLFilter(g, laser, cfg), laser.angles()


@pytest.mark.parametrize("margin", [0.0, 0.3])
def test_a_pose_that_sees_through_a_wall_loses_only_with_the_term(margin: float) -> None:
    """Readings of 3 m from x = 2 m end on the first wall; from x = 3 m they end on the
    second, through the first: the likelihood field cannot tell the two poses apart. Nine
    particles at x = 2 m, one at x = 3 m (a tenth of the cloud sees through, below
    ``see_through_max_share``)."""
    flt, angles = _two_wall_filter(margin)
    ranges = 3.0 / np.cos(angles)
    flt.particles = np.array([[2.0, 0.0, 0.0]] * 9 + [[3.0, 0.0, 0.0]])
    flt.weights = np.full(10, 0.1)
    flt.correct(ranges)
    if margin == 0.0:
        assert flt.weights[9] == pytest.approx(flt.weights[0], rel=0.2)
    else:
        assert flt.weights[9] < 1e-6 * flt.weights[0]


def test_the_terms_are_checked() -> None:
    with pytest.raises(ValueError, match="likelihood_field_prob"):
        replace(TUNED, laser_model_type="likelihood_field")
    with pytest.raises(ValueError, match="recovery_distance_filter_m > 0"):
        replace(TUNED, recovery_distance_filter_m=0.0)
    with pytest.raises(ValueError, match="see_through_max_share"):
        replace(TUNED, see_through_max_share=1.5)
    with pytest.raises(ValueError, match="see_through_margin_m"):
        replace(TUNED, see_through_margin_m=-0.1)


def test_a_reading_most_of_the_cloud_sees_through_is_a_removed_object() -> None:
    """``see_through_max_share``: when more of the cloud than that sees a reading through, it
    does not tell the particles apart and is scored by its end point."""
    flt, angles = _two_wall_filter(0.3)
    ranges = 3.0 / np.cos(angles)
    flt.particles = np.array([[2.0, 0.0, 0.0]] * 3 + [[3.0, 0.0, 0.0]] * 7)
    flt.weights = np.full(10, 0.1)
    flt.correct(ranges)
    assert flt.weights[9] == pytest.approx(flt.weights[0], rel=0.2)


@pytest.mark.parametrize("in_weights", [False, True])
def test_short_readings_leave_the_weights_with_the_distance_filter(in_weights: bool) -> None:
    """``distance_filter_weights``: an object in front of the first wall (readings of 1 m
    from x = 2 m) fits a particle 2 m ahead at x = 4 m on the end points; left out of the
    weights (short at the mean particle, x = 2 m), the other readings decide."""
    flt, angles = _two_wall_filter(0.0)
    flt.config = replace(flt.config, distance_filter_weights=in_weights)
    ranges = 3.0 / np.cos(angles)
    ranges[:2] = 1.0  # two of five readings end on the unmapped object
    flt.particles = np.array([[2.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 0.0, 0.0], [4.0, 0.0, 0.0]])
    flt.weights = np.array([0.33, 0.33, 0.33, 0.01])
    flt.correct(ranges)
    share_ahead = flt.weights[3]
    if in_weights:
        assert share_ahead < 1e-6
    else:
        assert share_ahead > 1e-6


def test_the_score_is_the_field_at_the_margin_and_the_floor_beyond() -> None:
    """Continuous at the margin (no step to split a cloud), ``z_rand / range_max`` far past
    it, untouched where the reading does not see through."""
    depth = np.array([[2.0, 2.0, 2.0, np.inf]])
    ranges = np.array([2.3, 2.45, 4.0, 3.0])
    lp = see_through_logp(depth, ranges, 0.3, 0.9, 0.1, 0.12, 5.6)
    assert lp[0, 0] == pytest.approx(np.log(0.9 + 0.1 / 5.6))
    assert lp[0, 0] > lp[0, 1] > lp[0, 2]
    assert lp[0, 2] == pytest.approx(np.log(0.1 / 5.6), abs=1e-9)
    assert lp[0, 3] == 0.0


def test_scoring_only_the_see_through_readings_gives_every_reading_s_bits() -> None:
    """The score of the see-through readings alone equals, bit for bit, the score computed
    for every reading and then masked (numpy's exp and log do not depend on where an element
    stands in the array)."""
    rng = np.random.default_rng(3)
    for n_p, n_b in ((1, 1), (7, 13), (500, 55), (64, 361)):
        ranges = rng.uniform(0.1, 8.0, n_b)
        depth = ranges - rng.uniform(-1.0, 3.0, (n_p, n_b))
        depth[rng.random((n_p, n_b)) < 0.8] = np.inf
        args = (0.3, 0.9, 0.1, 0.12, 8.0)
        beyond = np.maximum(ranges[None, :] - depth - 0.3, 0.0)
        p = 0.9 * np.exp(beyond * beyond * (-0.5 / 0.12**2)) + 0.1 / 8.0
        every = np.where(np.isfinite(depth), np.log(p), 0.0)
        got = see_through_logp(depth, ranges, *args)
        assert got.shape == (n_p, n_b)
        assert np.array_equal(got.view(np.int64), every.view(np.int64))
