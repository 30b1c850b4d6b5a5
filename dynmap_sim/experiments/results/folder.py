"""A results folder's guards: one writer (an OS lock), a full disk said as such, and the
leftovers of a deleted ``results.db``."""

from __future__ import annotations

import errno
import os
import shutil
import sqlite3
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from dynmap_sim.errors import InputError
from dynmap_sim.experiments.results.schema import CHECKPOINT_DIR, DB_NAME, LOCK_NAME


class DiskFullError(InputError):
    """The disk filled up while the store wrote ``what`` into results ``folder``; what was
    committed before is kept: ``runs_kept`` finished runs (None: no store was made, the
    folder holds no results; -1: not known)."""

    def __init__(self, folder: Path, what: str, runs_kept: int | None = None) -> None:
        super().__init__(f"the disk is full (no space left writing {what})")
        self.folder = folder
        self.what = what
        self.runs_kept = runs_kept

    def what_is_kept(self) -> str:
        """What the folder holds now and how to go on (for ``run``)."""
        if self.runs_kept is None:
            return (
                f"nothing was stored in {self.folder}: free some space, then the same command "
                "starts the experiment"
            )
        if self.runs_kept == 0:
            return (
                f"no run had finished; {self.folder} holds the experiment's store without "
                "runs: free some space, then the same command (with or without --resume) "
                "starts from the first run"
            )
        runs = {-1: "runs", 1: "one run"}.get(self.runs_kept, f"{self.runs_kept} runs")
        are = "is" if self.runs_kept == 1 else "are"
        return (
            f"the {runs} finished so far {are} kept in {self.folder}: free some space, then "
            f"the same command with --resume continues after {'it' if are == 'is' else 'them'}"
        )


def is_disk_full(exc: BaseException) -> bool:
    """True for ``ENOSPC``/``EDQUOT`` and SQLite's "database or disk is full"."""
    if isinstance(exc, DiskFullError):
        return True
    if isinstance(exc, OSError):
        return exc.errno in (errno.ENOSPC, errno.EDQUOT)
    if isinstance(exc, sqlite3.Error):
        code = getattr(exc, "sqlite_errorcode", None)
        return code == sqlite3.SQLITE_FULL or "disk is full" in str(exc)
    return False


def no_space_left(folder: Path) -> bool:
    """The file system of ``folder`` has no free block (SQLite then says only "disk I/O
    error" when it cannot make its shared-memory file)."""
    try:
        return shutil.disk_usage(folder).free == 0
    except OSError:
        return False


@contextmanager
def disk_full_is_clear(
    folder: Path, what: str, kept: Callable[[], int | None] = lambda: -1
) -> Iterator[None]:
    """Turn a full disk into :class:`DiskFullError` (the rest passes through); ``kept``: how
    many finished runs the folder holds then."""
    try:
        yield
    except (OSError, sqlite3.Error) as exc:
        if is_disk_full(exc):
            raise DiskFullError(folder, what, kept()) from None
        raise


class FolderLock:
    """An exclusive OS lock (``flock``) on ``<folder>/.results.lock``: one writer per results
    folder. Released by :meth:`release` or when the process ends, however it ends."""

    def __init__(self, folder: Path) -> None:
        self.fd: int | None = None
        try:
            import fcntl
        except ImportError:  # pragma: no cover - not POSIX: no lock
            return
        fd = os.open(folder / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            try:
                pid = os.read(fd, 32).decode("ascii", "replace").strip()
            except OSError:
                pid = ""
            os.close(fd)
            who = f" (pid {pid})" if pid.isdigit() else ""
            raise InputError(
                f"{folder}: another dynmap-sim process{who} is writing results here; "
                "one writer per folder: wait until it ends (--resume then continues its "
                "results) or choose another --out"
            ) from None
        try:
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
        except OSError:
            pass  # the pid is only for the message; the lock holds without it
        self.fd = fd

    def release(self) -> None:
        if self.fd is not None:
            os.close(self.fd)  # closing the descriptor releases the flock
            self.fd = None


def orphaned_checkpoint(folder: str | Path) -> Path | None:
    """What holds earlier runs in ``folder`` although it has no ``results.db`` (checkpoint
    files, or a write-ahead log with content), else None."""
    d = Path(folder)
    if (d / DB_NAME).exists():
        return None
    wal = d / (DB_NAME + "-wal")
    if wal.is_file() and wal.stat().st_size > 0:
        return wal
    cp = d / CHECKPOINT_DIR
    if cp.is_dir() and any(cp.glob("*.pkl")):
        return cp
    return None
