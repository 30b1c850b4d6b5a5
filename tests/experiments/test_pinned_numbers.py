"""The numbers the testbed produces are pinned: a CI scenario's per-day table is byte-identical
to the one recorded in tests/data/golden/ (re-pinned only where a change means to move it;
CHANGELOG.md says when and by how much), and results written by an earlier version are
refused by --resume with a clear message but still report."""

import shutil
from pathlib import Path

import pytest

from dynmap_sim.analysis.report import write_per_day_csv, write_report
from dynmap_sim.errors import InputError
from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.experiments.runner import run_experiment
from dynmap_sim.experiments.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"


def test_ci_apartment_mcl_per_day_table_is_pinned(tmp_path):
    scn = load_scenario(ROOT / "worlds" / "scenarios" / "ci-apartment-mcl.toml")
    out = run_experiment(scn, out_dir=tmp_path / "r", progress=False, workers=1)
    with ResultsDB.open(out) as db:
        got = write_per_day_csv(db, tmp_path / "per_day.csv").read_bytes()
    assert got == (DATA / "golden" / "ci-apartment-mcl.per_day.csv").read_bytes()


def test_results_of_the_earlier_version_are_refused_by_resume_but_report(tmp_path):
    old = tmp_path / "old"
    shutil.copytree(DATA / "pre-round-2" / "ci-apartment", old)
    scn = load_scenario(ROOT / "worlds" / "scenarios" / "ci-apartment.toml")
    with pytest.raises(InputError, match="checkpoint format 1.*--resume needs the version"):
        run_experiment(scn, out_dir=old, resume=True, progress=False)
    assert any(p.name == "summary.md" for p in write_report(old))  # the finished run reports
