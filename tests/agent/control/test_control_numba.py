"""The controllers' kernels (:mod:`.control_numba`) give the numpy code's numbers exactly: the
follower's offset choice and the collision monitor's action, on random grids, paths and scans."""

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from synthetic_scans import LASER, box, raycast

sys.path.insert(0, str(Path(__file__).parent))
from control_world import HARD_M, SPEED_MPS, grid_of  # noqa: E402

from dynmap_sim.agent.control import collision_monitor, control_numba  # noqa: E402
from dynmap_sim.agent.control.collision_monitor import CollisionMonitor  # noqa: E402
from dynmap_sim.agent.control.corridor_follower import CorridorFollower  # noqa: E402
from dynmap_sim.types import Scan  # noqa: E402

needs_numba = pytest.mark.skipif(
    not control_numba.numba_available(), reason="numba (extra 'fast') not installed"
)


def random_boxes(rng: np.random.Generator, n: int) -> np.ndarray:
    segs = [box(-1.0, -2.0, 7.0, 4.0)]
    for _ in range(n):
        x, y, s = rng.uniform(0.0, 6.0), rng.uniform(-1.5, 3.5), rng.uniform(0.05, 0.5)
        segs.append(box(x, y, x + s, y + s))
    return np.concatenate(segs)


def same_choice(a: tuple, b: tuple) -> None:
    assert a[0] == b[0] and a[3] == b[3]
    np.testing.assert_array_equal(a[1], b[1])
    np.testing.assert_array_equal(a[2], b[2])


@pytest.mark.parametrize("python", [False, True])
def test_offset_choice_of_the_kernel_equals_numpy(python: bool, monkeypatch) -> None:
    """Random paths (zero-length segments and narrowing ends included), poses, grids and
    current offsets: the same best offset, offsets, clearances ahead and clearance here."""
    if not python and not control_numba.numba_available():
        pytest.skip("numba (extra 'fast') not installed")
    if python:  # the uncompiled kernel behind the numba backend
        monkeypatch.setattr(control_numba, "_probe_offsets_nb", None)
        monkeypatch.setattr(
            "dynmap_sim.agent.control.corridor_follower.numba_available", lambda: True
        )
    rng = np.random.default_rng(5)
    n_cases = 0
    for _ in range(15 if python else 60):
        grid = grid_of(random_boxes(rng, int(rng.integers(0, 8))))
        k = int(rng.integers(2, 7))
        path = np.cumsum(rng.uniform(-1.0, 1.5, (k, 2)), axis=0) + [0.5, 0.5]
        if rng.random() < 0.3:
            path = np.insert(path, 1, path[1], axis=0)  # a zero-length segment
        hw = rng.uniform(0.0, 0.5, len(path))
        fast, ref = CorridorFollower(SPEED_MPS, HARD_M), CorridorFollower(SPEED_MPS, HARD_M)
        ref.backend = "numpy"
        for c in (fast, ref):
            c.set_path(path, hw)
        for _ in range(8):
            seg = int(rng.integers(0, len(path) - 1))
            xy = path[seg] + rng.uniform(-0.6, 0.6, 2)
            offset = float(rng.uniform(-0.5, 0.5))
            for c in (fast, ref):
                c._seg, c._offset_m = seg, offset
            s_robot, _ = ref._along(*xy)
            carrot = path[seg] + rng.uniform(0.0, 1.0) * (path[seg + 1] - path[seg])
            s_carrot = float(ref._cum[seg]) + float(np.hypot(*(carrot - path[seg])))
            a = fast._choose_offset(xy, s_robot, carrot, s_carrot, grid)
            b = ref._choose_offset(xy, s_robot, carrot, s_carrot, grid)
            same_choice(a, b)
            n_cases += a[0] is not None
    assert n_cases > 10  # free offsets were chosen, not only blocked cases


@needs_numba
def test_follower_drives_the_same_with_either_backend() -> None:
    """Whole commands along a path past boxes are identical."""
    rng = np.random.default_rng(1)
    grid = grid_of(random_boxes(rng, 5))
    path = np.array([[0.0, 0.0], [3.0, 0.2], [5.0, 2.5], [5.5, 3.0]])
    fast, ref = CorridorFollower(SPEED_MPS, HARD_M), CorridorFollower(SPEED_MPS, HARD_M)
    ref.backend = "numpy"
    for c in (fast, ref):
        c.set_path(path, np.full(len(path), 0.35))
    pose = np.array([0.0, 0.0, 0.0])
    for _ in range(300):
        pose = pose + [rng.normal(0, 0.05), rng.normal(0, 0.05), rng.normal(0, 0.1)]
        a, b = fast.command(pose, grid), ref.command(pose, grid)
        np.testing.assert_array_equal(a, b)
        assert fast.blocked == ref.blocked and fast.offset_m == ref.offset_m
        pose[:2] += 0.1 * a[0] * np.array([math.cos(pose[2]), math.sin(pose[2])])
        pose[2] += 0.1 * a[1]


@pytest.mark.parametrize("python", [False, True])
def test_monitor_action_of_the_kernel_equals_numpy(python: bool, monkeypatch) -> None:
    """Random boxes around the robot, REP-117 values and speeds (reversing, zero, forward):
    the same actions."""
    if not python and not control_numba.numba_available():
        pytest.skip("numba (extra 'fast') not installed")
    if python:
        monkeypatch.setattr(control_numba, "_monitor_action_nb", None)
        monkeypatch.setattr(collision_monitor, "numba_available", lambda: True)
    rng = np.random.default_rng(2)
    seen = set()
    for _ in range(100 if python else 400):
        segs = []
        for _ in range(rng.integers(0, 4)):
            x, y, s = rng.uniform(-0.8, 0.8), rng.uniform(-0.8, 0.8), rng.uniform(0.02, 0.4)
            segs.append(box(x, y, x + s, y + s))
        segs = np.concatenate(segs) if segs else np.zeros((0, 4))
        r = raycast(np.zeros(3), LASER.angles(), segs, LASER.range_max_m) if len(segs) else None
        if r is None:
            r = np.full(LASER.n_beams, np.inf)
        bad = rng.random(r.shape)
        r[bad < 0.02] = -np.inf
        r[(bad > 0.02) & (bad < 0.03)] = np.nan
        ranges = r.astype(np.float32)
        v = float(rng.choice([0.0, -0.1, 0.1, 0.35, -0.0, rng.uniform(-0.4, 0.4)]))
        fast, ref = CollisionMonitor(LASER, 0.2), CollisionMonitor(LASER, 0.2)
        ref.backend = "numpy"
        a = fast.filter(np.array([v, 0.3]), Scan(ranges), 0.0)
        b = ref.filter(np.array([v, 0.3]), Scan(ranges), 0.0)
        np.testing.assert_array_equal(a, b)
        assert fast.last_action == ref.last_action
        seen.add(ref.last_action)
    assert len(seen) == 4  # every action occurred
