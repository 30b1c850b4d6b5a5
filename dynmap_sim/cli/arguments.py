"""The argparse types of the ``dynmap-sim`` options and the checks of what they name.

A type refuses a malformed value at parse time (argparse: exit status 2); the checks of output
files and folders raise :class:`dynmap_sim.errors.InputError` before anything is written.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

if TYPE_CHECKING:
    Subparsers = argparse._SubParsersAction[argparse.ArgumentParser]

#: The help of a world and noise ``--seed``.
SEED_HELP = "world and noise seed, an integer >= 0"


def day_range(text: str) -> tuple[int, int]:
    """Parse ``A-B`` or ``A`` (1-based, inclusive) into a day range (an argparse ``type``; the
    benchmarks' ``--days`` use it too)."""
    try:
        a, dash, b = text.partition("-")
        if dash and not b.strip():  # "1-" is not "1": say what was meant
            raise ValueError(text)
        first, last = int(a), int(b or a)
    except ValueError:
        raise argparse.ArgumentTypeError(f"days must look like 3 or 1-7, not {text!r}") from None
    if first < 1 or last < first:
        raise argparse.ArgumentTypeError(f"bad day range {text!r}")
    return first, last


#: Seeds are stored as SQLite integers: 0 .. 2**63 - 1.
MAX_SEED = 2**63 - 1


T = TypeVar("T")


def _converted(text: str, convert: Callable[[str], T], expected: str) -> T:
    """``convert(text)``, or an argparse error saying what was ``expected``."""
    try:
        return convert(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}, not {text!r}") from None


def _seed(text: str) -> int:
    """A seed: an integer in 0 .. 2**63 - 1."""
    v = _converted(text, int, "an integer seed")
    if not 0 <= v <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"seed must be in 0..2**63-1, not {v}")
    return v


def _positive(text: str) -> int:
    """An integer >= 1 (a day, a run, a number of workers)."""
    v = _converted(text, int, "an integer")
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, not {v}")
    return v


def _localizer_arg(text: str) -> str:
    """``--localizer NAME[,key=value,...]``: the name must not be empty."""
    if not text.split(",")[0].strip():
        raise argparse.ArgumentTypeError(f"expected NAME[,key=value,...], not {text!r}")
    return text


def _reference_offset(text: str) -> float | None:
    """``--reference-offset``: seconds (finite), or ``auto`` (``None``: estimated)."""
    import math

    if text.strip().lower() == "auto":
        return None
    v = _converted(text, float, "seconds or auto")
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"must be a finite number of seconds, not {text!r}")
    return v


def _positive_seconds(text: str) -> float:
    """A finite duration > 0 [s]."""
    import math

    v = _converted(text, float, "seconds")
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"must be a number of seconds > 0, not {text!r}")
    return v


def _output_file(path: str) -> Path:
    """An output file named by ``-o``: its folder must exist (a typo does not create folders)
    and it must not be a folder, a device or a pipe (writing to a FIFO would block)."""
    from dynmap_sim.errors import InputError

    p = Path(path)
    if p.is_dir():
        raise InputError(f"-o {path}: is a folder; give a file name, e.g. {p / 'out'}")
    if p.exists() and not p.is_file():
        raise InputError(f"-o {path}: not a regular file; give a file name")
    if not p.parent.is_dir():
        raise InputError(f"-o {path}: folder {p.parent} does not exist; create it first")
    return p


def _output_dir(path: str | Path) -> Path:
    """An output folder (created with its parents); InputError when it cannot be."""
    from dynmap_sim.errors import InputError

    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create folder {path}: {exc.strerror or exc}") from None
    return p


def _refuse_results(out: str | Path | None, force: bool, what: str) -> None:
    """Refuse to write into a folder that holds results (``out/results.db``, or
    ``out/seed-*/results.db``) unless ``--force``."""
    from dynmap_sim.errors import InputError
    from dynmap_sim.experiments.results import DB_NAME

    if out is None or force:
        return
    d = Path(out)
    held = [d / DB_NAME, *sorted(d.glob(f"seed-*/{DB_NAME}"))]
    held = [h for h in held if h.exists()]
    if held:
        raise InputError(
            f"{held[0]} already holds results; {what} would replace them: pass --force to "
            "replace them or choose another --out"
        )


def _wrote(path: Path, existed: bool) -> str:
    """``wrote PATH``, saying so when it replaced a file that was there."""
    return f"wrote {path}" + (" (replaced the earlier file)" if existed else "")


def _refuse_world_file(path: str) -> None:
    """A world file given where a scenario is expected: say so (instead of listing every
    scenario field it lacks)."""
    from dynmap_sim.errors import FileError, read_toml
    from dynmap_sim.experiments.scenario import ScenarioFileError, is_scenario_file

    data = read_toml(path, ScenarioFileError)  # a bad file is reported here, read safely
    if is_scenario_file(path):
        return
    if {"calendar", "walls", "bounds"} & set(data):
        raise FileError(
            path,
            [
                (
                    "",
                    "this is a world file, not a scenario; a scenario names its world "
                    '(world = "path/to/world.toml") and the localizers to run, '
                    "e.g. worlds/scenarios/ci-apartment.toml",
                )
            ],
        )


def seed_list(text: str) -> tuple[int, ...]:
    """Parse ``0-3``, ``0,2,5`` or ``7`` into seeds (an argparse ``type``: ``sweep --seeds``
    and the benchmarks' ``--seeds``)."""
    from dynmap_sim.errors import InputError
    from dynmap_sim.experiments.sweep import parse_seeds

    try:
        return parse_seeds(text, "seeds")
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("seeds: ")) from None


def _sweep_set(text: str):  # -> Setting
    """``--set LABEL.KEY=V1,V2``."""
    from dynmap_sim.errors import InputError
    from dynmap_sim.experiments.sweep import parse_set

    try:
        return parse_set(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix(f"--set {text}: ")) from None


def _cluster_address(text: str) -> str:
    """A Dask scheduler's address: ``tcp://HOST:PORT`` (or ``tls://``, ``ws://``...)."""
    import re

    if not re.fullmatch(r"[a-z][a-z0-9+]*://[^\s/]+/?", text):
        raise argparse.ArgumentTypeError(f"expected tcp://HOST:PORT, not {text!r}")
    return text
