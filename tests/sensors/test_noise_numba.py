"""The compiled noise model of the numba lidar backend gives numpy's readings bit for bit,
with the same draws (the generator ends in the same state)."""

import numpy as np
import pytest

from dynmap_sim.sensors.lidar import NOISELESS, make_lidar
from dynmap_sim.sensors.noise_numba import noise_scan, numba_available

CASES = [
    ("urg-04lx", {}),
    ("lms200", {}),
    ("lms200", {"mode": "cm", "beams": 181}),
    ("urg-04lx", {"noise": {"p_invalid": 0.02, "p_short": 0.05, "p_dropout": 0.05}}),
    ("urg-04lx", {"noise": {"p_mixed": 0.0}}),
    ("urg-04lx", {"noise": {"p_mixed": 1.0, "mixed_jump_m": 0.0}}),
    ("urg-04lx", {"noise": {"sigma_rel": 0.0}}),
    ("urg-04lx", {"noise": NOISELESS}),
]


def _ranges(rng: np.random.Generator, n: int, r_max: float, trial: int) -> np.ndarray:
    """True ranges with no-hit beams, runs of equal ranges and out-of-range values."""
    r = rng.uniform(0.0, 1.2 * r_max, n)
    r[rng.random(n) < 0.2] = np.inf
    if trial % 2:  # steps between runs of ten equal ranges (few edges)
        r = np.repeat(r[: n // 10 + 1], 10)[:n].copy()
    return r


@pytest.mark.parametrize("python", [True, False])
@pytest.mark.parametrize(("sensor", "options"), CASES)
def test_compiled_noise_equals_numpy_bit_for_bit(python, sensor, options):
    if not python and not numba_available():
        pytest.skip("numba (extra 'fast') not installed")
    lidar = make_lidar(sensor, **options)
    spec = lidar.spec
    rng = np.random.default_rng(5)
    for trial in range(40):
        r = _ranges(rng, spec.n_beams, spec.range_max_m, trial)
        seed = int(rng.integers(1 << 30))
        ref_rng = np.random.default_rng(seed)
        ref = lidar.apply_noise(r[None, :], ref_rng)[0]  # a batch: always the numpy model
        got_rng = np.random.default_rng(seed)
        got = noise_scan(
            r, got_rng, lidar._bias_m, lidar.noise, spec.range_min_m, spec.range_max_m, python
        )
        assert got.dtype == np.float32
        assert got.tobytes() == ref.tobytes(), trial
        assert got_rng.bit_generator.state == ref_rng.bit_generator.state


@pytest.mark.skipif(not numba_available(), reason="numba (extra 'fast') not installed")
def test_numba_lidar_noise_equals_numpy_lidar_noise():
    """The two backends' lidars noise the same true ranges into the same readings."""
    fast, ref = make_lidar("urg-04lx", backend="numba"), make_lidar("urg-04lx")
    rng = np.random.default_rng(0)
    for trial in range(20):
        r = _ranges(rng, 683, 5.6, trial)
        a = fast.apply_noise(r, np.random.default_rng(trial))
        b = ref.apply_noise(r, np.random.default_rng(trial))
        assert a.tobytes() == b.tobytes()
