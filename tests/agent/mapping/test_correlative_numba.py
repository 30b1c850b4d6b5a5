"""The compiled branch and bound of the correlative matcher gives the numpy result bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim.agent.mapping.correlative_matcher import LikelihoodTable, correlative_match
from tests.agent.maps.test_sample_set import UPDATE_KERNELS as BACKENDS  # python, numba


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("seed", range(12))
def test_kernels_give_the_numpy_match(backend: str, seed: int) -> None:
    """Pose, score and count of evaluated translations as numpy's: blocks of 1-9 cells,
    windows that the blocks overrun, points that fall off the table (clipped lookups),
    few and many points, searches cut off by ``max_blocks``."""
    rng = np.random.default_rng(seed)
    res = float(rng.choice([0.05, 0.1]))
    target = rng.uniform(-2.5, 2.5, (int(rng.integers(5, 200)), 2))
    table = LikelihoodTable(target, res, float(rng.choice([0.05, 0.1])), margin_m=0.5)
    n = int(rng.integers(1, 150))
    pts = target[rng.integers(0, len(target), n)] + rng.normal(0, 0.05, (n, 2))
    pts[: n // 10] = rng.uniform(-6, 6, (n // 10, 2))  # off the table
    init = np.array([*rng.normal(0, 0.3, 2), rng.normal(0, 0.2)])
    kw = dict(
        window_xy_m=float(rng.uniform(0.0, 0.8)),
        window_theta_rad=float(rng.uniform(0.0, 0.3)),
        block=int(rng.integers(1, 10)),
        max_blocks=int(rng.choice([3, 400, 10**6])),
    )
    a = correlative_match(pts, table, init, backend="numpy", **kw)
    b = correlative_match(pts, table, init, backend=backend, **kw)
    assert a.pose.tobytes() == b.pose.tobytes()
    assert a.score == b.score and a.n_evaluated == b.n_evaluated
