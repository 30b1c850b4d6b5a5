"""Old FLASER lines: the maximum range found from the readings, time stamps that cannot order."""

from __future__ import annotations

import numpy as np
import pytest

from dynmap_sim.io.carmen import CarmenLogError, read_carmen, saturation_range


def _log(path, stamps, sat=50.0, n=181):
    lines = []
    for k, t in enumerate(stamps):
        r = np.full(n, 3.0 + 0.01 * k)
        r[::10] = sat  # no return, printed as the scanner's maximum
        rs = " ".join(f"{v:.2f}" for v in r)
        lines.append(f"FLASER {n} {rs} {0.1 * k} 0 0 {0.1 * k} 0 0 {t:.6f} h {t:.6f}")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_flaser_saturated_readings_are_no_return(tmp_path):
    log = read_carmen(_log(tmp_path / "a.log", [1.0, 1.2, 1.4]))
    assert log.laser.range_max_m == pytest.approx(50.0)
    assert np.isinf(log.ranges_m[:, ::10]).all()
    assert np.isfinite(log.ranges_m[:, 1]).all()
    # a log without a repeated top reading keeps CARMEN's 80 m
    assert saturation_range(np.array([[1.0, 2.0, 3.5 + k] for k in range(2000)])) is None


def test_time_stamps_that_go_back_are_refused_and_equal_ones_warned(tmp_path):
    with pytest.raises(CarmenLogError, match="go back at scan 2"):
        read_carmen(_log(tmp_path / "b.log", [1.0, 1.2, 1.1]))
    with pytest.warns(UserWarning, match="1 of 3 scans"):
        read_carmen(_log(tmp_path / "c.log", [1.0, 1.2, 1.2]))
