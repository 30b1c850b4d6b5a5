"""The shipped example of a user's own localizer plugged in by ``module:Class`` works end to
end through the same code path as ``dynmap-sim check``."""

from pathlib import Path

from dynmap_sim.testing import run_scenario

ROOT = Path(__file__).resolve().parents[2]


def test_user_localizer_example_passes_its_check(monkeypatch, tmp_path):
    monkeypatch.syspath_prepend(str(ROOT / "examples"))
    result = run_scenario(ROOT / "examples" / "wall-matcher.toml", out_dir=tmp_path)
    assert result.passed
    assert any(r.subject == "wall-matcher" for r in result.rows)
    assert (tmp_path / "results.db").is_file()
