"""The docs cannot rot.

Citations of the architecture page: every ``docs/architecture.md §N`` cited in the package
(and in the tests, benchmarks, examples, README and pyproject.toml) names a numbered section
heading of ``docs/architecture.md``, and nothing cites design notes from outside the
repository, which users never see. The site (``mkdocs.yml``): every page is in the nav, and
the generated parts (``docs/hooks/generate.py``: the world and scenario field references,
the CLI reference, the built-in roles) show every field, command, option and role of the
code. ``.ci/run`` builds the
site with ``mkdocs build --strict``; the pages' commands and examples are tested in
``tests/test_readme_commands.py``.
"""

import argparse
import dataclasses
import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "architecture.md"
HOOK = ROOT / "docs" / "hooks" / "generate.py"
#: ``docs/architecture.md §6``, or a range ``§2-3`` (hyphen or en dash).
CITATION = re.compile(r"docs/architecture\.md §(\d+)(?:\s*[-\u2013]\s*(\d+))?")
#: A section heading of the page: ``## 6. Experiments, results, metrics``.
HEADING = re.compile(r"^## (\d+)\. \S", flags=re.MULTILINE)
#: The old design notes (a file outside the repository); spelled in two parts so that this
#: file does not match itself.
OUTSIDE = "DESIGN" + ".md"


def _files() -> list[Path]:
    out = [
        p
        for d in ("dynmap_sim", "tests", "benchmarks", "examples")
        for p in (ROOT / d).rglob("*.py")
    ]
    return sorted(out) + [ROOT / "README.md", ROOT / "pyproject.toml"]


def _section_numbers() -> list[int]:
    return [int(n) for n in HEADING.findall(DOC.read_text(encoding="utf-8"))]


def cited_sections(text: str) -> list[tuple[int, int]]:
    """``(line number, section)`` of every citation in ``text``; a range cites each section."""
    out = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        for m in CITATION.finditer(line):
            first = int(m.group(1))
            last = int(m.group(2)) if m.group(2) else first
            out += [(lineno, n) for n in range(first, max(first, last) + 1)]
    return out


def test_citations_are_parsed_with_ranges():
    text = 'x = 1  # see docs/architecture.md §4\n"""(docs/architecture.md §2-3, §9)."""\n'
    assert cited_sections(text) == [(1, 4), (2, 2), (2, 3)]
    assert cited_sections("docs/architecture.md §N and DESIGN §2") == []


def test_sections_are_numbered_one_to_n():
    numbers = _section_numbers()
    assert numbers, f"no '## N. Title' headings in {DOC}"
    assert numbers == list(range(1, len(numbers) + 1))


def test_every_cited_section_exists():
    sections = set(_section_numbers())
    cites = {
        path: cited_sections(path.read_text(encoding="utf-8"))
        for path in _files()
        if path.resolve() != Path(__file__).resolve()
    }
    in_package = [p for p, c in cites.items() if c and (ROOT / "dynmap_sim") in p.parents]
    assert in_package, "the package cites docs/architecture.md nowhere: is the pattern right?"
    missing = [
        f"{path.relative_to(ROOT)}:{lineno}: §{n}"
        for path, found in cites.items()
        for lineno, n in found
        if n not in sections
    ]
    assert not missing, f"sections missing from {DOC.relative_to(ROOT)}: {missing}"


def test_nothing_cites_design_notes_outside_the_repository():
    hits = [
        f"{path.relative_to(ROOT)}:{lineno}"
        for path in _files()
        if path.resolve() != Path(__file__).resolve()
        for lineno, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1)
        if OUTSIDE in line
    ]
    assert not hits, f"cite docs/architecture.md instead of {OUTSIDE}: {hits}"


# ---------------------------------------------------------------------------------------------
# the site
# ---------------------------------------------------------------------------------------------


def _hook():
    spec = importlib.util.spec_from_file_location("docs_generate", HOOK)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _nav_pages(nav) -> list[str]:
    out = []
    for item in nav:
        value = next(iter(item.values())) if isinstance(item, dict) else item
        out += _nav_pages(value) if isinstance(value, list) else [value]
    return out


def _nav() -> list:
    yaml = pytest.importorskip("yaml")
    return yaml.safe_load((ROOT / "mkdocs.yml").read_text())["nav"]


def test_every_page_is_in_the_nav():
    docs = ROOT / "docs"
    nav = _hook().expand_nav(_nav(), docs)
    listed = set(_nav_pages(nav))
    pages = {p.relative_to(docs).as_posix() for p in docs.rglob("*.md")}
    assert pages <= listed, f"pages missing from mkdocs.yml's nav: {sorted(pages - listed)}"
    assert listed <= pages, f"nav entries without a page: {sorted(listed - pages)}"


def test_a_folder_in_the_nav_lists_its_pages(tmp_path):
    (tmp_path / "tuning").mkdir()
    (tmp_path / "tuning" / "b.md").write_text("# Bee notes\n")
    (tmp_path / "tuning" / "a.md").write_text("text without a heading\n")
    (tmp_path / "tuning" / "index.md").write_text("# Tuning\n")
    nav = [{"Home": "index.md"}, {"Tuning": "tuning/"}, {"Empty": "none/"}]
    assert _hook().expand_nav(nav, tmp_path) == [
        {"Home": "index.md"},
        {
            "Tuning": [
                {"Tuning": "tuning/index.md"},
                {"A": "tuning/a.md"},
                {"Bee notes": "tuning/b.md"},
            ]
        },
    ]


def _models(schema: dict) -> dict[str, dict]:
    return {"": schema, **schema.get("$defs", {})}


@pytest.mark.parametrize("kind", ["world", "scenario"])
def test_the_field_reference_shows_every_field_of_the_schema(kind):
    from dynmap_sim.experiments.scenario import scenario_json_schema
    from dynmap_sim.world import world_json_schema

    schema = world_json_schema() if kind == "world" else scenario_json_schema()
    page = (ROOT / "docs" / f"{kind}s.md").read_text(encoding="utf-8")
    assert f"<!-- generate: {kind}-schema -->" in page
    text = _hook().expand(f"<!-- generate: {kind}-schema -->")
    for name, model in _models(schema).items():
        if name:
            assert f"### {name}\n" in text, f"model {name} missing"
        for field in model.get("properties", {}):
            assert f"| `{field}` |" in text, f"{name or kind}.{field} missing"


def test_the_parameter_reference_shows_every_parameter_with_its_comment():
    from dynmap_sim.agent.control.corridor_follower import CorridorFollowerParams
    from dynmap_sim.agent.localization.particle_filter import MCLConfig
    from dynmap_sim.agent.navigation.stack_params import StackParams

    assert "<!-- generate: params-schema -->" in (ROOT / "docs" / "scenarios.md").read_text()
    text = _hook().expand("<!-- generate: params-schema -->")
    for cls in (MCLConfig, StackParams, CorridorFollowerParams):
        for field in dataclasses.fields(cls):
            assert f"| `{field.name}` |" in text, f"{cls.__name__}.{field.name} missing"
    assert "| `max_particles` | integer | `2000` | Most particles KLD-sampling keeps" in text
    assert "(&gt;= 1, &lt;= 1000000) |" in text


def test_the_type_of_a_field_reads_as_words():
    type_text = _hook().type_text
    assert type_text({"type": "array", "prefixItems": [{"type": "number"}] * 2}) == (
        "[number, number]"
    )
    assert type_text({"anyOf": [{"$ref": "#/$defs/WallSpec"}, {"type": "null"}]}) == (
        "[WallSpec](#wallspec) or null"
    )
    assert type_text({"enum": ["box", "circle"]}) == '"box" | "circle"'
    assert type_text({"type": "array", "items": {"type": "string", "format": "date"}}) == (
        "list of date"
    )


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def test_the_cli_reference_shows_every_command_and_option():
    from dynmap_sim.cli import build_parser

    page = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    assert "<!-- generate: cli -->" in page
    text = _hook().expand("<!-- generate: cli -->")
    commands = _subparsers(build_parser())
    assert commands
    for name, sub in commands.items():
        assert f"## `{name}` {{#{name}}}" in text, f"command {name} missing"
        section = text.split(f"## `{name}` ", 1)[1].split("\n## ", 1)[0]
        for action in sub._actions:
            for flag in action.option_strings:
                if flag not in ("-h", "--help"):
                    assert f"`{flag}`" in section, f"{name} {flag} missing"


def test_an_unknown_generated_part_is_an_error():
    with pytest.raises(KeyError, match="unknown generated part"):
        _hook().expand("<!-- generate: nothing-of-that-name -->")


def test_sphinx_roles_leave_the_api_pages():
    html = "see :class:<code>Registry</code> and :meth:<code>add</code>, not :note:"
    assert _hook().on_page_content(html, None, None, None) == (
        "see <code>Registry</code> and <code>add</code>, not :note:"
    )


def test_the_roles_table_lists_every_registered_name():
    from dynmap_sim.agent.control.controller import CONTROLLERS
    from dynmap_sim.agent.localization.localizer import LOCALIZERS
    from dynmap_sim.agent.planning.planner import PLANNERS
    from dynmap_sim.experiments.drivers.driver import DRIVERS

    assert "<!-- generate: roles -->" in (ROOT / "docs" / "plugins.md").read_text()
    text = _hook().expand("<!-- generate: roles -->")
    for registry in (LOCALIZERS, DRIVERS, PLANNERS, CONTROLLERS):
        for name in registry.names():
            assert f"| `{name}` | {registry.role} |" in text


def test_the_readme_links_to_files_that_exist():
    """The README is not part of the site, so ``mkdocs build --strict`` does not check it."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    local = [t for t in targets if "://" not in t]
    assert local, "no relative links in the README: is the pattern right?"
    missing = [t for t in local if not (ROOT / t).exists()]
    assert not missing, f"README links to missing files: {missing}"
