"""The CLI, called as ``dynmap_sim.cli.main([...])``: real runs, exit codes, clean errors."""

import csv
from pathlib import Path

import pytest

from dynmap_sim.cli import main

ROOT = Path(__file__).resolve().parents[1]
CI = ROOT / "worlds" / "scenarios" / "ci-apartment.toml"


def run_cli(capsys, *args):
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def test_validate_scenarios_and_worlds(capsys):
    code, out, err = run_cli(
        capsys,
        "validate",
        CI,
        ROOT / "worlds" / "apartment.toml",
        *sorted((ROOT / "worlds" / "scenarios").glob("*.toml")),
    )
    assert code == 0, err
    assert f"{CI}: OK" in out and "apartment.toml: OK" in out


def test_bad_scenario_exits_1_with_file_and_field_and_no_traceback(capsys, tmp_path):
    bad = tmp_path / "scenarios" / "bad.toml"
    bad.parent.mkdir()
    bad.write_text(
        'name = "bad"\nworld = "apartment"\ndays = [1, 99]\n'
        '[driver]\nspeed_mps = -0.3\n[[localizers]]\nname = "no-such"\n'
    )
    for cmd in ("validate", "run", "check"):
        code, out, err = run_cli(
            capsys, cmd, bad, *(["--out", tmp_path / "o"] if cmd != "validate" else [])
        )
        assert code == 1, (cmd, out, err)
        assert str(bad) in err
        assert "driver.speed_mps" in err and "localizers.0.name" in err
        assert "Traceback" not in err + out


def test_syntax_error_and_missing_file(capsys, tmp_path):
    bad = tmp_path / "broken.toml"
    bad.write_text('name = "x"\nlocalizers = [\n')
    code, _, err = run_cli(capsys, "run", bad)
    assert code == 1 and "TOML syntax error" in err and str(bad) in err
    code, _, err = run_cli(capsys, "run", tmp_path / "missing.toml")
    assert code == 1 and "file not found" in err and "Traceback" not in err


def test_schema_scenario(capsys, tmp_path):
    code, out, _ = run_cli(capsys, "schema", "scenario", "-o", tmp_path / "s.json")
    assert code == 0
    import json

    schema = json.loads((tmp_path / "s.json").read_text())
    assert "localizers" in schema["properties"]


def test_run_report_export_and_resume(capsys, tmp_path):
    out = tmp_path / "res"
    code, stdout, err = run_cli(capsys, "run", CI, "--days", "1-2", "--out", out, "-q", "--report")
    assert code == 0, err
    assert f"results in {out}" in stdout and "per_day.csv" in stdout
    with (out / "per_day.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert [r["day"] for r in rows] == ["1", "2"]
    assert float(rows[0]["mean_error_m"]) > 0.0
    # running again into the same folder is refused cleanly; --resume has nothing left to do
    code, _, err = run_cli(capsys, "run", CI, "--days", "1-2", "--out", out, "-q")
    assert code == 1 and "already holds results" in err and "Traceback" not in err
    code, _, err = run_cli(capsys, "run", CI, "--days", "1-2", "--out", out, "-q", "--resume")
    assert code == 0, err
    # resuming with another seed is refused with a clear message
    code, _, err = run_cli(
        capsys, "run", CI, "--days", "1-2", "--seed", "5", "--out", out, "-q", "--resume"
    )
    assert code == 1 and "seed" in err
    # report and export as their own commands
    code, stdout, _ = run_cli(capsys, "report", out)
    assert code == 0 and "summary.md" in stdout
    code, stdout, _ = run_cli(capsys, "export", out, "--tum", tmp_path / "tum")
    assert code == 0 and (tmp_path / "tum" / "truth.tum").is_file()
    assert (tmp_path / "tum" / "odometry.tum").is_file()


def test_report_on_a_folder_without_results(capsys, tmp_path):
    code, _, err = run_cli(capsys, "report", tmp_path)
    assert code == 1 and "no results database" in err


def test_corrupt_checkpoint_is_refused(capsys, tmp_path):
    import sqlite3

    out = tmp_path / "res"
    assert run_cli(capsys, "run", CI, "--days", "1-2", "--out", out, "-q")[0] == 0
    con = sqlite3.connect(out / "results.db")
    with con:
        con.execute("UPDATE checkpoint SET blob = x'00112233'")
    con.close()
    code, _, err = run_cli(capsys, "run", CI, "--days", "1-2", "--out", out, "-q", "--resume")
    assert code == 1 and "corrupt" in err and "Traceback" not in err


def test_check_passes_and_fails_with_exit_codes(capsys, tmp_path):
    code, out, err = run_cli(capsys, "check", CI, "-q", "--out", tmp_path / "ok")
    assert code == 0, out + err
    assert "PASSED" in out and "FAIL " not in out
    strict = tmp_path / "strict.toml"
    strict.write_text(
        CI.read_text()
        .replace('world = "apartment"', f'world = "{ROOT / "worlds" / "apartment.toml"}"')
        .replace("days = [1, 3]", "days = [1, 1]")
        .replace("max_error_m = 0.5", "max_error_m = 0.000001")
    )
    code, out, err = run_cli(capsys, "check", strict, "-q")
    assert code == 1
    assert "FAILED" in out and "max error [m]" in out and "FAIL" in out


@pytest.mark.parametrize("days", ["0-2", "3-1", "x"])
def test_bad_day_range_is_an_argument_error(capsys, days):
    with pytest.raises(SystemExit) as ei:
        main(["run", str(CI), "--days", days])
    assert ei.value.code == 2
    assert "day" in capsys.readouterr().err


def test_check_runs_every_seed(capsys, tmp_path):
    scn = tmp_path / "seeds.toml"
    scn.write_text(
        CI.read_text()
        .replace('world = "apartment"', f'world = "{ROOT / "worlds" / "apartment.toml"}"')
        .replace("days = [1, 3]", "days = [1, 1]")
        .replace("seeds = [0]", "seeds = [0, 1]")
        .replace("max_run_s = 20.0", "max_run_s = 4.0")
    )
    code, out, err = run_cli(capsys, "check", scn, "-q", "--out", tmp_path / "o")
    assert code == 0, out + err
    assert (tmp_path / "o" / "seed-0" / "results.db").is_file()
    assert (tmp_path / "o" / "seed-1" / "results.db").is_file()
    seeds = {line.split()[0] for line in out.splitlines()[3:] if line.strip()}
    assert seeds == {"0", "1"}


def test_a_failing_localizer_is_named_with_its_traceback_and_exit_1(capsys, tmp_path, monkeypatch):
    (tmp_path / "boom_loc.py").write_text(
        "from dynmap_sim.agent.dead_reckoning import DeadReckoning\n"
        "class Boom(DeadReckoning):\n"
        "    def update(self, odom, scan):\n"
        "        raise ZeroDivisionError('my localizer divides by zero')\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    scn = tmp_path / "boom.toml"
    scn.write_text(
        f'name = "boom"\nworld = "{ROOT / "worlds" / "apartment.toml"}"\ndays = [1, 1]\n'
        '[driver]\nmax_run_s = 2.0\n[[localizers]]\nname = "boom_loc:Boom"\nlabel = "mine"\n'
    )
    code, _, err = run_cli(capsys, "run", scn, "--out", tmp_path / "o", "-q", "--workers", "1")
    assert code == 1
    assert "error: localizer 'mine' failed on day 1 run 1 at scan 0" in err
    assert "ZeroDivisionError: my localizer divides by zero" in err
    assert 'boom_loc.py", line 4, in update' in err  # the plugin author sees where
