"""The world commands: ``list``, ``validate``, ``schema``, ``render-world``, ``generate``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from dynmap_sim.cli.arguments import SEED_HELP, _output_file, _positive, _seed, _wrote

if TYPE_CHECKING:
    from dynmap_sim.cli.arguments import Subparsers


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


def _add_list(sub: Subparsers) -> None:
    """The ``list`` command."""
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


def _add_validate(sub: Subparsers) -> None:
    """The ``validate`` command."""
    s = sub.add_parser("validate", help="validate world or scenario files")
    s.add_argument("files", nargs="+", metavar="FILE", help="world or scenario TOML files")
    s.set_defaults(func=_cmd_validate)


def _add_schema(sub: Subparsers) -> None:
    """The ``schema`` command."""
    s = sub.add_parser("schema", help="print the JSON schema of world or scenario files")
    s.add_argument(
        "kind", choices=["world", "scenario"], nargs="?", default="world", help="default: world"
    )
    s.add_argument(
        "-o", "--output", metavar="FILE", help="write to FILE (its folder must exist), not stdout"
    )
    s.set_defaults(func=_cmd_schema)


def _add_render_world(sub: Subparsers) -> None:
    """The ``render-world`` command."""
    s = sub.add_parser("render-world", help="draw a world at a day and run (or a sheet)")
    s.add_argument(
        "world",
        nargs="+",
        help=f"a world file, or a shipped world's name ({', '.join(_shipped_worlds())}); "
        "with --sheet, several worlds make one sheet of their first runs",
    )
    s.add_argument("--day", type=_positive, help="working day of the calendar (default: 1)")
    s.add_argument("--run", type=_positive, help="run of that day (default: 1)")
    s.add_argument("--seed", type=_seed, default=0, help=SEED_HELP + " (default: 0)")
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


def _add_generate(sub: Subparsers) -> None:
    """The ``generate`` command."""
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


def add_parsers(sub: Subparsers) -> None:
    """The world commands: list, validate, schema, render-world, generate."""
    for add in (_add_list, _add_validate, _add_schema, _add_render_world, _add_generate):
        add(sub)
