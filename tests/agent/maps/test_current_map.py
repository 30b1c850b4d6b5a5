"""The compiled greedy timescale selection of the current-map synthesis (§4.3, steps 2-5)."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim.agent.maps.current_map import select_timescales


def _brute_select(logp, log_floor, log_explained, min_readings):
    """Steps 2-5 by their definition, in Python: floor, mark the explained readings, then
    take the (map, level) of the best sum over the unexplained readings (the first on a tie)
    while at least ``min_readings`` remain and maps are left."""
    n_maps, n_levels, n = logp.shape
    lp = np.maximum(logp, log_floor)
    good = lp >= log_explained
    remaining = list(range(n))
    available = list(range(n_maps))
    chosen = []
    while len(remaining) >= min_readings and available:
        score = {(m, b): sum(lp[m, b, i] for i in remaining)
                 for m in available for b in range(n_levels)}  # fmt: skip
        best = max(score.values())
        m, b = next(k for k in sorted(score) if score[k] == best)
        chosen.append((m, b))
        available.remove(m)
        remaining = [i for i in remaining if not good[m, b, i]]
    return lp, good, chosen


@pytest.mark.parametrize("seed", range(40))
def test_select_timescales_is_the_greedy_selection(seed):
    """Integer log-likelihoods, so that every sum is exact and ties are real: the same
    selections in the same order, the floored values and the explained readings (equal
    models, all readings explained, fewer readings than ``min_readings``)."""
    rng = np.random.default_rng(seed)
    n_maps, n_levels = int(rng.integers(1, 7)), int(rng.integers(1, 6))
    n = int(rng.choice([0, 5, 19, 20, 21, 60]))
    logp = -rng.integers(0, 12, (n_maps, n_levels, n)).astype(np.float64)
    if seed % 5 == 1:  # equal models: the first wins
        logp[:] = logp[:1, :1]
    if seed % 6 == 3:
        logp[:, :, : n // 2] = -np.inf
    log_floor = -float(rng.choice([6, 9, 20]))
    log_explained = -float(rng.choice([0, 2, 5]))
    min_readings = int(rng.choice([0, 1, 20]))
    want_lp, want_good, want = _brute_select(logp, log_floor, log_explained, min_readings)
    got_lp = logp.copy()
    got_good, got = select_timescales(got_lp, log_floor, log_explained, min_readings)
    assert got == want
    np.testing.assert_array_equal(got_lp, want_lp)
    np.testing.assert_array_equal(got_good, want_good)
