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


def test_bad_scenario_exits_2_with_file_and_field_and_no_traceback(capsys, tmp_path):
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
        assert code == (1 if cmd == "validate" else 2), (cmd, out, err)  # validate: a no
        assert str(bad) in err
        assert "driver.speed_mps" in err and "localizers.0.name" in err
        assert "Traceback" not in err + out


def test_syntax_error_and_missing_file(capsys, tmp_path):
    bad = tmp_path / "broken.toml"
    bad.write_text('name = "x"\nlocalizers = [\n')
    code, _, err = run_cli(capsys, "run", bad)
    assert code == 2 and "TOML syntax error" in err and str(bad) in err
    code, _, err = run_cli(capsys, "run", tmp_path / "missing.toml")
    assert code == 2 and "file not found" in err and "Traceback" not in err


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
    assert code == 2 and "already holds results" in err and "Traceback" not in err
    code, _, err = run_cli(capsys, "run", CI, "--days", "1-2", "--out", out, "-q", "--resume")
    assert code == 0, err
    # resuming with another seed is refused with a clear message
    code, _, err = run_cli(
        capsys, "run", CI, "--days", "1-2", "--seed", "5", "--out", out, "-q", "--resume"
    )
    assert code == 2 and "seed" in err
    # report and export as their own commands
    code, stdout, _ = run_cli(capsys, "report", out)
    assert code == 0 and "summary.md" in stdout
    code, stdout, _ = run_cli(capsys, "export", out, "--tum", tmp_path / "tum")
    assert code == 0 and (tmp_path / "tum" / "truth.tum").is_file()
    assert (tmp_path / "tum" / "odometry.tum").is_file()
    before = (tmp_path / "tum" / "truth.tum").read_bytes()
    code, _, err = run_cli(capsys, "export", out, "--tum", tmp_path / "tum")  # never silently
    assert code == 2 and "truth.tum" in err and "--force" in err
    assert (tmp_path / "tum" / "truth.tum").read_bytes() == before
    code, stdout, _ = run_cli(capsys, "export", out, "--tum", tmp_path / "tum", "--force")
    assert (
        code == 0
        and f"wrote {tmp_path / 'tum' / 'truth.tum'} (replaced the earlier file)" in stdout
    )


def test_report_on_a_folder_without_results(capsys, tmp_path):
    code, _, err = run_cli(capsys, "report", tmp_path)
    assert code == 2 and "no results database" in err


def test_corrupt_checkpoint_is_refused(capsys, tmp_path):
    import sqlite3

    out = tmp_path / "res"
    assert run_cli(capsys, "run", CI, "--days", "1-2", "--out", out, "-q")[0] == 0
    con = sqlite3.connect(out / "results.db")
    with con:
        con.execute("UPDATE checkpoint SET blob = x'00112233'")
    con.close()
    code, _, err = run_cli(capsys, "run", CI, "--days", "1-2", "--out", out, "-q", "--resume")
    assert code == 2 and "corrupt" in err and "Traceback" not in err


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
        "from dynmap_sim.agent.localization.dead_reckoning import DeadReckoning\n"
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


# -- issue 14: every bad argument is one clear line, never a traceback ---------------------------

WORLD = ROOT / "worlds" / "apartment.toml"


def _one_line_error(capsys, *args):
    """Run the CLI; assert exit 2 (validate: 1, its answer) and no traceback; the last line
    of stderr."""
    try:
        code = main([str(a) for a in args])
    except SystemExit as exc:  # argparse
        code = exc.code
    out, err = capsys.readouterr()
    assert code == (1 if args[0] == "validate" else 2), (args, code, out, err)
    assert "Traceback" not in out + err, (args, err)
    return err.strip().splitlines()[-1]


def _scenario(tmp_path, old, new, name="scn.toml"):
    text = CI.read_text().replace('world = "apartment"', f'world = "{WORLD}"')
    assert old in text, old
    path = tmp_path / name
    path.write_text(text.replace(old, new))
    return path


def test_bad_invocations_of_every_command(capsys, tmp_path):
    import os

    (tmp_path / "dir").mkdir()
    fifo = tmp_path / "fifo.toml"
    os.mkfifo(fifo)
    cases = [
        (["validate", "/dev/zero"], "/dev/zero: not a regular file but a device"),
        (["validate", fifo], f"{fifo}: not a regular file but a FIFO"),
        (["validate", tmp_path / "dir"], "not a regular file but a directory"),
        (["validate", tmp_path / "nope.toml"], "nope.toml: file not found"),
        (["run", "/dev/zero"], "error: /dev/zero: not a regular file but a device"),
        (["run", fifo], "not a regular file but a FIFO"),
        (["run", WORLD], "this is a world file, not a scenario"),
        (["check", WORLD], "this is a world file, not a scenario"),
        (["run", CI, "--seed", "-1"], "argument --seed: seed must be in 0..2**63-1, not -1"),
        (["run", CI, "--seed", str(2**64)], "argument --seed: seed must be in 0..2**63-1"),
        (["run", CI, "--workers", "0"], "argument --workers: must be at least 1, not 0"),
        (["run", CI, "--days", "1-99"], "--days: the world's calendar has 28 days; days [1, 99]"),
        (["replay", "/dev/zero", "--localizer", "odometry", "--out", tmp_path / "r"], "device"),
        (["replay", fifo, "--localizer", "odometry", "--out", tmp_path / "r"], "but a FIFO"),
        (["render-world", CI, "-o", tmp_path / "a.png"], "this is a scenario file, not a world"),
        (["render-world", "/dev/zero", "-o", tmp_path / "a.png"], "not a regular file but a"),
        (["toy", "--out", tmp_path, "--seed", "-1"], "argument --seed: seed must be in"),
        (
            ["toy", "--out", "/dev/null/x"],
            "error: cannot create folder /dev/null/x: Not a directory",
        ),
        (["schema", "-o", tmp_path / "nope" / "x.json"], f"folder {tmp_path / 'nope'} does not"),
        (["schema", "-o", tmp_path / "dir"], "is a folder; give a file name"),
        (["schema", "-o", fifo], "not a regular file"),  # writing would block on the pipe
        (["export", tmp_path, "--tum", "/dev/null/x"], "cannot create folder /dev/null/x"),
        (["report", tmp_path / "nope"], "no results database here"),
        (["report", "/dev/zero"], "no results database here"),
        (["run", CI, "--out", "/dev/null/x", "-q"], "/dev/null/x: Not a directory"),
        (["replay", tmp_path / "x.log", "--localizer", "", "--out", tmp_path / "r"], "NAME"),
        (
            ["render-world", "apartment", "--day", "9", "--run", "2", "-o", tmp_path / "a.png"],
            "run 2 outside 1..1",
        ),
    ]
    for args, msg in cases:
        line = _one_line_error(capsys, *args)
        assert msg in line, (args, line)


def test_version_and_python_dash_m(capsys):
    import subprocess
    import sys

    from dynmap_sim import __version__

    with pytest.raises(SystemExit) as ei:
        main(["--version"])
    assert ei.value.code == 0 and capsys.readouterr().out.strip() == f"dynmap-sim {__version__}"
    res = subprocess.run(
        [sys.executable, "-m", "dynmap_sim", "validate", str(WORLD)],
        capture_output=True,
        text=True,
        check=False,
    )
    assert res.returncode == 0 and res.stdout.strip() == f"{WORLD}: OK", res.stderr


def test_every_option_of_every_command_has_help():
    import argparse

    from dynmap_sim.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    missing = [
        f"{cmd} {action.dest}"
        for cmd, parser in sub.choices.items()
        for action in parser._actions
        if not isinstance(action, argparse._HelpAction) and not action.help
    ]
    assert missing == []
    assert set(sub.choices) >= {"run", "check", "replay", "toy", "render-world", "validate"}
    for parser in (build_parser(), *sub.choices.values()):  # formatting the help must not fail
        assert parser.format_help()


@pytest.mark.parametrize(
    "old, new, field, msg",
    [
        ('name = "odometry"', 'name = ".relative:X"', "localizers.0.name", "give 'package.module"),
        (
            'preset = "urg-04lx"',
            'preset = "urg-04lx"\noverrides = { noise = 5 }',
            "sensor.overrides.noise",
            "must be a table of LidarNoise fields",
        ),
        (
            'preset = "urg-04lx"',
            'preset = "urg-04lx"\noverrides = { mount_pose = [1, 2] }',
            "sensor.overrides.mount_pose",
            "must be 3 finite numbers",
        ),
        (
            'preset = "urg-04lx"',
            'preset = "urg-04lx"\noverrides = { scan_period_s = 0 }',
            "sensor.overrides.scan_period_s",
            "must be >= 0.005 s (the scan period is the simulation step",
        ),
        (
            'preset = "urg-04lx"',
            'preset = "urg-04lx"\noverrides = { scan_period_s = 1e-6 }',
            "sensor.overrides.scan_period_s",
            "at most 200 steps per second), got 1e-06",
        ),
        (
            'preset = "urg-04lx"',
            'preset = "urg-04lx"\noverrides = { angle_min_rad = nan }',
            "sensor.overrides.angle_min_rad",
            "must be a finite number, got nan",
        ),
    ],
)
def test_scenario_values_that_crashed_validate(capsys, tmp_path, old, new, field, msg):
    bad = _scenario(tmp_path, old, new)
    line = _one_line_error(capsys, "validate", bad)
    assert line.startswith(f"{bad}: {field}: ") and msg in line, line


@pytest.mark.parametrize("folder", ["scenarios", "elsewhere"])
def test_a_scenario_with_a_byte_order_mark_loads(capsys, tmp_path, folder):
    scn = tmp_path / folder / "bom.toml"
    scn.parent.mkdir()
    text = CI.read_text().replace('world = "apartment"', f'world = "{WORLD}"')
    scn.write_text(text, encoding="utf-8-sig")
    code, out, err = run_cli(capsys, "validate", scn)
    assert code == 0 and out.startswith(f"{scn}: OK (3 runs"), err


def test_resume_with_nothing_to_resume_and_ctrl_c_say_what_happens(capsys, tmp_path, monkeypatch):
    import dynmap_sim.experiments.runner as runner

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(runner, "run_experiment", interrupted)
    code, _, err = run_cli(capsys, "run", CI, "--out", tmp_path / "new", "--resume", "-q")
    assert code == 130
    assert f"note: nothing to resume in {tmp_path / 'new'}: starting from the first run" in err
    assert err.strip().splitlines()[-1] == (
        "interrupted; the runs finished so far are stored: the same command with --resume "
        "continues from the last of them"
    )


def test_check_and_replay_do_not_overwrite_results_without_force(capsys, tmp_path):
    scn = _scenario(tmp_path, "days = [1, 3]", "days = [1, 1]")
    out = tmp_path / "o"
    assert run_cli(capsys, "check", scn, "-q", "--out", out)[0] == 0
    before = (out / "results.db").stat().st_mtime_ns
    line = _one_line_error(capsys, "check", scn, "-q", "--out", out)
    assert line == (
        f"error: {out / 'results.db'} already holds results; check would replace them: pass "
        "--force to replace them or choose another --out"
    )
    assert (out / "results.db").stat().st_mtime_ns == before
    assert run_cli(capsys, "check", scn, "-q", "--out", out, "--force")[0] == 0
    (tmp_path / "x.log").write_text("")
    line = _one_line_error(
        capsys, "replay", tmp_path / "x.log", "--localizer", "odometry", "--out", out
    )
    assert "already holds results; replay would replace them: pass --force" in line


def test_check_without_expectations_is_refused_before_running(capsys, tmp_path):
    text = CI.read_text().replace('world = "apartment"', f'world = "{WORLD}"')
    bare = tmp_path / "bare.toml"
    bare.write_text(text[: text.index("[expectations]")])
    line = _one_line_error(capsys, "check", bare, "-q", "--out", tmp_path / "o")
    assert line == (
        f"error: {bare}: nothing to check: [expectations] is missing or sets no limit (a check "
        "of nothing would pass); add some (README: Regression checks) or use `run`"
    )
    assert not (tmp_path / "o").exists()
    empty = tmp_path / "empty.toml"
    empty.write_text(
        text.replace("mean_error_m = 0.25\nmax_error_m = 0.5\nlost_fraction = 0.0", "").replace(
            "no_collisions = true\nmax_skipped_waypoints = 0", ""
        )
    )
    assert "nothing to check" in _one_line_error(capsys, "check", empty, "-q")


def test_run_ends_with_the_headline_numbers(tmp_path, capsys):
    """issue 14: after "results in DIR", per localizer ATE, mean, max and lost fraction (the
    report's overall numbers), and the navigation measures when the results hold them."""
    from dynmap_sim.analysis.report import overall_stats
    from dynmap_sim.experiments.results import ResultsDB

    out = tmp_path / "o"
    scn = ROOT / "worlds" / "scenarios" / "ci-apartment.toml"
    assert main(["run", str(scn), "--out", str(out), "-q"]) == 0
    lines = capsys.readouterr().out.splitlines()
    i = lines.index(f"results in {out}")
    assert lines[i + 1].split() == [
        "localizer",
        "ATE",
        "RMSE",
        "[m]",
        "mean",
        "[m]",
        "max",
        "[m]",
        "lost",
    ]
    with ResultsDB.open(out) as db:
        stats = overall_stats(db)
        nav = db.nav_runs()
    for s, line in zip(stats, lines[i + 2 :], strict=False):
        assert line.split() == [
            s["localizer"],
            f"{s['ate_rmse_m']:.3f}",
            f"{s['mean_error_m']:.3f}",
            f"{s['max_error_m']:.3f}",
            f"{100 * s['lost_fraction']:.1f}",
            "%",
        ]
    reached = sum(n.goal_reached for _, _, n in nav)
    stopped = sum(not n.goal_reached and n.time_s >= 20.0 for _, _, n in nav)
    assert reached + stopped == len(nav)  # the tour ends at the goal or at max_run_s = 20 s
    limit = f" ({stopped} stopped by the scenario's max_run_s = 20 s)" if stopped else ""
    assert lines[-1] == (
        f"navigation: goal reached in {reached} of {len(nav)} runs{limit}; "
        f"{sum(n.collisions for _, _, n in nav)} collisions"
    )


def _strict_check(tmp_path):
    """A scenario whose expectation no run meets (max error 1 µm over one day)."""
    text = CI.read_text().replace('world = "apartment"', f'world = "{WORLD}"')
    path = tmp_path / "strict.toml"
    path.write_text(
        text.replace("days = [1, 3]", "days = [1, 1]").replace(
            "max_error_m = 0.5", "max_error_m = 0.000001"
        )
    )
    return path


@pytest.mark.parametrize(
    "args,status",
    [
        (["run", "{tmp}/missing.toml"], 2),  # a file that is not there
        (["run", CI, "--seed", "x"], 2),  # argparse
        (["run", CI, "--days", "1-99"], 2),  # outside the world's calendar
        (["run", CI, "--out", "/dev/null/x", "-q"], 2),  # the file system refuses the path
        (["check", WORLD], 2),  # a world, not a scenario
        (["check", "{strict}", "-q", "--out", "{tmp}/o"], 1),  # ran; the expectation fails
        (["check", "{strict}", "-q", "--out", "{tmp}/o", "--force", "--bogus"], 2),
        (["report", "{tmp}/nope"], 2),  # no results there
        (["export", "{tmp}"], 2),  # nothing asked for
        (["validate", "{tmp}/missing.toml"], 1),  # validate's answer: the file is not valid
    ],
)
def test_exit_status_2_for_misuse_and_1_for_a_failed_check(capsys, tmp_path, args, status):
    strict = _strict_check(tmp_path)
    argv = [str(a).replace("{tmp}", str(tmp_path)).replace("{strict}", str(strict)) for a in args]
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse
        code = exc.code
    out, err = capsys.readouterr()
    assert code == status, (argv, out, err)
    assert "Traceback" not in out + err
    assert "FAILED" in out if status == 1 and args[0] == "check" else err.strip()
