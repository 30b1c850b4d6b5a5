"""The experiment commands: ``run``, ``report``, ``check``, ``sweep``, ``benchmark``,
``compare`` and ``toy``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from dynmap_sim.cli.arguments import (
    SEED_HELP,
    _cluster_address,
    _output_dir,
    _output_file,
    _positive,
    _refuse_results,
    _refuse_world_file,
    _seed,
    _sweep_set,
    _wrote,
    day_range,
    seed_list,
)

if TYPE_CHECKING:
    from dynmap_sim.cli.arguments import Subparsers


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
    from dynmap_sim.analysis.headline import results_headline

    overall = _write_report(out) if args.report else None
    print(f"results in {out}")
    for line in results_headline(out, overall=overall):
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


def _cmd_report(args: argparse.Namespace) -> int:
    _write_report(Path(args.dir))
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
    from dynmap_sim.analysis.leaderboard import (
        leaderboard,
        leaderboard_headline,
        write_leaderboard,
    )
    from dynmap_sim.env_factory import generated_world_toml, generator_kinds
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
    for line in leaderboard_headline(leaderboard(out)):
        print(line)
    if not outcome.complete:  # a run-time failure, not bad input: exit status 1
        print(
            f"error: {len(outcome.failed)} of {outcome.n_cells} worlds failed (see "
            f"{out / 'leaderboard.md'}); the same command retries them",
            file=sys.stderr,
        )
        return 1
    return 0


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


def _add_compare(sub: Subparsers) -> None:
    """The ``compare`` command."""
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


def _add_benchmark(sub: Subparsers) -> None:
    """The ``benchmark`` command."""
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


def _add_run(sub: Subparsers) -> None:
    """The ``run`` command."""
    s = sub.add_parser("run", help="run a multi-day experiment from a scenario file")
    s.add_argument("scenario", help="scenario TOML file")
    s.add_argument("--days", type=day_range, help="day range, e.g. 1-7 (default: the scenario's)")
    s.add_argument("--seed", type=_seed, help=SEED_HELP + " (default: the scenario's first)")
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


def _add_report(sub: Subparsers) -> None:
    """The ``report`` command."""
    s = sub.add_parser("report", help="figures, summary.md and per_day.csv of a results folder")
    s.add_argument("dir", help="a results folder (written by run, check or replay)")
    s.set_defaults(func=_cmd_report)


def _add_check(sub: Subparsers) -> None:
    """The ``check`` command."""
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


def _add_sweep(sub: Subparsers) -> None:
    """The ``sweep`` command."""
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


def _add_toy(sub: Subparsers) -> None:
    """The ``toy`` command."""
    s = sub.add_parser("toy", help="Biber & Duckett §3.5 toy example (Fig. 2)")
    s.add_argument("--out", required=True, help="output folder (created) for toy.csv, toy.png")
    s.add_argument("--seed", type=_seed, default=0, help="noise seed, an integer >= 0 (default: 0)")
    s.set_defaults(func=_cmd_toy)


def add_parsers(sub: Subparsers) -> None:
    """The experiment commands: compare, benchmark, run, report, check, sweep, toy."""
    for add in (
        _add_compare,
        _add_benchmark,
        _add_run,
        _add_report,
        _add_check,
        _add_sweep,
        _add_toy,
    ):
        add(sub)
