"""Independent Markov chain grid (Saarinen et al. IROS 2012) on simulated chains of known rates."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from dynmap_sim.agent.maps.markov_grid import MarkovGrid


def _simulate_chain(rng, lam_in, lam_out, duration_s, step_s, x0=0):
    """States of a continuous-time two-state chain (exponential holding times drawn in
    numpy) sampled every ``step_s``; also the true number of changes."""
    changes = [0.0]
    x = x0
    while changes[-1] < duration_s:
        changes.append(changes[-1] + rng.exponential(1.0 / (lam_in if x == 0 else lam_out)))
        x = 1 - x
    t = np.arange(0.0, duration_s, step_s)
    n_changes = np.searchsorted(np.array(changes[1:]), t, side="right")
    return t, ((x0 + n_changes) % 2).astype(float)


@pytest.mark.parametrize(
    ("lam_in", "lam_out"), [(1 / 3600, 1 / 600), (1 / 7200, 1 / 7200), (1 / 900, 1 / 5400)]
)
def test_learned_rates_match_the_simulated_chain(lam_in, lam_out):
    """Sampled 30x faster than the fastest rate, over ~1000 changes: the events-per-exposure
    estimate is within 4 sd (sd = λ / sqrt(events)) plus the sampling bias (< 3 %)."""
    rng = np.random.default_rng(2)
    duration = 1000.0 / (lam_in * lam_out / (lam_in + lam_out)) / 2
    step = 1.0 / (30 * max(lam_in, lam_out))
    t, s = _simulate_chain(rng, lam_in, lam_out, duration, step)
    g = MarkovGrid(1)
    g.update(t, np.zeros(t.size, np.int64), s)
    est_in, est_out = g.rates()
    for est, lam, n in ((est_in, lam_in, g.n_in[0]), (est_out, lam_out, g.n_out[0])):
        assert n > 500
        assert abs(est[0] - lam) < 4 * lam / np.sqrt(n) + 0.03 * lam
    assert g.stationary()[0] == pytest.approx(lam_in / (lam_in + lam_out), abs=0.03)


@pytest.mark.parametrize("dt", [0.0, 60.0, 1800.0, 86400.0])
@pytest.mark.parametrize("state", [0.0, 1.0])
def test_prediction_is_the_chain_transition_matrix(dt, state):
    """The closed form equals the matrix exponential of the chain's generator."""
    g = MarkovGrid(1)
    g.update([0.0, 100.0, 500.0, 900.0], [0, 0, 0, 0], [0.0, 1.0, 0.0, state])
    lam_in, lam_out = (float(r[0]) for r in g.rates())
    q = np.array([[-lam_in, lam_in], [lam_out, -lam_out]])
    expected = expm(q * dt)[int(state), 1]
    assert g.predict(900.0 + dt)[0] == pytest.approx(expected, abs=1e-12)


def test_many_cells_interleaved_match_one_at_a_time():
    rng = np.random.default_rng(4)
    rates = [(1 / 1000, 1 / 300), (1 / 5000, 1 / 2000), (1 / 400, 1 / 400)]
    sims = [_simulate_chain(rng, a, b, 2e5, 30.0) for a, b in rates]
    t = np.concatenate([x[0] for x in sims])
    c = np.concatenate([np.full(x[0].size, k) for k, x in enumerate(sims)])
    s = np.concatenate([x[1] for x in sims])
    order = np.argsort(t, kind="stable")
    together = MarkovGrid(3)
    together.update(t[order], c[order], s[order])
    for k, (tk, sk) in enumerate(sims):
        alone = MarkovGrid(1)
        alone.update(tk, np.zeros(tk.size, np.int64), sk)
        np.testing.assert_allclose(np.ravel(together.rates([k])), np.ravel(alone.rates()))
        np.testing.assert_allclose(together.predict(3e5, [k]), alone.predict(3e5))


def test_prior_gap_and_unobserved_cells():
    g = MarkovGrid(2, max_gap_s=100.0)
    g.update([0.0, 50.0, 1000.0], [0, 0, 0], [0.0, 1.0, 0.0])
    assert g.n_in[0] == 1 and g.n_out[0] == 0  # the 950 s interval is longer than max_gap_s
    assert g.exposure_free_s[0] == 50.0 and g.exposure_occ_s[0] == 0.0
    p = g.predict(np.array([1000.0, 2000.0]))
    assert p.shape == (2, 2) and np.all(p[:, 1] == 0.5)
    assert p[0, 0] == 0.0 and 0.0 < p[1, 0] < g.stationary([0])[0]
    lam_in, lam_out = MarkovGrid(1).rates()
    assert lam_in[0] == lam_out[0] == pytest.approx(1 / (7 * 86400.0))


def test_bad_input():
    g = MarkovGrid(2)
    g.update([10.0], [0], [1.0])
    with pytest.raises(ValueError, match="time order"):
        g.update([5.0], [0], [0.0])
    with pytest.raises(IndexError):
        g.update([20.0], [5], [0.0])
    with pytest.raises(ValueError):
        MarkovGrid(1, prior_weight_s=0.0)
    with pytest.raises(ValueError):
        MarkovGrid(1, prior_p=-0.1)


def test_out_of_order_batch_learns_nothing():
    g = MarkovGrid(1)
    with pytest.raises(ValueError, match="time order"):
        g.update([0.0, 10.0, 5.0], [0, 0, 0], [0.0, 1.0, 0.0])
    assert np.all(g.counts == 0) and np.isnan(g.last_t_s[0])
