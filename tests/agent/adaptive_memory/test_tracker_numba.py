"""The segmentation's and the tracker's kernels (:mod:`.tracker_numba`) give the numpy code's
numbers exactly: numpy's pairwise sums, whole segmentations of random rooms, people and
dropouts, and tracks of standing and walking objects."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_scans import LASER, box, raycast, room_segments

from dynmap_sim import se2
from dynmap_sim.agent.localization.adaptive_memory import tracker_numba
from dynmap_sim.agent.localization.adaptive_memory.object_tracker import (
    DYNAMIC,
    Boxes,
    ObjectTracker,
    TrackerParams,
    beam_trig,
    segment_scan,
)

needs_numba = pytest.mark.skipif(
    not tracker_numba.numba_available(), reason="numba (extra 'fast') not installed"
)
KERNELS = ["python", pytest.param("numba", marks=needs_numba)]


def test_pairwise_sums_are_numpys_reduceat() -> None:
    """Segments of 1 to 700 values (numpy's three regimes: < 8, blocks of 8 up to 128, and
    halves), of mixed magnitudes and signed zeros."""
    rng = np.random.default_rng(3)
    for _ in range(300):
        n = int(rng.integers(1, 700))
        a = rng.normal(0, 1, n) * 10.0 ** rng.integers(-6, 6, n)
        a[rng.random(n) < 0.05] = -0.0
        starts = np.unique(np.concatenate([[0], rng.choice(n, int(rng.integers(0, 12)))]))
        out = np.empty(len(starts))
        tracker_numba._reduceat_py(a, starts, n, out)
        assert out.tobytes() == np.add.reduceat(a, starts).tobytes()
    zeros = np.full(20, -0.0)
    out = np.empty(1)
    tracker_numba._reduceat_py(zeros, np.zeros(1, dtype=np.intp), 20, out)
    assert out.tobytes() == np.add.reduceat(zeros, [0]).tobytes()


def random_scan(rng: np.random.Generator) -> np.ndarray:
    """A room with a cupboard or not, a few boxes (people, chairs) and dropped beams."""
    segs = [room_segments(cupboard=bool(rng.random() < 0.5))]
    for _ in range(int(rng.integers(0, 4))):
        x, y = rng.uniform(0.5, 4.5, 2)
        s = rng.uniform(0.1, 0.6)
        segs.append(box(x, y, x + s, y + s))
    pose = np.array([*rng.uniform(0.8, 2.0, 2), rng.uniform(-np.pi, np.pi)])
    r = raycast(pose, LASER.angles(), np.concatenate(segs), LASER.range_max_m)
    r = r + rng.normal(0, 0.01, r.shape)
    r[rng.random(len(r)) < rng.choice([0.0, 0.05, 0.3])] = np.inf
    return r.astype(np.float32)


@pytest.mark.parametrize("kernel", KERNELS)
def test_segment_scan_of_the_kernels_equals_numpy_bit_for_bit(kernel: str) -> None:
    rng = np.random.default_rng(21)
    mount = np.array([0.1, -0.02, 0.05])
    for _ in range(40 if kernel == "python" else 200):
        r = random_scan(rng)
        params = TrackerParams(
            breakpoint_lambda_deg=float(rng.choice([5.0, 10.0, 20.0])),
            min_points=int(rng.integers(1, 6)),
            max_gap_beams=int(rng.integers(0, 4)),
            max_dynamic_length_m=float(rng.choice([0.3, 1.2])),
            occlusion_never_dynamic=bool(rng.random() < 0.5),
        )
        ref = segment_scan(r, LASER.angles(), mount, LASER.range_max_m, params, backend="numpy")
        got = segment_scan(r, LASER.angles(), mount, LASER.range_max_m, params, backend=kernel)
        trig = beam_trig(LASER.angles(), mount)  # the beams' cosines and sines at hand
        got_t = segment_scan(r, LASER.angles(), mount, LASER.range_max_m, params,
                             backend=kernel, beam_trig=trig)  # fmt: skip
        for name in ("center_robot", "phi", "length", "width", "never_dynamic", "labels"):
            a, b, c = getattr(ref, name), getattr(got, name), getattr(got_t, name)
            assert a.dtype == b.dtype == c.dtype and a.shape == b.shape == c.shape, name
            assert a.tobytes() == b.tobytes() == c.tobytes(), name


def test_an_unknown_backend_is_refused() -> None:
    r = np.full(LASER.n_beams, 2.0, dtype=np.float32)
    with pytest.raises(ValueError, match="backend must be one of"):
        segment_scan(r, LASER.angles(), np.zeros(3), 5.0, TrackerParams(), backend="cuda")


def random_boxes(rng: np.random.Generator, centres: np.ndarray) -> Boxes:
    """Boxes at ``centres`` (robot frame) plus noise, some dropped, some new ones."""
    keep = rng.random(len(centres)) > 0.1
    c = centres[keep] + rng.normal(0, 0.02, (int(keep.sum()), 2))
    extra = rng.uniform(-4, 4, (int(rng.integers(0, 3)), 2))
    c = np.concatenate([c, extra])[rng.permutation(len(c) + len(extra))]
    n = len(c)
    return Boxes(c, np.zeros(n), np.full(n, 0.3), np.full(n, 0.2), rng.random(n) < 0.2,
                 np.full(10, -1, dtype=np.intp))  # fmt: skip


@pytest.mark.parametrize("kernel", KERNELS)
def test_the_tracker_kernel_equals_numpy_bit_for_bit(kernel: str) -> None:
    """Objects standing, walking and appearing, seen from a moving robot (odometry frame
    tracks, gaps in time, ties of distance), through both backends in lock-step."""
    n_dynamic = n_tracks = 0
    for seed in range(4 if kernel == "python" else 12):
        rng = np.random.default_rng(seed)
        params = TrackerParams(confirm_steps=int(rng.integers(1, 4)),
                               max_misses=int(rng.integers(0, 3)),
                               gate_m=float(rng.choice([0.2, 0.5, 1.0])))  # fmt: skip
        trackers = {b: ObjectTracker(params) for b in ("numpy", kernel)}
        pos = rng.uniform(-3, 3, (8, 2))
        vel = rng.normal(0, 0.6, (8, 2)) * (rng.random((8, 1)) < 0.5)
        t = 0.0
        for step in range(60):
            t += float(rng.choice([0.1, 0.1, 0.2, 0.0]))
            pos += vel * 0.1
            odom = np.array([0.02 * step, 0.01 * step, 0.01 * step])
            centres = se2.transform_points(se2.inverse(odom), pos)
            if step == 30:  # exact ties: two boxes at the same place
                centres[1] = centres[0]
            boxes = random_boxes(rng, centres)
            out = {b: tr.update(boxes, odom, t, backend=b) for b, tr in trackers.items()}
            for a, b in zip(out["numpy"], out[kernel], strict=True):
                assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
            ref, got = trackers["numpy"], trackers[kernel]
            for name in ("x", "P", "hits", "misses", "fast", "slow", "dynamic"):
                assert getattr(ref, name).tobytes() == getattr(got, name).tobytes(), name
            n_dynamic += int(np.sum(out["numpy"][0] == DYNAMIC))
            n_tracks += ref.n_tracks
    assert n_dynamic > 20 and n_tracks > 100  # the cases were there
