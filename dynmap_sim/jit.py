"""Optional numba (the ``fast`` extra): the one import guard of every compiled backend.

Each ``*_numba`` module keeps a pure-Python kernel that the numpy code's tests check, and
compiles it with :func:`compiled` when numba is installed.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

try:  # pragma: no cover - depends on the optional extra
    import numba
except ImportError:  # pragma: no cover
    numba = None


def numba_available() -> bool:
    """True when numba is installed (the ``fast`` extra)."""
    return numba is not None


def compiled(fn: Callable[..., Any]) -> Callable[..., Any] | None:
    """``fn`` compiled by numba (no GIL, cached on disk next to its module), None without it."""
    return numba.njit(cache=True, nogil=True)(fn) if numba is not None else None


def require_numba(what: str) -> None:
    """Raise a clear error when the numba backend of ``what`` is asked for without numba."""
    if numba is None:
        raise RuntimeError(f'the numba {what} needs numba: pip install "dynmap-sim[fast]"')
