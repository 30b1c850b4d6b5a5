"""A small, deterministic TOML writer for the files the testbed writes (scenarios of a
benchmark, generated worlds): the same dict gives the same text byte for byte.

Python's ``tomllib`` only reads. This writes the subset the project's files use: strings,
booleans, integers, floats (Python's shortest round-trip ``repr``), dates, lists, inline
tables inside lists, tables (``[a.b]``) and arrays of tables (``[[a]]``), in the dict's own
key order.
"""

from __future__ import annotations

import datetime as dt
import json
import math
import re
from collections.abc import Mapping
from typing import Any

#: Keys TOML takes without quotes.
_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def key(k: str) -> str:
    """``k`` as a TOML key: bare when it can be, else a quoted string."""
    return k if _BARE.match(k) else json.dumps(k, ensure_ascii=False)


def value(v: Any) -> str:
    """One TOML value (inline: tables inside it are inline tables)."""
    if hasattr(v, "item") and not isinstance(v, list | tuple | Mapping):  # numpy scalars
        v = v.item()
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, dt.date):
        return v.isoformat()
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{key(k)} = {value(x)}" for k, x in v.items()) + " }"
    if isinstance(v, list | tuple):
        return "[" + ", ".join(value(x) for x in v) + "]"
    raise TypeError(f"cannot write a {type(v).__name__} as TOML")


def _is_table_array(v: Any) -> bool:
    return isinstance(v, list | tuple) and len(v) > 0 and all(isinstance(x, Mapping) for x in v)


def _table(data: Mapping[str, Any], path: list[str], out: list[str]) -> None:
    scalars = {
        k: v for k, v in data.items() if v is not None and not isinstance(v, Mapping)
        and not _is_table_array(v)
    }  # fmt: skip
    out += [f"{key(k)} = {value(v)}" for k, v in scalars.items()]
    for k, v in data.items():
        if isinstance(v, Mapping):
            sub = [*path, key(k)]
            out += ["", f"[{'.'.join(sub)}]"]
            _table(v, sub, out)
    for k, v in data.items():
        if _is_table_array(v):
            for item in v:
                out += ["", f"[[{'.'.join([*path, key(k)])}]]"]
                _table(item, [*path, key(k)], out)


def dumps(data: Mapping[str, Any], header: list[str] | None = None) -> str:
    """The TOML text of ``data`` (``None`` values left out), ``header`` lines as comments."""
    out = [f"# {h}".rstrip() for h in header or []]
    if out:
        out.append("")
    _table(data, [], out)
    return "\n".join(out).lstrip("\n") + "\n"
