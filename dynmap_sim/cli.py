"""``dynmap-sim``: the thin command-line front end.

Every subcommand parses its arguments and calls one library function; all logic lives in the
package. Bad input files are reported (file, field, message) with exit status 1, never with a
traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

Handler = Callable[[argparse.Namespace], int]


def _days(text: str) -> tuple[int, int]:
    """Parse ``A-B`` or ``A`` (1-based, inclusive) into a day range."""
    try:
        a, _, b = text.partition("-")
        first, last = int(a), int(b or a)
    except ValueError:
        raise argparse.ArgumentTypeError(f"days must look like 3 or 1-7, not {text!r}") from None
    if first < 1 or last < first:
        raise argparse.ArgumentTypeError(f"bad day range {text!r}")
    return first, last


def _cmd_validate(args: argparse.Namespace) -> int:
    from dynmap_sim.analysis.scenarios import load_scenario
    from dynmap_sim.experiments.scenario import ScenarioFileError, is_scenario_file
    from dynmap_sim.world import WorldFileError, load_world

    status = 0
    for path in args.files:
        try:
            if is_scenario_file(path):
                load_scenario(path)
            else:
                load_world(path)
        except (WorldFileError, ScenarioFileError) as exc:
            print(exc, file=sys.stderr)
            status = 1
        else:
            print(f"{path}: OK")
    return status


def _cmd_schema(args: argparse.Namespace) -> int:
    from dynmap_sim.experiments.scenario import scenario_json_schema
    from dynmap_sim.world import world_json_schema

    schema = world_json_schema() if args.kind == "world" else scenario_json_schema()
    text = json.dumps(schema, indent=2)
    if args.output:
        Path(args.output).write_text(text + "\n")
    else:
        print(text)
    return 0


def _cmd_render_world(args: argparse.Namespace) -> int:
    from dynmap_sim.world import load_world
    from dynmap_sim.world.render import render_sheet, render_snapshot

    spec = load_world(args.world)
    if args.sheet:
        render_sheet(spec, seed=args.seed, out_path=args.output)
    else:
        render_snapshot(spec, seed=args.seed, day=args.day, run=args.run, out_path=args.output)
    print(f"wrote {args.output}")
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    from dynmap_sim.analysis.scenarios import load_scenario
    from dynmap_sim.experiments.runner import run_experiment

    scenario = load_scenario(args.scenario)
    out = run_experiment(
        scenario,
        out_dir=args.out,
        days=args.days,
        seed=args.seed,
        resume=args.resume,
        progress=not args.quiet,
        workers=args.workers,
    )
    if args.report:
        from dynmap_sim.analysis.report import write_report

        for path in write_report(out):
            print(f"wrote {path}")
    print(f"results in {out}")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from dynmap_sim.analysis.report import write_report

    for path in write_report(Path(args.dir)):
        print(f"wrote {path}")
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from dynmap_sim.analysis.export import export_tum

    for path in export_tum(Path(args.dir), Path(args.tum)):
        print(f"wrote {path}")
    return 0


def _cmd_check(args: argparse.Namespace) -> int:
    from dynmap_sim.analysis.check import check_scenario

    result = check_scenario(args.scenario, out_dir=args.out, progress=not args.quiet)
    print(result.table())
    return 0 if result.passed else 1


def _cmd_replay(args: argparse.Namespace) -> int:
    from dynmap_sim.experiments.replay import replay_log

    out = replay_log(
        Path(args.log),
        localizers=args.localizer,
        out_dir=Path(args.out),
        map_from_log_poses=args.map_from_log_poses,
    )
    print(f"results in {out}")
    return 0


def _cmd_toy(args: argparse.Namespace) -> int:
    from dynmap_sim.studies.biber_duckett.toy import run_toy

    for path in run_toy(Path(args.out), seed=args.seed):
        print(f"wrote {path}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``dynmap-sim``."""
    p = argparse.ArgumentParser(
        prog="dynmap-sim", description="Long-term SLAM testbed in changing indoor worlds."
    )
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("validate", help="validate world or scenario files")
    s.add_argument("files", nargs="+")
    s.set_defaults(func=_cmd_validate)

    s = sub.add_parser("schema", help="print the JSON schema of world or scenario files")
    s.add_argument("kind", choices=["world", "scenario"], nargs="?", default="world")
    s.add_argument("-o", "--output")
    s.set_defaults(func=_cmd_schema)

    s = sub.add_parser("render-world", help="draw a world at a day and run (or a sheet)")
    s.add_argument("world")
    s.add_argument("--day", type=int, default=1)
    s.add_argument("--run", type=int, default=1)
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--sheet", action="store_true", help="a grid of snapshots over the calendar")
    s.add_argument("-o", "--output", required=True)
    s.set_defaults(func=_cmd_render_world)

    s = sub.add_parser("run", help="run a multi-day experiment from a scenario file")
    s.add_argument("scenario")
    s.add_argument("--days", type=_days, help="day range, e.g. 1-7 (default: the scenario's)")
    s.add_argument("--seed", type=int)
    s.add_argument("--out", help="results folder (default: results/<scenario name>)")
    s.add_argument("--resume", action="store_true", help="continue from the last checkpoint")
    s.add_argument("--report", action="store_true", help="write the report when done")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.add_argument(
        "--workers",
        type=int,
        help="localizer worker processes (1: sequential in-process; default: up to 2)",
    )
    s.set_defaults(func=_cmd_run)

    s = sub.add_parser("report", help="figures, summary.md and per_day.csv of a results folder")
    s.add_argument("dir")
    s.set_defaults(func=_cmd_report)

    s = sub.add_parser("export", help="export trajectories of a results folder")
    s.add_argument("dir")
    s.add_argument("--tum", required=True, help="output folder for TUM trajectory files")
    s.set_defaults(func=_cmd_export)

    s = sub.add_parser("check", help="run a scenario and check its expectations (exit 1 on fail)")
    s.add_argument("scenario")
    s.add_argument("--out")
    s.add_argument("-q", "--quiet", action="store_true")
    s.set_defaults(func=_cmd_check)

    s = sub.add_parser("replay", help="run mapping and localizers on a CARMEN log")
    s.add_argument("log")
    s.add_argument("--localizer", action="append", required=True)
    s.add_argument("--map-from-log-poses", action="store_true")
    s.add_argument("--out", required=True)
    s.set_defaults(func=_cmd_replay)

    s = sub.add_parser("toy", help="Biber & Duckett §3.5 toy example (Fig. 2)")
    s.add_argument("--out", required=True)
    s.add_argument("--seed", type=int, default=0)
    s.set_defaults(func=_cmd_toy)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``dynmap-sim``; returns the exit status."""
    args = build_parser().parse_args(argv)
    from dynmap_sim.errors import InputError
    from dynmap_sim.experiments.bench import LocalizerError

    try:
        return int(args.func(args))
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
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `dynmap-sim schema | head`: the reader left, that is fine
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
