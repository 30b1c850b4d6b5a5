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


def _robotlaser(start: float, ranges: list[float], t: float) -> str:
    rs = " ".join(f"{v:.3f}" for v in ranges)
    hdr = f"0 {start:.6f} 3.141593 0.017453 81.9 0.01 0"
    return f"ROBOTLASER1 {hdr} {len(ranges)} {rs} 0 0.22 0 0 0 0 0 0 0 0 0 0 {t:.6f} h {t:.6f}"


def test_interlaced_robotlaser_scans_keep_their_own_angles(tmp_path):
    """The hospital log's SICK: 181 beams at 1 deg from -90 deg, or 180 offset by 1/4 deg;
    every reading lands on the 1/4 deg grid at its own angle."""
    lines = [
        _robotlaser(-1.570796 + q * 0.004363, [2.0 + q] * (181 if q == 0 else 180), 10.0 + q)
        for q in range(4)
    ]
    p = tmp_path / "i.log"
    p.write_text("\n".join(lines) + "\n")
    log = read_carmen(p)
    assert log.laser.n_beams == 721 and log.laser.mount_pose == pytest.approx((0.22, 0, 0))
    assert log.laser.angle_increment_rad == pytest.approx(0.017453 / 4)
    for q in range(4):
        have = np.flatnonzero(np.isfinite(log.ranges_m[q]))
        assert np.array_equal(have, q + 4 * np.arange(181 if q == 0 else 180))
        assert np.all(log.ranges_m[q, have] == np.float32(2.0 + q))


@pytest.mark.parametrize(
    ("line", "where"),
    [
        ("ODOM 0 nan 0 0 0 0 1.0 h 1.0", "line 2: field 2 is 'nan', not finite"),
        ("ODOM 0 0 0 0 0 0 inf h 1.0", "line 2: field 7 is 'inf', not finite"),
        (_robotlaser(-1.5708, [1.0, float("nan"), 2.0], 1.0), "line 2.ranges: field 10"),
        (_robotlaser(-1.5708, [1.0, 2.0], float("nan")), "line 2.timestamp"),
    ],
)
def test_non_finite_values_are_refused_with_file_and_line(tmp_path, line, where):
    p = tmp_path / "n.log"
    p.write_text(_robotlaser(-1.5708, [1.0, 2.0], 0.5) + "\n" + line + "\n")
    with pytest.raises(CarmenLogError) as info:
        read_carmen(p)
    assert str(info.value).startswith(f"{p}: ") and where in str(info.value)


def test_a_file_that_is_no_carmen_log_is_refused_early(tmp_path):
    p = tmp_path / "x.log"
    p.write_text("".join(f"{k},{k * 2},hello\n" for k in range(100_000)))
    with pytest.raises(CarmenLogError, match="lines 1-20: none of the first 20 lines is a CARMEN"):
        read_carmen(p)
    q = tmp_path / "long.log"
    q.write_text("ODOM " + "1 " * 600_000 + "\n")
    with pytest.raises(CarmenLogError, match="line 1: longer than 1048576 characters"):
        read_carmen(q)
