"""Writing a generated world (and a scenario that drives it) as TOML, byte for byte the same
for the same input: fixed key order, floats as Python's shortest round-trip repr."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from dynmap_sim import toml_writer

_TOP = ("name", "description", "bounds")
_TABLES = ("calendar", "robot")
_ARRAYS = ("walls", "objects", "schedule", "people")
#: Lists of points longer than this go one point to a line.
_WRAP = 4


def _value(v: Any) -> str:
    """A TOML value (:func:`dynmap_sim.toml_writer.value`), lists of more than :data:`_WRAP`
    points one point to a line."""
    if (
        isinstance(v, list | tuple)
        and len(v) > _WRAP
        and all(isinstance(x, list | tuple) for x in v)
    ):
        inner = "".join(f"    {toml_writer.value(x)},\n" for x in v)
        return f"[\n{inner}]"
    return toml_writer.value(v)


def _lines(d: dict[str, Any]) -> list[str]:
    return [f"{k} = {_value(v)}" for k, v in d.items()]


def world_toml(data: dict[str, Any], header: list[str]) -> str:
    """The TOML text of a world-file dict, ``header`` lines as comments on top."""
    out = [f"# {h}".rstrip() for h in header]
    out.append("")
    out += _lines({k: data[k] for k in _TOP if k in data})
    for key in _TABLES:
        out += ["", f"[{key}]", *_lines(data[key])]
    for key in _ARRAYS:
        for item in data.get(key, ()):
            out += ["", f"[[{key}]]", *_lines(item)]
    return "\n".join(out) + "\n"


def scenario_toml(name: str, world_rel: str, days: int, seed: int, header: list[str]) -> str:
    """A scenario running the world at ``world_rel`` (relative to the scenario file) for all
    its days with the ``tour`` driver, as worlds/scenarios/office-tour.toml does."""
    lines = [f"# {h}".rstrip() for h in header] + [
        "",
        f"name = {_value(name)}",
        f"description = {_value('Generated world ' + name + ': tour over the whole calendar')}",
        f"world = {_value(world_rel)}",
        f"days = [1, {days}]",
        f"seeds = [{seed}]",
        "",
        "[sensor]",
        'preset = "urg-04lx"',
        "",
        "# Uncalibrated wheels (UMBmark E_d, E_b) as in apartment-28d.toml.",
        "[robot.overrides]",
        "wheels = { e_d = 1.002, e_b = 1.01 }",
        "",
        "[driver]",
        'kind = "tour"',
        "speed_mps = 0.35",
        "",
        "[prior]",
        'map = "walls"',
        'initial_pose = "known"',
    ]
    for name_, label, params in (
        ("odometry", "odometry", None),
        ("static-mcl", "static-mcl tuned", '{ config = "tuned" }'),
        ("dynamic-map", "dynamic-map", None),
    ):
        lines += ["", "[[localizers]]", f'name = "{name_}"', f'label = "{label}"']
        if params:
            lines.append(f"params = {params}")
    return "\n".join(lines) + "\n"


def relative_world(world_path: Path, scenario_path: Path) -> str:
    """The world file's path as a scenario in ``scenario_path``'s folder names it."""
    rel = os.path.relpath(world_path.resolve(), scenario_path.resolve().parent)
    return Path(rel).as_posix()


def write_atomically(files: dict[Path, str]) -> None:
    """Write every file or none: each to a temporary file beside it, then all renamed into
    place (a failure removes the temporary files and leaves the targets as they were)."""
    tmps: list[tuple[Path, Path]] = []
    try:
        for path, text in files.items():
            tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
            tmps.append((tmp, path))
            with open(tmp, "x", encoding="utf-8", newline="\n") as f:
                f.write(text)
        for tmp, path in tmps:
            os.replace(tmp, path)
    finally:
        for tmp, _ in tmps:
            tmp.unlink(missing_ok=True)
