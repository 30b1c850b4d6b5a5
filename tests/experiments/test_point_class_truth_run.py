"""The seen-before truth through the engine on the real apartment, into the store and the
report's point_classes_per_day.csv."""

import csv
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))

from dynmap_sim.analysis.report import POINT_CLASS_COLUMNS, write_report  # noqa: E402
from dynmap_sim.experiments.results import ResultsDB  # noqa: E402
from dynmap_sim.experiments.runner import ExperimentRunner  # noqa: E402
from dynmap_sim.experiments.scenario import parse_scenario  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def run_apartment(tmp_path: Path, days: list[int], workers: int = 1) -> Path:
    scn = parse_scenario(
        {
            "name": "pc",
            "world": str(ROOT / "worlds" / "apartment.toml"),
            "days": days,
            "driver": {"max_run_s": 8.0},
            "localizers": [
                {"name": "odometry", "label": "odo"},
                {"name": "point_class_localizers:EverythingSemistatic", "label": "all-semi"},
            ],
        },
        tmp_path / "s.toml",
    )
    out = tmp_path / "o"
    ExperimentRunner(scn, out, scn.days, 0, resume=False, overwrite=True, workers=workers).run(
        progress=False
    )
    return out


@pytest.fixture(scope="module")
def days_1_2(tmp_path_factory):
    return run_apartment(tmp_path_factory.mktemp("pc"), [1, 2])


def test_furniture_is_semistatic_on_day_1_and_static_on_day_2_of_the_static_week(days_1_2):
    with ResultsDB.open(days_1_2) as db:
        assert db.point_class_truth_per_day(0) == {}  # odometry reports no point classes
        t = db.point_class_truth_per_day(1)
        # column 2 (every valid reading called semi-static): rows are the truth's classes
        truth1, truth2 = t[1].confusion[:, 2], t[2].confusion[:, 2]
        # the beam-class truth calls furniture semi-static on both days
        by_beam = {
            d: sum(
                np.frombuffer(b, "<i8").reshape(4, 4)[:, 2]
                for (b,) in db.query(
                    "SELECT confusion FROM point_classes WHERE loc=1 AND day=?", (d,)
                )
            )
            for d in (1, 2)
        }
    # day 1: nothing seen before, so the furniture is semi-static (as by beam class)
    assert truth1[2] > 0.1 * truth1.sum()
    assert truth1[2] == by_beam[1][2] and truth1[3] == by_beam[1][3]
    # day 2: week 1 is static, the furniture seen on day 1 is at its place: static
    assert truth2[2] < 0.05 * truth1[2]
    assert truth2[3] > truth1[3] and by_beam[2][2] > 0.1 * by_beam[2].sum()
    assert t[1].n_scans == t[2].n_scans == 81
    np.testing.assert_allclose(t[1].fractions()[2], 1.0)  # every valid reading reported 2


def test_report_writes_point_classes_per_day_csv(days_1_2):
    names = {p.name for p in write_report(days_1_2)}
    assert {"point_classes_per_day.csv", "per_day.csv"} <= names
    with (days_1_2 / "point_classes_per_day.csv").open() as fh:
        rows = list(csv.reader(fh))
    assert (
        tuple(rows[0])
        == POINT_CLASS_COLUMNS
        == (
            "day",
            "localizer",
            "dynamic_fraction",
            "semistatic_fraction",
            "static_fraction",
            "dynamic_precision",
            "dynamic_recall",
            "semistatic_precision",
            "semistatic_recall",
        )
    )
    body = [dict(zip(rows[0], r, strict=True)) for r in rows[1:]]
    assert [(r["day"], r["localizer"]) for r in body] == [("1", "all-semi"), ("2", "all-semi")]
    assert [float(r["semistatic_fraction"]) for r in body] == [1.0, 1.0]
    # day 2 has no semi-static truth at all: its recall is undefined (nan), not 0 or 1
    assert [r["semistatic_recall"] for r in body] == ["1.000000", "nan"]
    # precision = the truth's semi-static share of the scored readings
    prec = [float(r["semistatic_precision"]) for r in body]
    assert prec[0] > 0.1 and prec[1] == 0.0
    assert body[0]["dynamic_precision"] == "nan"  # nothing reported dynamic
    md = (days_1_2 / "summary.md").read_text()
    assert "## Point classes against the truth seen before at that place" in md
    assert "| all-semi | semi-static | 100.0 % |" in md


def test_worker_processes_give_the_same_truth(tmp_path, days_1_2):
    out = run_apartment(tmp_path, [1, 2], workers=2)
    with ResultsDB.open(out) as a, ResultsDB.open(days_1_2) as b:
        ta, tb = a.point_class_truth_per_day(1), b.point_class_truth_per_day(1)
        for d in (1, 2):
            np.testing.assert_array_equal(ta[d].confusion, tb[d].confusion)


def test_results_format_2_is_read_without_the_truth_and_not_continued(days_1_2, tmp_path):
    import shutil

    from dynmap_sim.errors import InputError

    old = tmp_path / "old"
    shutil.copytree(days_1_2, old, ignore=shutil.ignore_patterns(".results.lock"))
    with ResultsDB.open(old) as db:
        db.con.execute("DROP TABLE point_class_truth")
        db.set_meta(results_format=2)
    with ResultsDB.open(old) as db:
        assert db.point_class_truth_per_day(1) == {}
        with pytest.raises(InputError, match="format 2.*before the seen-before point-class"):
            db._require_current_format()
    names = {p.name for p in write_report(old)}
    assert "per_day.csv" in names and "point_classes_per_day.csv" not in names
