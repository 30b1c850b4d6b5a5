"""Dynamic sample sets (Biber & Duckett §3.1–3.3, eq. 3–8)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dynmap_sim.agent.maps.sample_set import (
    SampleSets,
    _sort_by_ray,
    robust_estimates,
    to_mm,
)


def test_storage_is_two_bytes_per_sample():
    s = SampleSets(1440, 100, 0.05)
    assert s.samples_mm.dtype == np.uint16
    assert s.sample_bytes == 1440 * 100 * 2


def test_filling_phase_adds_u_n_then_replaces():
    rng = np.random.default_rng(0)
    s = SampleSets(3, 10, 0.3)
    s.update([0, 0, 1, 1], [1, 2, 3, 4], rng)  # first time step: initialized with all (§3.5)
    assert list(s.count) == [2, 2, 0]
    for step in range(1, 3):
        s.update(np.repeat([0, 1], 50), np.arange(100) + 1, rng)
        assert list(s.count) == [2 + 3 * step, 2 + 3 * step, 0]
    s.update(np.repeat([0, 1], 50), np.arange(100) + 1, rng)
    assert list(s.count) == [10, 10, 0]  # 8 + 2 added, 1 replaced
    for _ in range(5):
        s.update(np.repeat([0, 1], 50), np.arange(100) + 1, rng)
        assert list(s.count) == [10, 10, 0]


def test_update_replaces_exactly_u_n_samples():
    rng = np.random.default_rng(1)
    s = SampleSets(50, 20, 0.25)
    s.update(np.repeat(np.arange(50), 20), np.full(1000, 1000), rng, fill=True)
    assert np.all(s.count == 20)
    s.update(np.repeat(np.arange(50), 20), np.full(1000, 2000), rng)
    assert np.all(np.sum(s.samples_mm == 2000, axis=1) == 5)


def test_first_time_step_initializes_unless_only_seeded():
    rng = np.random.default_rng(4)
    s = SampleSets(2, 20, 0.05)
    s.update([0, 1], [500, 500], rng, fill=True, initialize=False)  # a seed (new local map)
    s.update(np.repeat([0, 1], 30), np.full(60, 900), rng)  # first time step: fill to 20
    assert list(s.count) == [20, 20]
    s.update(np.repeat([0, 1], 30), np.full(60, 700), rng)  # then the rule: u·n = 1
    assert list(np.sum(s.samples_mm == 700, axis=1)) == [1, 1]


def test_without_first_step_fill_the_set_grows_by_u_n_per_step():
    """§3.1: "until it is full an update just consists of adding u·n randomly chosen samples"
    (λ5 of Table 1: 5 per day, full after 20 days)."""
    rng = np.random.default_rng(5)
    s = SampleSets(2, 100, 0.05, first_step_fills=False)
    s.update([0, 1], [500, 500], rng, fill=True, initialize=False)  # a seed still goes in
    for day in range(1, 20):
        s.update(np.repeat([0, 1], 300), np.full(600, 900), rng)
        assert list(s.count) == [1 + 5 * day] * 2
    s.update(np.repeat([0, 1], 300), np.full(600, 700), rng)
    assert list(s.count) == [100, 100]  # 96 + 4 added, 1 replaced
    assert list(np.sum(s.samples_mm == 700, axis=1)) == [5, 5]
    assert s.copy().fills_first_step is False


def test_few_measurements_are_never_duplicated():
    rng = np.random.default_rng(2)
    s = SampleSets(1, 50, 0.8)
    s.update([0] * 50, np.full(50, 1000), rng, fill=True)
    s.update([0, 0, 0], [7, 8, 9], rng)  # u·n = 40 but only 3 measurements
    assert sorted(s.samples_mm[0][s.samples_mm[0] < 1000].tolist()) == [7, 8, 9]


def test_robust_estimates_closed_form():
    samples = np.array([[1000, 1010, 990, 1005, 5000, 0, 0]], dtype=np.uint16)
    est = robust_estimates(samples, np.array([5]))
    assert est.rho_m[0] == pytest.approx(1.005)  # sorted 990 1000 1005 1010 5000
    # |x - 1005| = 5 5 15 0 3995 -> sorted 0 5 5 15 3995 -> MAD 5 mm
    assert est.sigma_m[0] == pytest.approx(1.48 * 0.005)
    assert est.outlier_ratio[0] == pytest.approx(1 / 5)  # 3σ = 22.2 mm: only 5000 is out


def test_even_count_median_is_a_sample_not_a_mean():
    est = robust_estimates(np.array([[1000, 2000]], dtype=np.uint16), np.array([2]))
    assert est.rho_m[0] in (1.0, 2.0)


def test_empty_ray_gives_nan_and_uniform_likelihood():
    s = SampleSets(4, 5, 0.2)
    ll = s.log_likelihood([0, 1], [1.0, 3.0], max_range_m=5.0)
    assert np.allclose(ll, np.log(1 / 5.0))
    assert np.isnan(s.estimates().rho_m).all()


def test_perceptual_model_is_gaussian_plus_uniform():
    rng = np.random.default_rng(3)
    s = SampleSets(1, 100, 0.2)
    vals = to_mm(2.0 + 0.01 * rng.standard_normal(100))
    vals[:10] = 4000  # 10 % outliers
    s.update(np.zeros(100, int), vals, rng, fill=True)
    est = s.estimates()
    rho, sig, po = est.rho_m[0], est.sigma_m[0], est.outlier_ratio[0]
    assert po == pytest.approx(0.1, abs=0.03)
    d = np.array([rho, rho + sig, 0.5, 6.0])
    expect = (1 - po) * np.exp(-0.5 * ((d - rho) / sig) ** 2) / (sig * np.sqrt(2 * np.pi))
    expect += po * np.where(d <= 5.0, 1 / 5.0, 0.0)
    got = s.log_likelihood(np.zeros(4, int), d, max_range_m=5.0)
    assert np.allclose(np.exp(got[:3]), expect[:3])
    assert np.exp(got[3]) == pytest.approx(expect[3], abs=1e-300)


@settings(max_examples=25, deadline=None)
@given(
    n=st.integers(2, 30),
    count=st.integers(1, 30),
    seed=st.integers(0, 2**31),
)
def test_estimate_is_always_a_measured_value(n, count, seed):
    rng = np.random.default_rng(seed)
    s = SampleSets(8, n, 0.5)
    measured: list[set[int]] = [set() for _ in range(8)]
    for _ in range(4):
        ray = rng.integers(0, 8, size=count)
        val = rng.integers(100, 9000, size=count).astype(np.uint16)
        s.update(ray, val, rng)
        for r, v in zip(ray, val, strict=True):
            measured[r].add(int(v))
    est = s.estimates()
    for r in range(8):
        if s.count[r]:
            assert round(est.rho_m[r] * 1000) in measured[r]
            assert round(est.rho_m[r] * 1000) in s.samples_mm[r, : s.count[r]].tolist()
        else:
            assert np.isnan(est.rho_m[r])


@settings(max_examples=12, deadline=None)
@given(
    n=st.sampled_from([5, 10, 20, 40]),
    u=st.sampled_from([0.05, 0.1, 0.2, 0.25, 0.5, 0.75, 0.8, 0.33]),
    seed=st.integers(0, 2**31),
)
def test_age_distribution_follows_u_one_minus_u_power_t(n, u, seed):
    """§3.2, eq. 3: the share of samples of age t is u(1 − u)^t (truncated at the start)."""
    rng = np.random.default_rng(seed)
    n_rays = 8000 // n
    steps = int(np.ceil(np.log(1e-3) / np.log(1 - u)))
    s = SampleSets(n_rays, n, u)
    rays = np.repeat(np.arange(n_rays), n)
    s.update(rays, np.zeros(rays.size, np.uint16), rng, fill=True)  # value = birth step
    for t in range(1, steps + 1):
        s.update(rays, np.full(rays.size, t, np.uint16), rng)
    ages = steps - s.samples_mm.astype(int).ravel()
    hist = np.bincount(ages, minlength=steps + 1) / ages.size
    t = np.arange(steps + 1)
    expect = u * (1 - u) ** t
    expect[-1] = (1 - u) ** steps  # the initial samples, all of age `steps`
    assert expect.sum() == pytest.approx(1.0)
    ks = np.max(np.abs(np.cumsum(hist) - np.cumsum(expect)))  # Kolmogorov-Smirnov distance
    assert ks < 0.04, (ks, hist[:5], expect[:5])
    mean_age = np.sum(t * expect)
    assert ages.mean() == pytest.approx(mean_age, rel=0.1, abs=0.1)


@pytest.mark.parametrize("sigma_min", [0.001, 0.01, 0.05])
@pytest.mark.parametrize("min_outlier", [0.0, 0.01, 0.2])
def test_model_table_holds_the_mixture_constants(sigma_min, min_outlier):
    """Each row of the model table is eq. 6–8's constants: ``ρ``, ``1/(2σ²)``,
    ``log((1 − p_o)/(σ√(2π)))``, ``p_o/maxRange`` with the floored ``σ`` and ``p_o``; an empty
    ray the uniform density (``p_o = 1``)."""
    rng = np.random.default_rng(int(sigma_min * 1000) + int(min_outlier * 100))
    s = SampleSets(50, 10, 0.5)
    for _ in range(3):
        ray = rng.integers(0, 40, 300)  # rays 40..49 stay empty
        s.update(ray, rng.integers(100, 6000, 300), rng)
    tab = s.model_table(5.6, sigma_min, min_outlier)
    est = s.estimates()
    has = est.count > 0
    sig = np.maximum(est.sigma_m[has], max(sigma_min, 1e-6))
    po = np.maximum(est.outlier_ratio[has], min_outlier)
    np.testing.assert_array_equal(tab[has, 0], est.rho_m[has])
    np.testing.assert_allclose(tab[has, 1], 0.5 / sig**2, rtol=1e-12)
    with np.errstate(divide="ignore"):
        np.testing.assert_allclose(tab[has, 2], np.log((1 - po) / (sig * np.sqrt(2 * np.pi))),
                                   rtol=1e-12)  # fmt: skip
    np.testing.assert_allclose(tab[has, 3], po / 5.6, rtol=1e-12)
    np.testing.assert_array_equal(tab[~has, 2], -np.inf)
    np.testing.assert_allclose(tab[~has, 3], 1 / 5.6, rtol=1e-12)
    assert s.model_table(5.6, sigma_min, min_outlier) is tab  # cached until the next update
    s.update([0], [1000], rng)
    assert s.model_table(5.6, sigma_min, min_outlier) is not tab


def _brute_estimates(samples: list[int]) -> tuple[float, float, float]:
    """Eq. 4–5 and the 3σ share by their definitions: the lower middle sample, 1.48 x the
    median absolute deviation (numpy's median), the share beyond 3σ."""
    srt = sorted(samples)
    rho = srt[(len(srt) - 1) // 2]
    dev = [abs(v - rho) for v in samples]
    sig = 1.48 * float(np.median(dev))
    return rho / 1000.0, sig / 1000.0, sum(d > 3.0 * sig for d in dev) / len(dev)


@pytest.mark.parametrize("n_samples", [1, 2, 5, 10, 17, 50, 100])
def test_robust_estimates_are_the_definitions(n_samples):
    """Short rows (insertion sort) and long ones (numpy's sort in the kernel) alike; many
    equal samples and deviations; empty rows NaN."""
    rng = np.random.default_rng(n_samples)
    for trial in range(6):
        s = rng.integers(0, 65535 if trial % 2 else 3000, (60, n_samples)).astype(np.uint16)
        if trial % 3 == 0:
            s[:] = rng.integers(1000, 1004, s.shape)
        c = rng.integers(0, n_samples + 1, 60).astype(np.uint16)
        est = robust_estimates(s, c)
        for r in range(60):
            if c[r] == 0:
                assert np.isnan(est.rho_m[r]) and np.isnan(est.sigma_m[r])
                assert est.outlier_ratio[r] == 0.0
                continue
            rho, sig, po = _brute_estimates([int(v) for v in s[r, : c[r]]])
            assert est.rho_m[r] == rho
            assert est.sigma_m[r] == pytest.approx(sig, rel=1e-12, abs=1e-15)
            assert est.outlier_ratio[r] == po


@pytest.mark.parametrize("seed", range(20))
def test_an_update_keeps_old_samples_or_takes_measurements_of_the_same_ray(seed):
    """One §3.1 step, whatever the options: every sample is an old sample of its ray or one
    of the ray's measurements, each used at most once; rays without measurements are
    unchanged; a fill removes nothing; the same generator gives the same samples."""
    cfg = np.random.default_rng(1000 + seed)
    n_rays = int(cfg.integers(1, 40))
    n_samples = int(cfg.choice([1, 5, 10, 17, 50]))
    u = float(cfg.choice([0.05, 0.2, 0.25, 0.8, 1.0, 0.33]))
    fills = bool(cfg.integers(2))
    s = SampleSets(n_rays, n_samples, u, fills)
    twin = SampleSets(n_rays, n_samples, u, fills)
    rng, rng_twin = np.random.default_rng(seed), np.random.default_rng(seed)
    for _ in range(int(cfg.integers(1, 12))):
        m = int(cfg.integers(0, 30 * n_rays))
        ray = cfg.integers(0, n_rays, m)
        val = cfg.integers(1, 6000, m).astype(np.uint16)
        fill = bool(cfg.random() < 0.2)
        init = bool(cfg.random() < 0.7)
        old = [sorted(s.samples_mm[r, : s.count[r]].tolist()) for r in range(n_rays)]
        s.update(ray, val, rng, fill=fill, initialize=init)
        twin.update(ray, val, rng_twin, fill=fill, initialize=init)
        for r in range(n_rays):
            new = s.samples_mm[r, : s.count[r]].tolist()
            pool = old[r] + val[ray == r].tolist()
            for v in new:
                assert v in pool
                pool.remove(v)
            if not (ray == r).any():
                assert sorted(new) == old[r]
            elif fill:
                assert len(new) >= len(old[r])
                assert all(v in new for v in old[r])
        np.testing.assert_array_equal(s.samples_mm, twin.samples_mm)
        np.testing.assert_array_equal(s.count, twin.count)
    assert rng.random() == rng_twin.random()


@pytest.mark.parametrize("seed", range(12))
def test_sort_by_ray_orders_the_measurements_by_their_keys(seed):
    """The update's bucket sort: the measurements in the order of their keys ``ray + U[0,
    1)`` (Python's ``sorted``), short and long buckets, with the starts of the rays' runs."""
    rng = np.random.default_rng(seed)
    n_rays = int(rng.choice([1, 7, 360]))
    m = int(rng.integers(1, 400)) * (1 if seed % 3 else 20)  # long buckets: argsort
    ray = rng.integers(0, n_rays, m)
    val = rng.integers(0, 65536, m).astype(np.uint16)
    keys = ray + rng.random(m)
    r_s = np.empty(m, dtype=np.int64)
    v_s = np.empty(m, dtype=np.uint16)
    first = np.empty(m, dtype=np.int64)
    n_runs = _sort_by_ray(ray, keys, val, n_rays, r_s, v_s, first)
    order = sorted(range(m), key=lambda i: keys[i])
    assert r_s.tolist() == ray[order].tolist()
    assert v_s.tolist() == val[order].tolist()
    starts = [i for i in range(m) if i == 0 or r_s[i] != r_s[i - 1]]
    assert first[:n_runs].tolist() == starts


@pytest.mark.parametrize("bad", [-1, 7])
def test_update_refuses_a_ray_out_of_range(bad):
    s = SampleSets(7, 5, 0.2)
    with pytest.raises(ValueError, match="out of range"):
        s.update([0, bad, 3], [1000, 1000, 1000], np.random.default_rng(0))
    assert s.version == 0 and not s.count.any()
