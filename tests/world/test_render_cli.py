"""Rendering and the CLI commands that belong to the world package."""

import subprocess
import sys
from pathlib import Path

from dynmap_sim.world import load_world
from dynmap_sim.world.render import render_sheet, render_snapshot

WORLDS = Path(__file__).resolve().parents[2] / "worlds"


def test_render_snapshot_and_sheet(tmp_path):
    spec = load_world("apartment")
    a = render_snapshot(spec, seed=0, day=9, run=1, out_path=tmp_path / "a.png")
    b = render_sheet(spec, seed=0, out_path=tmp_path / "s.png")
    for p in (a, b):
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert p.stat().st_size > 10_000


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "dynmap_sim.cli", *args], capture_output=True, text=True
    )


def test_validate_prints_ok_or_errors_without_traceback(tmp_path):
    ok = _cli("validate", str(WORLDS / "lab.toml"), str(WORLDS / "apartment.toml"))
    assert ok.returncode == 0, ok.stderr
    assert ok.stdout.count("OK") == 2
    bad = tmp_path / "bad.toml"
    text = (
        (WORLDS / "apartment.toml").read_text().replace("size = [2.0, 0.9]", "size = [2.0, -0.9]")
    )
    bad.write_text(text)
    res = _cli("validate", str(bad))
    assert res.returncode == 1
    assert "objects.0.size: sizes must be > 0" in res.stderr
    assert "Traceback" not in res.stderr
