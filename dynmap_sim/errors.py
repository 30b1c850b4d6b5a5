"""Errors for bad input: they name the file and the dotted field path, never a traceback.

``InputError`` is what the CLI catches and prints; :class:`FileError` collects *all* the
problems of one file so a user fixes them in one go.
"""

from __future__ import annotations

import tomllib
from collections.abc import Iterable
from pathlib import Path
from typing import Any


class InputError(ValueError):
    """Bad user input (a file, an argument, a checkpoint); the message says what and where."""


class FileError(InputError):
    """All the errors of one input file, each as ``(dotted.field.path, message)``."""

    def __init__(self, path: str | Path, errors: Iterable[tuple[str, str]]) -> None:
        self.path = str(path)
        self.errors: list[tuple[str, str]] = list(errors)
        lines = [f"{self.path}: {len(self.errors)} error(s)"]
        lines += [f"  {loc}: {msg}" if loc else f"  {msg}" for loc, msg in self.errors]
        super().__init__("\n".join(lines))


def pydantic_errors(exc: Any) -> list[tuple[str, str]]:
    """Turn a ``pydantic.ValidationError`` into ``(dotted path, message)`` pairs."""
    out = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err["loc"])
        msg = err["msg"]
        if msg.startswith("Value error, "):
            msg = msg[len("Value error, ") :]
        out.append((loc, msg))
    return out


def read_toml(path: str | Path, error_cls: type[FileError]) -> dict[str, Any]:
    """Read a TOML file, turning I/O and syntax problems into ``error_cls``."""
    p = Path(path)
    try:
        return tomllib.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise error_cls(p, [("", "file not found")]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error_cls(p, [("", f"cannot read file: {exc}")]) from None
    except tomllib.TOMLDecodeError as exc:
        raise error_cls(p, [("", f"TOML syntax error: {exc}")]) from None
