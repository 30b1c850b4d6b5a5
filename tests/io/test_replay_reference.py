"""``replay --reference``: ground truth from another log matched by time stamp, and none
without it (issue 16, item 3). The tests write a small raw log and its reference."""

from __future__ import annotations

import sqlite3

import numpy as np
import pytest
from synthetic_scans import raycast, room_segments

from dynmap_sim.cli import main
from dynmap_sim.experiments.reference import REFERENCE_TOLERANCE_S, match_by_stamp

#: The reference log's clock runs this much behind the raw log's [s].
CLOCK_OFFSET_S = 500.0
N = 80


def _trajectory(n: int = N) -> np.ndarray:
    """An arc through the test room (5 Hz, as FR079's laser)."""
    t = np.linspace(0.0, 1.5, n)
    return np.column_stack([3.0 + 1.5 * np.cos(t), 2.4 + 1.0 * np.sin(t), t + np.pi / 2])


def _flaser(ranges: np.ndarray, pose: np.ndarray, odom: np.ndarray, stamp: float) -> str:
    rs = " ".join(f"{v:.2f}" for v in ranges)
    p = " ".join(f"{v:.6f}" for v in (*pose, *odom))
    return f"FLASER {len(ranges)} {rs} {p} {stamp:.6f} h {stamp:.6f}"


def known_offsets(n: int = N) -> np.ndarray:
    """The reference's displacement of each true pose: none for the first 10 scans (the start
    pose comes from them), then 0 / 5 / 10 / 15 cm along x, repeating."""
    d = np.zeros((n, 3))
    d[10:, 0] = 0.05 * (np.arange(10, n) % 4)
    return d


def write_logs(tmp_path, drop_every: int = 7) -> tuple:
    """``raw.log`` (laser-line poses = exact odometry, as a raw log) and ``ref.log`` (the same
    readings, poses = truth + :func:`known_offsets`, on a clock :data:`CLOCK_OFFSET_S` behind
    with +-20 ms jitter, every ``drop_every``-th scan missing)."""
    truth = _trajectory()
    fov, nb = np.pi, 181
    angles = -fov / 2 + fov / (nb - 1) * np.arange(nb)
    segs = room_segments(cupboard=False)
    stamps = 1000.0 + 0.2 * np.arange(N)
    ref_pose = truth + known_offsets()
    raw, ref = ["# raw"], ["# reference"]
    for k in range(N):
        r = raycast(truth[k], angles, segs, 50.0)
        r = np.where(np.isfinite(r), r, 81.91)
        raw.append(_flaser(r, truth[k], truth[k], stamps[k]))
        if drop_every and k % drop_every == drop_every - 1:
            continue
        jitter = 0.02 if k % 2 else -0.02
        ref.append(_flaser(r, ref_pose[k], ref_pose[k], stamps[k] - CLOCK_OFFSET_S + jitter))
    (tmp_path / "raw.log").write_text("\n".join(raw) + "\n")
    (tmp_path / "ref.log").write_text("\n".join(ref) + "\n")
    matched = np.array([not (drop_every and k % drop_every == drop_every - 1) for k in range(N)])
    return tmp_path / "raw.log", tmp_path / "ref.log", matched


def _replay(tmp_path, *extra: str, out: str = "out") -> int:
    raw = tmp_path / "raw.log"
    return main(
        ["replay", str(raw), "--localizer", "odometry", *extra, "--out", str(tmp_path / out)]
    )


def test_errors_equal_the_known_offsets_of_the_reference(tmp_path, capsys):
    _, ref, matched = write_logs(tmp_path)
    assert _replay(tmp_path, "--reference", str(ref)) == 0
    cap = capsys.readouterr()
    assert f"{matched.sum()} of {N} scans matched" in cap.err
    assert "from shared scans" in cap.err and "update CPU [ms/scan]" in cap.out
    con = sqlite3.connect(tmp_path / "out" / "results.db")
    for day in (1, 2):
        err = np.array(
            con.execute(
                "SELECT err_m FROM estimates WHERE loc=0 AND day=? ORDER BY step", (day,)
            ).fetchall(),
            dtype=np.float64,
        ).ravel()
        expect = np.where(matched, np.abs(known_offsets()[:, 0]), np.nan)
        np.testing.assert_array_equal(np.isnan(err), ~matched)  # no reference: no error
        np.testing.assert_allclose(err[matched], expect[matched], atol=1e-4)
    # summaries score only the matched scans; the unmatched are not "lost"
    mean_e, lost, n, ms = con.execute(
        "SELECT mean_error_m, lost_fraction, n_scans, update_ms_per_scan FROM run_summaries "
        "WHERE day=2"
    ).fetchone()
    assert mean_e == pytest.approx(np.abs(known_offsets()[matched, 0]).mean(), abs=1e-4)
    assert lost == 0.0 and n == N and ms > 0
    (day_lost,) = con.execute("SELECT lost_fraction FROM day_summaries WHERE day=2").fetchone()
    assert day_lost == 0.0
    meta = dict(con.execute("SELECT key, value FROM meta").fetchall())
    assert meta["has_reference"] == "true" and meta["reference_matched"] == str(matched.sum())
    assert abs(float(meta["reference_offset_s"]) - CLOCK_OFFSET_S) <= 0.02
    # the same with the offset given, and the truth export leaves the unmatched scans out
    assert _replay(tmp_path, "--reference", str(ref), "--reference-offset", "500", out="o2") == 0
    assert "clock offset +500.000 s, given" in capsys.readouterr().err
    assert main(["export", str(tmp_path / "o2"), "--tum", str(tmp_path / "tum")]) == 0
    assert len(np.loadtxt(tmp_path / "tum" / "truth.tum")) == matched.sum()


def test_without_reference_the_log_has_no_ground_truth(tmp_path, capsys):
    write_logs(tmp_path)
    assert _replay(tmp_path) == 0
    out = capsys.readouterr().out
    assert "this log has no ground truth" in out and "ATE" not in out
    con = sqlite3.connect(tmp_path / "out" / "results.db")
    assert con.execute("SELECT count(*) FROM scans WHERE x IS NOT NULL").fetchone() == (0,)
    assert con.execute("SELECT count(*) FROM estimates WHERE err_m IS NOT NULL").fetchone() == (0,)
    rows = con.execute(
        "SELECT mean_error_m, max_error_m, lost_fraction, update_ms_per_scan FROM run_summaries"
    ).fetchall()
    assert len(rows) == 2 and all(r[:3] == (None, None, None) and r[3] > 0 for r in rows)
    assert main(["report", str(tmp_path / "out")]) == 0
    summary = (tmp_path / "out" / "summary.md").read_text()
    assert "this log has no ground truth" in summary and "ATE RMSE" not in summary
    assert not (tmp_path / "out" / "error_per_day.png").exists()
    assert main(["export", str(tmp_path / "out"), "--tum", str(tmp_path / "tum")]) == 0
    assert not (tmp_path / "tum" / "truth.tum").exists()


def test_map_from_the_reference_poses(tmp_path, capsys):
    """--map-from-log-poses with --reference renders the map at the reference poses."""
    _, ref, _ = write_logs(tmp_path, drop_every=0)
    args = ["--localizer", "static-mcl", "--map-from-log-poses", "--reference", str(ref)]
    assert _replay(tmp_path, *args) == 0
    con = sqlite3.connect(tmp_path / "out" / "results.db")
    (mean_e,) = con.execute(
        "SELECT mean_error_m FROM run_summaries WHERE loc=1 AND day=2"
    ).fetchone()
    assert mean_e < 0.15  # the reference's own 0-15 cm displacements bound what it can reach


def test_dynamic_map_takes_the_scans_at_the_reference_poses(tmp_path, capsys):
    """--map-from-log-poses gives dynamic-map (a ScanMapUser) the keyframe scans at the
    reference poses as its first map: no first-run SLAM on pass 1, which already localizes
    (within the reference's own 0-15 cm displacements), and both localizers get a map."""
    _, ref, _ = write_logs(tmp_path, drop_every=0)
    args = ["--localizer", "dynamic-map", "--localizer", "static-mcl", "--map-from-log-poses"]
    assert _replay(tmp_path, *args, "--reference", str(ref)) == 0
    assert "goes to dynamic-map, static-mcl" in capsys.readouterr().err
    con = sqlite3.connect(tmp_path / "out" / "results.db")
    for day in (1, 2):
        (mean_e,) = con.execute(
            "SELECT mean_error_m FROM run_summaries WHERE loc=1 AND day=?", (day,)
        ).fetchone()
        assert mean_e < 0.15, day


def test_dynamic_map_acquires_c_o_from_the_reference_run_only(tmp_path):
    """With a reference, --map-from-log-poses also hands dynamic-map the reference's poses of
    every scan and the log's odometry, from which it acquires ``C_O`` (B&D §4.3); without
    one it keeps its configured rates (the laser lines' poses may be the odometry itself)."""
    from dynmap_sim.agent.localization.localizer import make_localizer
    from dynmap_sim.agent.localization.odometry_calibration import odometry_error_rates
    from dynmap_sim.experiments.reference import load_reference
    from dynmap_sim.experiments.replay import _give_maps
    from dynmap_sim.io.carmen import read_carmen

    raw, ref_path, _ = write_logs(tmp_path, drop_every=0)
    log = read_carmen(raw)
    ref = load_reference(ref_path, log, None, REFERENCE_TOLERANCE_S)
    with_ref = make_localizer("dynamic-map", laser=log.laser, rng=np.random.default_rng(0))
    assert _give_maps(log, ref, [with_ref], ["dynamic-map"], None) == [True]
    expected = odometry_error_rates(log.odometry, ref.poses)
    assert expected is not None and with_ref.odom_rates == expected
    without = make_localizer("dynamic-map", laser=log.laser, rng=np.random.default_rng(0))
    assert _give_maps(log, None, [without], ["dynamic-map"], None) == [True]
    assert without.odom_rates is None


def test_dynamic_map_given_scans_maps_no_first_run():
    """``set_map_from_scans``: local maps at the given poses, none of the first-run mapper;
    a static variant freezes as after its first day; mismatched input is refused."""
    from dynmap_sim.agent.localization.localizer import make_localizer
    from dynmap_sim.types import LaserSpec, Prior

    truth = _trajectory()
    fov, nb = np.pi, 181
    angles = -fov / 2 + fov / (nb - 1) * np.arange(nb)
    segs = room_segments(cupboard=False)
    ranges = [raycast(p, angles, segs, 8.0) for p in truth]
    laser = LaserSpec(
        name="test", n_beams=nb, angle_min_rad=-fov / 2, angle_increment_rad=fov / (nb - 1),
        range_min_m=0.02, range_max_m=8.0, scan_period_s=0.2, time_increment_s=0.0,
    )  # fmt: skip
    for name in ("dynamic-map", "static-map"):
        loc = make_localizer(name, laser=laser, rng=np.random.default_rng(0))
        loc.set_map_from_scans(truth[::10], ranges[::10])
        assert len(loc.dmap) >= 1  # the 2.3 m arc: local maps local_map_spacing_m apart
        loc.begin_run(Prior(initial_pose=truth[0], day=1, run=1, first_run=True))
        assert loc._mapper is None
        assert loc.frozen == (name == "static-map")
    with pytest.raises(ValueError, match="3 poses for 2 scans"):
        loc.set_map_from_scans(truth[:3], ranges[:2])


@pytest.mark.parametrize(
    ("case", "message"),
    [
        ("missing", "nope.log: file not found"),
        ("folder", "not a regular file but a directory"),
        ("corrupt", "bad.log.gz: cannot read file"),
        ("no poses", "carry no poses"),
        ("no overlap", f"far.log: no time stamp within {REFERENCE_TOLERANCE_S:g} s of a scan"),
        ("offset alone", "--reference-offset and --reference-tolerance need --reference"),
    ],
)
def test_bad_reference_is_one_line_naming_the_file(tmp_path, capsys, case, message):
    write_logs(tmp_path)
    if case == "missing":
        args = ["--reference", str(tmp_path / "nope.log")]
    elif case == "folder":
        args = ["--reference", str(tmp_path)]
    elif case == "corrupt":
        (tmp_path / "bad.log.gz").write_bytes(b"\x1f\x8bnot gzip at all")
        args = ["--reference", str(tmp_path / "bad.log.gz")]
    elif case == "no poses":
        hdr = "0 -1.5707963 3.1415927 0.0174533 50.0 0.01 0"
        line = f"RAWLASER1 {hdr} 3 1.0 1.0 1.0 0 1000.0 h 0"
        (tmp_path / "raw1.log").write_text(f"ODOM 0 0 0 0 0 0 1000.0 h 0\n{line}\n")
        args = ["--reference", str(tmp_path / "raw1.log")]
    elif case == "no overlap":  # other readings (no shared scans: offset 0), another clock
        lines = [
            _flaser(np.full(181, 2.0 + 0.01 * k), np.zeros(3), np.zeros(3), 5.0 + 0.1 * k)
            for k in range(20)
        ]
        (tmp_path / "far.log").write_text("\n".join(lines) + "\n")
        args = ["--reference", str(tmp_path / "far.log")]
    else:
        args = ["--reference-offset", "3"]
    assert _replay(tmp_path, *args) == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and err.count("\n") == 0 and err.startswith("error: ")
    assert message in err
    assert not (tmp_path / "out" / "results.db").exists()


@pytest.mark.parametrize(
    "args",
    [["--reference-tolerance", "0"], ["--reference-tolerance", "x"], ["--reference-offset", "nan"]],
)
def test_bad_reference_numbers_are_usage_errors(tmp_path, capsys, args):
    with pytest.raises(SystemExit) as ei:
        main(
            ["replay", "a.log", "--localizer", "odometry", "--reference", "r", *args, "--out", "o"]
        )
    assert ei.value.code == 2
    assert "Traceback" not in capsys.readouterr().err


def test_match_by_stamp_takes_the_nearest_within_the_tolerance():
    ref_t = np.array([0.0, 1.0, 2.0])
    poses = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])
    t = np.array([-0.05, 0.49, 0.5, 1.2, 2.09, 3.0])
    got = match_by_stamp(t, ref_t, poses, tolerance_s=0.1)
    np.testing.assert_array_equal(got[:, 0], [0.0, np.nan, np.nan, np.nan, 2.0, np.nan])
    wide = match_by_stamp(t, ref_t, poses, tolerance_s=0.5)
    np.testing.assert_array_equal(wide[:, 0], [0.0, 0.0, 0.0, 1.0, 2.0, np.nan])  # tie: earlier
