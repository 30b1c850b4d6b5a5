"""The toy example of Biber & Duckett §3.5 (Fig. 2)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from dynmap_sim.agent.maps.sample_set import SampleSets
from dynmap_sim.studies.biber_duckett.toy import (
    CUPBOARD_M,
    WALL_M,
    ToyConfig,
    run_toy,
    rwa_step_size,
    simulate_toy,
)


def _series(rows, u, method):
    return np.array([e for t, uu, m, e in sorted(rows) if uu == u and m == method])


def _is_cupboard(est):
    return np.abs(est - CUPBOARD_M) < np.abs(est - WALL_M)


def test_run_toy_writes_csv_and_png(tmp_path):
    paths = run_toy(tmp_path / "out", seed=0)
    assert [p.name for p in paths] == ["toy.csv", "toy.png"]
    assert paths[1].stat().st_size > 1000
    with paths[0].open() as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == ["t", "u", "method", "estimate"]
    assert {r["method"] for r in rows} == {"samples", "rwa"}
    assert {float(r["u"]) for r in rows} == {0.75, 0.25, 0.05}
    assert len(rows) == 40 * 3 * 2


def test_estimate_is_always_a_measured_value():
    """Requirement 4: with 20 (even) samples the median is one of the middle samples."""
    rng = np.random.default_rng(5)
    ss = SampleSets(1, 20, 0.25)
    seen: set[int] = set()
    for t in range(30):
        vals = rng.integers(900, 2100, size=20).astype(np.uint16)
        seen |= set(vals.tolist())
        ss.update(np.zeros(20, int), vals, rng, fill=(t == 0))
        rho_mm = round(ss.estimates().rho_m[0] * 1000)
        assert rho_mm in seen
        assert rho_mm in ss.samples_mm[0].tolist()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sample_sets_switch_like_fig2(seed):
    rows = simulate_toy(ToyConfig(), seed)
    # u = 0.75: cupboard within 1 step after t = 10, wall again within 1 step after t = 20.
    for u, max_delay in ((0.75, 1), (0.25, 4)):
        cup = _is_cupboard(_series(rows, u, "samples"))
        assert not cup[:10].any()
        assert cup[10 + max_delay : 20].all(), (u, cup.astype(int))
        assert not cup[20 + max_delay :].any(), (u, cup.astype(int))
    # u = 0.05: stays at the wall, at most a few steps off.
    cup = _is_cupboard(_series(rows, 0.05, "samples"))
    assert cup.sum() <= 3
    est = _series(rows, 0.05, "samples")
    # a wall measurement (σ = 10 cm noise; cupboard samples push the median to low wall ones)
    assert np.all(np.abs(est[~cup] - WALL_M) < 0.3)


def test_rwa_interpolates_for_small_u():
    rows = simulate_toy(ToyConfig(), 0)
    rwa = _series(rows, 0.05, "rwa")
    assert CUPBOARD_M + 0.2 < rwa[20] < WALL_M - 0.2  # "neither of the two objects"
    fast = _series(rows, 0.75, "rwa")
    assert abs(fast[19] - CUPBOARD_M) < 0.1 and abs(fast[25] - WALL_M) < 0.1


def test_rwa_step_size_matches_update_ratio():
    for u in (0.75, 0.25, 0.05):
        a = rwa_step_size(u, 20)
        assert (1 - a) ** 20 == pytest.approx(1 - u)
