"""Scenario files: shipped ones validate; bad ones report every problem with file and field."""

import json
from pathlib import Path

import pytest

from dynmap_sim.experiments.scenario import (
    Scenario,
    ScenarioFileError,
    is_scenario_file,
    load_scenario,
    scenario_json_schema,
)

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = sorted((ROOT / "worlds" / "scenarios").glob("*.toml"))


def test_there_are_shipped_scenarios():
    names = {p.name for p in SCENARIOS}
    assert "ci-apartment.toml" in names
    assert "apartment-28d.toml" in names


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.name)
def test_every_shipped_scenario_validates(path):
    scn = load_scenario(path)
    assert isinstance(scn, Scenario)
    assert scn.world_path.is_file()
    assert is_scenario_file(path)
    assert len(set(scn.labels)) == len(scn.labels)
    if path.name.startswith("ci-"):
        # CI scenarios stay small: a few days, a time limit per run
        assert scn.days[1] - scn.days[0] < 5
        assert scn.driver.max_run_s is not None and scn.driver.max_run_s <= 90


def write(tmp_path, text, name="s.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_all_errors_at_once_with_file_and_field(tmp_path):
    p = write(
        tmp_path,
        """
name = ""
world = "nowhere"
days = [5, 2]
bogus = 3
[driver]
speed_mps = -1
[[localizers]]
name = "no-such-localizer"
[expectations.localizers.x]
lost_fraction = 2
""",
    )
    with pytest.raises(ScenarioFileError) as ei:
        load_scenario(p)
    err = ei.value
    fields = {loc for loc, _ in err.errors}
    assert {
        "name",
        "world",
        "days",
        "bogus",
        "driver.speed_mps",
        "localizers.0.name",
        "expectations.localizers.x.lost_fraction",
    } <= fields
    assert str(p) in str(err)
    assert "no-such-localizer" in str(err) and "odometry" in str(err)


def test_cross_field_errors(tmp_path):
    p = write(
        tmp_path,
        """
name = "x"
world = "apartment"
days = "1-40"
[[localizers]]
name = "odometry"
[[localizers]]
name = "dynmap_sim.agent.localization.dead_reckoning:DeadReckoning"
label = "odometry"
params = { wrong = 1 }
[[kidnappings]]
day = 50
[expectations.localizers.ghost]
mean_error_m = 1
""",
    )
    with pytest.raises(ScenarioFileError) as ei:
        load_scenario(p)
    errs = dict(ei.value.errors)
    assert "used twice" in errs["localizers.1.label"]
    assert "wrong" in errs["localizers.1.params"]
    assert "ghost" in errs["expectations.localizers.ghost"]
    assert "outside days" in errs["kidnappings.0.day"]
    assert "28 days" in errs["days"]


def test_required_findings_are_known_keys_and_need_a_dynamic_map(tmp_path):
    p = write(
        tmp_path,
        """
name = "f"
world = "lab"
days = 2
[[localizers]]
name = "static-map"
[expectations]
findings = ["ltm_usage_rises", "lambda5_is_great"]
""",
    )
    from dynmap_sim.analysis.scenarios import load_scenario as load_with_findings

    load_scenario(p)  # the engine does not know the studies' findings ...
    with pytest.raises(ScenarioFileError) as ei:  # ... the analysis does
        load_with_findings(p)
    errs = dict(ei.value.errors)
    assert "unknown finding 'lambda5_is_great'" in errs["expectations.findings.1"]
    assert "ltm_usage_rises" in errs["expectations.findings.1"]  # the known keys are listed
    assert "dynamic-map" in errs["expectations.findings"]
    assert "expectations.findings.0" not in errs
    assert str(p) in str(ei.value)


def test_same_class_twice_with_labels_and_module_path(tmp_path):
    p = write(
        tmp_path,
        """
name = "two"
world = "apartment"
days = 3
[[localizers]]
name = "odometry"
label = "odo-a"
[[localizers]]
name = "dynmap_sim.agent.localization.dead_reckoning:DeadReckoning"
label = "odo-b"
params = { var_per_m = 0.01 }
[[kidnappings]]
day = 3
time_s = 5.0
pose = [2.0, 3.0, 0.0]
[expectations.localizers.odo-b]
max_error_m = 1.0
""",
    )
    scn = load_scenario(p)
    assert scn.days == (3, 3)
    assert scn.labels == ["odo-a", "odo-b"]
    assert scn.kidnappings[0].pose == (2.0, 3.0, 0.0)
    assert scn.expectations.localizers["odo-b"].max_error_m == 1.0


def test_world_path_relative_to_the_scenario_file(tmp_path):
    world = (ROOT / "worlds" / "apartment.toml").read_text()
    (tmp_path / "w").mkdir()
    (tmp_path / "w" / "mine.toml").write_text(world)
    p = write(
        tmp_path,
        'name = "r"\nworld = "w/mine.toml"\ndays = [1, 1]\n[[localizers]]\nname = "odometry"\n',
    )
    scn = load_scenario(p)
    assert scn.world_path == (tmp_path / "w" / "mine.toml").resolve()
    # the hash covers the world file: change it and the hash changes
    h = scn.content_hash()
    (tmp_path / "w" / "mine.toml").write_text(world + "\n# changed\n")
    assert load_scenario(p).content_hash() != h


def test_syntax_error_and_missing_file(tmp_path):
    p = write(tmp_path, "name = \n")
    with pytest.raises(ScenarioFileError, match="TOML syntax error"):
        load_scenario(p)
    with pytest.raises(ScenarioFileError, match="file not found"):
        load_scenario(tmp_path / "missing.toml")


def test_is_scenario_file_tells_worlds_apart():
    assert not is_scenario_file(ROOT / "worlds" / "apartment.toml")
    assert is_scenario_file(ROOT / "worlds" / "scenarios" / "ci-apartment.toml")


def test_json_schema():
    schema = scenario_json_schema()
    json.dumps(schema)
    assert {"world", "days", "localizers", "expectations"} <= set(schema["properties"])
    assert schema.get("additionalProperties") is False


def test_robot_and_sensor_overrides_are_checked(tmp_path):
    p = write(
        tmp_path,
        """
name = "x"
world = "apartment"
days = [1, 2]
[sensor]
preset = "urg-04lx"
overrides = { foo = 1 }
[robot.overrides]
radius_m = -1
[[localizers]]
name = "odometry"
""",
    )
    with pytest.raises(ScenarioFileError) as ei:
        load_scenario(p)
    errs = dict(ei.value.errors)
    assert "radius_m" in errs["robot.overrides"]
    assert "foo" in errs["sensor"]
    ok = write(
        tmp_path,
        'name = "y"\nworld = "apartment"\ndays = [1, 1]\n[sensor]\npreset = "lms200"\n'
        "overrides = { beams = 361, noise = { p_dropout = 0.0 } }\n"
        '[robot.overrides]\nwheels = { e_d = 1.01 }\n[[localizers]]\nname = "odometry"\n',
        "ok.toml",
    )
    from dynmap_sim.env_factory import make_env

    env = make_env(load_scenario(ok).sim_spec())
    assert env.laser_spec.n_beams == 361 and env.robot_params.wheels.e_d == 1.01
