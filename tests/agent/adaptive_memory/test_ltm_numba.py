"""The long-term map's kernels (:mod:`.ltm_numba`) give the numpy code's numbers exactly:
§4.4's test and eq. 15's update, on random grids, points and covariances."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim.agent.localization.adaptive_memory import ltm_numba
from dynmap_sim.agent.localization.adaptive_memory.ltm_map import (
    LTMMap,
    LTMParams,
    point_covariances,
)

needs_numba = pytest.mark.skipif(
    not ltm_numba.numba_available(), reason="numba (extra 'fast') not installed"
)
KERNELS = ["python", pytest.param("numba", marks=needs_numba)]


def random_map(rng: np.random.Generator, h: int, w: int, res_m: float = 0.05) -> LTMMap:
    """A grid of log-odds around ``l_occupied`` (many exactly at the clamps), a few pinned."""
    lo = rng.choice([-2.0, 0.0, 1.4, 2.5, 3.5], size=(h, w)).astype(np.float32)
    lo += (rng.random((h, w)) < 0.3) * rng.normal(0, 0.5, (h, w)).astype(np.float32)
    pinned = rng.random((h, w)) < 0.05
    lo[pinned] = 3.5
    origin = rng.uniform(-2, 2, 2)
    return LTMMap(lo, origin, res_m, pinned, rng.random((h, w)) < 0.5)


def random_points(rng: np.random.Generator, m: LTMMap, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Points over the grid and up to half a metre beyond it, with random covariances."""
    h, w = m.shape
    lo_xy = m.origin - 0.5
    hi_xy = m.origin + np.array([w, h]) * m.resolution + 0.5
    pts = rng.uniform(lo_xy, hi_xy, (n, 2))
    a = rng.normal(0, rng.choice([0.005, 0.02, 0.08]), (n, 2, 2))
    return pts, a @ a.transpose(0, 2, 1)


def random_params(rng: np.random.Generator) -> LTMParams:
    return LTMParams(
        free_space=bool(rng.random() < 0.8),
        l_free=float(rng.choice([-0.4, -0.3])),
        l_occupied=float(rng.choice([2.5, 1.4, 0.7])),  # 1.4, 0.7: not float32 numbers
        l_min=float(rng.choice([-2.0, -0.7, 0.0])),
        stencil_cells=int(rng.integers(1, 4)),
        semistatic_sigma=float(rng.uniform(1, 3)),
        semistatic_max_cells=int(rng.integers(1, 6)),
    )


@pytest.mark.parametrize("kernel", KERNELS)
def test_explained_of_the_kernel_equals_numpy(kernel: str) -> None:
    rng = np.random.default_rng(11)
    for _ in range(60 if kernel == "python" else 300):
        m = random_map(rng, *(int(v) for v in rng.integers(3, 40, 2)))
        p = random_params(rng)
        pts, covs = random_points(rng, m, int(rng.integers(1, 80)))
        ref = m.explained(pts, covs, p, backend="numpy")
        np.testing.assert_array_equal(m.explained(pts, covs, p, backend=kernel), ref)


@pytest.mark.parametrize("kernel", KERNELS)
def test_update_of_the_kernel_equals_numpy_bit_for_bit(kernel: str) -> None:
    rng = np.random.default_rng(12)
    for _ in range(40 if kernel == "python" else 200):
        ref = random_map(rng, *(int(v) for v in rng.integers(3, 60, 2)))
        p = random_params(rng)
        # within the clamps, the pinned cells at l_max, as every map starts (update's contract)
        np.clip(ref.logodds, p.l_min, p.l_max, out=ref.logodds)
        ref.logodds[ref.pinned] = p.l_max
        fast = ref.copy()
        for _ in range(int(rng.integers(1, 6))):
            pts, covs = random_points(rng, ref, int(rng.integers(1, 40)))
            h, w = ref.shape
            laser = ref.origin + rng.uniform(-0.3, 1.1, 2) * np.array([w, h]) * ref.resolution
            occ = None if rng.random() < 0.5 else rng.random(len(pts)) < 0.6
            ref.update(laser, pts, covs, p, occ, backend="numpy")
            fast.update(laser, pts, covs, p, occ, backend=kernel)
            assert fast.logodds.tobytes() == ref.logodds.tobytes()


@pytest.mark.parametrize("kernel", ["numpy", *KERNELS])
def test_update_clamps_as_a_clamp_of_the_whole_grid(kernel: str) -> None:
    """The update clamps and re-pins only the cells it can change: on a map within
    ``[l_min, l_max]`` with its pinned cells at ``l_max`` (as every map starts), clamping
    and re-pinning the whole grid afterwards changes nothing."""
    rng = np.random.default_rng(13)
    for _ in range(10 if kernel == "python" else 60):
        m = random_map(rng, *(int(v) for v in rng.integers(3, 60, 2)))
        p = random_params(rng)
        np.clip(m.logodds, p.l_min, p.l_max, out=m.logodds)
        m.logodds[m.pinned] = p.l_max
        h, w = m.shape
        for _ in range(int(rng.integers(1, 6))):
            pts, covs = random_points(rng, m, int(rng.integers(1, 40)))
            laser = m.origin + rng.uniform(-0.3, 1.1, 2) * np.array([w, h]) * m.resolution
            m.update(laser, pts, covs, p, backend=kernel)
            whole = np.clip(m.logodds, p.l_min, p.l_max)
            whole[m.pinned] = p.l_max
            assert whole.tobytes() == m.logodds.tobytes()


@pytest.mark.parametrize("kernel", KERNELS)
def test_point_covariances_of_the_kernel_equal_numpy_bit_for_bit(kernel: str) -> None:
    rng = np.random.default_rng(14)
    for _ in range(50):
        n = int(rng.integers(0, 300))
        pose = np.array([*rng.uniform(-5, 5, 2), rng.uniform(-np.pi, np.pi)])
        a = rng.normal(0, rng.choice([1e-3, 0.05]), (3, 3))
        mount = np.array([*rng.uniform(-0.2, 0.2, 2), rng.uniform(-0.1, 0.1)])
        ranges, angles = rng.uniform(0.02, 6.0, n), rng.uniform(-2.1, 2.1, n)
        sig_r = np.maximum(0.01, 0.01 * ranges)
        args = (pose, a @ a.T, mount, ranges, angles, 0.0018, sig_r)
        ref = point_covariances(*args, backend="numpy")
        out = point_covariances(*args, backend=kernel)
        for r, o in zip(ref, out, strict=True):
            assert r.shape == o.shape and r.tobytes() == o.tobytes()


def test_an_unknown_backend_is_refused() -> None:
    m = random_map(np.random.default_rng(0), 5, 5)
    with pytest.raises(ValueError, match="backend must be one of"):
        m.explained(np.zeros((1, 2)), np.zeros((1, 2, 2)), LTMParams(), backend="cuda")
