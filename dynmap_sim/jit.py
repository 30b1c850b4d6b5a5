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


#: Values of a ``backend`` argument of code with optional kernels: ``numba`` (``auto`` when
#: installed) runs the compiled kernels, identical in result to ``numpy``; ``python`` the same
#: kernels uncompiled (slow: for the tests).
KERNEL_BACKENDS = ("auto", "numpy", "numba", "python")


def kernel_backend(backend: str) -> str | None:
    """``"numba"``, ``"python"`` or None (the numpy code) for a ``backend`` argument
    (:data:`KERNEL_BACKENDS`)."""
    if backend not in KERNEL_BACKENDS:
        raise ValueError(f"backend must be one of {KERNEL_BACKENDS}, got {backend!r}")
    if backend == "auto":
        return "numba" if numba is not None else None
    return None if backend == "numpy" else backend


def require_numba(what: str) -> None:
    """Raise a clear error when the numba backend of ``what`` is asked for without numba."""
    if numba is None:
        raise RuntimeError(f'the numba {what} needs numba: pip install "dynmap-sim[fast]"')


def pick_kernel(plain: Any, jitted: Any, python: bool, what: str) -> Any:
    """The plain kernel ``plain`` if ``python``, else its compiled twin ``jitted`` (from
    :func:`compiled`); a clear error (:func:`require_numba`) when that is None."""
    if python:
        return plain
    if jitted is None:
        require_numba(what)
    return jitted
