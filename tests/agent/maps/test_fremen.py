"""FreMEn (Krajník et al. T-RO 2017) on synthetic periodic signals with known spectra."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim.agent.maps.fremen import DAY_S, WEEK_S, Fremen, default_periods


def _weekly_batches(f: Fremen, t, cells, s) -> None:
    """Feed the model a week at a time, so each week is scored before it is learned."""
    for w in range(int(np.ceil(t.max() / WEEK_S)) + 1):
        m = (t >= w * WEEK_S) & (t < (w + 1) * WEEK_S)
        f.update(t[m], cells[m], s[m])


def test_default_periods_are_a_week_and_its_harmonics():
    p = default_periods()
    assert p[0] == WEEK_S and p[6] == DAY_S and p[13] == DAY_S / 2
    assert p[-1] == pytest.approx(3 * 3600.0)


def test_bernoulli_daily_signal_recovers_period_amplitude_phase():
    """p(t) = 0.4 + 0.3 cos(2π t / day + 0.7), one Bernoulli sample every 10 min for 4 weeks:
    the strongest component is the day, with amplitude 0.3 (sd ≈ sqrt(2·0.24/n) ≈ 0.011)."""
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 4 * WEEK_S, 600.0)
    p = 0.4 + 0.3 * np.cos(2 * np.pi * t / DAY_S + 0.7)
    s = (rng.random(t.size) < p).astype(float)
    f = Fremen(1, max_order=4)
    _weekly_batches(f, t, np.zeros(t.size, np.int64), s)
    alpha = f.spectrum()[0]
    best = np.argmax(np.abs(alpha))
    assert f.periods_s[best] == DAY_S
    assert 2 * np.abs(alpha[best]) == pytest.approx(0.3, abs=0.045)
    assert np.angle(alpha[best]) == pytest.approx(0.7, abs=0.15)
    assert f.mean()[0] == pytest.approx(0.4, abs=0.03)
    assert f.order[0] >= 1
    # the model beats the static mean on a fresh week of the same process
    t2 = np.arange(4 * WEEK_S, 5 * WEEK_S, 600.0)
    p2 = 0.4 + 0.3 * np.cos(2 * np.pi * t2 / DAY_S + 0.7)
    mse_model = np.mean((f.predict(t2)[:, 0] - p2) ** 2)
    assert mse_model < 0.1 * np.mean((f.mean()[0] - p2) ** 2)


@pytest.mark.parametrize("duty", [0.5, 10 / 24, 0.25])
def test_square_wave_harmonics_match_fourier_series(duty):
    """A door open a share ``duty`` of each day, sampled every minute for 2 weeks: the
    component of period day/k has amplitude (2 / (kπ)) |sin(kπ·duty)| (Fourier series)."""
    t = np.arange(0.0, 2 * WEEK_S, 60.0)
    s = ((t % DAY_S) < duty * DAY_S).astype(float)
    f = Fremen(1)
    f.update(t, np.zeros(t.size, np.int64), s)
    amp = 2 * np.abs(f.spectrum()[0])
    for k in (1, 2, 3):
        i = int(np.flatnonzero(f.periods_s == DAY_S / k)[0])
        assert amp[i] == pytest.approx(2 / (k * np.pi) * abs(np.sin(k * np.pi * duty)), abs=2e-3)
    assert f.mean()[0] == pytest.approx(duty, abs=1e-3)


def test_incremental_sums_equal_direct_transform():
    """α_k after many irregular batches equals (1/n) Σ (s − mean) e^{−iω t} computed at once."""
    rng = np.random.default_rng(3)
    n_cells = 5
    t = np.sort(rng.uniform(0, 3 * WEEK_S, 3000))
    c = rng.integers(0, n_cells, t.size)
    s = rng.random(t.size)
    f = Fremen(n_cells, periods_s=[WEEK_S, DAY_S, 5000.0], max_order=3)
    for chunk in np.array_split(np.arange(t.size), 17):
        f.update(t[chunk], c[chunk], s[chunk], score=False)
    for k in range(n_cells):
        m = c == k
        mu = s[m].mean()
        direct = np.mean((s[m] - mu)[:, None] * np.exp(-1j * f.omegas[None] * t[m, None]), axis=0)
        np.testing.assert_allclose(f.spectrum([k])[0], direct, atol=1e-9)
        assert f.mean([k])[0] == pytest.approx(mu)


def test_many_cells_at_once_match_one_at_a_time():
    """Vectorised over cells: cells sharing scan times, each with its own phase."""
    rng = np.random.default_rng(11)
    n_cells = 40
    times = np.arange(0.0, 2 * WEEK_S, 1800.0)
    phase = rng.uniform(-np.pi, np.pi, n_cells)
    p = 0.5 + 0.4 * np.cos(2 * np.pi * times[:, None] / DAY_S + phase[None])
    s = (rng.random(p.shape) < p).astype(float)
    t_all = np.repeat(times, n_cells)
    c_all = np.tile(np.arange(n_cells), times.size)
    together = Fremen(n_cells, max_order=3)
    _weekly_batches(together, t_all, c_all, s.ravel())
    for k in (0, 17, 39):
        alone = Fremen(1, max_order=3)
        _weekly_batches(alone, times, np.zeros(times.size, np.int64), s[:, k])
        np.testing.assert_allclose(together.spectrum([k]), alone.spectrum(), atol=1e-12)
        np.testing.assert_allclose(together.sse[k], alone.sse[0], atol=1e-9)
        q = np.array([3 * WEEK_S + 123.0, 3 * WEEK_S + 40000.0])
        np.testing.assert_allclose(together.predict(q, [k]), alone.predict(q), atol=1e-12)
    best = np.argmax(np.abs(together.spectrum()), axis=1)
    assert np.all(together.periods_s[best] == DAY_S)
    np.testing.assert_allclose(np.angle(together.spectrum()[:, 6]), phase, atol=0.35)


def test_order_chosen_by_prediction_error():
    """Constant-probability cells keep the static mean (order 0, nearly all of them);
    a daily square wave needs components."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 4 * WEEK_S, 900.0)
    n_static = 20
    s_static = (rng.random((t.size, n_static)) < 0.3).astype(float)
    s_door = ((t % DAY_S) < 0.4 * DAY_S).astype(float)[:, None]
    s = np.concatenate([s_static, s_door], axis=1)
    f = Fremen(n_static + 1, max_order=5)
    _weekly_batches(
        f, np.repeat(t, n_static + 1), np.tile(np.arange(n_static + 1), t.size), s.ravel()
    )
    assert np.mean(f.order[:n_static] == 0) >= 0.9
    assert f.order[-1] >= 3


def test_predictions_are_probabilities_and_shapes():
    f = Fremen(3, periods_s=[DAY_S], max_order=1, default_order=1)
    t = np.arange(0.0, DAY_S, 60.0)
    f.update(t, np.zeros(t.size, np.int64), ((t % DAY_S) < DAY_S / 2).astype(float))
    p = f.predict(np.arange(0.0, DAY_S, 100.0))
    assert p.shape == (864, 3) and p.min() >= 0.0 and p.max() <= 1.0
    assert f.predict(10.0).shape == (3,)
    assert f.predict(10.0)[1] == 0.5  # never observed: the prior


@pytest.mark.parametrize(
    ("kwargs", "error"),
    [
        ({"periods_s": [0.0]}, ValueError),
        ({"periods_s": []}, ValueError),
        ({"periods_s": [DAY_S], "max_order": 2}, ValueError),
        ({"default_order": 6}, ValueError),
        ({"prior_p": 1.5}, ValueError),
    ],
)
def test_bad_parameters(kwargs, error):
    with pytest.raises(error):
        Fremen(2, **kwargs)


def test_bad_observations():
    f = Fremen(2)
    with pytest.raises(IndexError):
        f.update([0.0], [2], [1.0])
    with pytest.raises(ValueError):
        f.update([0.0, 1.0], [0], [1.0])


def test_added_cells_start_unobserved_and_leave_the_others_unchanged():
    f = Fremen(2, periods_s=[DAY_S, 3600.0], max_order=2)
    f.update([0.0, 0.0, 900.0], [0, 1, 0], [1.0, 0.0, 1.0])
    before = f.spectrum()
    assert f.add_cells(3) == 2 and f.n_cells == 5
    np.testing.assert_array_equal(f.spectrum([0, 1]), before)
    assert np.all(f.mean([2, 3, 4]) == 0.5) and np.all(f.order[2:] == f.default_order)
    f.update([1800.0], [4], [1.0])
    assert f.mean([4])[0] == 1.0


def test_scored_errors_are_the_predictions_errors_at_each_order():
    """The order selection's summed errors equal those of :meth:`Fremen.predict` at each
    order on the batch, computed before the batch is learned."""
    rng = np.random.default_rng(9)
    f = Fremen(3, periods_s=default_periods(WEEK_S, 14), max_order=3)
    t0 = np.sort(rng.uniform(0, WEEK_S, 500))
    f.update(t0, rng.integers(0, 2, t0.size), rng.random(t0.size) < 0.6)
    t1 = np.sort(rng.uniform(WEEK_S, 2 * WEEK_S, 400))
    c1 = rng.integers(0, 3, t1.size)  # cell 2 is new: not scored
    s1 = (rng.random(t1.size) < 0.5).astype(float)
    expected = np.zeros((3, 4))
    for k in range(2):
        m = c1 == k
        for order in range(4):
            p = f.predict(t1[m], [k], order=order)[:, 0]
            expected[k, order] = np.sum((p - s1[m]) ** 2)
    before = f.sse.copy()
    f.update(t1, c1, s1)
    np.testing.assert_allclose(f.sse - before, expected, rtol=1e-9, atol=1e-9)
    assert f.n_scored[2] == 0 and f.n_scored[:2].sum() == np.sum(c1 < 2)
