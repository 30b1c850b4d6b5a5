"""The boundaries of docs/architecture.md §1 hold: import-linter contracts in pyproject.toml."""

import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_contracts_are_declared():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    names = [c["name"] for c in cfg["contracts"]]
    agent = next(c for c in cfg["contracts"] if c["source_modules"] == ["dynmap_sim.agent"])
    assert {"dynmap_sim.world", "dynmap_sim.sensors", "dynmap_sim.robot", "dynmap_sim.env"} <= set(
        agent["forbidden_modules"]
    )
    assert len(names) >= 5


def test_import_contracts_hold():
    exe = shutil.which("lint-imports")
    if exe is None:
        pytest.fail("import-linter is a dev dependency: pip install -e '.[dev]'")
    proc = subprocess.run([exe], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "0 broken" in proc.stdout, proc.stdout


def test_agent_does_not_load_the_simulator():
    """Importing the whole agent package pulls in neither pymunk nor the simulator modules."""
    code = (
        "import sys, importlib, pkgutil, dynmap_sim.agent as a\n"
        "for m in pkgutil.walk_packages(a.__path__, 'dynmap_sim.agent.'):\n"
        "    importlib.import_module(m.name)\n"
        "bad = [m for m in sys.modules if m.split('.')[0] == 'pymunk' or m.startswith(("
        "'dynmap_sim.world', 'dynmap_sim.sensors', 'dynmap_sim.robot', 'dynmap_sim.env'))]\n"
        "print(bad); sys.exit(1 if bad else 0)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr
