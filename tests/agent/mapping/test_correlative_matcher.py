"""Correlative scan matcher: exact block bounds and recovery of large initial errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dynmap_sim import se2
from dynmap_sim.agent.mapping.correlative_matcher import LikelihoodTable, correlative_match
from tests.agent.mapping.conftest import raycast, room_segments


def _scan_points(pose: np.ndarray, n: int = 361) -> np.ndarray:
    angles = np.linspace(-np.pi, np.pi, n, endpoint=False)
    r = raycast(pose, angles, room_segments(), 8.0)
    ok = np.isfinite(r)
    return se2.scan_to_points(r[ok], angles[ok])


def _room_points(step_m: float = 0.02) -> np.ndarray:
    out = []
    for x0, y0, x1, y1 in room_segments():
        n = max(2, int(np.hypot(x1 - x0, y1 - y0) / step_m))
        t = np.linspace(0, 1, n)[:, None]
        out.append(np.array([x0, y0]) * (1 - t) + np.array([x1, y1]) * t)
    return np.concatenate(out)


@settings(max_examples=15, deadline=None)
@given(block=st.integers(1, 9), seed=st.integers(0, 10_000))
def test_block_max_is_the_max_over_the_block(block: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    table = LikelihoodTable(rng.uniform(0, 2, (30, 2)), resolution_m=0.1, margin_m=0.3)
    m = table.block_max(block)
    t = table.table
    for iy, ix in rng.integers(0, t.shape, size=(20, 2)):
        assert m[iy, ix] == t[iy : iy + block, ix : ix + block].max()


def test_recovers_a_large_offset_in_a_synthetic_room() -> None:
    truth = np.array([3.0, 1.5, 0.4])
    pts = _scan_points(truth)
    table = LikelihoodTable(_room_points(), resolution_m=0.05, sigma_m=0.05)
    init = se2.compose(truth, np.array([0.8 * np.cos(1.0), 0.8 * np.sin(1.0), np.radians(15)]))
    res = correlative_match(pts, table, init, window_xy_m=1.0, window_theta_rad=0.35)
    assert np.hypot(*(res.pose[:2] - truth[:2])) < 0.06
    assert abs(se2.wrap_angle(res.pose[2] - truth[2])) < 0.02
    assert res.score > 0.8


def test_branch_and_bound_equals_brute_force() -> None:
    truth = np.array([6.0, 1.8, -0.3])
    pts = _scan_points(truth, n=90)
    table = LikelihoodTable(_room_points(), resolution_m=0.1, sigma_m=0.1)
    init = truth + np.array([0.3, -0.2, 0.1])
    kw = dict(window_xy_m=0.5, window_theta_rad=0.15)
    bnb = correlative_match(pts, table, init, block=4, **kw)
    brute = correlative_match(pts, table, init, block=1, max_blocks=10**9, **kw)
    # block=1: the bounds are the exact scores of every pose of the window.
    assert bnb.score == pytest.approx(brute.score, abs=1e-12)
    n_poses = (2 * 5 + 1) ** 2 * len(np.arange(-0.15, 0.15 + 1e-9, 0.01))
    assert bnb.n_evaluated < n_poses


def test_search_stays_inside_its_window_on_both_sides():
    """The branch-and-bound blocks tile more than the window (2 n + 1 cells in blocks of
    8): a best pose outside the window, on either side, is not returned."""
    rng = np.random.default_rng(0)
    pts = rng.uniform(-3, 3, (300, 2))
    table = LikelihoodTable(pts, 0.1, 0.1, margin_m=2.0)
    for shift in ([1.0, 0.0], [-1.0, 0.0], [0.0, 0.9], [0.0, -0.9]):
        res = correlative_match(
            pts - np.array(shift), table, np.zeros(3), window_xy_m=0.4, window_theta_rad=0.0
        )
        assert np.all(np.abs(res.pose[:2]) <= 0.4 + 1e-9)
    inside = correlative_match(
        pts - np.array([0.3, -0.2]), table, np.zeros(3), window_xy_m=0.4, window_theta_rad=0.0
    )
    assert np.allclose(inside.pose, [0.3, -0.2, 0.0]) and inside.score > 0.99


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 10_000), block=st.integers(2, 6))
def test_best_score_is_the_brute_force_maximum(seed: int, block: int) -> None:
    """The branch and bound's score is the maximum of the fine score over every pose of the
    window, each computed plainly as the sum of table lookups of the moved points."""
    rng = np.random.default_rng(seed)
    target = rng.uniform(0, 3, (60, 2))
    table = LikelihoodTable(target, resolution_m=0.1, sigma_m=0.1, margin_m=0.5)
    pts = target[:40] + rng.normal(0, 0.03, (40, 2))
    init = np.array([*rng.uniform(-0.2, 0.2, 2), rng.uniform(-0.1, 0.1)])
    step = 0.02
    res = correlative_match(pts, table, init, 0.3, 0.06, theta_step_rad=step, block=block,
                            max_blocks=10**9)  # fmt: skip
    best = -1.0
    h, w = table.table.shape
    for th in init[2] + step * np.arange(-3, 4):
        c, s = np.cos(th), np.sin(th)
        moved = pts @ np.array([[c, s], [-s, c]]) + init[:2]
        ix0, iy0 = table.cell_of(moved)
        for oy in range(-3, 4):
            for ox in range(-3, 4):
                ix = np.clip(ix0 + ox, 0, w - 1)
                iy = np.clip(iy0 + oy, 0, h - 1)
                best = max(best, float(table.table[iy, ix].sum()))
    assert res.score == pytest.approx(best / len(pts), rel=1e-12)
