"""The long-term memories against the true world (B&D §5.2), and a dynamic-map report end to
end: figures, map_structure.csv and findings from a real run."""

from __future__ import annotations

import csv
import json
import shutil

import numpy as np
import pytest

from dynmap_sim.agent.maps.dynamic_map import MapSnapshot
from dynmap_sim.analysis.check import evaluate
from dynmap_sim.analysis.report import write_report
from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.experiments.runner import run_experiment
from dynmap_sim.experiments.scenario import parse_scenario
from dynmap_sim.studies.biber_duckett.findings import structure_finding
from dynmap_sim.studies.biber_duckett.map_structure import (
    map_structure,
    plot_map_structure,
    surface_samples,
    write_map_structure_csv,
)
from dynmap_sim.types import BeamClass

LEVELS = (1, 2, 3, 4)
RAYS = {1: 360, 2: 720, 3: 1440, 4: 1440}
#: A 4 m x 4 m room around the origin, and a chair at x = 1 m.
ROOM = np.array([[2, -2, 2, 2], [2, 2, -2, 2], [-2, 2, -2, -2], [-2, -2, 2, -2]], float)
CHAIR = np.array([[1.0, -0.3, 1.0, 0.3]])


def _geometry(chair: bool):
    seg = np.vstack([ROOM, CHAIR]) if chair else ROOM
    cls = [BeamClass.WALL] * 4 + ([BeamClass.FURNITURE] if chair else [])
    return seg, np.array(cls, dtype=np.int8)


def _snapshot(n_wall: int, n_chair: int) -> MapSnapshot:
    """One local map at the origin: in every sub-map, the first ``n_wall`` rays (from angle 0)
    end on the wall x = 2 m, the next ``n_chair`` at 1 m (the chair's place)."""
    meds = []
    for level in LEVELS:
        n = RAYS[level]
        th = np.arange(n) * 2 * np.pi / n
        mm = np.zeros(n, dtype=np.uint16)
        mm[:n_wall] = np.rint(2000 / np.cos(th[:n_wall]))
        mm[n_wall : n_wall + n_chair] = 1000
        meds.append(mm[None, :])
    return MapSnapshot(np.zeros((1, 2)), LEVELS, tuple(meds), 0.10)


def test_surface_samples_are_spaced_along_each_segment():
    pts, cls = surface_samples(*_geometry(chair=True), step_m=0.01)
    assert len(pts) == 4 * 401 + 61
    assert np.all(cls[-61:] == BeamClass.FURNITURE) and np.all(cls[:-61] == BeamClass.WALL)
    assert np.allclose(pts[-61:, 0], 1.0) and np.isclose(np.diff(pts[-61:, 1]).max(), 0.01)


def test_shares_on_walls_and_on_the_world_per_day_and_level():
    snaps = [(1, _snapshot(5, 5)), (2, _snapshot(8, 2)), (3, _snapshot(10, 0))]
    worlds = {1: _geometry(True), 2: _geometry(True), 3: _geometry(False)}
    ms = map_structure(snaps, worlds.get, tol_m=0.05)
    assert ms.days == (1, 2, 3) and ms.levels == LEVELS
    assert np.all(ms.n_points == [[10], [10], [10]])
    assert np.allclose(ms.on_walls, [[0.5], [0.8], [1.0]])
    assert np.allclose(ms.on_world, 1.0)  # the chair stood there on days 1 and 2
    assert np.all(ms.median_dist_m < 0.006)
    f = structure_finding(ms)  # three daily maps: too few for a trend
    assert f.holds is None and "not measurable: only 3 daily maps" in f.measured
    five = [(d, _snapshot(n, 10 - n)) for d, n in enumerate((5, 6, 8, 9, 10), start=1)]
    f = structure_finding(map_structure(five, lambda day: _geometry(True), tol_m=0.05))
    assert f.holds is True and "λ5 50.0 % → 100.0 %" in f.measured
    gone = map_structure(snaps, {1: _geometry(True), 2: _geometry(True)}.get)
    assert gone.days == (1, 2)  # a day without geometry is skipped


def test_median_distances_are_exact_also_where_most_points_are_far_from_the_world():
    """Points 1 m from every surface (a chair's rays, the chair gone) beyond the bounded
    search's 0.5 m: the median is the brute-force one whether most points are near (6 of 10)
    or far (8 of 10, the search redone unbounded)."""
    no_chair = _geometry(chair=False)
    surf, _ = surface_samples(*no_chair, step_m=0.01)
    for n_wall, n_chair in ((6, 4), (2, 8)):
        snap = _snapshot(n_wall, n_chair)
        ms = map_structure([(1, snap)], lambda day: no_chair, tol_m=0.05)
        for j, level in enumerate(LEVELS):
            p = snap.points(0, level)
            d = np.hypot(*(p[:, None, :] - surf[None]).transpose(2, 0, 1)).min(axis=1)
            assert ms.median_dist_m[0, j] == pytest.approx(np.median(d), abs=1e-12)
            assert ms.on_world[0, j] == np.mean(d < 0.05)
    assert ms.median_dist_m[0, 0] == pytest.approx(1.0, abs=0.01)  # the far ones: 1 m off


def test_structure_finding_needs_a_rise_of_one_point():
    snaps = [(d, _snapshot(11 - d, d - 1)) for d in (1, 2, 3, 4, 6)]
    ms = map_structure(snaps, lambda day: _geometry(True))
    f = structure_finding(ms)
    assert f.holds is False and "λ5 100.0 % → 50.0 %" in f.measured
    assert structure_finding(map_structure(snaps[:1], lambda day: _geometry(True))).holds is None


def test_csv_and_figure(tmp_path):
    ms = map_structure([(1, _snapshot(5, 5)), (2, _snapshot(10, 0))], lambda d: _geometry(True))
    rows = list(csv.reader(write_map_structure_csv(ms, tmp_path / "m.csv").open()))
    assert rows[0] == ["day", "timescale", "n_points", "on_walls", "on_world", "median_dist_m"]
    assert len(rows) == 1 + 2 * 4 and rows[4][:4] == ["1", "lambda5", "10", "0.5000"]
    assert plot_map_structure(ms, tmp_path / "m.png").stat().st_size > 10_000


@pytest.fixture(scope="module")
def dynamic_report(tmp_path_factory):
    """Three apartment days, the three sample-based localizers, and the report."""
    out = tmp_path_factory.mktemp("dyn") / "res"
    fast = {"min_update_dist_m": 0.1, "min_update_angle_rad": 0.1}
    data = {
        "name": "ci-dynamic",
        "world": "apartment",
        "days": [1, 3],
        "driver": {"max_run_s": 40.0},
        "localizers": [
            {"name": n, "params": fast} for n in ("dynamic-map", "static-map", "static-map+stm")
        ],
    }
    scn = parse_scenario(data, out.parent / "ci-dynamic.toml")
    run_experiment(scn, out_dir=out, progress=False, workers=1)
    # the daily map snapshots are day artifacts in the store: no checkpoint is unpickled
    shutil.rmtree(out / "checkpoint")
    with ResultsDB.open(out) as db:
        snaps = db.artifacts(0, "map_snapshot")
        assert [day for day, _ in snaps] == [1, 2, 3]
        assert MapSnapshot.from_arrays(snaps[0][1]).levels == LEVELS
    return out, {p.name for p in write_report(out)}


def test_a_dynamic_map_report_measures_its_maps_against_the_truth(dynamic_report):
    out, names = dynamic_report
    assert {"map_structure.png", "map_structure.csv", "findings.json"} <= names
    rows = list(csv.DictReader((out / "map_structure.csv").open()))
    assert [(r["day"], r["timescale"]) for r in rows[:4]] == [
        ("1", f"lambda{k}") for k in (2, 3, 4, 5)
    ]
    assert len(rows) == 3 * 4
    for r in rows:
        assert int(r["n_points"]) > 100
        assert 0.0 < float(r["on_walls"]) <= float(r["on_world"]) <= 1.0
        assert float(r["on_world"]) > 0.6  # the map is mostly where the world is
        assert float(r["median_dist_m"]) < 0.05
    found = {f["key"]: f for f in json.loads((out / "findings.json").read_text())}
    assert "static_structure_emerges" in found
    assert found["static_structure_emerges"]["holds"] is None  # three days: too few
    assert "not measurable: only 3 daily maps" in found["static_structure_emerges"]["measured"]
    assert "likelihood_above_static" in found and "safe_mode_rare" in found


def test_scenario_expectations_on_findings(dynamic_report):
    """``[expectations] findings``: one check row per finding, failing when it does not hold
    or cannot be measured (the apartment has no exhibition)."""
    out, _ = dynamic_report
    data = {
        "name": "ci-dynamic",
        "world": "apartment",
        "days": [1, 3],
        "localizers": [{"name": "dynamic-map"}],
        "expectations": {"findings": ["safe_mode_rare", "exhibition_fades"]},
    }
    scn = parse_scenario(data, out.parent / "ci-dynamic.toml")
    rows = {r.criterion: r for r in evaluate(scn, out, seed=0)}
    assert set(rows) == {"finding safe_mode_rare fails", "finding exhibition_fades fails"}
    found = {f["key"]: f for f in json.loads((out / "findings.json").read_text())}
    safe = rows["finding safe_mode_rare fails"]
    assert safe.passed is (found["safe_mode_rare"]["holds"] is True)
    assert safe.measured == (0.0 if safe.passed else 1.0) and safe.limit == 0
    ex = rows["finding exhibition_fades fails"]
    assert not ex.passed and ex.measured == 1.0 and ex.where == "not measurable"
