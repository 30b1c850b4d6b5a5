"""`dynmap-sim benchmark`: a suite of worlds run as a sweep, judged by a leaderboard."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import pytest

from dynmap_sim.analysis.leaderboard import (
    BAR_ATE_M,
    CSV_COLUMNS,
    leaderboard,
    leaderboard_headline,
    leaderboard_md,
    write_leaderboard,
)
from dynmap_sim.errors import InputError
from dynmap_sim.experiments.benchmark import (
    BENCHMARK_INDEX,
    SuiteFileError,
    load_suite,
    prepare_benchmark,
    run_benchmark,
)

ROOT = Path(__file__).resolve().parents[2]

SUITE = """
name = "tiny"
days = "1-2"
baseline = "mcl"

[worlds]
files = ["{apartment}", "{office}"]

[scenario]
driver = {{ kind = "tour", max_run_s = 5.0 }}
prior = {{ map = "walls", initial_pose = "known" }}

[[scenario.localizers]]
name = "odometry"

[[scenario.localizers]]
name = "static-mcl"
label = "mcl"
params = {{ config = "tuned" }}
"""


def _no_generator(kind: str, seed: int, params: dict) -> str:
    raise AssertionError("file worlds need no generator")


def _suite(tmp: Path, text: str = SUITE) -> Path:
    p = tmp / "suite.toml"
    p.write_text(
        text.format(apartment=ROOT / "worlds/apartment.toml", office=ROOT / "worlds/office.toml")
    )
    return p


@pytest.fixture(scope="module")
def bench(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("bench")
    out = tmp / "out"
    outcome = run_benchmark(load_suite(_suite(tmp)), out, _no_generator, workers=1, progress=False)
    assert outcome.complete and len(outcome.done) == 2
    return out


def test_every_world_gets_its_world_file_scenario_and_cell(bench: Path) -> None:
    record = json.loads((bench / BENCHMARK_INDEX).read_text())
    assert [w["name"] for w in record["worlds"]] == ["apartment", "office"]
    for name in ("apartment", "office"):
        assert (bench / "worlds" / f"{name}.toml").read_bytes() == (
            ROOT / "worlds" / f"{name}.toml"
        ).read_bytes()
        text = (bench / "scenarios" / f"{name}.toml").read_text()
        assert f'world = "../worlds/{name}.toml"' in text and "days = [1, 2]" in text


def test_the_leaderboard_ranks_the_localizers_over_the_worlds(bench: Path) -> None:
    board = leaderboard(bench)
    assert board.baseline == "mcl" and board.references == ("odometry",)
    assert {r.world for r in board.rows} == {"apartment", "office"}
    (score,) = board.scores  # odometry is a reference, not ranked
    assert score.localizer == "mcl" and score.n_worlds == 2
    ate = sorted(r.ate_m for r in board.rows if r.localizer == "mcl")
    assert score.ate_median.value == pytest.approx(sum(ate) / 2)
    assert score.vs_baseline is None  # the baseline against itself
    assert [w for w, _ in board.worst()] == sorted(
        ("apartment", "office"), key=lambda w: -next(
            r.ate_m for r in board.rows if r.world == w and r.localizer == "mcl"
        )
    )  # fmt: skip
    # each world's days, per localizer: what the per-day figure draws
    assert sorted((r.world, r.localizer, r.day) for r in board.days) == sorted(
        (w, lb, d) for w in ("apartment", "office") for lb in ("odometry", "mcl") for d in (1, 2)
    )
    md = leaderboard_md(board)
    assert f"ATE ≤ {BAR_ATE_M} m" in md and "dynmap-sim run " in md and "apartment.toml" in md
    head = leaderboard_headline(board)  # what the command prints: up to the worst worlds
    assert head[0] == f"# Leaderboard: {board.name}" and head[-1].startswith("| mcl |")
    assert md.startswith("\n".join(head))


def test_files_are_written_and_a_second_run_resumes_without_running(bench: Path) -> None:
    paths = write_leaderboard(bench)
    assert [p.name for p in paths] == [
        "leaderboard.md", "leaderboard.csv", "leaderboard.png", "leaderboard_per_day.png"
    ]  # fmt: skip
    rows = (bench / "leaderboard.csv").read_text().splitlines()
    assert rows[0].split(",") == list(CSV_COLUMNS) and len(rows) == 1 + 2 * 2
    suite = load_suite(bench.parent / "suite.toml")
    again = run_benchmark(suite, bench, _no_generator, workers=1, progress=False)
    assert again.complete and len(again.skipped) == 2 and not again.done


def test_a_folder_of_another_suite_is_refused(bench: Path, tmp_path: Path) -> None:
    other = _suite(tmp_path, SUITE.replace('days = "1-2"', 'days = "1-1"'))
    with pytest.raises(InputError, match="holds another benchmark"):
        prepare_benchmark(load_suite(other), bench, _no_generator)


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (
            lambda s: s.replace('files = ["{apartment}", ', 'files = ["nope.toml", '),
            "worlds.files.0",
        ),
        (lambda s: s.replace('name = "static-mcl"', 'name = "no-such"'), "scenario.localizers"),
        (lambda s: s.replace('days = "1-2"', 'days = "2-1"'), "days"),
        (lambda s: s.replace("[worlds]", '[worlds]\nkinds = ["castle"]\nseeds = "x"'), "worlds"),
        (lambda s: s.replace("[scenario]", '[scenario]\nworld = "lab"'), "scenario"),
    ],
)
def test_a_bad_suite_is_one_clear_error_and_writes_nothing(
    tmp_path: Path, edit, field: str
) -> None:
    out = tmp_path / "out"
    with pytest.raises(SuiteFileError, match=field.replace(".", r"\.")):
        suite = load_suite(_suite(tmp_path, edit(SUITE)), kinds=("office",))
        prepare_benchmark(suite, out, _no_generator)
    assert not out.exists() or not any(p.name != ".staging" for p in out.iterdir())


@pytest.mark.parametrize("path", sorted((ROOT / "benchmarks" / "suites").glob("*.toml")), ids=str)
def test_every_shipped_suite_loads(path: Path) -> None:
    from dynmap_sim.env_factory import generator_kinds

    suite = load_suite(path, kinds=generator_kinds())
    assert suite.days[0] == 1
    # every world's calendar holds the suite's days (the generator's default: 10 days)
    assert all(suite.days[1] <= dict(w.params).get("days", 10) for w in suite.worlds)
    kinds = {w.kind for w in suite.worlds}
    if path.stem.startswith("generalization") or path.stem == "periodic":
        assert len(suite.worlds) >= 24 and kinds == set(generator_kinds())  # every kind
    else:  # a suite of one kind, named for it
        assert len(kinds) == 1 and kinds.pop() in path.stem


def test_the_goals_not_reached_are_listed_and_counted_by_cause(bench: Path) -> None:
    board = leaderboard(bench)
    assert board.missed == {}  # the tour reaches the end of every run
    assert "## Goals not reached" not in leaderboard_md(board)
    missed = {
        "apartment": [
            "day 1 run 1: goal not reached: no way to the goal exists: no way around the block "
            "on the costmap (no_way)",
            "day 2 run 1: goal not reached: stuck for 90 s near (1.0, 2.0) on the way to the "
            "goal: no progress after 6 recoveries (stuck)",
        ],
        "office": [
            "day 1 run 1: goal not reached: the driver gave up after 12 s",
            "and 3 more runs without the goal",
        ],
    }
    md = leaderboard_md(dataclasses.replace(board, missed=missed))
    section = md.split("## Goals not reached")[1]
    assert "By cause: no_way 1, other 1, stuck 1." in section
    assert "- office: day 1 run 1: goal not reached: the driver gave up after 12 s" in section
