"""The generator's named parameters: each family of change and its rate, sizes, calendar.

Every parameter has a type, a default and an inclusive range; ``--param key=value`` on the
command line and the ``params`` mapping of :func:`~dynmap_sim.world.generator.generate_world`
are checked against this table, and any problem is one :class:`GeneratorError` line.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

KINDS: tuple[str, ...] = ("apartment", "office", "lab", "hall")


class GeneratorError(ValueError):
    """Bad generator input (kind, seed, parameter): the message is one line saying what."""


@dataclass(frozen=True)
class Param:
    """One named parameter: ``kind`` is ``int`` or ``float``, ``lo``..``hi`` its range."""

    name: str
    kind: type
    default: float
    lo: float
    hi: float
    doc: str


PARAMS: tuple[Param, ...] = (
    Param("scale", float, 1.0, 0.6, 2.0, "floor-plan size factor on the kind's drawn size"),
    Param("wall_thickness_m", float, 0.1, 0.08, 0.25, "thickness of inner walls [m]"),
    Param("door_min_m", float, 0.9, 0.8, 1.2, "narrowest doorway drawn [m]"),
    Param("door_max_m", float, 1.1, 0.8, 1.2, "widest doorway drawn [m]"),
    Param("clutter_per_10m2", float, 0.3, 0.0, 3.0, "loose items (boxes, bins) per 10 m2 of room"),
    Param("days", int, 10, 1, 60, "working days of the calendar (Mon-Fri)"),
    Param("runs_per_day", int, 2, 1, 4, "runs a day, at times drawn from the working hours"),
    Param("move_per_week", float, 2.0, 0.0, 10.0, "furniture moves per week"),
    Param("add_per_week", float, 1.0, 0.0, 5.0, "pieces of furniture added per week"),
    Param("remove_per_week", float, 1.0, 0.0, 5.0, "pieces of furniture removed per week"),
    Param("shuffle_groups", int, 2, 0, 6, "groups of chairs re-placed every run or every day"),
    Param("door_per_week", float, 2.0, 0.0, 10.0, "door closings (opened again later) per week"),
    Param("blocks_with_way_round", int, 1, 0, 3, "route blocks that leave a way round"),
    Param("blocks_without_way_round", int, 1, 0, 2, "route blocks that leave no way round"),
    Param("exhibitions", int, 1, 0, 2, "temporary exhibitions (a group present for some days)"),
    Param("installs", int, 1, 0, 4, "permanent installations (radiators, cabinets)"),
    Param("growth", int, 1, 0, 3, "plants that grow over the calendar"),
    Param("periodic_doors", int, 0, 0, 6, "doors off the route open in office hours only"),
    Param("periodic_groups", int, 0, 0, 3, "groups of chairs taken out at lunch every day"),
    Param("periodic_p", float, 0.9, 0.0, 1.0, "chance a periodic door keeps its hours that day"),
    Param("runs_through_day", int, 0, 0, 1, "1: runs at set times from morning to evening"),
    Param("people", int, 6, 0, 40, "people walking in the world at the busiest hour"),
    Param("robot_radius_m", float, 0.2, 0.1, 0.4, "robot radius the route is checked for [m]"),
)
PARAM_BY_NAME: dict[str, Param] = {p.name: p for p in PARAMS}


def _convert(p: Param, value: Any) -> int | float:
    """``value`` as the parameter's type (a string from the command line too)."""
    if isinstance(value, bool):
        raise GeneratorError(f"parameter {p.name} must be a number, not {value!r}")
    try:
        if p.kind is int:
            if isinstance(value, float) and not value.is_integer():
                raise ValueError
            v: int | float = int(value) if not isinstance(value, str) else int(value.strip())
        else:
            v = float(value)
    except (TypeError, ValueError):
        what = "an integer" if p.kind is int else "a number"
        raise GeneratorError(f"parameter {p.name} must be {what}, not {value!r}") from None
    if not (p.lo <= v <= p.hi):  # also refuses NaN
        raise GeneratorError(f"parameter {p.name} = {value} is outside its range {p.lo}..{p.hi}")
    return v


def resolve_params(params: Mapping[str, Any] | None) -> dict[str, int | float]:
    """Defaults overridden by ``params``, each checked (name, type, range); GeneratorError."""
    out: dict[str, int | float] = {p.name: p.kind(p.default) for p in PARAMS}
    for name, value in (params or {}).items():
        p = PARAM_BY_NAME.get(name)
        if p is None:
            raise GeneratorError(
                f"unknown parameter {name!r}; known: {', '.join(sorted(PARAM_BY_NAME))}"
            )
        out[name] = _convert(p, value)
    if out["door_min_m"] > out["door_max_m"]:
        raise GeneratorError(
            f"door_min_m = {out['door_min_m']} is larger than door_max_m = {out['door_max_m']}"
        )
    return out


def parse_param(text: str) -> tuple[str, str]:
    """``key=value`` -> ``(key, value)``; GeneratorError for anything else."""
    key, sep, value = text.partition("=")
    if not sep or not key.strip() or not value.strip():
        raise GeneratorError(f"--param takes key=value, not {text!r}")
    return key.strip(), value.strip()


def check_kind(kind: str) -> str:
    """``kind`` if known, else GeneratorError listing the kinds."""
    if kind not in KINDS:
        raise GeneratorError(f"unknown kind {kind!r}; kinds: {', '.join(KINDS)}")
    return kind


def check_seed(seed: Any) -> int:
    """``seed`` as an int in 0 .. 2**63 - 1, else GeneratorError."""
    if isinstance(seed, bool) or not isinstance(seed, int):
        try:
            if isinstance(seed, str) and seed.strip().lstrip("-").isdigit():
                seed = int(seed)
            else:
                raise ValueError
        except ValueError:
            raise GeneratorError(f"the seed must be an integer, not {seed!r}") from None
    if not 0 <= seed <= 2**63 - 1:
        raise GeneratorError(f"the seed must be in 0..2**63-1, not {seed}")
    return seed
