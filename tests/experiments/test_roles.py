"""Roles picked by name or ``module:Class`` from scenario files: a user's own driver,
planner and controller (examples/own_navigation.py), and the registries' errors."""

from pathlib import Path

import numpy as np
import pytest

from dynmap_sim.agent.control.controller import CONTROLLERS
from dynmap_sim.agent.control.pure_pursuit import PurePursuit
from dynmap_sim.agent.planning.grid_dijkstra import GridDijkstra
from dynmap_sim.agent.planning.planner import PLANNERS
from dynmap_sim.experiments.drivers import DRIVERS, TourDriver
from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.experiments.scenario import ScenarioFileError, parse_scenario
from dynmap_sim.registry import DuplicateNameError
from dynmap_sim.testing import run_scenario

ROOT = Path(__file__).resolve().parents[2]


def test_a_users_driver_that_sees_no_truth_runs_a_scenario(tmp_path):
    result = run_scenario(ROOT / "examples" / "wall-follower.toml", out_dir=tmp_path)
    assert result.passed, result.table()
    with ResultsDB.open(tmp_path) as db:
        runs = db.query("SELECT n_steps, collisions FROM runs ORDER BY day, run")
        xy = np.array(db.query("SELECT x, y FROM scans WHERE day = 1 ORDER BY step"))
    assert len(runs) == 2 and all(n == 301 for n, _ in runs)  # 30 s at 10 Hz, and the first
    path_m = np.hypot(*np.diff(xy, axis=0).T).sum()
    assert path_m > 2.0, path_m  # it went along the walls, not in circles on the spot


def test_a_users_controller_and_planner_serve_the_tour(tmp_path):
    result = run_scenario(ROOT / "examples" / "cautious-tour.toml", out_dir=tmp_path)
    assert result.passed, result.table()
    with ResultsDB.open(tmp_path) as db:
        xy = np.array(db.query("SELECT x, y FROM scans WHERE day = 1 ORDER BY step"))
    speed = np.hypot(*np.diff(xy, axis=0).T) / 0.1
    assert 0.15 < speed.max() <= 0.2 + 0.01  # the user's cap, not the 0.35 m/s cruise speed


def test_the_tour_builds_the_roles_it_is_given():
    d = DRIVERS.get("tour")
    assert d is TourDriver and d.sees_truth and not d.needs_estimate
    assert PLANNERS.get("grid-dijkstra") is GridDijkstra
    assert CONTROLLERS.get("pure-pursuit") is PurePursuit


@pytest.mark.parametrize(
    ("registry", "name", "base"),
    [
        (DRIVERS, "tour", TourDriver),
        (PLANNERS, "grid-dijkstra", GridDijkstra),
        (CONTROLLERS, "pure-pursuit", PurePursuit),
    ],
)
def test_a_name_registered_twice_is_a_clear_error(registry, name, base):
    impostor = type("Impostor", (base,), {})
    with pytest.raises(DuplicateNameError, match=f"'{name}' is already taken by"):
        registry.add(name, impostor)
    assert registry.get(name) is base


def _scenario(tmp_path, driver):
    data = {
        "name": "t",
        "world": "apartment",
        "days": [1, 1],
        "driver": driver,
        "localizers": [{"name": "odometry"}],
    }
    return parse_scenario(data, tmp_path / "s.toml")


def test_driver_errors_name_the_field(tmp_path):
    with pytest.raises(ScenarioFileError) as ei:
        _scenario(tmp_path, {"kind": "taxi"})
    assert "unknown driver 'taxi'; known: autonomous, tour" in dict(ei.value.errors)["driver.kind"]
    with pytest.raises(ScenarioFileError) as ei:
        _scenario(tmp_path, {"params": {"wait_for_ppl": True}})
    assert "wait_for_ppl" in dict(ei.value.errors)["driver.params"]
    with pytest.raises(ScenarioFileError) as ei:
        _scenario(tmp_path, {"params": {"controller": "no_such_module:X"}})
    msg = dict(ei.value.errors)["driver.params"]
    assert "cannot load controller 'no_such_module:X'" in msg and "PYTHONPATH" in msg


def test_the_steering_localizer_is_checked(tmp_path):
    with pytest.raises(ScenarioFileError) as ei:
        _scenario(tmp_path, {"localizer": "odometry"})
    assert "does not steer on an estimate" in dict(ei.value.errors)["driver.localizer"]


def test_the_first_formats_tour_fields_still_load(tmp_path):
    scn = _scenario(tmp_path, {"wait_for_people": False, "clearance_m": 0.2})
    assert scn.driver.params == {"wait_for_people": False, "clearance_m": 0.2}
