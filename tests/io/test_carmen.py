"""CARMEN logs: the tests write small logs (FLASER / ROBOTLASER1 / RAWLASER1, plain and gzip)."""

from __future__ import annotations

import gzip
import json
import sqlite3

import numpy as np
import pytest
from synthetic_scans import raycast, room_segments

from dynmap_sim import se2
from dynmap_sim.cli import main
from dynmap_sim.errors import InputError
from dynmap_sim.io.carmen import (
    CarmenLogError,
    CarmenOdometryWarning,
    interpolate_poses,
    read_carmen,
)


def trajectory(n=240):
    """A loop around the pillar: a rounded rectangle driven at ~0.4 m/s, 10 Hz."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    x = 3.0 + 1.8 * np.cos(t)
    y = 2.4 + 1.3 * np.sin(t)
    th = np.arctan2(1.3 * np.cos(t), -1.8 * np.sin(t))
    return np.column_stack([x, y, th])


def assert_poses_close(a, b, atol):
    d = np.asarray(a) - np.asarray(b)
    d[:, 2] = se2.wrap_angle(d[:, 2])
    assert np.abs(d).max() < atol


def write_log(path, kind="FLASER", n_beams=181, gz=False, odom_drift=True, seed=0):
    rng = np.random.default_rng(seed)
    segs = room_segments(cupboard=False)
    truth = trajectory()
    stamps = 1_000_000.0 + 0.1 * np.arange(len(truth))
    odo = [np.array([0.5, -0.2, 0.1])]
    for k in range(1, len(truth)):
        d = se2.between(truth[k - 1], truth[k])
        if odom_drift:
            d = d * [1.03, 1.03, 1.0] + [0, 0, 0.01 * np.hypot(d[0], d[1])]
        odo.append(se2.compose(odo[-1], d))
    odo = np.array(odo)
    fov = np.pi if n_beams == 181 else np.deg2rad(179.0)
    angles = -fov / 2 + fov / (n_beams - 1) * np.arange(n_beams)
    lines = ["# a test log", "PARAM robot_width 0.5 nohost 0"]
    for k in range(len(truth)):
        r = raycast(truth[k], angles, segs, 50.0) + rng.normal(0, 0.01, n_beams)
        r = np.where(np.isfinite(r), r, 81.92)
        rs = " ".join(f"{v:.3f}" for v in r)
        ts = stamps[k]
        if k % 2 == 0:  # odometry at its own (shifted) times: interpolated to the scans
            oi = interpolate_poses(stamps, odo, np.array([ts - 0.03]))[0]
            lines.append(f"ODOM {oi[0]:.6f} {oi[1]:.6f} {oi[2]:.6f} 0.4 0 0 {ts - 0.03:.6f} h 0")
        tp, op = truth[k], odo[k]
        if kind == "FLASER":
            pose = f"{tp[0]:.6f} {tp[1]:.6f} {tp[2]:.6f} {op[0]:.6f} {op[1]:.6f} {op[2]:.6f}"
            lines.append(f"FLASER {n_beams} {rs} {pose} {ts:.6f} h {ts:.6f}")
        elif kind == "ROBOTLASER1":
            lp = se2.compose(tp, [0.1, 0.0, 0.0])
            hdr = f"0 {-fov / 2:.9f} {fov:.9f} {fov / (n_beams - 1):.9f} 50.0 0.01 0"
            pose = f"{lp[0]:.6f} {lp[1]:.6f} {lp[2]:.6f} {tp[0]:.6f} {tp[1]:.6f} {tp[2]:.6f}"
            rs = " ".join(f"{v:.3f}" for v in raycast(lp, angles, segs, 50.0))
            lines.append(
                f"ROBOTLASER1 {hdr} {n_beams} {rs} 0 {pose} 0.4 0 0.5 0.3 0.1 {ts:.6f} h {ts:.6f}"
            )
        else:
            hdr = f"0 {-fov / 2:.9f} {fov:.9f} {fov / (n_beams - 1):.9f} 50.0 0.01 0"
            lines.append(f"RAWLASER1 {hdr} {n_beams} {rs} 0 {ts:.6f} h {ts:.6f}")
    text = "\n".join(lines) + "\n"
    if gz:
        with gzip.open(path, "wt") as fh:
            fh.write(text)
    else:
        path.write_text(text)
    return truth, odo, stamps


def test_flaser_with_interpolated_odometry(tmp_path):
    p = tmp_path / "a.log"
    truth, odo, stamps = write_log(p)
    log = read_carmen(p)
    assert log.message == "FLASER" and len(log) == len(truth)
    assert log.laser.n_beams == 181
    assert log.laser.angle_min_rad == pytest.approx(-np.pi / 2)
    assert log.laser.angle_increment_rad == pytest.approx(np.pi / 180)
    np.testing.assert_allclose(log.stamps_s, stamps)
    assert_poses_close(log.reference, truth, 1e-5)
    # Odometry interpolated from ODOM lines at other times matches the true odometry.
    err = np.hypot(*(log.odometry[2:-2, :2] - odo[2:-2, :2]).T)
    assert err.max() < 0.002  # linear interpolation of a curve: sub-mm chord error
    assert np.all(np.isfinite(log.ranges_m))
    assert log.ranges_m.dtype == np.float32
    odom, scan = log.stream()[5]
    assert scan.stamp_s == odom.stamp_s == stamps[5]


def test_robotlaser_gzip_mount_and_rawlaser(tmp_path):
    p = tmp_path / "b.log.gz"
    truth, _, _ = write_log(p, kind="ROBOTLASER1", gz=True)
    # its robot poses are the truth, its ODOM lines drifting odometry: a corrected log
    with pytest.warns(CarmenOdometryWarning, match="this looks like a corrected log"):
        log = read_carmen(p)
    assert log.message == "ROBOTLASER1" and log.odometry_source == "laser-lines"
    assert log.laser.mount_pose == pytest.approx((0.1, 0.0, 0.0), abs=1e-6)
    assert_poses_close(log.reference, truth, 1e-5)
    p2 = tmp_path / "c.log"
    write_log(p2, kind="RAWLASER1", n_beams=180)
    raw = read_carmen(p2)
    assert raw.reference is None
    assert raw.laser.angle_increment_rad == pytest.approx(np.deg2rad(1.0))
    assert np.isinf(raw.ranges_m).sum() == 0


def test_bad_log_names_file_and_line(tmp_path):
    p = tmp_path / "bad.log"
    p.write_text("ODOM 0 0 0 0 0 0 1.0 h 0\nFLASER 3 1.0 x 1.0 0 0 0 0 0 0 2.0 h 0\n")
    with pytest.raises(CarmenLogError) as ei:
        read_carmen(p)
    assert "bad.log" in str(ei.value) and "line 2" in str(ei.value)
    with pytest.raises(CarmenLogError, match="file not found"):
        read_carmen(tmp_path / "missing.log")
    empty = tmp_path / "empty.log"
    empty.write_text("ODOM 0 0 0 0 0 0 1.0 h 0\n")
    with pytest.raises(InputError, match="no laser lines"):
        read_carmen(empty)


def test_replay_writes_results(tmp_path):
    p = tmp_path / "loop.log"
    write_log(p)
    out = tmp_path / "out"
    rc = main(
        [
            "replay",
            str(p),
            "--localizer",
            "static-mcl",
            "--localizer",
            "static-mcl,config=nav2-default",
            "--reference",  # the log's own laser-line poses are the truth
            str(p),
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    con = sqlite3.connect(out / "results.db")
    rows = con.execute(
        "SELECT loc, day, mean_error_m, max_error_m FROM run_summaries ORDER BY loc, day"
    ).fetchall()
    assert len(rows) == 4
    for loc, day, mean_e, max_e in rows:
        assert mean_e < 0.1 and max_e < 0.3, (loc, day, mean_e, max_e)
    # With the map from the log's corrected poses.
    out2 = tmp_path / "out2"
    assert (
        main(
            [
                "replay",
                str(p),
                "--localizer",
                "static-mcl",
                "--map-from-log-poses",
                "--reference",
                str(p),
                "--out",
                str(out2),
            ]
        )
        == 0
    )
    con2 = sqlite3.connect(out2 / "results.db")
    (mean_e,) = con2.execute("SELECT mean_error_m FROM run_summaries WHERE day=2").fetchone()
    assert mean_e < 0.1


def test_replay_seed_draws_the_filters_anew_and_repeats_itself(tmp_path, capsys):
    """``replay --seed``: the same seed gives the same estimates bit for bit, another seed
    another draw of the particle filter; the seed is stored; a bad one is a usage error."""
    p = tmp_path / "loop.log"
    write_log(p)

    def estimates(seed: int, name: str) -> np.ndarray:
        out = tmp_path / name
        args = ["replay", str(p), "--localizer", "static-mcl", "--seed", str(seed)]
        assert main([*args, "--out", str(out)]) == 0
        con = sqlite3.connect(out / "results.db")
        rows = con.execute("SELECT x, y, theta FROM estimates ORDER BY day, step").fetchall()
        (meta,) = con.execute("SELECT value FROM meta WHERE key='seed'").fetchone()
        con.close()
        assert json.loads(meta) == seed
        return np.array(rows)

    a, b, c = estimates(3, "a"), estimates(3, "b"), estimates(4, "c")
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)
    with pytest.raises(SystemExit):
        main(["replay", str(p), "--localizer", "static-mcl", "--seed", "-1", "--out", "d"])
    assert "seed must be in 0..2**63-1" in capsys.readouterr().err


def test_replay_bad_log_is_a_clean_error(tmp_path, capsys):
    p = tmp_path / "bad.log"
    p.write_text("FLASER nope\n")
    assert main(["replay", str(p), "--localizer", "static-mcl", "--out", str(tmp_path)]) == 2
    assert "bad.log" in capsys.readouterr().err


def test_a_replay_folder_reports_and_exports_like_an_experiment(tmp_path, capsys):
    """issue 14: report and export of a replay folder work, its summary names the log and both
    runs, update times are measured; --map-from-log-poses says who takes the map."""
    p = tmp_path / "loop.log"
    write_log(p)
    out = tmp_path / "r"
    args = ["replay", str(p), "--localizer", "odometry", "--localizer", "static-mcl"]
    assert main([*args, "--reference", str(p), "--out", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == f"results in {out}"
    assert lines[1].startswith("localizer") and "ATE RMSE [m]" in lines[1]  # the headline
    assert [ln.split()[0] for ln in lines[2:]] == ["odometry", "static-mcl"]
    assert main(["report", str(out)]) == 0
    summary = (out / "summary.md").read_text()
    assert "world: `CARMEN log loop.log`" in summary and "2 of 2 runs done" in summary
    assert "(incomplete)" not in summary
    overall = [ln for ln in summary.splitlines() if ln.startswith(("| odometry", "| static-mcl"))]
    assert len(overall) >= 2 and not any(ln.endswith("| nan |") for ln in overall[:2])
    tum = tmp_path / "tum"
    assert main(["export", str(out), "--tum", str(tum)]) == 0
    names = sorted(q.name for q in tum.iterdir())
    assert names == [
        "odometry-mapping.tum",
        "odometry.tum",
        "static-mcl-mapping.tum",
        "static-mcl.tum",
        "truth.tum",
    ]
    for q in tum.iterdir():
        t = np.loadtxt(q)[:, 0]
        assert len(t) == 240 and np.all(np.diff(t) > 0)
        assert t[0] == pytest.approx(1_000_000.0)  # the log's own clock
    capsys.readouterr()
    # the map from the log's poses: refused when no localizer takes one, else said who does
    only = ["replay", str(p), "--localizer", "odometry", "--map-from-log-poses"]
    assert main([*only, "--out", str(tmp_path / "m0")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "none of the localizers takes a map (odometry)" in err
    assert not (tmp_path / "m0" / "results.db").exists()
    assert main([*args, "--map-from-log-poses", "--out", str(tmp_path / "m1")]) == 0
    err = capsys.readouterr().err
    assert "goes to static-mcl; not to odometry, which take no map" in err


def test_a_localizer_breaking_its_contract_in_a_replay_is_named(tmp_path, capsys, monkeypatch):
    from dynmap_sim.agent.localization.dead_reckoning import DeadReckoning

    p = tmp_path / "loop.log"
    write_log(p)
    monkeypatch.setattr(DeadReckoning, "update", lambda self, odom, scan: None)
    assert main(["replay", str(p), "--localizer", "odometry", "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and err.count("\n") == 0
    cls = "dynmap_sim.agent.localization.dead_reckoning.DeadReckoning"
    assert f"localizer 'odometry' ({cls}) broke" in err
    assert "on pass 1 (mapping) at scan 0: update() must return a PoseEstimate, got None" in err
