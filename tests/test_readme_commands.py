"""The README's and the docs pages' commands and examples match the code.

CI runs the README's test command and then builds the docs; the main job names a shipped
scenario. On every page (README.md and docs/**/*.md): every ``dynmap-sim`` command parses
with the CLI's own parser and the repository files it names exist, every ``pip install``
names extras that exist, every ``python benchmarks/...`` script exists, every world and
scenario example validates (a schedule entry inside the page's example world, a scenario
fragment inside the page's example scenario or the file its marker names), and every Python
example runs.

A page steers the test of the block that follows with an HTML comment on the line before it
(invisible where the page is shown):

- ``<!-- test: compile-only (why) -->``: the Python block is compiled, not run;
- ``<!-- test: needs MODULE -->``: the Python block runs only where MODULE is installed;
- ``<!-- test: into PATH -->``: the TOML fragment is merged into the scenario at PATH.
"""

from __future__ import annotations

import importlib.util
import re
import shlex
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from dynmap_sim.cli import build_parser, main
from dynmap_sim.experiments.scenario import parse_scenario

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
PAGES = [ROOT / "README.md"] + sorted(
    p for p in (ROOT / "docs").rglob("*.md") if "hooks" not in p.relative_to(ROOT).parts
)
FENCE = re.compile(
    r"^(?:<!-- test: (?P<mark>[^\n]*?) -->\n)?```(?P<lang>[\w-]*)\n(?P<code>.*?)^```",
    flags=re.S | re.M,
)
#: Top-level folders of the repository whose files a command may name.
REPO_DIRS = {"worlds", "examples", "benchmarks", "docs", "tests", "scripts"}


@dataclass(frozen=True)
class Block:
    page: Path
    line: int
    lang: str
    code: str
    mark: str

    @property
    def id(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"


def page_blocks(page: Path) -> list[Block]:
    text = page.read_text(encoding="utf-8")
    return [
        Block(
            page,
            text.count("\n", 0, m.start("code")),
            m.group("lang"),
            m.group("code"),
            (m.group("mark") or "").strip(),
        )
        for m in FENCE.finditer(text)
    ]


BLOCKS = [b for page in PAGES for b in page_blocks(page)]


def _of(lang: str) -> list[Block]:
    return [b for b in BLOCKS if b.lang == lang]


def _section(heading: str, text: str = README) -> str:
    return text.split(f"\n## {heading}\n", 1)[1].split("\n## ", 1)[0]


def _two_commands() -> list[str]:
    section = _section("The two commands")
    return [b.group("code").strip() for b in FENCE.finditer(section) if b.group("lang") == "bash"]


# ---------------------------------------------------------------------------------------------
# the README's two commands and CI
# ---------------------------------------------------------------------------------------------


def _ci_lines() -> list[str]:
    return [
        ln.strip()
        for ln in (ROOT / ".ci" / "run").read_text().splitlines()
        if ln.strip() and not ln.lstrip().startswith("#")
    ]


def test_ci_runs_the_readme_test_command_then_builds_the_docs():
    main_job, tests = _two_commands()
    assert "pytest" in tests and "pip install" in tests
    lines = _ci_lines()
    assert tests in lines, f"{tests!r} not in .ci/run"
    docs = [i for i, ln in enumerate(lines) if ln.startswith("mkdocs build --strict")]
    assert docs and docs[0] > lines.index(tests), ".ci/run builds the docs after the tests"
    assert "docs" in _extras(tests), "the test command installs what the docs build needs"


def test_main_job_runs_a_shipped_scenario():
    main_job, _ = _two_commands()
    m = re.search(r"dynmap-sim run (\S+\.toml)", main_job)
    assert m and (ROOT / m.group(1)).is_file()
    assert main(["validate", str(ROOT / m.group(1))]) == 0


def test_ci_script_fails_on_errors():
    assert "set -euo pipefail" in (ROOT / ".ci" / "run").read_text()


def test_readme_stays_short():
    assert len(README.splitlines()) <= 300


# ---------------------------------------------------------------------------------------------
# shell commands on every page
# ---------------------------------------------------------------------------------------------


def commands(code: str) -> list[list[str]]:
    """The commands of a bash block, each as its words: continuation lines joined, comments,
    ``VAR=value`` prefixes and trailing ``&`` dropped, ``&&``, ``;`` and ``|`` split."""
    out: list[list[str]] = []
    for line in code.replace("\\\n", " ").splitlines():
        words: list[str] = []
        for word in shlex.split(line, comments=True) + ["&&"]:
            if word in ("&&", ";", "|", "&", "||"):
                if words:
                    out.append(words)
                words = []
            elif words or not re.fullmatch(r"[A-Z_][A-Z0-9_]*=\S*", word):
                words.append(word)
    return out


def test_commands_are_split_as_a_shell_would():
    code = 'X=1 dynmap-sim run a.toml --days 1-2 \\\n    --out r  # note\nb & c && d "e f"\n'
    assert commands(code) == [
        ["dynmap-sim", "run", "a.toml", "--days", "1-2", "--out", "r"],
        ["b"],
        ["c"],
        ["d", "e f"],
    ]


def _all_commands() -> list[tuple[str, list[str]]]:
    """Every command of the bash blocks, and of the ``run:`` steps of the CI (yaml) blocks."""
    shells = [(b, b.code) for b in _of("bash")] + [
        (b, "\n".join(re.findall(r"^\s*-?\s*run:\s*(.+)$", b.code, flags=re.M)))
        for b in _of("yaml")
    ]
    return [(b.id, words) for b, code in shells for words in commands(code)]


def _extras(command: str) -> set[str]:
    m = re.search(r"\[([\w,-]+)\]", command)
    return set(m.group(1).split(",")) if m else set()


def _project_extras() -> set[str]:
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())
    return set(data["project"]["optional-dependencies"])


CLI_COMMANDS = [(i, w) for i, w in _all_commands() if w[0] == "dynmap-sim"]
PIP_COMMANDS = [(i, w) for i, w in _all_commands() if "pip" in w[:3] and "install" in w]
SCRIPTS = [(i, w) for i, w in _all_commands() if w[0] == "python" and w[1].endswith(".py")]


def test_the_pages_show_commands():
    assert len(CLI_COMMANDS) > 20 and PIP_COMMANDS and SCRIPTS


@pytest.mark.parametrize(("where", "words"), CLI_COMMANDS, ids=[i for i, _ in CLI_COMMANDS])
def test_cli_command_parses_and_names_existing_files(where, words, capsys):
    try:
        build_parser().parse_args(words[1:])
    except SystemExit:
        pytest.fail(f"{where}: {shlex.join(words)}: {capsys.readouterr().err}")
    missing = [
        w
        for w in words[1:]
        if not w.startswith("-") and w.split("/", 1)[0] in REPO_DIRS and "/" in w
        if not (ROOT / w).exists() and not _is_output(words, w)
    ]
    assert not missing, f"{where}: {missing} not in the repository"


def _is_output(words: list[str], word: str) -> bool:
    """Whether ``word`` follows an option that names something the command writes."""
    i = words.index(word)
    return i > 0 and words[i - 1] in ("-o", "--output", "--out", "--tum", "--mcap", "--parquet")


@pytest.mark.parametrize(("where", "words"), PIP_COMMANDS, ids=[i for i, _ in PIP_COMMANDS])
def test_pip_installs_name_existing_extras(where, words):
    assert _extras(" ".join(words)) <= _project_extras(), where


@pytest.mark.parametrize(("where", "words"), SCRIPTS, ids=[i for i, _ in SCRIPTS])
def test_python_scripts_exist(where, words):
    assert (ROOT / words[1]).is_file(), f"{where}: {words[1]}"


# ---------------------------------------------------------------------------------------------
# world and scenario examples on every page
# ---------------------------------------------------------------------------------------------


def _is_world(data: dict[str, Any]) -> bool:
    return "calendar" in data and "bounds" in data


def _is_scenario(data: dict[str, Any]) -> bool:
    return isinstance(data.get("world"), str) and "name" in data


def merge(base: dict[str, Any], part: dict[str, Any]) -> dict[str, Any]:
    """``part`` merged into ``base``: tables key by key, arrays of tables appended."""
    out = dict(base)
    for key, value in part.items():
        old = out.get(key)
        if isinstance(value, dict) and isinstance(old, dict):
            out[key] = merge(old, value)
        elif (
            isinstance(value, list)
            and isinstance(old, list)
            and value
            and isinstance(value[0], dict)
        ):
            out[key] = old + value
        else:
            out[key] = value
    return out


def test_merge_joins_tables_and_appends_arrays_of_tables():
    base = {"a": {"x": 1, "y": 2}, "l": [{"n": 1}], "s": 1}
    part = {"a": {"y": 3}, "l": [{"n": 2}], "s": 2}
    assert merge(base, part) == {"a": {"x": 1, "y": 3}, "l": [{"n": 1}, {"n": 2}], "s": 2}


def _first(page: Path, kind) -> str | None:
    for b in page_blocks(page):
        if b.lang == "toml" and kind(tomllib.loads(b.code)):
            return b.code
    return None


TOML = _of("toml")


@pytest.mark.parametrize("block", TOML, ids=[b.id for b in TOML])
def test_toml_example_validates(block, tmp_path, capsys):
    data = tomllib.loads(block.code)
    if {"worlds", "scenario"} <= set(data):  # a benchmark suite, as if in benchmarks/suites/
        from dynmap_sim.env_factory import generator_kinds
        from dynmap_sim.experiments.benchmark import load_suite

        (tmp_path / "worlds").symlink_to(ROOT / "worlds")
        suite = tmp_path / "benchmarks" / "suites" / "example.toml"
        suite.parent.mkdir(parents=True)
        suite.write_text(block.code)
        load_suite(suite, kinds=generator_kinds())  # raises with every error
        return
    if _is_world(data) or _is_scenario(data):
        path = tmp_path / "example.toml"
        path.write_text(block.code)
    elif set(data) == {"schedule"}:
        world = _first(block.page, _is_world)
        assert world, f"{block.id}: a schedule entry needs an example world on its page"
        path = tmp_path / "world.toml"
        path.write_text(world + "\n" + block.code)
    else:
        if block.mark.startswith("into "):
            base_path = ROOT / block.mark.removeprefix("into ").strip()
            base = tomllib.loads(base_path.read_text())
        else:
            text = _first(block.page, _is_scenario)
            assert text, f"{block.id}: a fragment needs an example scenario or an 'into' mark"
            base_path, base = block.page, tomllib.loads(text)
        parse_scenario(merge(base, data), base_path)  # raises with every error
        return
    assert main(["validate", str(path)]) == 0, f"{block.id}: {capsys.readouterr().err}"


def test_every_schedule_action_has_an_example():
    from dynmap_sim.world import world_json_schema

    items = world_json_schema()["properties"]["schedule"]["items"]
    actions = set(items["discriminator"]["mapping"])
    page = ROOT / "docs" / "worlds.md"
    shown = {
        entry["action"]
        for b in page_blocks(page)
        if b.lang == "toml"
        for entry in tomllib.loads(b.code).get("schedule", [])
    }
    assert actions <= shown, f"no example on {page.name} for {sorted(actions - shown)}"


# ---------------------------------------------------------------------------------------------
# Python examples on every page
# ---------------------------------------------------------------------------------------------

PYTHON = _of("python")


@pytest.mark.parametrize("block", PYTHON, ids=[b.id for b in PYTHON])
def test_python_example_runs(block, tmp_path, monkeypatch):
    code = compile(block.code, block.id, "exec")
    if block.mark.startswith("compile-only"):
        return
    if block.mark.startswith("needs "):
        module = block.mark.removeprefix("needs ").strip()
        if importlib.util.find_spec(module) is None:
            pytest.skip(f"{module} is not installed")
    else:
        assert not block.mark, f"{block.id}: unknown test mark {block.mark!r}"
    monkeypatch.chdir(tmp_path)  # examples may write files (videos/, tables/)
    scope: dict[str, Any] = {"__name__": "docs_example"}
    exec(code, scope)  # noqa: S102 - our own pages
    if "policy" in scope:  # the navigation stack's loop: it drives to the goal
        assert scope["terminated"] or scope["policy"].done
        assert not scope["truncated"]
