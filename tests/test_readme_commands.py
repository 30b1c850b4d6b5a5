"""The README's commands and examples match the code: CI runs its test command, its example
world and scenario files validate, and its main job names a shipped scenario."""

import re
from pathlib import Path

import pytest

from dynmap_sim.cli import main

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def _blocks(lang: str, text: str = README) -> list[str]:
    return [b.strip() for b in re.findall(rf"```{lang}\n(.*?)```", text, flags=re.S)]


def _two_commands() -> list[str]:
    section = README.split("## The two commands", 1)[1].split("\n## ", 1)[0]
    return _blocks("bash", section)


def test_ci_runs_the_readme_test_command():
    main_job, tests = _two_commands()
    assert "pytest" in tests and "pip install" in tests
    ci_lines = [
        ln.strip()
        for ln in (ROOT / ".ci" / "run").read_text().splitlines()
        if ln.strip() and not ln.lstrip().startswith("#")
    ]
    assert tests in ci_lines, f"{tests!r} not in .ci/run"


def test_main_job_runs_a_shipped_scenario():
    main_job, _ = _two_commands()
    m = re.search(r"dynmap-sim run (\S+\.toml)", main_job)
    assert m and (ROOT / m.group(1)).is_file()
    assert main(["validate", str(ROOT / m.group(1))]) == 0


def test_ci_script_fails_on_errors():
    assert "set -euo pipefail" in (ROOT / ".ci" / "run").read_text()


@pytest.mark.parametrize("index", [0, 1], ids=["world", "scenario"])
def test_readme_examples_validate(index, tmp_path, capsys):
    path = tmp_path / f"example{index}.toml"
    path.write_text(_blocks("toml")[index])
    assert main(["validate", str(path)]) == 0, capsys.readouterr().err


def test_readme_navigation_policy_example_drives_to_the_goal():
    section = README.split("## The robot drives itself", 1)[1].split("\n## ", 1)[0]
    (code,) = _blocks("python", section)
    scope: dict = {}
    exec(compile(code, "README.md", "exec"), scope)  # noqa: S102 - our own README
    assert scope["terminated"] or scope["policy"].done
    assert not scope["truncated"]
