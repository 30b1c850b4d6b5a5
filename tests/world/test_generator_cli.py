"""``dynmap-sim generate`` and what ``validate`` says about generated and hand-written worlds:
bad input is one line with exit 2 and nothing written; a route the robot cannot follow on
some day is a warning naming the day and the place; a pose out of the bounds an error."""

from pathlib import Path

import pytest

from dynmap_sim.cli import main
from dynmap_sim.experiments.scenario import load_scenario
from dynmap_sim.world import WorldFileError, load_world, parse_world

ROOT = Path(__file__).resolve().parents[2]


def run_cli(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_generate_writes_a_world_and_a_scenario_that_validate(capsys, tmp_path):
    w, s = tmp_path / "w.toml", tmp_path / "sub" / "s.toml"
    s.parent.mkdir()
    code, out, err = run_cli(
        capsys,
        "generate",
        "apartment",
        "--seed",
        "2",
        "-o",
        w,
        "--scenario",
        s,
        "--param",
        "days=4",
        "--param",
        "people=3",
    )
    assert code == 0, err
    assert load_scenario(s).world_path == w.resolve()
    assert load_world(w).calendar.n_days == 4
    code, out, err = run_cli(capsys, "validate", w, s)
    assert code == 0 and out.count("OK") == 2 and "warning" not in err, err
    code, out, err = run_cli(capsys, "render-world", w, w, "--sheet", "-o", tmp_path / "sheet.png")
    assert code == 0, err
    assert (tmp_path / "sheet.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    "args,msg",
    [
        (["castle", "--seed", "1"], "unknown kind 'castle'"),
        (["lab", "--seed", "one"], "the seed must be an integer, not 'one'"),
        (["lab", "--seed", "1", "--param", "days=61"], "parameter days = 61 is outside its range"),
        (["lab", "--seed", "1", "--param", "days"], "--param takes key=value"),
        (["lab", "--seed", "1", "--scenario", "/no/such/dir/s.toml"], "folder /no/such/dir does"),
    ],
)
def test_bad_input_is_one_line_exit_2_nothing_written(capsys, tmp_path, args, msg):
    w = tmp_path / "w.toml"
    code, out, err = run_cli(capsys, "generate", *args, "-o", w)
    assert code == 2
    assert err.startswith("error: ") and msg in err and err.count("\n") == 1, err
    assert list(tmp_path.iterdir()) == []


def test_an_existing_file_is_replaced_only_with_force(capsys, tmp_path):
    w = tmp_path / "w.toml"
    w.write_text("mine\n")
    code, _, err = run_cli(capsys, "generate", "hall", "--seed", "0", "-o", w)
    assert code == 2 and "already exists; pass --force" in err
    assert w.read_text() == "mine\n"
    code, _, err = run_cli(
        capsys, "generate", "hall", "--seed", "0", "-o", w, "--force", "--param", "days=2"
    )
    assert code == 0, err
    assert w.read_text().startswith("# A generated hall")


def test_an_unwritable_folder_is_one_line(capsys, tmp_path):
    d = tmp_path / "ro"
    d.mkdir()
    d.chmod(0o500)
    try:
        code, _, err = run_cli(capsys, "generate", "lab", "--seed", "0", "-o", d / "w.toml")
    finally:
        d.chmod(0o700)
    if code == 0:  # root writes anywhere
        pytest.skip("running as root: the folder is writable")
    assert code == 2 and "is not writable" in err and list(d.iterdir()) == []


# -- validation of poses and routes (issue 43 item 5) and route warnings (issue 39 item 4) --

TWO_ROOMS = """name = "two"
bounds = [-0.5, -0.5, 10.5, 5.5]
[calendar]
start = 2024-01-01
n_days = 3
runs = ["09:00"]
[robot]
start = START
route = ROUTE
[[walls]]
id = "outer"
points = [[0, 0], [10, 0], [10, 5], [0, 5], [0, 0]]
thickness_m = 0.2
[[walls]]
id = "mid_s"
points = [[5, 0], [5, GAP0]]
[[walls]]
id = "mid_n"
points = [[5, GAP1], [5, 5]]
[[objects]]
id = "box"
kind = "furniture"
size = [0.6, 0.6]
pose = [8.0, 4.0, 0.0]
present = false
[[schedule]]
action = "add"
target = "box"
at = 2
"""
LOOP = "[[1.0, 2.5], [7.5, 2.5], [7.5, 3.5], [6.0, 2.5], [1.0, 2.5]]"


def two_rooms(tmp_path, route=LOOP, gap=(2.0, 3.1), start="[1.0, 2.5, 0.0]"):
    text = TWO_ROOMS.replace("ROUTE", route).replace("START", start)
    text = text.replace("GAP0", str(gap[0])).replace("GAP1", str(gap[1]))
    p = tmp_path / "two.toml"
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    "route,gap,warnings",
    [
        (LOOP, (2.0, 3.1), []),
        (
            LOOP,
            (2.3, 2.75),
            [
                "day 1 run 1: robot.route.0 at (4.95, 2.50): leg 0->1 passes a gap "
                "of 0.35 m between 'mid_s' and 'mid_n', narrower than the robot "
                "(0.40 m)"
            ],
        ),
        (
            "[[1.0, 2.5], [7.0, 2.5], [8.5, 4.0], [6.0, 2.5], [1.0, 2.5]]",
            (2.0, 3.1),
            [
                "day 2 run 1: robot.route.1 at (8.21, 3.71): leg 1->2 is blocked by 'box' "
                "(furniture) and there is no way round"
            ],
        ),
        (
            "[[1.0, 2.5], [1.0, 2.5]]",
            (2.0, 3.1),
            [
                "robot.route.0 at (1.00, 2.50): leg 0->1 has no length",
                "robot.route at (1.00, 2.50): the route ends where it starts with nothing between",
            ],
        ),
    ],
)
def test_validate_warns_where_the_route_cannot_be_followed(capsys, tmp_path, route, gap, warnings):
    p = two_rooms(tmp_path, route, gap)
    code, out, err = run_cli(capsys, "validate", p)
    assert code == 0 and out == f"{p}: OK\n"
    lines = err.splitlines()
    for w in warnings:
        assert any(line.startswith(f"warning: {p}: {w}") for line in lines), err
    assert len(lines) >= len(warnings) and (warnings or not lines), err


def test_the_shipped_worlds_have_no_route_warnings(capsys):
    worlds = sorted((ROOT / "worlds").glob("*.toml"))
    code, out, err = run_cli(capsys, "validate", *worlds)
    assert code == 0 and err == "", err


@pytest.mark.parametrize(
    "start,msg",
    [
        ("[1e308, 1e308, 0]", "robot.start: start pose at (1e+308, 1e+308) is outside the world"),
        ("[-3.0, 2.0, 0]", "robot.start: start pose at (-3, 2) is outside the world bounds"),
        ("[1.0, 2.5, 1e9]", "robot.start: start pose: heading 1e+09 rad is not within +-100"),
    ],
)
def test_a_start_outside_the_bounds_is_refused_naming_file_and_field(capsys, tmp_path, start, msg):
    p = two_rooms(tmp_path, start=start)
    code, out, err = run_cli(capsys, "validate", p)
    assert code == 1 and err.startswith(f"{p}: {msg}") and err.count("\n") == 1, err


def test_far_poses_of_objects_routes_and_bounds_are_refused(base_world):
    base_world["objects"][0]["pose"] = [1e308, 1e308, 0.0]
    base_world["robot"]["route"][1] = [-1e308, 1.0]
    base_world["schedule"].append(
        {"action": "move", "target": "table", "at": 2, "pose": [1e300, 2.0, 0.0]}
    )
    with pytest.raises(WorldFileError) as info:
        parse_world(base_world, "far.toml")
    locs = [loc for loc, _ in info.value.errors]
    assert "objects.0" in locs and "robot.route.1" in locs
    assert f"schedule.{len(base_world['schedule']) - 1}.pose" in locs
    base_world = {**base_world, "bounds": [1e7, 1e7, 1e7 + 10, 1e7 + 10]}
    with pytest.raises(WorldFileError, match="bounds: bounds must lie within 1e"):
        parse_world(base_world, "far.toml")
