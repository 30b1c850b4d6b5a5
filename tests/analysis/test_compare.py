"""`dynmap-sim compare`: paired per-run differences of two results folders of one scenario."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from dynmap_sim.analysis.compare import MIN_RUNS, compare_results, comparison_table
from dynmap_sim.cli import main
from dynmap_sim.errors import InputError
from dynmap_sim.experiments.runner import run_experiment
from dynmap_sim.experiments.scenario import parse_scenario

ROOT = Path(__file__).resolve().parents[2]


def _scenario(name: str, mcl_params: dict, days=(1, 4)) -> dict:
    """Four apartment days of 8 s, dead reckoning beside static MCL on the walls prior."""
    return {
        "name": name,
        "world": "apartment",
        "days": list(days),
        "driver": {"kind": "tour", "max_run_s": 8.0},
        "prior": {"map": "walls", "initial_pose": "known"},
        "localizers": [
            {"name": "odometry", "label": "odometry"},
            {"name": "static-mcl", "label": "mcl", "params": mcl_params},
        ],
    }


def _run(tmp: Path, data: dict, folder: str, seed: int = 0) -> Path:
    scn = parse_scenario(data, ROOT / "worlds/scenarios/compare.toml")
    return run_experiment(scn, out_dir=tmp / folder, progress=False, workers=1, seed=seed)


@pytest.fixture(scope="module")
def folders(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    tmp = tmp_path_factory.mktemp("compare")
    tuned = _scenario("cmp", {"config": "tuned"})
    # the same class with motion noise ten times too large: a change that must show
    noisy = _scenario("cmp", {"config": "tuned", "overrides": {"alpha1": 2.0, "alpha3": 2.0}})
    return {
        "a": _run(tmp, tuned, "a"),
        "a2": _run(tmp, tuned, "a2"),
        "worse": _run(tmp, noisy, "worse"),
        "other": _run(tmp, _scenario("other", {"config": "tuned"}, days=(1, 1)), "other"),
    }


def test_the_same_run_twice_is_identical_in_every_measure(folders: dict[str, Path]) -> None:
    cmp = compare_results(folders["a"], folders["a2"])
    assert cmp.n_runs == 4 >= MIN_RUNS
    judged = [c for c in cmp.changes if c.measure != "update_ms_per_scan"]
    assert judged and all(c.verdict == "identical" for c in judged)
    assert cmp.moved == []
    assert "nothing moved beyond noise" in comparison_table(cmp)


def test_a_worse_localizer_is_named_and_the_unchanged_one_is_not(
    folders: dict[str, Path],
) -> None:
    cmp = compare_results(folders["a"], folders["worse"])
    by = {(c.localizer, c.measure): c for c in cmp.changes}
    odo = by[("odometry", "mean_error_m")]
    assert odo.verdict == "identical" and odo.difference.mean == 0.0  # same sensor stream
    mcl = by[("mcl", "mean_error_m")]
    assert mcl.mean_b > mcl.mean_a
    assert mcl.difference.mean == pytest.approx(mcl.mean_b - mcl.mean_a)
    assert sorted(mcl.per_day) == [1, 2, 3, 4]
    assert math.isfinite(mcl.difference.low)
    if mcl.verdict == "higher in B":  # judged by its interval, not by its mean alone
        assert mcl.difference.low > 0
        assert "mcl mean_error_m (higher in B)" in comparison_table(cmp)
    else:
        assert mcl.verdict == "within noise" and mcl.difference.low <= 0


def test_folders_of_other_scenarios_are_refused(folders: dict[str, Path]) -> None:
    with pytest.raises(InputError, match="not comparable: .* holds scenario 'cmp'.*'other'"):
        compare_results(folders["a"], folders["other"])


def test_cli_prints_the_table_writes_the_csv_and_refuses_bad_folders(
    folders: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "diff.csv"
    assert main(["compare", str(folders["a"]), str(folders["worse"]), "--csv", str(out)]) == 0
    text = capsys.readouterr().out
    assert "| mcl | mean_error_m [m] |" in text and f"wrote {out}" in text
    rows = out.read_text().splitlines()
    assert rows[0] == "localizer,measure,day,difference,verdict" and len(rows) > 8
    assert main(["compare", str(folders["a"]), str(folders["worse"]), "--csv", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err  # never overwritten silently
    assert main(["compare", str(folders["a"]), str(tmp_path / "nothing")]) == 2
    assert "not a results folder" in capsys.readouterr().err
