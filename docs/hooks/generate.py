"""MkDocs hook: the pages' generated parts, rendered from the code at build time so that they
cannot drift from it.

A page asks for a part with an HTML comment on a line of its own (invisible where the page is
read as plain Markdown):

- ``<!-- generate: world-schema -->``: the world file's fields, from ``world_json_schema()``;
- ``<!-- generate: scenario-schema -->``: the scenario file's fields, from
  ``scenario_json_schema()``;
- ``<!-- generate: params-schema -->``: the localizers' and the navigation stack's parameters,
  from their classes' JSON schemas (:mod:`dynmap_sim.agent.params`);
- ``<!-- generate: cli -->``: every ``dynmap-sim`` command and option, from ``build_parser()``;
- ``<!-- generate: roles -->``: the built-in localizers, drivers, planners and controllers,
  from their registries, each with the first paragraph of its class's docstring.

The docstrings' Sphinx roles (``:class:`X```), which mkdocstrings leaves as text, are dropped
from the API pages' HTML: the name stays as code.

A ``nav`` entry whose value is a folder (``tuning/``) becomes one entry per page in that folder,
titled by each page's first heading, so that pages added there need no edit of ``mkdocs.yml``.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import json
import re
import sys
from pathlib import Path
from typing import Any

MARKER = re.compile(r"^<!-- generate: ([a-z-]+) -->$", flags=re.MULTILINE)
#: A Sphinx role left in a docstring's rendered HTML (``:class:`X``` -> ``:class:<code>X``).
SPHINX_ROLE = re.compile(r":(?:class|func|meth|attr|mod|data|exc|obj):(?=<code)")

# ---------------------------------------------------------------------------------------------
# JSON schema -> tables
# ---------------------------------------------------------------------------------------------


def _ref_name(ref: str) -> str:
    return ref.rsplit("/", 1)[-1]


def _anchor(name: str) -> str:
    return name.lower()


def type_text(prop: dict[str, Any]) -> str:
    """A JSON-schema property's type in a few words: ``number``, ``[number, number]``,
    ``list of WallSpec``, ``"box" | "circle"``, ``string or null``."""
    if "$ref" in prop:
        name = _ref_name(prop["$ref"])
        return f"[{name}](#{_anchor(name)})"
    if "enum" in prop:
        return " | ".join(json.dumps(v) for v in prop["enum"])
    if "const" in prop:
        return json.dumps(prop["const"])
    for key in ("anyOf", "oneOf"):
        if key in prop:
            parts = list(dict.fromkeys(type_text(p) for p in prop[key]))
            if "number" in parts and "integer" in parts:  # an integer is a number
                parts.remove("integer")
            return " or ".join(parts)
    kind = prop.get("type")
    if kind == "array":
        if "prefixItems" in prop:
            return "[" + ", ".join(type_text(p) for p in prop["prefixItems"]) + "]"
        items = prop.get("items")
        return f"list of {_grouped(type_text(items))}" if items else "list"
    if kind == "object":
        extra = prop.get("additionalProperties")
        if isinstance(extra, dict) and extra:
            return f"table of {_grouped(type_text(extra))}"
        return "table"
    if kind == "string" and prop.get("format") == "date":
        return "date"
    if isinstance(kind, list):
        return " or ".join(kind)
    return kind or "any"


def _grouped(text: str) -> str:
    """``text`` in parentheses when it is a choice (``list of (number or string)``)."""
    return f"({text})" if " or " in text or " | " in text else text


def _limits(prop: dict[str, Any]) -> str:
    words = {
        "minimum": ">=",
        "exclusiveMinimum": ">",
        "maximum": "<=",
        "exclusiveMaximum": "<",
        "minLength": "length >=",
        "minItems": "items >=",
    }
    found = [f"{w} {prop[k]}" for k, w in words.items() if k in prop and k != "minItems"]
    for alt in prop.get("anyOf", []):
        found += [f"{w} {alt[k]}" for k, w in words.items() if k in alt and k != "minItems"]
    return ", ".join(dict.fromkeys(found))


def _cell(text: str) -> str:
    """Text for a table cell: one line, pipes escaped, ``<x>`` shown rather than taken as
    HTML."""
    text = " ".join(str(text).split()).replace("|", "\\|")
    return text.replace("<", "&lt;").replace(">", "&gt;")


def _sentence(text: str) -> str:
    text = text.replace("%%", "%")
    return text[:1].upper() + text[1:]


def _default(prop: dict[str, Any], required: bool) -> str:
    if required:
        return "**required**"
    if "default" not in prop:
        return ""
    return f"`{json.dumps(prop['default'], ensure_ascii=False)}`"


def model_table(schema: dict[str, Any]) -> str:
    """One model of a JSON schema as a Markdown table: field, type, default, description."""
    required = set(schema.get("required", ()))
    rows = ["| field | type | default | what |", "|---|---|---|---|"]
    for name, prop in schema.get("properties", {}).items():
        what = prop.get("description", "")
        limits = _limits(prop)
        if limits:
            what = f"{what} ({limits})" if what else limits
        if "discriminator" in prop.get("items", {}):
            tags = prop["items"]["discriminator"]["mapping"]
            what = (
                (what + " " if what else "")
                + "one of: "
                + ", ".join(f"[{tag}](#{_anchor(_ref_name(ref))})" for tag, ref in tags.items())
            )
            kind = "list of events"
        else:
            kind = type_text(prop)
        rows.append(
            f"| `{name}` | {_cell(kind)} | {_default(prop, name in required)} | {_cell(what)} |"
        )
    return "\n".join(rows)


def _docstring(text: str) -> str:
    """A model's docstring as Markdown: RST's ``x`` code spans become `x`."""
    return re.sub(r"``([^`]+)``", r"`\1`", text.strip())


def schema_reference(schema: dict[str, Any], title: str, level: int = 3) -> str:
    """The whole schema: the top-level model, then every model it uses, in the order they
    are first referenced."""
    defs = schema.get("$defs", {})
    order: list[str] = []

    def visit(node: Any) -> None:
        if isinstance(node, dict):
            ref = node.get("$ref")
            if ref and _ref_name(ref) not in order:
                order.append(_ref_name(ref))
                visit(defs.get(_ref_name(ref), {}))
            for value in node.values():
                visit(value)
        elif isinstance(node, list):
            for value in node:
                visit(value)

    visit(schema.get("properties", {}))
    hashes = "#" * level
    out = [f"{hashes} {title}", "", _docstring(schema.get("description", "")), ""]
    out += [model_table(schema), ""]
    for name in order:
        model = defs[name]
        out += [f"{hashes} {name}", ""]
        if model.get("description"):
            out += [_docstring(model["description"]), ""]
        out += [model_table(model), ""]
    return "\n".join(out)


# ---------------------------------------------------------------------------------------------
# argparse -> reference
# ---------------------------------------------------------------------------------------------


def _usage(parser: argparse.ArgumentParser) -> str:
    formatter = argparse.HelpFormatter(parser.prog, width=10_000)
    formatter.add_usage(parser.usage, parser._actions, parser._mutually_exclusive_groups, "")
    return formatter.format_help().strip()


def _option_row(action: argparse.Action) -> str:
    if action.option_strings:
        flags = ", ".join(f"`{s}`" for s in action.option_strings)
        if action.nargs != 0:
            metavar = action.metavar or action.dest.upper()
            if action.choices:
                metavar = "{" + ",".join(map(str, action.choices)) + "}"
            flags += f" `{metavar}`"
    else:
        flags = f"`{action.metavar or action.dest}`"
    help_text = (action.help or "").replace("%%", "%")
    if "%(default)" in help_text:
        help_text = help_text % {"default": action.default}
    if action.choices and not action.option_strings:
        help_text += " (one of: " + ", ".join(f"`{c}`" for c in action.choices) + ")"
    if action.required and action.option_strings:
        help_text += " **(required)**"
    return f"| {_cell(flags)} | {_cell(help_text)} |"


def _subcommands(parser: argparse.ArgumentParser) -> list[tuple[str, argparse.ArgumentParser]]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return list(action.choices.items())
    return []


def _summaries(parser: argparse.ArgumentParser) -> dict[str, str]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return {a.dest: a.help or "" for a in action._choices_actions}
    return {}


def cli_reference(parser: argparse.ArgumentParser, level: int = 2) -> str:
    """Every subcommand of ``parser``: a table of them, then each one's usage, description
    and options."""
    commands = _subcommands(parser)
    summaries = _summaries(parser)
    hashes = "#" * level
    out = ["| command | what it does |", "|---|---|"]
    out += [
        f"| [`{name}`](#{name}) | {_cell(_sentence(summaries.get(name, '')))} |"
        for name, _ in commands
    ]
    out.append("")
    for name, sub in commands:
        out += [f"{hashes} `{name}` {{#{name}}}", ""]
        out += [_cell(_sentence(summaries.get(name, ""))) + ".", ""]
        out += ["```text", _usage(sub), "```", ""]
        if sub.description:
            out += [_cell(sub.description.replace("%%", "%")), ""]
        rows = [
            _option_row(a)
            for a in sub._actions
            if not isinstance(a, argparse._HelpAction) and a.help != argparse.SUPPRESS
        ]
        if rows:
            out += ["| argument | what |", "|---|---|", *rows, ""]
    return "\n".join(out)


# ---------------------------------------------------------------------------------------------
# the parts, by name
# ---------------------------------------------------------------------------------------------


def _world_schema() -> str:
    from dynmap_sim.world import world_json_schema

    return schema_reference(world_json_schema(), "WorldSpec")


def _scenario_schema() -> str:
    from dynmap_sim.experiments.scenario import scenario_json_schema

    return schema_reference(scenario_json_schema(), "Scenario")


def _field_comments(cls: type) -> dict[str, str]:
    """The ``#:`` comment lines above each field of a class (Sphinx's attribute docs)."""
    out: dict[str, str] = {}
    lines: list[str] = []
    for line in inspect.getsource(cls).splitlines():
        text = line.strip()
        if text.startswith("#:"):
            lines.append(text[2:].strip())
        elif lines and (m := re.match(r"(\w+)\s*:", text)):
            what = re.sub(r":[a-z]+:`~?\.?([^`]+)`", r"``\1``", " ".join(lines))
            out[m.group(1)] = _docstring(what)
            lines = []
    return out


def params_reference(cls: type, title: str) -> str:
    """A parameter class (:func:`dynmap_sim.agent.params.params_dataclass`) and the parameter
    classes of its fields, from its JSON schema, each field described by its ``#:`` comment."""
    from pydantic import TypeAdapter

    schema = TypeAdapter(cls).json_schema()
    models = {"": (cls, schema)}
    for f in dataclasses.fields(cls):
        if f.type in schema.get("$defs", {}):
            models[f.type] = (
                cls.__pydantic_fields__[f.name].annotation,
                schema["$defs"][f.type],
            )
    for kind, model in models.values():
        for name, what in _field_comments(kind).items():
            model.get("properties", {}).get(name, {}).setdefault("description", what)
    return schema_reference(schema, title)


def _params_schema() -> str:
    from dynmap_sim.agent.localization.adaptive_memory.localizer import AdaptiveMemoryConfig
    from dynmap_sim.agent.localization.dynamic_map_localizer import DynamicMapConfig
    from dynmap_sim.agent.localization.particle_filter import MCLConfig
    from dynmap_sim.agent.mapping.first_run import FirstRunConfig
    from dynmap_sim.agent.navigation.stack_params import StackParams

    parts = {
        "static-mcl: overrides (MCLConfig)": MCLConfig,
        "static-mcl, dynamic-map, static-map, static-map+stm: mapper_params (FirstRunConfig)": (
            FirstRunConfig
        ),
        "dynamic-map, static-map, static-map+stm: params (DynamicMapConfig)": DynamicMapConfig,
        "adaptive-memory: params (AdaptiveMemoryConfig)": AdaptiveMemoryConfig,
        "autonomous driver: params (StackParams)": StackParams,
    }
    return "\n".join(params_reference(cls, title) for title, cls in parts.items())


def _cli() -> str:
    from dynmap_sim.cli import build_parser

    return cli_reference(build_parser())


def _summary(cls: type) -> str:
    """The first paragraph of a class's docstring, as one line of Markdown."""
    text = (cls.__doc__ or "").strip().split("\n\n", 1)[0]
    text = re.sub(r":[a-z]+:`~?([^`]+)`", r"``\1``", text)
    text = re.sub(r"``[\w.]*?\.?(\w+)``", lambda m: f"``{m.group(1)}``", text)
    return _cell(_docstring(text).replace(" (module doc)", ""))


def roles_table(registries: dict[str, Any]) -> str:
    """One row per registered name of each role: name, role, what, module."""
    rows = ["| name | role | what | module |", "|---|---|---|---|"]
    for role, registry in registries.items():
        for name in registry.names():
            cls = registry.get(name)
            rows.append(f"| `{name}` | {role} | {_summary(cls)} | `{cls.__module__}` |")
    return "\n".join(rows)


def _roles() -> str:
    from dynmap_sim.agent.control.controller import CONTROLLERS
    from dynmap_sim.agent.localization.localizer import LOCALIZERS
    from dynmap_sim.agent.planning.planner import PLANNERS
    from dynmap_sim.experiments.drivers.driver import DRIVERS

    return roles_table(
        {
            "localizer": LOCALIZERS,
            "driver": DRIVERS,
            "planner": PLANNERS,
            "controller": CONTROLLERS,
        }
    )


PARTS = {
    "world-schema": _world_schema,
    "scenario-schema": _scenario_schema,
    "params-schema": _params_schema,
    "cli": _cli,
    "roles": _roles,
}


def expand(markdown: str) -> str:
    """``markdown`` with every ``<!-- generate: NAME -->`` line replaced by its part."""

    def part(m: re.Match[str]) -> str:
        name = m.group(1)
        if name not in PARTS:
            raise KeyError(f"unknown generated part {name!r}; known: {sorted(PARTS)}")
        return PARTS[name]()

    return MARKER.sub(part, markdown)


def _title(path: Path) -> str:
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("# "):
            return line[2:].strip()
    return path.stem.replace("-", " ").capitalize()


def expand_nav(nav: list[Any], docs_dir: Path) -> list[Any]:
    """``nav`` with each folder entry (``Title: folder/``) replaced by that folder's pages."""
    out: list[Any] = []
    for item in nav:
        if isinstance(item, dict):
            ((title, value),) = item.items()
            if isinstance(value, list):
                out.append({title: expand_nav(value, docs_dir)})
                continue
            if isinstance(value, str) and value.endswith("/"):
                pages = sorted((docs_dir / value).glob("*.md"))
                index = [p for p in pages if p.stem == "index"]
                pages = index + [p for p in pages if p.stem != "index"]
                if pages:
                    rel = [{_title(p): p.relative_to(docs_dir).as_posix()} for p in pages]
                    out.append({title: rel})
                continue
        out.append(item)
    return out


# ---------------------------------------------------------------------------------------------
# MkDocs events
# ---------------------------------------------------------------------------------------------


def on_config(config: Any) -> Any:
    root = str(Path(config.config_file_path).resolve().parent)
    if root not in sys.path:  # the generated parts describe this tree's code, as the API does
        sys.path.insert(0, root)
    if config.nav:
        config.nav = expand_nav(config.nav, Path(config.docs_dir))
    return config


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    return expand(markdown)


def on_page_content(html: str, page: Any, config: Any, files: Any) -> str:
    return SPHINX_ROLE.sub("", html)
