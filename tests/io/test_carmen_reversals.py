"""ODOM poses integrated without the sign of a reversing base are found and repaired (issue 16:
FR079 raw, written by bag2carmen, moves forward wherever its ``tv`` says the robot backs up)."""

from __future__ import annotations

import numpy as np
import pytest
from carmen_helpers import read_warned

from dynmap_sim import se2
from dynmap_sim.cli import REVERSAL_CHOICES
from dynmap_sim.io.carmen import (
    REVERSAL_MODES,
    CarmenLogError,
    interpolate_poses,
    read_carmen,
    repair_reversals,
    unsigned_reversals,
)


def _drive(signed: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ODOM lines at 10 Hz: 2 s forward at 0.3 m/s on a slow left turn, 1.5 s reversing,
    2 s forward; poses integrated with the velocity's sign (``signed``) or without it."""
    tv = np.r_[np.full(20, 0.3), np.full(15, -0.3), np.full(20, 0.3)]
    t = 50.0 + 0.1 * np.arange(len(tv) + 1)
    poses = [np.array([1.0, -2.0, 0.3])]
    for v in tv:
        step = v if signed else abs(v)
        poses.append(se2.compose(poses[-1], np.array([0.1 * step, 0.0, 0.01])))
    return t, np.array(poses), np.r_[0.0, tv]


def _write(path, t, poses, tv):
    """ODOM lines and FLASER lines between them whose odometry fields are the ODOM lines'."""
    lines = [
        f"ODOM {x:.6f} {y:.6f} {th:.6f} {v:.4f} 0.01 0 {s:.6f} h {s:.6f}"
        for s, (x, y, th), v in zip(t, poses, tv, strict=True)
    ]
    scan_t = t[:-1] + 0.05
    odo = interpolate_poses(t, np.round(poses, 6), scan_t)
    rs = " ".join(["2.00"] * 181)
    for s, o in zip(scan_t, odo, strict=True):
        f = " ".join(f"{v:.6f}" for v in (*o, *o))
        lines.append(f"FLASER 181 {rs} {f} {s:.6f} h {s:.6f}")
    lines.sort(key=lambda ln: float(ln.split()[-1]))
    path.write_text("\n".join(lines) + "\n")
    return path, scan_t


def _read(path, **kw):
    return read_warned(path, **kw)


def test_unsigned_reversing_is_found_and_repaired(tmp_path):
    t, logged, tv = _drive(signed=False)
    _, truth, _ = _drive(signed=True)
    path, scan_t = _write(tmp_path / "unsigned.log", t, logged, tv)
    log, caught = _read(path)
    assert log.odometry_source == "odom-lines"
    assert len(caught) == 1 and "15 of 55 ODOM increments" in caught[0]
    assert "negated" in caught[0] and str(path) in caught[0]
    assert (log.n_reversals, log.reversals) == (15, "repair")
    want = interpolate_poses(t, truth, scan_t)
    np.testing.assert_allclose(log.odometry, want, rtol=0, atol=2e-5)
    # the robot backed up 0.45 m: the repaired odometry ends 0.9 m short of the logged one
    end = np.hypot(*(logged[-1, :2] - truth[-1, :2]))
    assert end == pytest.approx(0.9, abs=0.01)


def test_keep_takes_the_poses_as_logged_and_still_warns(tmp_path):
    t, logged, tv = _drive(signed=False)
    path, scan_t = _write(tmp_path / "unsigned.log", t, logged, tv)
    log, caught = _read(path, reversals="keep")
    assert len(caught) == 1 and "kept as logged" in caught[0]
    assert (log.n_reversals, log.reversals) == (15, "keep")
    np.testing.assert_allclose(log.odometry, interpolate_poses(t, logged, scan_t), atol=2e-5)


def test_a_log_that_reverses_with_its_sign_is_untouched(tmp_path):
    t, truth, tv = _drive(signed=True)
    path, scan_t = _write(tmp_path / "signed.log", t, truth, tv)
    log, caught = _read(path)
    assert caught == [] and log.n_reversals == 0
    np.testing.assert_allclose(log.odometry, interpolate_poses(t, truth, scan_t), atol=2e-5)


def test_the_kernels_on_their_own():
    t, logged, tv = _drive(signed=False)
    _, truth, _ = _drive(signed=True)
    flagged = unsigned_reversals(logged, tv)
    assert flagged.sum() == 15 and flagged[20:35].all()
    np.testing.assert_allclose(repair_reversals(logged, flagged), truth, rtol=0, atol=1e-12)
    assert unsigned_reversals(truth, tv).sum() == 0  # backwards with the sign: nothing flagged
    assert unsigned_reversals(logged[:1], tv[:1]).shape == (0,)


def test_bad_mode_is_refused_and_the_cli_offers_the_modes(tmp_path):
    t, logged, tv = _drive(signed=False)
    path, _ = _write(tmp_path / "unsigned.log", t, logged, tv)
    with pytest.raises(CarmenLogError, match="reversals"):
        read_carmen(path, reversals="flip")
    assert REVERSAL_CHOICES == REVERSAL_MODES
