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


def test_figures_have_axis_labels(tmp_path, monkeypatch):
    import matplotlib.figure

    from dynmap_sim.world import render

    seen = []
    monkeypatch.setattr(
        matplotlib.figure.Figure,
        "savefig",
        lambda fig, *a, **k: seen.extend((ax.get_xlabel(), ax.get_ylabel()) for ax in fig.axes),
    )
    spec = load_world("apartment")
    render.render_snapshot(spec, out_path=tmp_path / "a.png")
    assert seen == [("x [m]", "y [m]")]


def test_image_path_appends_png_and_refuses_unknown_formats(tmp_path):
    import pytest

    from dynmap_sim.world.render import image_path

    assert image_path(tmp_path / "fig") == tmp_path / "fig.png"
    assert image_path(tmp_path / "fig.PDF") == tmp_path / "fig.PDF"
    with pytest.raises(ValueError, match="unsupported image format 'xyz'; supported: .*png"):
        image_path(tmp_path / "fig.xyz")


def test_a_sheet_of_a_1000_day_calendar_samples_the_runs(tmp_path):
    import time

    from dynmap_sim.world import World
    from dynmap_sim.world.render import MAX_SHEET_SCAN, sheet_slots

    text = (WORLDS / "lab.toml").read_text()
    long = tmp_path / "long.toml"
    long.write_text(text.replace("n_days = 23", "n_days = 1000", 1))
    world = World(load_world(long), seed=0)
    assert world.calendar.n_slots == 3000 > MAX_SHEET_SCAN
    t0 = time.perf_counter()
    picks = sheet_slots(world)
    assert time.perf_counter() - t0 < 30.0  # ~240 snapshots, not 3000
    assert 1 < len(picks) <= 12 and picks[0] == (1, 1)
    # a calendar below the limit is examined run by run, as before
    short = World(load_world(WORLDS / "lab.toml"), seed=0)
    assert short.calendar.n_slots <= MAX_SHEET_SCAN
    assert sheet_slots(short)[:3] == [(1, 1), (4, 1), (4, 3)]


def _err_line(res):
    """The one line a refused command prints: no traceback, exit status 2 (bad input)."""
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    assert "Traceback" not in res.stderr + res.stdout
    return res.stderr.strip().splitlines()[-1]


def test_render_world_validates_every_argument(tmp_path):
    (tmp_path / "somedir").mkdir()
    shipped = sorted(p.stem for p in WORLDS.glob("*.toml"))
    assert {"apartment", "lab"} <= set(shipped)
    cases = [
        (["apartment", "--day", "99"], "apartment: day 99 outside the calendar (1..28)"),
        (["lab", "--run", "5"], "lab: run 5 outside 1..3"),
        (["apartment", "--day", "0"], "argument --day: must be at least 1, not 0"),
        (["apartment", "--seed", "-1"], "argument --seed: seed must be in 0..2**63-1, not -1"),
        (["labb"], f"labb: no such file or shipped world; shipped: {', '.join(shipped)}"),
        (["apartment", "--sheet", "--day", "2"], "drop --day and --run"),
    ]
    for args, msg in cases:
        line = _err_line(_cli("render-world", *args, "-o", str(tmp_path / "a.png")))
        assert line.endswith(msg), (args, line)
    line = _err_line(_cli("render-world", "apartment", "-o", str(tmp_path / "x.xyz")))
    assert "unsupported image format 'xyz'; supported: " in line and "png" in line
    line = _err_line(_cli("render-world", "apartment", "-o", str(tmp_path / "nodir" / "x.png")))
    assert line.endswith(f"folder {tmp_path / 'nodir'} does not exist; create it first")
    line = _err_line(_cli("render-world", "apartment", "-o", str(tmp_path / "somedir")))
    assert "is a folder; give a file name" in line
    assert not list(tmp_path.glob("*.png"))  # nothing was written by the failures


def test_render_world_prints_the_file_it_wrote(tmp_path):
    out = tmp_path / "fig"
    res = _cli("render-world", "apartment", "--day", "2", "-o", str(out))
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == f"wrote {out}.png"
    assert (tmp_path / "fig.png").is_file() and not out.exists()
    res = _cli("render-world", "apartment", "-o", str(out))
    assert res.stdout.strip() == f"wrote {out}.png (replaced the earlier file)"
