"""``dynmap-sim slam-eval`` on a small synthetic CARMEN log with relations from its truth."""

from __future__ import annotations

import json

import numpy as np
import pytest
from synthetic_scans import raycast, room_segments

from dynmap_sim import se2
from dynmap_sim.cli import main
from dynmap_sim.errors import InputError
from dynmap_sim.experiments.slam_eval import slam_eval


def write_log_and_relations(tmp_path, n=160, seed=0):
    """A loop in a room, FLASER lines with drifting odometry (3 % scale, 0.6 deg/m), and the
    benchmark's relations (consecutive scans and every 40th scan against the first)."""
    rng = np.random.default_rng(seed)
    segs = room_segments(cupboard=False)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    truth = np.column_stack(
        [
            3.0 + 1.8 * np.cos(t),
            2.4 + 1.3 * np.sin(t),
            np.arctan2(1.3 * np.cos(t), -1.8 * np.sin(t)),
        ]
    )
    stamps = 1_000.0 + 0.1 * np.arange(n)
    odo = [truth[0].copy()]
    for k in range(1, n):
        d = se2.between(truth[k - 1], truth[k])
        odo.append(se2.compose(odo[-1], d * [1.03, 1.03, 1.0] + [0, 0, 0.01 * np.hypot(*d[:2])]))
    angles = -np.pi / 2 + np.pi / 180 * np.arange(181)
    lines = []
    for k in range(n):
        r = raycast(truth[k], angles, segs, 50.0) + rng.normal(0, 0.01, 181)
        rs = " ".join(f"{v:.3f}" for v in np.where(np.isfinite(r), r, 81.92))
        o = odo[k]
        pose = f"{o[0]:.6f} {o[1]:.6f} {o[2]:.6f} {o[0]:.6f} {o[1]:.6f} {o[2]:.6f}"
        lines.append(f"FLASER 181 {rs} {pose} {stamps[k]:.6f} h {stamps[k]:.6f}")
    log = tmp_path / "room.log"
    log.write_text("\n".join(lines) + "\n")
    pairs = [(k, k + 1) for k in range(0, n - 1, 3)] + [(0, k) for k in range(40, n, 40)]
    rel_lines = []
    for i, j in pairs:
        d = se2.between(truth[i], truth[j])
        rel_lines.append(f"{stamps[i]:.6f} {stamps[j]:.6f} {d[0]:.6f} {d[1]:.6f} 0 0 0 {d[2]:.6f}")
    rel = tmp_path / "room.relations"
    rel.write_text("\n".join(rel_lines) + "\n")
    return log, rel, len(pairs)


def test_slam_eval_beats_odometry_and_writes_tum_and_json(tmp_path, capsys):
    log, rel, n_rel = write_log_and_relations(tmp_path)
    res = slam_eval(log, rel)
    assert res.loop_closed.n_relations == n_rel and res.n_scans == 160
    assert res.loop_closed.translation_mean_m < 0.5 * res.odometry_error.translation_mean_m
    assert res.loop_closed.translation_mean_m < 0.05
    tum, out = tmp_path / "traj.txt", tmp_path / "err.json"
    assert (
        main(
            [
                "slam-eval",
                str(log),
                "--relations",
                str(rel),
                "--tum",
                str(tum),
                "--json",
                str(out),
                "-q",
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "loop-closed" in text and "scans/s" in text
    rows = np.loadtxt(tum)
    assert rows.shape == (160, 8)
    np.testing.assert_allclose(rows[:, 0], 1_000.0 + 0.1 * np.arange(160), atol=1e-6)
    d = json.loads(out.read_text())
    for key in (
        "n_relations",
        "translation_mean_m",
        "translation_std_m",
        "rotation_mean_deg",
        "rotation_std_deg",
    ):
        assert key in d
    assert d["n_relations"] == n_rel
    assert (d["odometry_reversals"], d["odometry_reversals_found"]) == ("repair", 0)
    assert d["translation_mean_m"] == pytest.approx(res.loop_closed.translation_mean_m, abs=1e-9)
    # refuses to overwrite without --force
    assert main(["slam-eval", str(log), "--relations", str(rel), "--json", str(out), "-q"]) == 2
    assert "--force" in capsys.readouterr().err


def test_relations_of_another_log_are_refused(tmp_path):
    log, _, _ = write_log_and_relations(tmp_path, n=30)
    other = tmp_path / "other.relations"
    other.write_text("5.0 6.0 1 0 0 0 0 0\n")
    with pytest.raises(InputError, match="none of its 1 relations"):
        slam_eval(log, other)


def test_incremental_closures_hold_on_the_synthetic_loop(tmp_path):
    from dynmap_sim.agent.mapping.first_run import FirstRunConfig

    log, rel, n_rel = write_log_and_relations(tmp_path)
    cfg = FirstRunConfig.from_params(incremental_loops=True, keep_closures=True)
    res = slam_eval(log, rel, config=cfg)
    assert res.loop_closed.n_relations == n_rel
    assert res.loop_closed.translation_mean_m < 0.05


def test_mapper_params_are_passed_and_checked(tmp_path, capsys):
    log, rel, _ = write_log_and_relations(tmp_path, n=60)
    args = ["slam-eval", str(log), "--relations", str(rel), "-q"]
    assert main([*args, "--mapper-param", "seed_window=[0.3,0.4]"]) == 0
    assert "loop-closed" in capsys.readouterr().out
    assert main([*args, "--mapper-param", "no_such_param=1"]) == 2
    assert "no_such_param" in capsys.readouterr().err
