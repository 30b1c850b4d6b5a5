"""First-run static SLAM on a synthetic room: trajectory and map accuracy against truth."""

from __future__ import annotations

import numpy as np

from dynmap_sim import se2
from dynmap_sim.agent.grid import OCCUPIED
from dynmap_sim.agent.mapping.first_run import FirstRunMapper
from dynmap_sim.types import Odometry, Scan


def _segment_distance(points: np.ndarray, segs: np.ndarray) -> np.ndarray:
    a = segs[None, :, :2]
    b = segs[None, :, 2:]
    p = points[:, None, :]
    ab = b - a
    t = np.clip(np.sum((p - a) * ab, -1) / np.sum(ab * ab, -1), 0.0, 1.0)
    return np.min(np.linalg.norm(p - (a + t[..., None] * ab), axis=-1), axis=1)


def test_first_run_map_and_trajectory(segments, laser, cast, path_fn, odo_fn):
    rng = np.random.default_rng(0)
    truth = path_fn(step_m=0.05, laps=2)
    odo = odo_fn(truth, rng)
    mapper = FirstRunMapper(laser, truth[0])
    est = []
    for k in range(len(truth)):
        r = cast(truth[k], laser.angles(), segments, laser.range_max_m)
        r = (r + rng.normal(0, 0.01, r.shape)).astype(np.float32)
        e = mapper.update(Odometry(odo[k], 0.1 * k), Scan(r, 0.1 * k))
        est.append(e.mean)
    est = np.array(est)
    dead = np.array([se2.compose(truth[0], se2.between(odo[0], o)) for o in odo])
    smap = mapper.finish()
    assert smap.trajectory.shape == truth.shape
    ate = np.sqrt(np.mean(np.sum((smap.trajectory[:, :2] - truth[:, :2]) ** 2, axis=1)))
    ate_dead = np.sqrt(np.mean(np.sum((dead[:, :2] - truth[:, :2]) ** 2, axis=1)))
    assert ate_dead > 0.15  # the odometry really drifts
    assert ate < 0.03
    assert smap.n_loop_closures >= 1
    # Online estimates are already good; the map frame is the initial pose's frame.
    assert np.max(np.hypot(*(est[:, :2] - truth[:, :2]).T)) < 0.1
    assert np.allclose(smap.trajectory[0], truth[0], atol=1e-6)
    # The grid: occupied cells lie on the true geometry.
    occ = smap.grid.occupied_points()
    assert len(occ) > 300
    d = _segment_distance(occ, segments)
    assert np.mean(d <= 0.05) > 0.95
    assert smap.grid.occupancy.dtype == np.int8
    assert (smap.grid.occupancy == OCCUPIED).sum() == len(occ)
    assert len(smap.keyframes) > 20
    assert all(k.ranges_m.shape == (laser.n_beams,) for k in smap.keyframes)
