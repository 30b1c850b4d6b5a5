"""The Hentschel & Wagner study: registered, applies to results with point classes, writes
its figures and findings on a small results folder."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "experiments"))

from dynmap_sim.analysis.report import write_report  # noqa: E402
from dynmap_sim.experiments.results import ResultsDB  # noqa: E402
from dynmap_sim.experiments.runner import ExperimentRunner  # noqa: E402
from dynmap_sim.experiments.scenario import load_scenario, parse_scenario  # noqa: E402
from dynmap_sim.studies.hentschel_wagner import data as hw_data  # noqa: E402
from dynmap_sim.studies.hentschel_wagner.figures import plot_ltm  # noqa: E402
from dynmap_sim.studies.hentschel_wagner.findings import FINDING_KEYS, evaluate  # noqa: E402
from dynmap_sim.studies.study import STUDIES, study_of_finding  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """Days 1-2 of the H&W apartment, 8 s a run: a localizer with point classes and a
    long-term map, and static MCL on the prior's walls."""
    tmp = tmp_path_factory.mktemp("hw")
    scn = parse_scenario(
        {
            "name": "hw-small",
            "world": str(ROOT / "worlds" / "apartment-hw.toml"),
            "days": [1, 2],
            "driver": {"max_run_s": 8.0},
            "prior": {"map": "walls", "initial_pose": "known"},
            "sensor": {"preset": "urg-04lx", "overrides": {"range_max_m": 4.0}},
            "localizers": [
                {"name": "point_class_localizers:WithLongTermMap", "label": "hw"},
                {
                    "name": "static-mcl",
                    "label": "static-mcl walls",
                    "params": {"config": "tuned", "map_source": "prior-walls"},
                },
            ],
        },
        tmp / "s.toml",
    )
    out = tmp / "o"
    ExperimentRunner(scn, out, scn.days, 0, resume=False, overwrite=True, workers=1).run(
        progress=False
    )
    return out


def test_registered_and_applies_only_with_point_classes(small, tmp_path):
    assert "hentschel-wagner" in STUDIES.names()
    study = STUDIES.get("hentschel-wagner")()
    assert study_of_finding("hw_static_mcl_fails_days_8_11").name == "hentschel-wagner"
    with ResultsDB.open(small) as db:
        assert study.applies(db)
        assert hw_data.find_subject(db) == (0, "hw")
        data = hw_data.load(db)
    assert [b[1:] for b in data.baselines] == [("static-mcl walls", True)]
    assert data.shares is not None and data.shares.days.tolist() == [1, 2]
    # day 1 nothing was seen before: the truth's semistatic share is the furniture's; day 2 none
    assert data.shares.truth[0, 2] > 0.1 and data.shares.truth[1, 2] == 0.0


def test_report_writes_the_study_figures_and_findings(small):
    names = {p.name for p in write_report(small)}
    assert {
        "hw_point_shares_per_day.png",
        "hw_error_per_day.png",
        "hw_ltm_day7.png",  # the latest map before day 7: day 2's
        "hw_findings.md",
        "hw_findings.json",
        "hw_point_class_scores_per_day.png",
        "hw_point_class_scores_per_day.csv",
        "point_classes_per_day.csv",
    } <= names
    assert "hw_ltm_day22.png" not in names  # no map after day 22 in a 2-day experiment
    for n in ("hw_point_shares_per_day.png", "hw_ltm_day7.png"):
        assert (small / n).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    found = {f["key"]: f for f in json.loads((small / "hw_findings.json").read_text())}
    assert list(found) == list(FINDING_KEYS)
    # two days: trends are not measurable, never a verdict
    assert found["hw_semistatic_falls_week1"]["holds"] is None
    assert "not measurable: only 2 days" in found["hw_semistatic_falls_week1"]["measured"]
    assert found["hw_static_mcl_fails_days_8_11"]["holds"] is None
    # the tour operator drove: the paper's autonomous-driving claim is not measurable here
    assert found["hw_goal_every_day"]["holds"] is None
    assert "not by itself" in found["hw_goal_every_day"]["measured"]
    assert "## Hentschel & Wagner" in (small / "summary.md").read_text()


def test_long_term_map_read_from_the_day_artifacts(small):
    with ResultsDB.open(small) as db:
        g = hw_data.ltm_grid(db, 0, 7)
        assert hw_data.ltm_day(db, 0, 7) == 2 and hw_data.ltm_day(db, 0, 0) is None
    assert g is not None and g.prob.shape == (40, 30) and g.resolution_m == 0.05
    assert g.origin_m == (0.5, 1.0) and g.extent == pytest.approx((0.5, 2.0, 1.0, 3.0))
    # day 2's slot (2) holds the wall, as log-odds 3 -> p 0.95
    assert g.prob[5:35, 10] == pytest.approx(1 / (1 + np.exp(-3.0)))
    assert g.prob[0, 0] == pytest.approx(1 / (1 + np.exp(2.0)))


def test_ltm_figure_with_route_memory(tmp_path):
    grid = hw_data.LTMGrid(np.random.default_rng(0).random((20, 20)), (0.0, 0.0), 0.05, "t")
    mem = {
        "routes": [
            {
                "prior": True,
                "ids": [0, 1, 2],
                "waypoints": [{"x_m": x, "y_m": 0.5} for x in (0.1, 0.5, 0.9)],
            },
            {
                "prior": False,
                "ids": [3, 4],
                "waypoints": [{"x_m": 0.5, "y_m": y} for y in (0.2, 0.8)],
            },
        ],
        "blocked": [[1, 2]],
    }
    p = plot_ltm(grid, tmp_path / "m.png", "t", walls=np.array([[0, 0, 1, 0.0]]), route_memory=mem)
    assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_findings_on_a_constructed_28_day_experiment():
    """The verdicts on made-up per-day figures shaped like the paper's."""
    days = np.arange(1, 29)
    semi = np.where(days <= 7, 0.23 - 0.033 * (days - 1), np.where(days <= 14, 0.095, 0.035))
    dyn = np.where((days >= 15) & (days <= 21), 0.092, 0.005)
    fr = np.column_stack([np.zeros(28), dyn, semi, 1 - dyn - semi])
    conf = np.zeros((4, 4), np.int64)
    conf[1, 1], conf[1, 3], conf[3, 1] = 95, 5, 2
    tallies = [hw_data.PointClassTally(conf.copy(), f.copy(), 1) for f in fr]
    shares = hw_data.PointShares(days, fr, fr.copy(), tallies)
    err = np.where(days <= 7, 0.14 - 0.007 * (days - 1), 0.09)
    mx = err * 2
    mx[8] = 0.48
    subj = hw_data.DaySeries("am", days, err, mx, np.zeros(28))
    lost = np.where((days >= 8) & (days <= 11), 0.9, 0.0)
    walls = hw_data.DaySeries("mcl", days, err + 0.05, mx + 0.1, lost)
    data = hw_data.HWData(
        subject=(0, "am"),
        baselines=[(1, "mcl", True)],
        series={"am": subj, "mcl": walls},
        shares=shares,
        nav=[],
        n_days=28,
        bounds=None,
    )
    got = {f.key: f.holds for f in evaluate(data)}
    assert got == {
        "hw_semistatic_falls_week1": True,
        "hw_semistatic_higher_week2": True,
        "hw_dynamic_rises_week3": True,
        "hw_week4_like_end_of_week1": True,
        "hw_error_falls_week1": True,
        "hw_worst_day_in_week2": True,
        "hw_never_lost": True,
        "hw_static_mcl_tracks_week1": True,
        "hw_static_mcl_fails_days_8_11": True,
        "hw_goal_every_day": None,  # no navigation measures
        "hw_dynamic_points_scored": True,  # precision 95/97, recall 95/100
    }
    # driven autonomously: every goal reached, the day-22 block passed by replanning
    from types import SimpleNamespace

    data.driver_kind = "autonomous"
    data.nav = [
        (d, 1, SimpleNamespace(goal_reached=True, collisions=0, replans=3 if d == 22 else 0))
        for d in range(1, 29)
    ]
    nav = next(f for f in evaluate(data) if f.key == "hw_goal_every_day")
    assert nav.holds is True and "28/28" in nav.measured and "3 replans" in nav.measured
    data.nav[21] = (22, 1, SimpleNamespace(goal_reached=True, collisions=0, replans=0))
    assert next(f for f in evaluate(data) if f.key == "hw_goal_every_day").holds is False
    # the walls baseline tracking on day 9 breaks its finding
    walls.lost_fraction[8] = 0.1
    assert {f.key: f.holds for f in evaluate(data)}["hw_static_mcl_fails_days_8_11"] is False


def test_the_shipped_scenario_validates():
    scn = load_scenario(ROOT / "worlds" / "scenarios" / "apartment-28d-hw.toml")
    assert scn.world_path.name == "apartment-hw.toml"
    labels = scn.labels
    assert {"adaptive-memory", "static-mcl walls", "static-mcl tuned", "dynamic-map"} <= set(labels)
    assert scn.driver.kind == "autonomous" and scn.driver.localizer == "adaptive-memory"
    assert scn.driver.speed_mps <= 0.2
    # H&W §6.3's speed law: slower for obstacles only, the clearance band scaled to 0.2 m/s
    follower = scn.driver.params["follower"]
    assert follower["regulated_min_radius_m"] == 0.0
    assert follower["full_speed_clearance_m"] == pytest.approx(0.25 + 0.55 * 0.2 / 0.35, abs=1e-3)
    walls = next(loc for loc in scn.localizers if loc.display == "static-mcl walls")
    assert walls.params["map_source"] == "prior-walls"
    assert walls.params["config"] == "walls-only"  # tuned was lost on 72 % of week 1
    assert STUDIES.get("hentschel-wagner")().scenario_errors(scn, ["hw_never_lost"]) == []
    assert scn.sensor.overrides["range_max_m"] == 4.0


def test_day_22_map_with_route_memory_from_a_driving_localizer(tmp_path):
    """The localizer the autonomous driver steers on (run in lock-step) reports point classes
    and a long-term map; after day 22 the study draws it with the driver's route memory."""
    scn = parse_scenario(
        {
            "name": "hw-d22",
            "world": str(ROOT / "worlds" / "apartment-hw.toml"),
            "days": [22, 22],
            "driver": {
                "kind": "autonomous",
                "localizer": "hw",
                "speed_mps": 0.2,
                "max_run_s": 6.0,
            },
            "prior": {"map": "walls", "initial_pose": "known"},
            "localizers": [{"name": "point_class_localizers:WithLongTermMap", "label": "hw"}],
        },
        tmp_path / "s.toml",
    )
    out = tmp_path / "o"
    ExperimentRunner(scn, out, scn.days, 0, resume=False, overwrite=True, workers=1).run(
        progress=False
    )
    with ResultsDB.open(out) as db:
        t = db.point_class_truth_per_day(0)
        # the first run of the experiment: every object is new, the blocker too
        assert list(t) == [22] and t[22].n_scans == 61
        assert t[22].confusion[2, 2] > 0 and t[22].confusion[1].sum() == 0
    names = {p.name for p in write_report(out)}
    assert {"hw_ltm_day22.png", "hw_ltm_day7.png"} - names == {"hw_ltm_day7.png"}
    assert "route_memory.png" in names


def test_class_scores_per_day_are_each_days_confusion(small):
    """Per day and class: precision and recall of that day's confusion against the truth,
    the truth's own beam counts (day 1: every object new, day 2: none) and the CSV's rows."""
    with ResultsDB.open(small) as db:
        data = hw_data.load(db)
    sc = hw_data.class_scores_per_day(data.shares)
    assert sc.days.tolist() == [1, 2]
    for k, tally in enumerate(data.shares.tallies):
        c = tally.confusion[1:, 1:]
        np.testing.assert_array_equal(sc.truth_points[k], c.sum(axis=1))
        np.testing.assert_array_equal(sc.predicted_points[k], c.sum(axis=0))
        with np.errstate(invalid="ignore", divide="ignore"):
            np.testing.assert_allclose(sc.precision[k], np.diag(c) / c.sum(axis=0))
            np.testing.assert_allclose(sc.recall[k], np.diag(c) / c.sum(axis=1))
    assert sc.truth_points[0, 1] > 0 and sc.truth_points[1, 1] == 0
    write_report(small)
    rows = (small / "hw_point_class_scores_per_day.csv").read_text().splitlines()
    head = rows[0].split(",")
    assert head[:2] == ["day", "week"] and len(rows) == 3
    day1 = dict(zip(head, rows[1].split(","), strict=True))
    assert int(day1["semistatic_truth_points"]) == sc.truth_points[0, 1]
