"""Errors for bad input: they name the file and the dotted field path, never a traceback.

``InputError`` is what the CLI catches and prints; :class:`FileError` collects *all* the
problems of one file so a user fixes them in one go.
"""

from __future__ import annotations

import os
import stat
import tomllib
from collections.abc import Iterable
from pathlib import Path
from typing import Any


class InputError(ValueError):
    """Bad user input (a file, an argument, a checkpoint); the message says what and where."""


class FileError(InputError):
    """All the errors of one input file, each as ``(dotted.field.path, message)``; one error
    is one line (``file: field: message``), several a header and a line each."""

    def __init__(self, path: str | Path, errors: Iterable[tuple[str, str]]) -> None:
        self.path = str(path)
        self.errors: list[tuple[str, str]] = list(errors)
        if len(self.errors) == 1:  # one problem, one line
            loc, msg = self.errors[0]
            super().__init__(f"{self.path}: {loc}: {msg}" if loc else f"{self.path}: {msg}")
            return
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


#: Largest input file read [bytes]: world and scenario files are a few kB.
MAX_FILE_BYTES = 16 * 2**20


def _kind(mode: int) -> str:
    """What a non-regular file is, for a message."""
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "something else"


def regular_file_size(path: str | Path, error_cls: type[FileError]) -> int:
    """The size of ``path`` [bytes]; ``error_cls`` unless it is a regular file (checked with
    ``stat``, without opening it: a FIFO would block, a device never end)."""
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise error_cls(p, [("", "file not found")]) from None
    except (OSError, ValueError) as exc:
        raise error_cls(p, [("", f"cannot read file: {exc}")]) from None
    if not stat.S_ISREG(st.st_mode):
        raise error_cls(p, [("", f"not a regular file but {_kind(st.st_mode)}")])
    return st.st_size


def read_input_text(path: str | Path, error_cls: type[FileError]) -> str:
    """The text of an input file: only a regular file of at most :data:`MAX_FILE_BYTES`,
    UTF-8 with or without a byte-order mark; every problem as ``error_cls``.

    The file is checked with ``stat`` before it is opened, so a FIFO or a device
    (``/dev/zero``) is refused at once instead of blocking or filling the memory.
    """
    p = Path(path)
    size = regular_file_size(p, error_cls)
    limit = MAX_FILE_BYTES
    if size > limit:
        raise error_cls(
            p, [("", f"file too large: {size} bytes (the limit is {limit // 2**20} MiB)")]
        )
    try:  # non-blocking open and fstat: swapped for a FIFO since the stat, it is still refused
        with os.fdopen(os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0)), "rb") as f:
            mode = os.fstat(f.fileno()).st_mode
            if not stat.S_ISREG(mode):
                raise error_cls(p, [("", f"not a regular file but {_kind(mode)}")])
            data = f.read(limit + 1)
    except OSError as exc:
        raise error_cls(p, [("", f"cannot read file: {exc}")]) from None
    if len(data) > limit:  # grew since the stat
        raise error_cls(p, [("", f"file too large (the limit is {limit // 2**20} MiB)")])
    try:
        return data.decode("utf-8-sig")  # a leading byte-order mark is not content
    except UnicodeDecodeError as exc:
        raise error_cls(p, [("", f"cannot read file: not UTF-8 text ({exc})")]) from None


def read_toml(path: str | Path, error_cls: type[FileError]) -> dict[str, Any]:
    """Read a TOML file (see :func:`read_input_text`), turning I/O and syntax problems and
    absurd nesting into ``error_cls``."""
    p = Path(path)
    text = read_input_text(p, error_cls)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error_cls(p, [("", f"TOML syntax error: {exc}")]) from None
    except RecursionError:
        raise error_cls(p, [("", "TOML nested too deeply to read")]) from None
