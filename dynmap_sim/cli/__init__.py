"""``dynmap-sim``: the thin command-line front end.

Every subcommand parses its arguments and calls one library function; all logic lives in the
package. The commands come in groups, one module each: :mod:`.worlds`, :mod:`.experiments`,
:mod:`.exports` and :mod:`.logs`; :mod:`.arguments` holds the option types they share. Bad
input files are reported (file, field, message), never with a traceback.

Exit status (:data:`EXIT_FAILED`, :data:`EXIT_MISUSE`): 0 done; 1 the command ran and the answer
is no: a ``check`` whose expectations fail, a file ``validate`` refuses, a localizer's own error,
failed sweep cells or benchmark worlds; 2 misuse or bad input: a bad option (argparse), a file,
folder or value the command refuses, a path the file system refuses (not found, permissions) or
a full disk; 130 interrupted.
"""

from __future__ import annotations

import argparse
import errno
import sys
from collections.abc import Sequence

from dynmap_sim.cli import experiments, exports, logs, worlds
from dynmap_sim.cli.arguments import MAX_SEED, day_range, seed_list
from dynmap_sim.cli.logs import ODOMETRY_CHOICES, REVERSAL_CHOICES
from dynmap_sim.cli.worlds import LIST_SECTIONS

__all__ = [
    "LIST_SECTIONS",
    "MAX_SEED",
    "ODOMETRY_CHOICES",
    "REVERSAL_CHOICES",
    "build_parser",
    "day_range",
    "main",
    "seed_list",
]

#: Exit status of a command that ran and failed: a check, a localizer, a cell of a sweep.
EXIT_FAILED = 1
#: Exit status of misuse or bad input (argparse's too): nothing was run, or it stopped at once.
EXIT_MISUSE = 2
#: ``OSError`` numbers that say the user's path is wrong (exit 2), not that the run failed.
USER_PATH_ERRNOS = frozenset(
    (errno.ENOENT, errno.ENOTDIR, errno.EISDIR, errno.EACCES, errno.EPERM, errno.EROFS,
     errno.EEXIST, errno.ENAMETOOLONG, errno.ELOOP)
)  # fmt: skip

#: The commands in the order ``dynmap-sim --help`` and the CLI reference list them.
COMMANDS = (
    "list", "compare", "benchmark", "validate", "schema", "render-world", "generate", "run",
    "report", "export", "video", "check", "replay", "slam-eval", "sweep", "toy",
)  # fmt: skip


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``dynmap-sim``: each group adds its commands, listed in the
    order of :data:`COMMANDS`."""
    from dynmap_sim import __version__

    p = argparse.ArgumentParser(
        prog="dynmap-sim", description="Long-term SLAM testbed in changing indoor worlds."
    )
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    for group in (worlds, experiments, exports, logs):
        group.add_parsers(sub)
    parsers = dict(sub.choices)
    if set(parsers) != set(COMMANDS):
        raise AssertionError(f"COMMANDS lists {COMMANDS}, the groups add {tuple(parsers)}")
    sub.choices.clear()  # the usage line's {list,compare,...}
    sub.choices.update((name, parsers[name]) for name in COMMANDS)
    sub._choices_actions.sort(key=lambda a: COMMANDS.index(a.dest))  # the help's list
    return p


def _disk_full_message(args: argparse.Namespace, exc: BaseException) -> str:
    """One line for a full disk: what failed, what is kept, how to go on."""
    from dynmap_sim.experiments.results import DiskFullError

    if isinstance(exc, DiskFullError):
        what, folder = str(exc), str(exc.folder)
    else:
        name = getattr(exc, "filename", None)
        what = "the disk is full" + (f" (no space left writing {name})" if name else "")
        folder = str(getattr(args, "out", None) or getattr(args, "dir", None) or "the folder")
    if args.command == "run":
        if isinstance(exc, DiskFullError):  # it knows how many runs are kept
            return f"{what}; {exc.what_is_kept()}"
        return (
            f"{what}; the runs finished so far are kept in {folder}: free some space, then the "
            "same command with --resume continues after them"
        )
    if args.command in ("replay", "check"):
        return (
            f"{what}; free some space, then {args.command} again (with --force: the "
            f"incomplete results in {folder} are replaced)"
        )
    return f"{what}; nothing that was there before is lost: free some space and try again"


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``dynmap-sim``; returns the exit status."""
    args = build_parser().parse_args(argv)
    from dynmap_sim.errors import InputError
    from dynmap_sim.experiments.localizer_pool import LocalizerError
    from dynmap_sim.experiments.results import is_disk_full

    try:
        try:
            return int(args.func(args))
        except Exception as exc:  # a full disk anywhere: one line saying what is kept
            if not is_disk_full(exc):
                raise
            raise InputError(_disk_full_message(args, exc)) from None
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_MISUSE
    except LocalizerError as exc:  # a localizer's own bug: name it, show its traceback
        import traceback

        if exc.__cause__ is not None:  # in-process; a worker's traceback is in the message
            traceback.print_exception(exc.__cause__, file=sys.stderr)
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt:
        if args.command == "run":
            print(
                "interrupted; the runs finished so far are stored: the same command with "
                "--resume continues from the last of them",
                file=sys.stderr,
            )
        else:
            print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `dynmap-sim schema | head`: the reader left, that is fine
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:  # the file system said no (not found, permissions, ...)
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"error: {where}{exc.strerror or exc}", file=sys.stderr)
        return EXIT_MISUSE if exc.errno in USER_PATH_ERRNOS else EXIT_FAILED
