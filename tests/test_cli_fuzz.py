"""Fuzz the CLI with mutated files: ``validate`` of a world or scenario file with one value
replaced by a hostile one (huge, NaN, wrong type, a date past 9999, a relative module, ...)
exits 0 or 1 with file and field, never with an exception (issue 14)."""

import random
import re
from pathlib import Path

import pytest

from dynmap_sim.cli import main

ROOT = Path(__file__).resolve().parents[1]
SOURCES = [
    ROOT / "worlds" / "apartment.toml",
    ROOT / "tests" / "world" / "data" / "room.toml",
    ROOT / "worlds" / "scenarios" / "ci-apartment.toml",
    ROOT / "worlds" / "scenarios" / "ci-apartment-kidnap.toml",
]
HOSTILE = [
    "-1", "0", "1e308", "-1e308", "nan", "inf", '"x"', '""', "[]", "[1, 2]", "[[1]]", "{}",
    "true", "9999-12-31", "0001-01-01", "18446744073709551616", '"../../x"',
    "[1e308, 1e308, 0]", "[nan, 0, 0]", '".relative:X"', '"os:path"', "{ noise = 5 }",
    "[" * 2000 + "]" * 2000,
]  # fmt: skip
ASSIGNMENT = re.compile(r"^\s*[a-z_]+\s*=")


def _mutants(n: int, seed: int = 14):
    rng = random.Random(seed)
    for i in range(n):
        src = SOURCES[i % len(SOURCES)]
        lines = src.read_text().splitlines()
        k = rng.choice([j for j, line in enumerate(lines) if ASSIGNMENT.match(line)])
        lines[k] = f"{lines[k].split('=')[0]}= {rng.choice(HOSTILE)}"
        text = "\n".join(lines).replace('"apartment"', f'"{ROOT / "worlds" / "apartment.toml"}"')
        yield src, lines[k][:60], text


@pytest.mark.parametrize("chunk", range(4))
def test_mutated_files_give_file_errors_not_exceptions(tmp_path, capsys, chunk):
    (tmp_path / "scenarios").mkdir()
    mutants = list(_mutants(240))[chunk::4]
    for i, (src, line, text) in enumerate(mutants):
        folder = tmp_path / "scenarios" if "scenarios" in src.parts else tmp_path
        path = folder / f"m{i}.toml"
        path.write_text(text)
        code = main(["validate", str(path)])  # an exception fails the test with its traceback
        out, err = capsys.readouterr()
        assert code in (0, 1), (src.name, line)
        assert (f"{path}: OK" in out) if code == 0 else err.startswith(f"{path}: "), (line, err)
