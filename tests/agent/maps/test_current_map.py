"""The compiled greedy timescale selection of the current-map synthesis (§4.3, steps 2-5)."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim.agent.maps.current_map import SynthesisParams, _select_numpy
from dynmap_sim.agent.maps.current_map_numba import _pairwise_sum_py, select_timescales
from tests.agent.maps.test_sample_set import UPDATE_KERNELS as BACKENDS  # python, numba


@pytest.mark.parametrize("n", [*range(0, 40), 127, 128, 129, 240, 255, 256, 257, 700, 2049])
def test_pairwise_sum_is_numpys_sum(n):
    """The kernel's sum of a contiguous run is numpy's ``sum`` bit for bit (pairwise
    blocks, eight accumulators, from 0)."""
    rng = np.random.default_rng(n)
    a = rng.normal(size=n) * 10.0 ** rng.integers(-6, 7, n)
    assert _pairwise_sum_py(a, n) == a.sum()
    assert _pairwise_sum_py(-np.zeros(n), n) == (-np.zeros(n)).sum()


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", range(40))
def test_select_kernel_gives_the_numpy_selections(backend, seed):
    """select_timescales floors, marks and selects as the numpy loop does: the same
    selections in the same order, the same floored values and explained readings (ties
    between models, NaN, all readings explained, no maps to select from)."""
    rng = np.random.default_rng(seed)
    n_maps, n_levels = int(rng.integers(1, 9)), int(rng.integers(1, 6))
    n = int(rng.choice([0, 5, 19, 20, 21, 80, 240, 300]))
    logp = rng.normal(-1.0, 3.0, (n_maps, n_levels, n))
    if seed % 5 == 1:  # equal models: the first maximum wins
        logp[:] = logp[:1, :1]
    if seed % 7 == 2:  # a NaN reading
        logp[rng.integers(n_maps), rng.integers(n_levels), : max(n, 1) // 3] = np.nan
    if seed % 6 == 3:
        logp[:, :, : n // 2] = -np.inf
    prm = SynthesisParams(
        min_readings=int(rng.choice([0, 1, 20])),
        explained_density=float(rng.choice([0.05, 0.5, 2.0])),
        density_floor=float(rng.choice([1e-3, 1e-9])),
    )
    log_floor = np.log(prm.density_floor)
    want_logp = logp.copy()
    want_good, want = _select_numpy(want_logp, log_floor, prm)
    got_logp = logp.copy()
    got_good, got = select_timescales(
        got_logp, log_floor, np.log(prm.explained_density), prm.min_readings,
        python=backend == "python",
    )  # fmt: skip
    assert got == want
    assert got_logp.tobytes() == want_logp.tobytes()
    assert np.array_equal(got_good, want_good)
