"""``dynmap-sim``: the thin command-line front end.

Every subcommand parses its arguments and calls one library function; all logic lives in the
package. Bad input files are reported (file, field, message) with exit status 1, never with a
traceback.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

Handler = Callable[[argparse.Namespace], int]


def day_range(text: str) -> tuple[int, int]:
    """Parse ``A-B`` or ``A`` (1-based, inclusive) into a day range (an argparse ``type``; the
    benchmarks' ``--days`` use it too)."""
    try:
        a, dash, b = text.partition("-")
        if dash and not b.strip():  # "1-" is not "1": say what was meant
            raise ValueError(text)
        first, last = int(a), int(b or a)
    except ValueError:
        raise argparse.ArgumentTypeError(f"days must look like 3 or 1-7, not {text!r}") from None
    if first < 1 or last < first:
        raise argparse.ArgumentTypeError(f"bad day range {text!r}")
    return first, last


#: Seeds are stored as SQLite integers: 0 .. 2**63 - 1.
MAX_SEED = 2**63 - 1


T = TypeVar("T")


def _converted(text: str, convert: Callable[[str], T], expected: str) -> T:
    """``convert(text)``, or an argparse error saying what was ``expected``."""
    try:
        return convert(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}, not {text!r}") from None


def _seed(text: str) -> int:
    """A seed: an integer in 0 .. 2**63 - 1."""
    v = _converted(text, int, "an integer seed")
    if not 0 <= v <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"seed must be in 0..2**63-1, not {v}")
    return v


def _positive(text: str) -> int:
    """An integer >= 1 (a day, a run, a number of workers)."""
    v = _converted(text, int, "an integer")
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, not {v}")
    return v


def _localizer_arg(text: str) -> str:
    """``--localizer NAME[,key=value,...]``: the name must not be empty."""
    if not text.split(",")[0].strip():
        raise argparse.ArgumentTypeError(f"expected NAME[,key=value,...], not {text!r}")
    return text


def _reference_offset(text: str) -> float | None:
    """``--reference-offset``: seconds (finite), or ``auto`` (``None``: estimated)."""
    import math

    if text.strip().lower() == "auto":
        return None
    v = _converted(text, float, "seconds or auto")
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"must be a finite number of seconds, not {text!r}")
    return v


def _positive_seconds(text: str) -> float:
    """A finite duration > 0 [s]."""
    import math

    v = _converted(text, float, "seconds")
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be a number of seconds > 0, not {text!r}")
    return v


def _output_file(path: str) -> Path:
    """An output file named by ``-o``: its folder must exist (a typo does not create folders)
    and it must not be a folder, a device or a pipe (writing to a FIFO would block)."""
    from dynmap_sim.errors import InputError

    p = Path(path)
    if p.is_dir():
        raise InputError(f"-o {path}: is a folder; give a file name, e.g. {p / 'out'}")
    if p.exists() and not p.is_file():
        raise InputError(f"-o {path}: not a regular file; give a file name")
    if not p.parent.is_dir():
        raise InputError(f"-o {path}: folder {p.parent} does not exist; create it first")
    return p


def _output_dir(path: str | Path) -> Path:
    """An output folder (created with its parents); InputError when it cannot be."""
    from dynmap_sim.errors import InputError

    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create folder {path}: {exc.strerror or exc}") from None
    return p


def _refuse_results(out: str | Path | None, force: bool, what: str) -> None:
    """Refuse to write into a folder that holds results (``out/results.db``, or
    ``out/seed-*/results.db``) unless ``--force``."""
    from dynmap_sim.errors import InputError
    from dynmap_sim.experiments.results import DB_NAME

    if out is None or force:
        return
    d = Path(out)
    held = [d / DB_NAME, *sorted(d.glob(f"seed-*/{DB_NAME}"))]
    held = [h for h in held if h.exists()]
    if held:
        raise InputError(
            f"{held[0]} already holds results; {what} would replace them: pass --force to "
            "replace them or choose another --out"
        )


def _wrote(path: Path, existed: bool) -> str:
    return f"wrote {path}" + (" (replaced the earlier file)" if existed else "")


def _shipped_worlds() -> list[str]:
    from dynmap_sim.registration import WORLDS_DIR

    return sorted(p.stem for p in WORLDS_DIR.glob("*.toml"))


def _load_world_arg(ref: str):  # -> WorldSpec
    """A world by file or shipped name; an unknown name lists the shipped worlds."""
    from dynmap_sim.experiments.scenario import is_scenario_file
    from dynmap_sim.world import WorldFileError, load_world

    try:
        return load_world(ref)
    except WorldFileError as exc:
        p = Path(ref)
        if exc.errors == [("", "file not found")] and p.suffix == "" and len(p.parts) == 1:
            raise WorldFileError(
                ref,
                [("", f"no such file or shipped world; shipped: {', '.join(_shipped_worlds())}")],
            ) from None
        if len(exc.errors) > 1 and is_scenario_file(p):  # readable, so safe to look into
            raise WorldFileError(
                ref, [("", "this is a scenario file, not a world file: give its world")]
            ) from None
        raise


def _refuse_world_file(path: str) -> None:
    """A world file given where a scenario is expected: say so (instead of listing every
    scenario field it lacks)."""
    from dynmap_sim.errors import FileError, read_toml
    from dynmap_sim.experiments.scenario import ScenarioFileError, is_scenario_file

    data = read_toml(path, ScenarioFileError)  # a bad file is reported here, read safely
    if is_scenario_file(path):
        return
    if {"calendar", "walls", "bounds"} & set(data):
        raise FileError(
            path,
            [
                (
                    "",
                    "this is a world file, not a scenario; a scenario names its world "
                    '(world = "path/to/world.toml") and the localizers to run, '
                    "e.g. worlds/scenarios/ci-apartment.toml",
                )
            ],
        )


def _cmd_validate(args: argparse.Namespace) -> int:
    from dynmap_sim.analysis.scenarios import load_scenario
    from dynmap_sim.errors import FileError, InputError, read_toml
    from dynmap_sim.experiments.scenario import ScenarioFileError, is_scenario_file
    from dynmap_sim.world import WorldFileError, load_world

    status = 0
    seen: dict[Path, list[Any]] = {}
    for path in args.files:
        try:
            data = read_toml(path, FileError)  # refuses devices, FIFOs and huge files at once
            # a world file has no "world" key (is_scenario_file cannot read a file with a BOM)
            if is_scenario_file(path) or isinstance(data.get("world"), str):
                from dynmap_sim.experiments.runner import scenario_size

                scenario = load_scenario(path)
                world = scenario.world_path
                size = f" ({scenario_size(scenario).describe()})"
            else:
                world, size = Path(path), ""
            spec = load_world(world)
        except (WorldFileError, ScenarioFileError, FileError, InputError) as exc:
            print(exc, file=sys.stderr)
            status = 1
        else:
            print(f"{path}: OK{size}")
            _route_warnings(path, spec, world.resolve(), seen)
    return status


def _route_warnings(path: str, spec: Any, world: Path, seen: dict[Path, list[Any]]) -> None:
    """Warn (stderr) where a robot of the default radius cannot follow the route on a day
    (each world checked once per command)."""
    from dynmap_sim.world.generator import route_problems

    if world not in seen:
        seen[world] = route_problems(spec)
    for pr in seen[world]:
        when = f"day {pr.day} run {pr.run}: " if pr.day else ""
        print(
            f"warning: {path}: {when}{pr.field} at ({pr.x:.2f}, {pr.y:.2f}): {pr.message}",
            file=sys.stderr,
        )


def _cmd_schema(args: argparse.Namespace) -> int:
    from dynmap_sim.experiments.scenario import scenario_json_schema
    from dynmap_sim.world import world_json_schema

    schema = world_json_schema() if args.kind == "world" else scenario_json_schema()
    text = json.dumps(schema, indent=2)
    if args.output:
        out = _output_file(args.output)
        existed = out.exists()
        out.write_text(text + "\n", encoding="utf-8")
        print(_wrote(out, existed))
    else:
        print(text)
    return 0


def _cmd_render_world(args: argparse.Namespace) -> int:
    from dynmap_sim.errors import InputError
    from dynmap_sim.world import Calendar
    from dynmap_sim.world.render import MAX_SHEET_SCAN, image_path, render_sheet, render_snapshot

    out = _output_file(args.output)
    try:
        out = image_path(out)
    except ValueError as exc:
        raise InputError(f"-o {args.output}: {exc}") from None
    if len(args.world) > 1:  # a sheet of several worlds, each at day 1 run 1
        from dynmap_sim.world.render import render_worlds

        if not args.sheet or args.day is not None or args.run is not None:
            raise InputError("several worlds make one sheet: pass --sheet, without --day/--run")
        existed = out.exists()
        specs = [_load_world_arg(w) for w in args.world]
        print(_wrote(render_worlds(specs, seed=args.seed, out_path=out), existed))
        return 0
    args.world = args.world[0]
    spec = _load_world_arg(args.world)
    cal = Calendar(spec.calendar)
    if args.sheet:
        if args.day is not None or args.run is not None:
            raise InputError("--sheet shows runs over the whole calendar: drop --day and --run")
    else:
        try:
            cal.slot_index(args.day or 1, args.run or 1)
        except ValueError as exc:
            raise InputError(f"{args.world}: {exc}") from None
    existed = out.exists()
    if args.sheet:
        out = render_sheet(spec, seed=args.seed, out_path=out)
        if cal.n_slots > MAX_SHEET_SCAN:
            print(
                f"note: the calendar has {cal.n_slots} runs; the sheet shows runs picked from "
                f"{MAX_SHEET_SCAN} evenly spaced ones"
            )
    else:
        day, run = args.day or 1, args.run or 1
        out = render_snapshot(spec, seed=args.seed, day=day, run=run, out_path=out)
    print(_wrote(out, existed))
    return 0


def _cmd_generate(args: argparse.Namespace) -> int:
    """Write a generated world (and a scenario); bad input is one line and exit status 2."""
    from dynmap_sim.world.generator import GeneratorError, parse_param, write_world

    try:
        params = dict(parse_param(t) for t in args.param or ())
        g = write_world(args.kind, args.seed, args.output, params, args.scenario, args.force)
    except GeneratorError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.output}" + (f" and {args.scenario}" if args.scenario else ""))
    print(f"{g.spec.name}: " + ", ".join(f"{k} {v}" for k, v in g.counts.items()))
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from dynmap_sim.analysis.scenarios import load_scenario
    from dynmap_sim.errors import InputError
    from dynmap_sim.experiments.runner import run_experiment

    _refuse_world_file(args.scenario)
    scenario = load_scenario(args.scenario)
    if args.days is not None:  # the scenario's own days were checked when it was loaded
        from dynmap_sim.env_factory import sim_spec_errors

        for field, msg in sim_spec_errors(scenario.sim_spec(), args.days):
            if field == "days":
                raise InputError(f"--days: {msg}")
    from dynmap_sim.experiments.runner import default_out_dir

    out_dir = Path(args.out) if args.out is not None else default_out_dir(scenario)
    if args.report and not args.resume:
        _refuse_foreign_report_files(out_dir)
    if args.resume:
        from dynmap_sim.experiments.results import DB_NAME, orphaned_checkpoint

        if not (out_dir / DB_NAME).exists() and orphaned_checkpoint(out_dir) is None:
            print(
                f"note: nothing to resume in {out_dir}: starting from the first run",
                file=sys.stderr,
            )
    out = run_experiment(
        scenario,
        out_dir=args.out,
        days=args.days,
        seed=args.seed,
        resume=args.resume,
        progress=not args.quiet,
        workers=args.workers,
        keep_scans=args.keep_scans,
    )
    overall = _write_report(out) if args.report else None
    print(f"results in {out}")
    for line in _headline(out, overall=overall):
        print(line)
    return 0


#: Kinds of file a report writes into a results folder (summary.md, per_day.csv, figures,
#: findings.json, ...).
REPORT_SUFFIXES = (".md", ".csv", ".png", ".json")


def _refuse_foreign_report_files(out: Path) -> None:
    """Before a new run with ``--report`` into ``out``: refuse a folder that already holds
    files of the kinds a report writes (the user's own ``summary.md``, say), which the report
    would replace at the end of the run."""
    from dynmap_sim.errors import InputError

    if not out.is_dir():
        return
    held = sorted(p.name for p in out.iterdir() if p.is_file() and p.suffix in REPORT_SUFFIXES)
    if held:
        raise InputError(
            f"--out {out}: holds {', '.join(held[:3])}{' …' if len(held) > 3 else ''}, which "
            "the report would replace: choose an empty folder (or run without --report)"
        )


def _write_report(out: Path) -> list[dict[str, Any]]:
    """Write the report of ``out`` and say what it wrote; a full disk is one clear line. The
    whole-experiment figures it computed (:func:`dynmap_sim.analysis.report.overall_stats`)."""
    from dynmap_sim.analysis.report import make_report
    from dynmap_sim.errors import InputError
    from dynmap_sim.experiments.results import is_disk_full

    try:
        report = make_report(out)
    except (OSError, RuntimeError, ValueError) as exc:  # matplotlib wraps some OSErrors
        if not (is_disk_full(exc) or is_disk_full(exc.__context__ or exc)):
            raise
        raise InputError(
            f"the disk is full (writing the report into {out}); the results are kept: free "
            f"some space, then `dynmap-sim report {out}` writes the report"
        ) from None
    for path in report.written:
        print(f"wrote {path}")
    return report.overall


def _headline(
    out: Path, timing: bool = False, overall: list[dict[str, Any]] | None = None
) -> list[str]:
    """The headline numbers of a results folder: per localizer ATE RMSE, mean and max
    position error and the lost fraction (:func:`dynmap_sim.analysis.report.overall_stats`;
    ``overall``: those, when the report just computed them), with ``timing`` the time per
    scan too; goals reached and collisions when the results hold navigation measures.
    Without any ground truth: that line and the time per scan only."""
    import math

    from dynmap_sim.analysis.navigation import goals_reached_line
    from dynmap_sim.analysis.report import NO_GROUND_TRUTH, has_ground_truth, overall_stats
    from dynmap_sim.experiments.results import ResultsDB

    with ResultsDB.open(out) as db:
        if not db.query("SELECT 1 FROM runs LIMIT 1"):
            return []
        stats = overall_stats(db) if overall is None else overall
        nav = db.nav_runs()
        goals = goals_reached_line(db)
        truth = has_ground_truth(db)
        update_header = db.update_time_header()

    def num(v: float) -> str:
        return "n/a" if v is None or math.isnan(v) else f"{v:.3f}"

    def ms(v: float) -> str:
        return "n/a" if v is None or math.isnan(v) else f"{v:.2f}"

    if truth:
        table = [("localizer", "ATE RMSE [m]", "mean [m]", "max [m]", "lost")]
    else:
        table = [("localizer", "scans")]
    if timing:
        table[0] += (update_header,)
    for s in stats:
        lost = s["lost_fraction"]
        row: tuple[str, ...] = (
            (
                str(s["localizer"]),
                num(s["ate_rmse_m"]),
                num(s["mean_error_m"]),
                num(s["max_error_m"]),
                "n/a" if math.isnan(lost) else f"{100.0 * lost:.1f} %",
            )
            if truth
            else (str(s["localizer"]), str(s["n_scans"]))
        )
        table.append(row + ((ms(s["update_ms_per_scan"]),) if timing else ()))
    widths = [max(len(row[j]) for row in table) for j in range(len(table[0]))]
    lines = [] if truth else [f"{NO_GROUND_TRUTH}: the localizers are not scored"]
    lines += [
        "  ".join(
            c.ljust(w) if j == 0 else c.rjust(w)
            for j, (c, w) in enumerate(zip(row, widths, strict=True))
        )
        for row in table
    ]
    if nav:
        collisions = sum(int(n.collisions) for _, _, n in nav)
        lines.append(f"navigation: {goals}; {collisions} collisions")
    return lines


def _cmd_report(args: argparse.Namespace) -> int:
    _write_report(Path(args.dir))
    return 0


def _export_parquet(args: argparse.Namespace) -> None:
    from dynmap_sim.errors import InputError

    try:
        from dynmap_sim.analysis.export_parquet import export_parquet, parquet_paths
    except ImportError as exc:  # the extra is not installed: say how to get it
        raise InputError(str(exc)) from None
    existed = {p for p in parquet_paths(args.parquet).values() if p.exists()}
    for f in export_parquet(Path(args.dir), Path(args.parquet), force=args.force):
        print(f"{_wrote(f.path, f.path in existed)}: {f.rows} rows, {f.bytes:,} bytes")


def _cmd_export(args: argparse.Namespace) -> int:
    from dynmap_sim.errors import InputError

    if args.tum is None and args.mcap is None and args.parquet is None:
        raise InputError("export: give --tum DIR, --mcap OUT, --parquet OUT or several")
    ros_only = [f"--{k}" for k in ("localizer", "day", "run") if getattr(args, k) is not None]
    if args.mcap is None and ros_only:
        raise InputError(f"{', '.join(ros_only)}: only with --mcap")
    if args.tum is not None:
        from dynmap_sim.analysis.export import export_tum

        out = Path(args.tum)
        existed = {p.name for p in out.iterdir()} if out.is_dir() else set()
        for path in export_tum(Path(args.dir), out, force=args.force):
            print(_wrote(path, path.name in existed))
    if args.mcap is not None:
        from dynmap_sim.analysis.export_mcap import export_mcap

        existed_bag = Path(args.mcap).exists()
        bag = export_mcap(
            Path(args.dir),
            Path(args.mcap),
            localizer=args.localizer,
            days=args.day,
            run=args.run,
            force=args.force,
        )
        counts = ", ".join(f"{t} {n}" for t, n in bag.counts.items())
        print(f"{_wrote(bag.path, existed_bag)} (ROS 2 bag, {bag.mcap_file.name}): {counts}")
        for note in bag.notes:
            print(f"note: {note}", file=sys.stderr)
    if args.parquet is not None:
        _export_parquet(args)
    return 0


def _cmd_video(args: argparse.Namespace) -> int:
    from dynmap_sim.analysis.video import write_video

    out = _output_file(args.output)
    existed = out.exists()
    opts = dict(fps=args.fps, localizers=args.localizer, size_px=args.size, force=args.force)
    res = write_video(Path(args.dir), args.day, args.run, out, progress=not args.quiet, **opts)
    w, h = res.size_px
    print(
        f"{_wrote(res.path, existed)}: {res.n_frames} frames, {w}x{h} px, "
        f"{res.duration_s:.1f} s at {res.fps} fps (encoded in {res.encode_s:.1f} s)"
    )
    for note in res.notes:
        print(f"note: {note}", file=sys.stderr)
    return 0


def _cmd_check(args: argparse.Namespace) -> int:
    from dynmap_sim.analysis.check import check_scenario
    from dynmap_sim.analysis.scenarios import load_scenario
    from dynmap_sim.errors import InputError

    _refuse_world_file(args.scenario)
    scenario = load_scenario(args.scenario)
    exp = scenario.expectations
    limits = [v for le in exp.localizers.values() for v in le.model_dump().values()]
    if not (exp.no_collisions or exp.max_skipped_waypoints is not None or exp.findings) and all(
        v is None for v in limits
    ):
        raise InputError(
            f"{args.scenario}: nothing to check: [expectations] is missing or sets no limit "
            "(a check of nothing would pass); add some (README: Regression checks) or use `run`"
        )
    _refuse_results(args.out, args.force, "check")
    result = check_scenario(scenario, out_dir=args.out, progress=not args.quiet)
    print(result.table())
    return 0 if result.passed else 1


#: ``--odometry`` choices: :data:`dynmap_sim.io.carmen.ODOMETRY_SOURCES` (not imported here, so
#: the CLI starts without numpy; a test keeps the two equal).
ODOMETRY_CHOICES = ("auto", "odom-lines", "laser-lines")
#: ``--odometry-reversals`` choices: :data:`dynmap_sim.io.carmen.REVERSAL_MODES` (the same).
REVERSAL_CHOICES = ("repair", "keep")


#: ``list`` sections: :data:`dynmap_sim.catalog.SECTIONS` (not imported here, so the CLI starts
#: without the registries; a test keeps the two equal).
LIST_SECTIONS = ("worlds", "scenarios", "localizers", "drivers", "planners", "controllers")


def _section(text: str) -> str:
    """A ``list`` section (argparse's ``choices`` refuses an empty ``nargs="*"``)."""
    if text not in LIST_SECTIONS:
        raise argparse.ArgumentTypeError(
            f"no section {text!r}; sections: {', '.join(LIST_SECTIONS)}"
        )
    return text


def _cmd_list(args: argparse.Namespace) -> int:
    from dynmap_sim.catalog import SECTIONS, catalog, catalog_text

    print(catalog_text(catalog(tuple(args.sections) or SECTIONS)), end="")
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    from dynmap_sim.analysis.compare import (
        compare_results,
        comparison_table,
        write_comparison_csv,
    )

    csv_out = _output_file(args.csv) if args.csv is not None else None
    if csv_out is not None and csv_out.exists() and not args.force:
        from dynmap_sim.errors import InputError

        raise InputError(f"--csv {csv_out}: already exists; pass --force to replace it")
    cmp = compare_results(args.dir_a, args.dir_b)
    print(comparison_table(cmp), end="")
    if csv_out is not None:
        existed = csv_out.exists()
        print(_wrote(write_comparison_csv(cmp, csv_out), existed))
    return 0


def _cmd_benchmark(args: argparse.Namespace) -> int:
    from dynmap_sim.analysis.leaderboard import leaderboard, leaderboard_md, write_leaderboard
    from dynmap_sim.env_factory import generated_world_toml, generator_kinds
    from dynmap_sim.errors import InputError
    from dynmap_sim.experiments.benchmark import load_suite, run_benchmark

    try:
        kinds = generator_kinds()
    except ImportError:  # pragma: no cover - a tree without the generator
        kinds = ()
    suite = load_suite(args.suite, kinds=kinds)
    out = Path(args.out) if args.out is not None else Path("results") / f"benchmark-{suite.name}"

    def note(text: str) -> None:
        print(f"note: {text}", file=sys.stderr)

    outcome = run_benchmark(
        suite,
        out,
        generated_world_toml,
        workers=args.workers,
        cluster=args.cluster,
        progress=not args.quiet,
        note=note,
    )
    for path in write_leaderboard(out):
        print(f"wrote {path}")
    board = leaderboard(out)
    print(leaderboard_md(board).split("\n## ")[0].rstrip())
    if not outcome.complete:
        raise InputError(
            f"{len(outcome.failed)} of {outcome.n_cells} worlds failed (see "
            f"{out / 'leaderboard.md'}); the same command retries them"
        )
    return 0


def _odometry_option(s: argparse.ArgumentParser) -> None:
    """``--odometry`` for the subcommands that read a CARMEN log."""
    s.add_argument(
        "--odometry",
        choices=ODOMETRY_CHOICES,
        default="auto",
        help="the log's odometry: the ODOM lines where they agree with the laser lines' "
        "odometry fields, else those fields, with a warning (auto, default); or always the "
        "odom-lines or the laser-lines",
    )
    s.add_argument(
        "--odometry-reversals",
        choices=REVERSAL_CHOICES,
        default="repair",
        help="ODOM poses that move forward while the line's velocity tv says the base "
        "reverses (integrated without the sign, e.g. FR079 raw): negate their translation "
        "(repair, default) or take them as logged (keep); either way a warning counts them",
    )


def _bag_option(s: argparse.ArgumentParser) -> None:
    """``--scan-topic``, ``--odom-topic`` and ``--laser-mount`` for a ROS bag log."""
    s.add_argument("--scan-topic", help="a bag's sensor_msgs/LaserScan topic (default: the one)")
    s.add_argument(
        "--odom-topic",
        help="a bag's nav_msgs/Odometry topic, or /tf for odom -> base_link (default: the one "
        "Odometry topic, else /tf)",
    )
    s.add_argument(
        "--laser-mount",
        type=_laser_mount,
        metavar="X,Y,THETA",
        help="a bag's laser pose on the robot [m, m, rad] (default: from /tf_static)",
    )


def _laser_mount(text: str) -> tuple[float, float, float]:
    try:
        v = tuple(float(t) for t in text.split(","))
    except ValueError:
        v = ()
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise argparse.ArgumentTypeError(f"expected three finite numbers X,Y,THETA, got {text!r}")
    return v


def _bag(args: argparse.Namespace):  # -> BagOptions
    from dynmap_sim.io.logs import BagOptions

    return BagOptions(args.scan_topic, args.odom_topic, args.laser_mount)


def _log_file(path: str) -> None:
    """A log must be a regular file (a FIFO or a device would hang the reader) or a ROS 2
    bag's folder."""
    from dynmap_sim.errors import FileError, regular_file_size

    p = Path(path)
    if not (p.is_dir() and (p / "metadata.yaml").is_file()):
        regular_file_size(p, FileError)


def _cmd_replay(args: argparse.Namespace) -> int:
    from dynmap_sim.errors import FileError, InputError, regular_file_size
    from dynmap_sim.experiments.reference import REFERENCE_TOLERANCE_S
    from dynmap_sim.experiments.replay import replay_log

    _log_file(args.log)
    if args.reference is not None:
        regular_file_size(args.reference, FileError)
    elif args.reference_offset is not None or args.reference_tolerance is not None:
        raise InputError("--reference-offset and --reference-tolerance need --reference REF.log")
    _refuse_results(args.out, args.force, "replay")
    out = replay_log(
        Path(args.log),
        localizers=args.localizer,
        out_dir=Path(args.out),
        map_from_log_poses=args.map_from_log_poses,
        note=lambda text: print(text, file=sys.stderr),
        reference=Path(args.reference) if args.reference is not None else None,
        reference_offset_s=args.reference_offset,
        reference_tolerance_s=args.reference_tolerance or REFERENCE_TOLERANCE_S,
        odometry=args.odometry,
        reversals=args.odometry_reversals,
        seed=args.seed,
        bag=_bag(args),
        keep_scans=args.keep_scans,
    )
    print(f"results in {out}")
    for line in _headline(out, timing=True):
        print(line)
    return 0


def _cmd_slam_eval(args: argparse.Namespace) -> int:
    from dynmap_sim.analysis.export import write_tum
    from dynmap_sim.errors import FileError, InputError, regular_file_size
    from dynmap_sim.experiments.slam_eval import slam_eval

    _log_file(args.log)
    regular_file_size(args.relations, FileError)
    outs = [(opt, _output_file(p)) for opt, p in (("--tum", args.tum), ("--json", args.json)) if p]
    for opt, p in outs:
        if p.exists() and not args.force:
            raise InputError(f"{opt} {p}: exists; pass --force to replace it or choose another")
    from dynmap_sim.agent.mapping.first_run import FirstRunConfig
    from dynmap_sim.experiments.replay import json_or_text

    params: dict = {}
    for item in args.mapper_param or []:
        key, sep, val = item.partition("=")
        if not sep or not key.strip():
            raise InputError(f"--mapper-param {item!r}: expected KEY=VALUE")
        params[key.strip()] = json_or_text(val)
    try:
        config = FirstRunConfig.from_params(**params)
    except (TypeError, ValueError) as exc:
        raise InputError(f"--mapper-param: {exc}") from None
    res = slam_eval(
        Path(args.log),
        Path(args.relations),
        config=config,
        progress=not args.quiet,
        note=lambda text: print(text, file=sys.stderr),
        odometry=args.odometry,
        reversals=args.odometry_reversals,
        bag=_bag(args),
    )
    for line in res.table():
        print(line)
    for opt, p in outs:
        existed = p.exists()
        if opt == "--tum":
            write_tum(p, res.stamps_s, res.trajectory)
        else:
            p.write_text(json.dumps(res.summary(), indent=2) + "\n", encoding="utf-8")
        print(_wrote(p, existed))
    return 0


def seed_list(text: str) -> tuple[int, ...]:
    """Parse ``0-3``, ``0,2,5`` or ``7`` into seeds (an argparse ``type``: ``sweep --seeds``
    and the benchmarks' ``--seeds``)."""
    from dynmap_sim.errors import InputError
    from dynmap_sim.experiments.sweep import parse_seeds

    try:
        return parse_seeds(text, "seeds")
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("seeds: ")) from None


def _sweep_set(text: str):  # -> Setting
    """``--set LABEL.KEY=V1,V2``."""
    from dynmap_sim.errors import InputError
    from dynmap_sim.experiments.sweep import parse_set

    try:
        return parse_set(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix(f"--set {text}: ")) from None


def _cluster_address(text: str) -> str:
    """A Dask scheduler's address: ``tcp://HOST:PORT`` (or ``tls://``, ``ws://``...)."""
    import re

    if not re.fullmatch(r"[a-z][a-z0-9+]*://[^\s/]+/?", text):
        raise argparse.ArgumentTypeError(f"expected tcp://HOST:PORT, not {text!r}")
    return text


def _cmd_sweep(args: argparse.Namespace) -> int:
    import time

    from dynmap_sim.analysis.scenarios import load_scenario
    from dynmap_sim.analysis.sweep_report import headline, write_sweep_report
    from dynmap_sim.errors import InputError
    from dynmap_sim.experiments.sweep import SweepSpec, load_sweep_file, run_sweep

    if args.file is not None:
        extra = [
            opt
            for opt, v in (
                ("SCENARIO", args.scenarios),
                ("--seeds", args.seeds),
                ("--set", args.set),
                ("--days", args.days),
                ("--only", args.only),
            )
            if v
        ]
        if extra:
            raise InputError(f"--file {args.file} says what to sweep: drop {', '.join(extra)}")
        spec = load_sweep_file(args.file, load=load_scenario)
        out = Path(args.out) if args.out else Path("results") / spec.name
    else:
        if not args.scenarios:
            raise InputError("sweep: give scenario files and --seeds, or --file SWEEP.toml")
        if args.seeds is None:
            raise InputError("sweep: --seeds is needed, e.g. --seeds 0-3")
        if args.out is None:
            raise InputError("sweep: --out DIR is needed (the sweep's folder)")
        for path in args.scenarios:
            _refuse_world_file(path)
        spec = SweepSpec(
            scenarios=tuple(load_scenario(p) for p in args.scenarios),
            seeds=args.seeds,
            days=args.days,
            settings=tuple(args.set or ()),
            only=tuple(args.only) if args.only else None,
            name=Path(args.out).name,
        )
        out = Path(args.out)
    if args.cluster is not None and args.workers is not None:
        raise InputError("--workers sets the local pool; a --cluster has its own workers")
    t0 = time.perf_counter()
    res = run_sweep(
        spec,
        out,
        workers=args.workers,
        cluster=args.cluster,
        progress=not args.quiet,
        note=lambda text: print(text, file=sys.stderr),
    )
    print(
        f"sweep in {out}: {res.n_cells} cells, {len(res.done)} run now, {len(res.skipped)} "
        f"done before, {len(res.failed)} failed ({time.perf_counter() - t0:.1f} s)"
    )
    if res.done or res.skipped:
        for path in write_sweep_report(out):
            print(f"wrote {path}")
        for line in headline(out):
            print(line)
    for key, error in res.failed.items():
        first = error.splitlines()[0] if error else "unknown error"
        print(f"failed: cell {key[:16]}: {first}", file=sys.stderr)
    if res.failed:
        print(
            f"{len(res.failed)} cell(s) failed (errors in {out / 'sweep.json'}); the same "
            "command retries them and skips the finished ones",
            file=sys.stderr,
        )
    return 1 if res.failed else 0


def _cmd_toy(args: argparse.Namespace) -> int:
    from dynmap_sim.studies.biber_duckett.toy import run_toy

    out = _output_dir(args.out)
    existed = {p.name for p in out.iterdir()}
    for path in run_toy(out, seed=args.seed):
        print(_wrote(path, path.name in existed))
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``dynmap-sim``."""
    from dynmap_sim import __version__

    p = argparse.ArgumentParser(
        prog="dynmap-sim", description="Long-term SLAM testbed in changing indoor worlds."
    )
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    seed_help = "world and noise seed, an integer >= 0"

    s = sub.add_parser(
        "list",
        help="the shipped worlds, scenarios, localizers, drivers, planners and controllers",
        description="List what ships, one line each: the worlds and scenarios under worlds/ "
        "and the names a scenario file can give each role.",
    )
    s.add_argument(
        "sections",
        nargs="*",
        type=_section,
        metavar="SECTION",
        help="only these: worlds, scenarios, localizers, drivers, planners, controllers "
        "(default: all)",
    )
    s.set_defaults(func=_cmd_list)

    s = sub.add_parser(
        "compare",
        help="compare two results folders of one scenario (before and after a change)",
        description="Paired per-run differences B - A of the error and navigation measures of "
        "two results folders of the same scenario, per localizer and day, with a 95 %% "
        "Student t interval over the runs and a verdict on which measures moved beyond noise. "
        "Folders of different scenarios or worlds are refused.",
    )
    s.add_argument("dir_a", metavar="DIR_A", help="the results folder before the change (A)")
    s.add_argument("dir_b", metavar="DIR_B", help="the results folder after the change (B)")
    s.add_argument("--csv", metavar="FILE", help="also write the per-day differences to FILE (CSV)")
    s.add_argument("--force", action="store_true", help="replace an existing --csv FILE")
    s.set_defaults(func=_cmd_compare)

    s = sub.add_parser(
        "benchmark",
        help="run a suite of worlds (generated and given) and write its leaderboard",
        description="Run a benchmark suite: every world of the suite (generator kinds x seeds, "
        "world files) with the suite's scenario, as the cells of a sweep (resumed after a kill: "
        "the same command skips finished worlds), then leaderboard.md, leaderboard.csv and "
        "leaderboard.png in the output folder: each localizer's ATE over the worlds with "
        "bootstrap intervals, paired differences against the baseline and the worst worlds "
        "with the command that re-runs each alone.",
    )
    s.add_argument("suite", help="suite TOML file (e.g. benchmarks/suites/generalization.toml)")
    s.add_argument("--out", help="benchmark folder (default: results/benchmark-<suite name>)")
    s.add_argument(
        "--workers",
        type=_positive,
        help="worlds run at once in local processes (default: the cores); ignored with --cluster",
    )
    s.add_argument(
        "--cluster",
        type=_cluster_address,
        metavar="ADDRESS",
        help="run the worlds on a Dask cluster (tcp://HOST:PORT; extra 'cluster'); its workers "
        "need dynmap_sim and the benchmark folder at the same path",
    )
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_benchmark)

    s = sub.add_parser("validate", help="validate world or scenario files")
    s.add_argument("files", nargs="+", metavar="FILE", help="world or scenario TOML files")
    s.set_defaults(func=_cmd_validate)

    s = sub.add_parser("schema", help="print the JSON schema of world or scenario files")
    s.add_argument(
        "kind", choices=["world", "scenario"], nargs="?", default="world", help="default: world"
    )
    s.add_argument(
        "-o", "--output", metavar="FILE", help="write to FILE (its folder must exist), not stdout"
    )
    s.set_defaults(func=_cmd_schema)

    s = sub.add_parser("render-world", help="draw a world at a day and run (or a sheet)")
    s.add_argument(
        "world",
        nargs="+",
        help=f"a world file, or a shipped world's name ({', '.join(_shipped_worlds())}); "
        "with --sheet, several worlds make one sheet of their first runs",
    )
    s.add_argument("--day", type=_positive, help="working day of the calendar (default: 1)")
    s.add_argument("--run", type=_positive, help="run of that day (default: 1)")
    s.add_argument("--seed", type=_seed, default=0, help=seed_help + " (default: 0)")
    s.add_argument(
        "--sheet",
        action="store_true",
        help="a grid of snapshots over the calendar (a long calendar is sampled evenly)",
    )
    s.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="FILE",
        help="image file: .png, .pdf, .svg, ... (.png is added to a name without a suffix); "
        "its folder must exist",
    )
    s.set_defaults(func=_cmd_render_world)

    s = sub.add_parser("generate", help="generate a world (apartment, office, lab, hall)")
    s.add_argument("kind", help="apartment, office, lab or hall")
    s.add_argument("--seed", required=True, help="an integer >= 0: same seed, same file")
    s.add_argument("-o", "--output", required=True, metavar="FILE", help="world file to write")
    s.add_argument("--scenario", metavar="FILE", help="also write a scenario touring the world")
    s.add_argument(
        "--param",
        action="append",
        metavar="KEY=VALUE",
        help="a generator parameter (repeatable); docs/worlds/generated.md lists them",
    )
    s.add_argument("--force", action="store_true", help="replace existing files")
    s.set_defaults(func=_cmd_generate)

    s = sub.add_parser("run", help="run a multi-day experiment from a scenario file")
    s.add_argument("scenario", help="scenario TOML file")
    s.add_argument("--days", type=day_range, help="day range, e.g. 1-7 (default: the scenario's)")
    s.add_argument("--seed", type=_seed, help=seed_help + " (default: the scenario's first)")
    s.add_argument("--out", help="results folder (default: results/<scenario name>)")
    s.add_argument("--resume", action="store_true", help="continue from the last checkpoint")
    s.add_argument("--report", action="store_true", help="write the report when done")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.add_argument(
        "--workers",
        type=_positive,
        help="localizer worker processes (1: sequential in-process; default: up to 2, one per "
        "core, or one per localizer when they are one more than that)",
    )
    s.add_argument(
        "--keep-scans",
        action="store_true",
        help="also store every scan's ranges (about 2.3 kB a scan of 683 beams) and the "
        "people's positions, so that export --mcap writes /scan and /world/people and video "
        "draws the scan and the people; a resumed experiment keeps what it began with",
    )
    s.set_defaults(func=_cmd_run)

    s = sub.add_parser("report", help="figures, summary.md and per_day.csv of a results folder")
    s.add_argument("dir", help="a results folder (written by run, check or replay)")
    s.set_defaults(func=_cmd_report)

    s = sub.add_parser(
        "export",
        help="export trajectories (TUM), tables (Parquet) or runs as a ROS 2 bag (MCAP) of a "
        "results folder",
        description="Export a results folder: TUM trajectories (--tum), Parquet tables "
        "(--parquet, extra 'analysis') for pandas and polars, and/or a ROS 2 bag "
        "(--mcap, extra 'ros') for Foxglove, RViz and `ros2 bag play`. The bag holds /tf, "
        "/tf_static, /odom, /truth/pose, /<localizer>/pose, /world/obstacles, /plan, "
        "/<localizer>/map (OccupancyGrid) of a localizer that stores its map as a grid "
        "(adaptive-memory), and /scan and /world/people when the experiment was run with "
        "--keep-scans.",
    )
    s.add_argument("dir", help="a results folder (written by run, check or replay)")
    s.add_argument("--tum", help="output folder for TUM trajectory files")
    s.add_argument(
        "--mcap",
        metavar="OUT",
        help="write a ROS 2 bag folder OUT (metadata.yaml + OUT.mcap; zstd chunks, ros2 "
        'profile) of the chosen runs; needs pip install "dynmap-sim[ros]". /scan and '
        "/world/people only when the experiment was run with --keep-scans",
    )
    s.add_argument(
        "--parquet",
        metavar="OUT",
        help="write scans.parquet (per scan and localizer), runs.parquet, days.parquet and "
        "localizers.parquet into folder OUT, for pandas and polars; needs pip install "
        '"dynmap-sim[analysis]"',
    )
    s.add_argument(
        "--localizer",
        metavar="LABEL",
        help="with --mcap: the localizer whose estimate gives map->odom on /tf "
        "(default: the first)",
    )
    s.add_argument(
        "--day", type=day_range, help="with --mcap: day or day range, e.g. 2 or 1-3 (default: all)"
    )
    s.add_argument("--run", type=_positive, help="with --mcap: run of each day (default: all)")
    s.add_argument(
        "--force",
        action="store_true",
        help="replace existing TUM files (--tum), an existing bag OUT (--mcap) or Parquet "
        "files in OUT (--parquet); else refused",
    )
    s.set_defaults(func=_cmd_export)

    s = sub.add_parser(
        "video",
        help="a video of one stored run (extra 'video')",
        description="A video of one stored run, one frame per scan: the run's obstacles, the "
        "route, the planned path and a dynamic-map's long-term map when stored, the true pose "
        "and each localizer's estimate with trails, errors, bumper and events, and the scan "
        "and the people when the experiment was run with --keep-scans.",
    )
    s.add_argument("dir", help="a results folder (written by run, check or replay)")
    s.add_argument("--day", type=_positive, required=True, help="day of the run to show")
    s.add_argument("--run", type=_positive, required=True, help="run of that day")
    s.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="FILE",
        help="video file: .mp4 (H.264 by imageio-ffmpeg's ffmpeg) or .gif (short runs: its "
        "frames are held in memory); its folder must exist",
    )
    s.add_argument(
        "--fps",
        type=_positive,
        help="frames (scans) per second of video (default: the scan rate, i.e. real time; "
        "twice that plays at double speed)",
    )
    s.add_argument(
        "--localizer",
        action="append",
        metavar="LABEL",
        help="draw only this localizer, by label; repeat for several (default: all of the "
        "folder's)",
    )
    s.add_argument(
        "--size",
        type=_positive,
        default=640,
        metavar="PX",
        help="pixels along the map's longer side, 64..4096 (default: 640)",
    )
    s.add_argument("--force", action="store_true", help="replace an existing FILE (else refused)")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_video)

    s = sub.add_parser("check", help="run a scenario and check its expectations (exit 1 on fail)")
    s.add_argument("scenario", help="scenario TOML file with [expectations]")
    s.add_argument(
        "--out",
        help="keep the results in this folder (seed-<n> subfolders for several seeds; "
        "default: a temporary folder, removed afterwards)",
    )
    s.add_argument(
        "--force", action="store_true", help="replace earlier results in --out (else refused)"
    )
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_check)

    s = sub.add_parser("replay", help="run mapping and localizers on a CARMEN log or ROS bag")
    s.add_argument("log", help="CARMEN log file, or a ROS 1 .bag / ROS 2 bag (.db3, .mcap)")
    s.add_argument(
        "--localizer",
        action="append",
        required=True,
        type=_localizer_arg,
        metavar="NAME",
        help="a localizer to run, by registry name or package.module:Class, with optional "
        "parameters (static-mcl,config=nav2-default); repeat for several",
    )
    s.add_argument(
        "--map-from-log-poses",
        action="store_true",
        help="build the map from the log's scans at the reference poses (--reference; without "
        "it, at the poses on the log's laser lines, which on a raw log are its odometry) and "
        "give it to every localizer that accepts a map (static-mcl: as a grid; dynamic-map: "
        "its keyframe scans, and with --reference its odometry covariance acquired from the "
        "reference poses and the log's odometry); the others still map on day 1",
    )
    s.add_argument(
        "--reference",
        metavar="REF.log",
        help="ground truth: a CARMEN log (plain or gzip) whose laser lines carry the true "
        "poses, e.g. a Radish '-corrected' log, matched to the scans by time stamp; scans "
        "without a match get no error. Without it the log has no ground truth and no errors "
        "are stored (the log itself may be given to score against its own laser-line poses)",
    )
    s.add_argument(
        "--reference-offset",
        type=_reference_offset,
        default=None,
        metavar="SECONDS|auto",
        help="seconds added to the reference's time stamps to put them on the log's clock; "
        "default auto: the median difference over the scans both logs hold (0 without any)",
    )
    s.add_argument(
        "--reference-tolerance",
        type=_positive_seconds,
        default=None,
        metavar="SECONDS",
        help="largest time difference between a scan and the reference pose it takes "
        "(default: REFERENCE_TOLERANCE_S, 0.1 s)",
    )
    _odometry_option(s)
    _bag_option(s)
    s.add_argument(
        "--keep-scans",
        action="store_true",
        help="store every scan's ranges (export --mcap then writes /scan)",
    )
    s.add_argument(
        "--seed",
        type=_seed,
        default=0,
        help="root of the localizers' random generators, an integer >= 0 (default: 0); "
        "another seed is another draw of every particle filter on the same log",
    )
    s.add_argument("--out", required=True, help="results folder")
    s.add_argument(
        "--force", action="store_true", help="replace earlier results in --out (else refused)"
    )
    s.set_defaults(func=_cmd_replay)

    s = sub.add_parser(
        "slam-eval", help="map a CARMEN log and score it by Kümmerle's relation error"
    )
    s.add_argument("log", help="CARMEN log file or ROS bag (raw odometry)")
    s.add_argument("--relations", required=True, help="relations file (t1 t2 x y z r p yaw)")
    s.add_argument("--tum", help="write the loop-closed trajectory here (TUM, the log's stamps)")
    s.add_argument("--json", help="write the relation error and timings here (JSON)")
    s.add_argument(
        "--mapper-param",
        action="append",
        metavar="KEY=VALUE",
        help="a first-run mapper parameter (mapper_params), e.g. seed_window=[0,0]; repeat",
    )
    _odometry_option(s)
    _bag_option(s)
    s.add_argument("--force", action="store_true", help="replace existing --tum/--json files")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_slam_eval)

    s = sub.add_parser(
        "sweep",
        help="run scenarios over seeds and parameter values; report means with 95 %% CIs",
        description="Every cell (scenario x seed x parameter values) is one experiment in "
        "DIR/cells/<hash>/, indexed in DIR/sweep.json; the same command resumes a sweep, "
        "skipping finished cells. The report (sweep_summary.csv/.md, sweep_paired.csv, "
        "sweep_error_per_day.png) is written into DIR at the end.",
    )
    s.add_argument("scenarios", nargs="*", metavar="SCENARIO", help="scenario TOML files")
    s.add_argument("--file", help="a sweep TOML file (instead of SCENARIO, --seeds, --set, ...)")
    s.add_argument("--seeds", type=seed_list, help="seeds: 0-3, 0,2,5 or 7")
    s.add_argument(
        "--set",
        action="append",
        type=_sweep_set,
        metavar="LABEL.KEY=V1,V2",
        help="values of a localizer parameter to sweep, by the localizer's label "
        "(mcl-tuned.config=tuned,nav2-default); repeat for several parameters",
    )
    s.add_argument(
        "--only",
        action="append",
        metavar="LABEL",
        help="keep only the localizer with this label; repeat for several (default: all)",
    )
    s.add_argument("--days", type=day_range, help="day range, e.g. 1-7 (default: each scenario's)")
    s.add_argument(
        "--out", help="the sweep's folder (needed with SCENARIO; --file: results/<its name>)"
    )
    s.add_argument(
        "--cluster",
        type=_cluster_address,
        metavar="tcp://HOST:PORT",
        help="run the cells on this Dask scheduler (extra 'cluster'; its workers need "
        "dynmap_sim and the same files); default: a local process pool",
    )
    s.add_argument(
        "--workers",
        type=_positive,
        help="local processes running cells at once (default: one per core; not with --cluster)",
    )
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_sweep)

    s = sub.add_parser("toy", help="Biber & Duckett §3.5 toy example (Fig. 2)")
    s.add_argument("--out", required=True, help="output folder (created) for toy.csv, toy.png")
    s.add_argument("--seed", type=_seed, default=0, help="noise seed, an integer >= 0 (default: 0)")
    s.set_defaults(func=_cmd_toy)
    return p


def _disk_full_message(args: argparse.Namespace, exc: BaseException) -> str:
    """One line for a full disk: what failed, what is kept, how to go on."""
    from dynmap_sim.experiments.results import DiskFullError

    if isinstance(exc, DiskFullError):
        what, folder = str(exc), str(exc.folder)
    else:
        name = getattr(exc, "filename", None)
        what = "the disk is full" + (f" (no space left writing {name})" if name else "")
        folder = str(getattr(args, "out", None) or getattr(args, "dir", None) or "the folder")
    if args.command == "run":
        if isinstance(exc, DiskFullError):  # it knows how many runs are kept
            return f"{what}; {exc.what_is_kept()}"
        return (
            f"{what}; the runs finished so far are kept in {folder}: free some space, then the "
            "same command with --resume continues after them"
        )
    if args.command in ("replay", "check"):
        return (
            f"{what}; free some space, then {args.command} again (with --force: the "
            f"incomplete results in {folder} are replaced)"
        )
    return f"{what}; nothing that was there before is lost: free some space and try again"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``dynmap-sim``; returns the exit status."""
    args = build_parser().parse_args(argv)
    from dynmap_sim.errors import InputError
    from dynmap_sim.experiments.localizer_pool import LocalizerError
    from dynmap_sim.experiments.results import is_disk_full

    try:
        try:
            return int(args.func(args))
        except Exception as exc:  # a full disk anywhere: one line saying what is kept
            if not is_disk_full(exc):
                raise
            raise InputError(_disk_full_message(args, exc)) from None
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except LocalizerError as exc:  # a localizer's own bug: name it, show its traceback
        import traceback

        if exc.__cause__ is not None:  # in-process; a worker's traceback is in the message
            traceback.print_exception(exc.__cause__, file=sys.stderr)
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        if args.command == "run":
            print(
                "interrupted; the runs finished so far are stored: the same command with "
                "--resume continues from the last of them",
                file=sys.stderr,
            )
        else:
            print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `dynmap-sim schema | head`: the reader left, that is fine
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:  # the file system said no (permissions, disk full, ...)
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
