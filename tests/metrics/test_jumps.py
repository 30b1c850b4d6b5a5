"""Jumps of an estimate between consecutive scans (closed-form cases)."""

import numpy as np
import pytest

from dynmap_sim.metrics.jumps import JUMP_THRESHOLD_M, count_jumps


def _line(n: int) -> np.ndarray:
    return np.column_stack([np.linspace(0, 1, n), np.zeros(n), np.zeros(n)])


def test_an_estimate_that_follows_the_robot_with_an_offset_never_jumps() -> None:
    truth = _line(50)
    assert count_jumps(truth, truth + [2.0, -1.0, 0.3], np.zeros(50)) == 0


@pytest.mark.parametrize(("size", "jumps"), [(0.4, 0), (0.6, 2), (3.0, 2)])
def test_a_detour_of_the_estimate_counts_going_and_coming_back(size: float, jumps: int) -> None:
    truth = _line(20)
    est = truth.copy()
    est[10, 0] += size  # one scan off by ``size``: away and back
    assert count_jumps(truth, est, np.zeros(20)) == jumps


def test_a_new_run_is_no_jump_and_nan_poses_are_skipped() -> None:
    truth = np.vstack([_line(10), _line(10) + [5.0, 5.0, 0.0]])
    runs = np.repeat([[1, 1], [1, 2]], 10, axis=0)
    assert count_jumps(truth, truth, runs) == 0  # the 5 m between runs is no jump
    est = truth.copy()
    est[3] = np.nan
    assert count_jumps(truth, est, runs) == 0
    assert JUMP_THRESHOLD_M == 0.5


def test_shapes_must_agree() -> None:
    with pytest.raises(ValueError, match="3 true poses for 2 estimates"):
        count_jumps(np.zeros((3, 3)), np.zeros((2, 3)), np.zeros(3))
