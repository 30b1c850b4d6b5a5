"""ruff keeps the code base clean; the check is part of the suite so CI enforces it."""

import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_ruff_check_is_clean():
    exe = shutil.which("ruff")
    if exe is None:
        pytest.fail("ruff is a dev dependency: pip install -e '.[dev]'")
    proc = subprocess.run(
        [exe, "check", "dynmap_sim", "tests", "benchmarks", "examples"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
