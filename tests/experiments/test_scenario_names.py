"""A scenario's name names its results folder: refused at validation where it could not."""

from __future__ import annotations

from pathlib import Path

import pytest

from dynmap_sim.cli import day_range, main
from dynmap_sim.experiments.scenario import MAX_NAME_CHARS, ScenarioFileError, parse_scenario

BASE = {
    "world": "apartment",
    "days": [1, 1],
    "driver": {"kind": "tour"},
    "prior": {"map": "walls", "initial_pose": "known"},
    "localizers": [{"name": "odometry"}],
}


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("x" * 300, f"name: the name is a file name .*at most {MAX_NAME_CHARS} characters"),
        ("../up", "name: the name is a file name .*no path separators"),
        ("a/b", "name: the name is a file name"),
    ],
)
def test_a_name_that_cannot_name_a_folder_is_refused(name: str, message: str) -> None:
    with pytest.raises(ScenarioFileError, match=message):
        parse_scenario({**BASE, "name": name}, Path("s.toml"))


def test_the_shipped_kind_of_name_is_taken() -> None:
    scn = parse_scenario({**BASE, "name": "ci-apartment_2.b+c"}, Path("s.toml"))
    assert scn.name == "ci-apartment_2.b+c"


@pytest.mark.parametrize("text", ["1-", "3- ", "-2", "a-b", ""])
def test_a_day_range_with_a_missing_end_is_refused(text: str) -> None:
    import argparse

    with pytest.raises(argparse.ArgumentTypeError, match="days must look like 3 or 1-7"):
        day_range(text)


def test_run_with_report_refuses_a_folder_holding_the_users_own_summary(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = Path(__file__).resolve().parents[2]
    out = tmp_path / "mine"
    out.mkdir()
    (out / "summary.md").write_text("my notes\n")
    scn = str(root / "worlds/scenarios/ci-apartment.toml")
    assert main(["run", scn, "--days", "1", "--out", str(out), "--report", "-q"]) == 2
    assert "summary.md" in capsys.readouterr().err
    assert (out / "summary.md").read_text() == "my notes\n"
    assert not (out / "results.db").exists()  # refused before anything ran
