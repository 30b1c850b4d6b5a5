"""World files: every kind of mistake gives a clear error naming the field."""

import json
from pathlib import Path

import pytest

from dynmap_sim.errors import FileError
from dynmap_sim.world import WorldFileError, load_world, parse_world, world_json_schema

ROOT = Path(__file__).resolve().parents[2]


def errors_of(data) -> list[tuple[str, str]]:
    with pytest.raises(WorldFileError) as info:
        parse_world(data, "bad.toml")
    assert isinstance(info.value, FileError) and isinstance(info.value, ValueError)
    assert "bad.toml" in str(info.value)
    return info.value.errors


def has(errors, loc, text):
    return any(e[0] == loc and text in e[1] for e in errors), errors


def test_base_world_is_valid(base_world):
    spec = parse_world(base_world)
    assert spec.robot.route.shape == (3, 2)
    assert spec.robot.route_length_m == pytest.approx(6.0)


def test_size_must_be_positive(base_world):
    base_world["objects"][0]["size"] = [1.0, -0.6]
    ok, errs = has(errors_of(base_world), "objects.0.size", "sizes must be > 0")
    assert ok, errs


def test_unknown_field_is_rejected(base_world):
    base_world["objects"][0]["colour"] = "red"
    ok, errs = has(errors_of(base_world), "objects.0.colour", "Extra inputs are not permitted")
    assert ok, errs


def test_missing_field(base_world):
    del base_world["calendar"]["n_days"]
    ok, errs = has(errors_of(base_world), "calendar.n_days", "Field required")
    assert ok, errs


def test_shape_needs_its_parameters(base_world):
    base_world["objects"][0] = {
        "id": "t",
        "kind": "furniture",
        "shape": "circle",
        "pose": [3, 3, 0],
    }
    ok, errs = has(errors_of(base_world), "objects.0", "needs 'radius_m'")
    assert ok, errs


def test_non_convex_polygon(base_world):
    base_world["objects"][0] = {
        "id": "t",
        "kind": "furniture",
        "shape": "polygon",
        "vertices": [[0, 0], [1, 0], [0.2, 0.2], [0, 1]],
        "pose": [3, 3, 0],
    }
    ok, errs = has(errors_of(base_world), "objects.0.vertices", "convex")
    assert ok, errs


def test_bad_run_time(base_world):
    base_world["calendar"]["runs"] = ["9h", "14:00"]
    ok, errs = has(errors_of(base_world), "calendar.runs", "HH:MM")
    assert ok, errs


def test_unknown_action(base_world):
    base_world["schedule"].append({"action": "teleport", "target": "table", "at": 2})
    errs = errors_of(base_world)
    assert any(e[0] == "schedule.4" for e in errs), errs


def test_duplicate_ids(base_world):
    base_world["objects"][1]["id"] = "table"
    ok, errs = has(errors_of(base_world), "objects.1.id", "duplicate id 'table'")
    assert ok, errs


def test_unknown_group(base_world):
    base_world["schedule"][0]["group"] = "expos"
    ok, errs = has(errors_of(base_world), "schedule.0.group", "unknown group 'expos'")
    assert ok, errs


def test_unknown_target(base_world):
    base_world["schedule"][2]["target"] = "gate"
    ok, errs = has(errors_of(base_world), "schedule.2.target", "unknown object id 'gate'")
    assert ok, errs


def test_event_outside_calendar(base_world):
    base_world["schedule"][0]["end"] = 12
    ok, errs = has(errors_of(base_world), "schedule.0.end", "outside the calendar")
    assert ok, errs


def test_event_date_outside_calendar(base_world):
    import datetime as dt

    base_world["schedule"][2]["at"] = dt.date(2023, 12, 1)
    ok, errs = has(errors_of(base_world), "schedule.2.at", "outside the calendar")
    assert ok, errs


def test_run_beyond_runs_per_day(base_world):
    base_world["schedule"][2]["run"] = 3
    ok, errs = has(errors_of(base_world), "schedule.2.run", "2 per day")
    assert ok, errs


def test_object_inside_wall(base_world):
    base_world["objects"][0]["pose"] = [3.0, 3.9, 0.0]
    ok, errs = has(errors_of(base_world), "objects.0", "inside wall 'outer.2'")
    assert ok, errs


def test_move_into_wall(base_world):
    base_world["schedule"].append(
        {"action": "move", "target": "table", "at": 2, "pose": [5.9, 2.0, 0.0]}
    )
    ok, errs = has(errors_of(base_world), "schedule.4.pose", "inside wall")
    assert ok, errs


def test_route_through_wall(base_world):
    base_world["robot"]["route"].append([7.0, 3.0])
    errs = errors_of(base_world)
    ok, _ = has(errs, "robot.route.2", "goes through wall 'outer.1'")
    assert ok, errs


def test_door_event_on_a_non_door(base_world):
    base_world["schedule"][2]["target"] = "table"
    ok, errs = has(errors_of(base_world), "schedule.2.target", "is not a door")
    assert ok, errs


def test_removing_an_installation(base_world):
    base_world["schedule"] += [
        {"action": "install", "target": "table", "at": 2},
        {"action": "remove", "target": "table", "at": 3},
    ]
    ok, errs = has(errors_of(base_world), "schedule.5", "permanent installation")
    assert ok, errs


def test_all_errors_reported_at_once(base_world):
    base_world["objects"][1]["id"] = "table"
    base_world["schedule"][0]["group"] = "nope"
    base_world["schedule"][2]["at"] = 99
    errs = errors_of(base_world)
    assert len(errs) >= 3


def test_file_errors(tmp_path):
    with pytest.raises(WorldFileError, match="file not found"):
        load_world(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("name = [unclosed")
    with pytest.raises(WorldFileError, match="TOML syntax error"):
        load_world(bad)


def test_shipped_schema_is_current():
    shipped = json.loads((ROOT / "worlds" / "world.schema.json").read_text())
    assert shipped == json.loads(json.dumps(world_json_schema()))


def test_growing_into_a_wall(base_world):
    base_world["schedule"][3]["scale_end"] = 4.0  # the plant at 0.5 m from the wall, r 0.2
    ok, errs = has(errors_of(base_world), "objects.5", "inside wall")
    assert ok, errs


def test_docstring_example_is_a_valid_world():
    import textwrap
    import tomllib

    import dynmap_sim.world.spec as spec_module

    doc = spec_module.__doc__
    example = doc[doc.index("A minimal file::") + 16 : doc.index("Set ``blocks_route")]
    spec = parse_world(tomllib.loads(textwrap.dedent(example)))
    assert spec.name == "room" and spec.people[0].count == 3
