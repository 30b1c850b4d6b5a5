"""``C_O`` acquired from the map's run (B&D §4.3): the odometry's error rates against a
trajectory, on cases whose rates are known in closed form."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim import se2
from dynmap_sim.agent.localization.odometry_calibration import odometry_error_rates


def _integrate(increments: np.ndarray) -> np.ndarray:
    poses = [np.zeros(3)]
    for d in increments:
        poses.append(se2.compose(poses[-1], d))
    return np.array(poses)


def test_a_scale_error_of_the_wheels_is_its_rate():
    """Straight on: odometry 3 % long is a translation rate of 0.03 in every window, and no
    heading error; turning on the spot: 5 % over in heading is a heading rate of 0.05."""
    step = np.tile([0.1, 0.0, 0.0], (60, 1))
    rates = odometry_error_rates(_integrate(step * [1.03, 1, 1]), _integrate(step), window=10)
    assert rates is not None and rates.n_windows == 51
    assert rates.k_xy == pytest.approx(0.03, abs=1e-12)
    assert rates.k_th == pytest.approx(0.0, abs=1e-12)
    turn = np.tile([0.0, 0.0, 0.05], (60, 1))
    rates = odometry_error_rates(_integrate(turn * [1, 1, 1.05]), _integrate(turn), window=5)
    assert rates is not None
    assert rates.k_th == pytest.approx(0.05, abs=1e-12)
    assert rates.k_xy == pytest.approx(0.0, abs=1e-12)


def test_the_quantile_is_taken_over_the_windows():
    """Half the path with exact odometry, half 10 % long: the median window is between,
    the 0.9 quantile 10 %."""
    step = np.tile([0.1, 0.0, 0.0], (200, 1))
    odo_step = step.copy()
    odo_step[100:, 0] *= 1.10
    odo, ref = _integrate(odo_step), _integrate(step)
    assert odometry_error_rates(odo, ref, window=1, quantile=0.9).k_xy == pytest.approx(0.10)
    assert odometry_error_rates(odo, ref, window=1, quantile=0.25).k_xy == pytest.approx(0.0)


def test_unknown_poses_and_standstill_leave_windows_out():
    step = np.tile([0.1, 0.0, 0.0], (60, 1))
    step[:20] = 0.0  # standing still: no motion to relate an error to
    odo, ref = _integrate(step * [1.02, 1, 1]), _integrate(step)
    ref[40] = np.nan  # unknown (a reference with a gap)
    rates = odometry_error_rates(odo, ref, window=5)
    assert rates is not None
    # 56 windows, of which those that do not move (starting before scan 16) and the two
    # that start or end at scan 40 are left out
    assert rates.n_windows == 56 - 16 - 2
    assert rates.k_xy == pytest.approx(0.02, abs=1e-12)
    assert odometry_error_rates(odo[:30], ref[:30], window=5) is None  # too few windows


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"window": 0}, "window must be >= 1"),
        ({"quantile": 0.0}, r"quantile must be in \(0, 1\]"),
        ({"quantile": 1.5}, r"quantile must be in \(0, 1\]"),
    ],
)
def test_bad_arguments_are_named(kwargs, message):
    p = np.zeros((50, 3))
    with pytest.raises(ValueError, match=message):
        odometry_error_rates(p, p, **kwargs)
    with pytest.raises(ValueError, match="49 odometry poses for 50 poses"):
        odometry_error_rates(p[:49], p)
