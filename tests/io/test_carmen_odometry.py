"""Which odometry a CARMEN log gives: the ODOM lines only where they are raw (issue 16)."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from carmen_helpers import read_warned

from dynmap_sim import se2
from dynmap_sim.cli import ODOMETRY_CHOICES, main
from dynmap_sim.experiments.reference import load_reference
from dynmap_sim.io.carmen import (
    ODOMETRY_SOURCES,
    CarmenLogError,
    CarmenOdometryWarning,
    interpolate_poses,
    read_carmen,
)

#: The benchmark logs next to the repository (a clean clone has none: those tests skip).
DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "slam-benchmark"


def _odometry(n: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """Time stamps at 5 Hz and a drifting odometry along an arc."""
    t = 100.0 + 0.2 * np.arange(n)
    s = 0.05 * np.arange(n)
    odo = np.column_stack([2.0 * np.sin(s), 2.0 * (1 - np.cos(s)), s])
    return t, odo


def _write(path, stamps, pose, odom, odom_t, odom_lines, kind="FLASER", in_time_order=True):
    """A log with one ``kind`` line per scan (``pose`` and odometry fields) and ODOM lines,
    in time order as the logger writes them (else the ODOM lines first, as given)."""
    lines = [
        f"ODOM {x:.6f} {y:.6f} {th:.6f} 0.3 0 0 {t:.6f} h {t:.6f}"
        for t, (x, y, th) in zip(odom_t, odom_lines, strict=True)
    ]
    rs = " ".join(["2.00"] * 181)
    for t, p, o in zip(stamps, pose, odom, strict=True):
        if kind == "FLASER":
            f = f"{p[0]:.6f} {p[1]:.6f} {p[2]:.6f} {o[0]:.6f} {o[1]:.6f} {o[2]:.6f}"
            lines.append(f"FLASER 181 {rs} {f} {t:.6f} h {t:.6f}")
        else:
            hdr = f"0 {-np.pi / 2:.9f} {np.pi:.9f} {np.pi / 180:.9f} 50.0 0.01 0"
            f = f"{p[0]:.6f} {p[1]:.6f} {p[2]:.6f} {o[0]:.6f} {o[1]:.6f} {o[2]:.6f}"
            lines.append(f"ROBOTLASER1 {hdr} 181 {rs} 0 {f} 0.3 0 0.5 0.3 0.1 {t:.6f} h {t:.6f}")
    if in_time_order:
        lines.sort(key=lambda ln: float(ln.split()[-1]))
    path.write_text("\n".join(lines) + "\n")
    return path


def _read(path, **kw):
    return read_warned(path, **kw)


def test_raw_log_takes_the_odom_lines_without_a_warning(tmp_path):
    """Raw: ODOM lines at their own times, the laser lines' odometry interpolated from them."""
    t, odo = _odometry()
    odom_t = t[:-1] + 0.07  # between the scans
    odom_lines = np.round(interpolate_poses(t, odo, odom_t), 6)  # as printed
    scan_odo = interpolate_poses(odom_t, odom_lines, t)  # what CARMEN's robot module writes
    # a ROBOTLASER1 laser 0.2 m ahead of the robot: its pose is the odometry plus the mount
    laser = se2.compose(scan_odo, np.broadcast_to([0.2, 0.0, 0.0], scan_odo.shape))
    for kind, pose in (("FLASER", scan_odo), ("ROBOTLASER1", laser)):
        p = _write(tmp_path / f"{kind}.log", t, pose, scan_odo, odom_t, odom_lines, kind)
        log, caught = _read(p)
        assert caught == [] and log.odometry_source == "odom-lines", kind
        np.testing.assert_allclose(log.odometry, scan_odo, rtol=0, atol=1e-12)


def test_corrected_log_takes_the_laser_lines_and_says_it_is_not_raw(tmp_path):
    """Corrected-like: the laser lines carry one (corrected) pose in both fields, the ODOM lines
    are something else (here: raw odometry 0.5 m and more away)."""
    t, odo = _odometry()
    corrected = odo.copy()
    corrected[:, :2] += 0.5 + 0.01 * np.arange(len(t))[:, None]
    p = _write(tmp_path / "corrected.log", t, corrected, corrected, t + 0.05, odo)
    log, caught = _read(p)
    assert log.odometry_source == "laser-lines"
    np.testing.assert_allclose(log.odometry, corrected, atol=1e-6)
    np.testing.assert_allclose(log.reference, corrected, atol=1e-6)
    (msg,) = caught
    assert msg.startswith(f"{p}: odometry from the FLASER lines' odometry fields, not the ODOM")
    assert "% of 59 scans agree to 0.01 m and 0.01 rad" in msg
    assert "pose and odometry fields are identical (up to a fixed mount)" in msg
    assert "this looks like a corrected log; its odometry is not raw wheel odometry" in msg
    assert "--odometry odom-lines" in msg
    # asked for, each stream is taken without a warning
    log, caught = _read(p, odometry="odom-lines")
    assert caught == [] and log.odometry_source == "odom-lines"
    np.testing.assert_allclose(log.odometry, interpolate_poses(t + 0.05, odo, t), atol=1e-6)
    log, caught = _read(p, odometry="laser-lines")
    assert caught == [] and log.odometry_source == "laser-lines"
    # as a reference only its poses are read: no word on its odometry
    raw = _write(tmp_path / "raw.log", t, odo, odo, [], [])
    with warnings.catch_warnings():
        warnings.simplefilter("error", CarmenOdometryWarning)
        match = load_reference(p, read_carmen(raw), offset_s=0.0)
    assert match.n_matched == len(t)


def test_disagreeing_raw_streams_take_the_laser_lines_odometry(tmp_path):
    """Pose corrected, odometry fields raw, ODOM lines another stream: the laser lines'
    odometry is used, and the log is not called corrected (its two fields differ)."""
    t, odo = _odometry()
    other = odo.copy()
    other[:, 2] += 0.002 * np.arange(len(t))  # a heading drift the laser lines do not have
    truth = odo + [0.3, -0.2, 0.0]
    p = _write(tmp_path / "two.log", t, truth, odo, t, other)
    log, caught = _read(p)
    assert log.odometry_source == "laser-lines"
    np.testing.assert_allclose(log.odometry, odo, atol=1e-6)
    (msg,) = caught
    assert "not the raw odometry the scans were logged with" in msg
    assert "corrected log" not in msg and "ODOM time stamps go back" not in msg
    # ODOM time stamps that go back are named (FR079 corrected: every other one is 0)
    odom_t = np.column_stack([t + 0.05, np.zeros_like(t)]).ravel()
    odom_lines = np.repeat(other, 2, axis=0)
    back = _write(tmp_path / "back.log", t, odo, odo, odom_t, odom_lines, in_time_order=False)
    (msg,) = _read(back)[1]
    assert "60 ODOM time stamps go back" in msg


def test_one_stream_only_and_a_bad_choice(tmp_path):
    t, odo = _odometry(10)
    p = _write(tmp_path / "flaser.log", t, odo, odo, [], [])
    log, caught = _read(p)
    assert caught == [] and log.odometry_source == "laser-lines"
    with pytest.raises(CarmenLogError, match=r"flaser.log: odometry: odom-lines: the log has no"):
        read_carmen(p, odometry="odom-lines")
    with pytest.raises(CarmenLogError, match=r"flaser.log: odometry: must be one of auto, odom-"):
        read_carmen(p, odometry="wheels")
    assert ODOMETRY_CHOICES == ODOMETRY_SOURCES


def test_cli_takes_odometry(tmp_path, capsys):
    t, odo = _odometry(10)
    p = _write(tmp_path / "flaser.log", t, odo, odo, [], [])
    args = ["replay", str(p), "--localizer", "odometry", "--out", str(tmp_path / "r")]
    assert main([*args, "--odometry", "odom-lines"]) == 2
    assert "odometry: odom-lines: the log has no ODOM lines" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([*args, "--odometry", "wheels"])
    assert "invalid choice: 'wheels'" in capsys.readouterr().err


needs_data = pytest.mark.skipif(
    not (DATA / "fr079.raw.log.gz").exists() or not (DATA / "fr079-corrected.log.gz").exists(),
    reason=f"the benchmark logs are not in {DATA}",
)


@needs_data
def test_fr079_raw_is_raw_and_corrected_is_warned():
    raw, caught = _read(DATA / "fr079.raw.log.gz")
    assert raw.odometry_source == "odom-lines"
    # its one warning: the poses of its reversing, integrated without the sign (repaired)
    (msg,) = caught
    assert "400 of 8950 ODOM increments move forward" in msg and "negated" in msg
    corrected, caught = _read(DATA / "fr079-corrected.log.gz")
    assert corrected.odometry_source == "laser-lines"
    (msg,) = caught
    assert "this looks like a corrected log; its odometry is not raw wheel odometry" in msg
