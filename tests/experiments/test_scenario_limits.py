"""Scenario values that used to validate and then crash or hang ``run`` are refused when the
scenario is loaded, with the file and the field (issue 14, audit items 6, 7 and 9)."""

from __future__ import annotations

import pytest

from dynmap_sim.cli import main
from dynmap_sim.experiments.scenario import ScenarioFileError, load_scenario

BASE = """
name = "{name}"
world = "apartment"
days = [1, 2]
seeds = [{seed}]
[driver]
max_run_s = {max_run_s}
[prior]
initial_pose_sigma_xy_m = {sxy}
initial_pose_sigma_theta_rad = {sth}
[robot.overrides]
{robot}
[[localizers]]
name = "odometry"
{kidnap}
"""

GOOD = {
    "name": "x",
    "seed": "0",
    "max_run_s": "20.0",
    "sxy": "0.05",
    "sth": "0.05",
    "robot": "",
    "kidnap": "",
}


def scenario(tmp_path, **changes):
    p = tmp_path / "s.toml"
    p.write_text(BASE.format(**(GOOD | changes)))
    return p


def kidnap(time_s="8.0", pose="[5.9, 5.0, -1.5]", day=2, run=1):
    return f"[[kidnappings]]\nday = {day}\nrun = {run}\ntime_s = {time_s}\npose = {pose}\n"


def test_the_base_scenario_is_valid(tmp_path):
    load_scenario(scenario(tmp_path, kidnap=kidnap()))


@pytest.mark.parametrize(
    ("changes", "field", "words"),
    [
        ({"kidnap": kidnap(time_s="nan")}, "kidnappings.0.time_s", "0..86400"),
        ({"kidnap": kidnap(time_s="inf")}, "kidnappings.0.time_s", "0..86400"),
        ({"kidnap": kidnap(time_s="1e308")}, "kidnappings.0.time_s", "0..86400"),
        ({"kidnap": kidnap(pose="[nan, 5.0, 0.0]")}, "kidnappings.0.pose", "finite"),
        ({"kidnap": kidnap(pose="[1e308, 5.0, 0.0]")}, "kidnappings.0.pose", "bounds"),
        ({"kidnap": kidnap(pose="[5.0, 5.0, 1e308]")}, "kidnappings.0.pose", "theta"),
        ({"kidnap": kidnap(pose="[100.0, 5.0, 0.0]")}, "kidnappings.0.pose", "outside the world"),
        ({"kidnap": kidnap(pose="[5.0, -3.0, 0.0]")}, "kidnappings.0.pose", "outside the world"),
        ({"kidnap": kidnap(run=7)}, "kidnappings.0.run", "runs 1-"),
        ({"max_run_s": "inf"}, "driver.max_run_s", "finite"),
        ({"max_run_s": "1e308"}, "driver.max_run_s", "86400"),
        ({"sxy": "inf"}, "prior.initial_pose_sigma_xy_m", "finite"),
        ({"sxy": "1e308"}, "prior.initial_pose_sigma_xy_m", "100"),
        ({"sth": "1e308"}, "prior.initial_pose_sigma_theta_rad", "6.28"),
        ({"seed": str(2**64)}, "seeds", ""),
        ({"seed": str(2**63)}, "seeds", "2**63-1"),
        ({"robot": "max_substep_m = 1e-9"}, "robot.overrides", "max_substep_m must be in"),
        ({"robot": "wheels = { e_d = 1e308 }"}, "robot.overrides", "e_d must be in 0.5..2"),
        ({"robot": "wheels = { e_b = 0.0 }"}, "robot.overrides", "e_b must be finite and > 0"),
        ({"robot": "radius_m = 1e308"}, "robot.overrides", "radius_m must be in"),
        ({"robot": "encoder = { ticks_per_rev = 1.5 }"}, "robot.overrides", "ticks_per_rev"),
        ({"name": "../../X"}, "name", "file name"),
        ({"name": ".."}, "name", "file name"),
        ({"name": "a\\\\b"}, "name", "file name"),
    ],
)
def test_values_that_crashed_or_hung_run_are_refused_with_file_and_field(
    tmp_path, changes, field, words
):
    p = scenario(tmp_path, **changes)
    with pytest.raises(ScenarioFileError) as ei:
        load_scenario(p)
    errs = dict(ei.value.errors)
    assert field in errs, ei.value.errors
    assert words in errs[field]
    assert str(p) in str(ei.value)


def test_the_cli_refuses_them_in_one_line_before_running(tmp_path, capsys):
    p = scenario(tmp_path, name="../../escape", kidnap=kidnap(time_s="inf"))
    assert main(["run", str(p), "--out", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "name" in err and "kidnappings.0.time_s" in err
    assert not (tmp_path / "out").exists()
    assert not (tmp_path.parent / "escape").exists()
