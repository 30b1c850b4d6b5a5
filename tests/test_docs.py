"""Citations of the architecture page cannot rot: every ``docs/architecture.md §N`` cited in
the package (and in the tests, benchmarks, examples, README and pyproject.toml) names a
numbered section heading of ``docs/architecture.md``, and nothing cites design notes from
outside the repository, which users never see."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "architecture.md"
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
