"""What ships: the worlds, scenarios and the implementations of each role, one line each
(``dynmap-sim list``).

Worlds and scenarios are the TOML files under the source tree's ``worlds/`` folder, described
by their ``description`` field; the roles are their registries (the names a scenario file
uses), described by the first line of each class's docstring.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from dynmap_sim.registration import WORLDS_DIR


@dataclass(frozen=True)
class Entry:
    """One shipped thing: the name a file or scenario uses and one line on what it is."""

    name: str
    summary: str


#: The sections of :func:`catalog`, in the order they are listed.
SECTIONS = ("worlds", "scenarios", "localizers", "drivers", "planners", "controllers")


def _description(path: Path) -> str:
    try:
        with path.open("rb") as fh:
            return str(tomllib.load(fh).get("description", "")).strip()
    except (OSError, tomllib.TOMLDecodeError) as exc:
        return f"(unreadable: {exc})"


def _first_sentence(cls: type) -> str:
    """The first sentence of ``cls``'s docstring as plain text (reST roles and literals
    unwrapped, a trailing "(module doc)" pointer dropped)."""
    doc = " ".join((cls.__doc__ or "").strip().split("\n\n")[0].split())
    doc = re.sub(r":\w+:`~?([^`]+)`", lambda m: m.group(1).rsplit(".", 1)[-1], doc)
    doc = doc.replace("``", "")
    sentence = re.split(r"(?<=[.;])\s", doc, maxsplit=1)[0].rstrip(".;")
    return sentence.replace(" (module doc)", "")


def _files(folder: Path) -> list[Entry]:
    return [
        Entry(p.stem, _description(p)) for p in sorted(folder.glob("*.toml"), key=lambda p: p.stem)
    ]


def _registry(section: str) -> list[Entry]:
    from dynmap_sim.agent.control.controller import CONTROLLERS
    from dynmap_sim.agent.localization.localizer import LOCALIZERS
    from dynmap_sim.agent.planning.planner import PLANNERS
    from dynmap_sim.experiments.drivers.driver import DRIVERS

    registry = {
        "localizers": LOCALIZERS,
        "drivers": DRIVERS,
        "planners": PLANNERS,
        "controllers": CONTROLLERS,
    }[section]
    return [Entry(name, _first_sentence(registry.get(name))) for name in registry.names()]


def catalog(sections: tuple[str, ...] = SECTIONS) -> dict[str, list[Entry]]:
    """The shipped entries of each of ``sections`` (:data:`SECTIONS`), by section."""
    unknown = [s for s in sections if s not in SECTIONS]
    if unknown:
        raise ValueError(f"unknown section {unknown[0]!r}; sections: {', '.join(SECTIONS)}")
    out: dict[str, list[Entry]] = {}
    for section in sections:
        if section == "worlds":
            out[section] = _files(WORLDS_DIR)
        elif section == "scenarios":
            out[section] = _files(WORLDS_DIR / "scenarios")
        else:
            out[section] = _registry(section)
    return out


def catalog_text(entries: dict[str, list[Entry]]) -> str:
    """The catalog as aligned plain text, a heading per section."""
    width = max((len(e.name) for es in entries.values() for e in es), default=0)
    lines: list[str] = []
    for section, es in entries.items():
        lines.append(f"{section}:")
        lines += [f"  {e.name:<{width}}  {e.summary}".rstrip() for e in es]
        lines.append("")
    return "\n".join(lines)
