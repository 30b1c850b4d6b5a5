"""The per-scan point bookkeeping's kernels (:mod:`.classes_numba`) give the numpy code's
numbers exactly: valid returns, their classes and boxes, the static ones, §4.4's classes
with the long-term map's veto, and the beams MCL may use."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_scans import LASER

from dynmap_sim.agent.localization.adaptive_memory import classes_numba
from dynmap_sim.agent.localization.adaptive_memory.object_tracker import Boxes
from dynmap_sim.agent.localizer import make_localizer

needs_numba = pytest.mark.skipif(
    not classes_numba.numba_available(), reason="numba (extra 'fast') not installed"
)
KERNELS = ["python", pytest.param("numba", marks=needs_numba)]


def random_scan(rng: np.random.Generator, n: int) -> tuple[np.ndarray, Boxes, np.ndarray]:
    """Ranges with dropouts (inf, nan, 0, negative, beyond the maximum), boxes over runs of
    the valid ones, and the boxes' classes."""
    r = rng.uniform(0.01, 6.0, n)
    bad = rng.random(n) < rng.choice([0.0, 0.1, 0.5])
    r[bad] = rng.choice([np.inf, -np.inf, np.nan, 0.0, -1.0, 7.0], int(bad.sum()))
    labels = np.full(n, -1, dtype=np.intp)
    nb = int(rng.integers(0, 12)) if n else 0
    for b in range(nb):
        lo = int(rng.integers(0, n))
        labels[lo : lo + int(rng.integers(1, 40))] = b
    labels[~(np.isfinite(r) & (r > 0) & (r < 5.6))] = -1
    e = np.zeros(nb)
    boxes = Boxes(np.zeros((nb, 2)), e, e, e, np.zeros(nb, bool), labels)
    return r, boxes, rng.choice(np.array([0, 1, 3], dtype=np.int8), nb)


@pytest.mark.parametrize("kernel", KERNELS)
def test_scan_points_and_final_classes_of_the_kernels_equal_numpy(kernel: str) -> None:
    rng = np.random.default_rng(31)
    for _ in range(200):
        veto = float(rng.choice([0.0, 0.3, 0.5, 1.0]))
        loc = make_localizer("adaptive-memory", laser=LASER, rng=np.random.default_rng(0),
                             ltm_veto_dynamic=veto)  # fmt: skip
        r, boxes, box_cls = random_scan(rng, int(rng.integers(0, 300)))
        loc.range_max = 5.6
        ref = loc._scan_points(r, boxes, box_cls, backend="numpy")
        got = loc._scan_points(r, boxes, box_cls, backend=kernel)
        for a, b in zip(ref, got, strict=True):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
        vi, _, _, cls_v, lab, _ = ref
        explained = rng.random(len(vi)) < rng.choice([0.1, 0.5, 0.9])
        args = (lab, explained, len(boxes.length), vi, len(r))
        ref_c = loc._final_classes(cls_v.copy(), *args, backend="numpy")
        got_c = loc._final_classes(cls_v.copy(), *args, backend=kernel)
        for a, b in zip(ref_c, got_c, strict=True):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("kernel", KERNELS)
def test_masked_beams_of_the_kernel_equal_numpy(kernel: str) -> None:
    rng = np.random.default_rng(32)
    for _ in range(200):
        r, _, _ = random_scan(rng, int(rng.integers(0, 300)))
        mask = None if rng.random() < 0.3 else rng.random(len(r)) < 0.6
        lo, hi = float(rng.choice([0.0, 0.02, 0.5])), float(rng.choice([4.0, 5.6, 10.0]))
        ok = np.isfinite(r) & (r > 0) & (r < hi) & (r >= lo)
        if mask is not None:
            ok &= mask
        got = classes_numba.masked_beams(r, hi, lo, mask, python=kernel == "python")
        assert got.tobytes() == np.nonzero(ok)[0].tobytes()
