"""The one way kernels are compiled: numba's ``njit``, cached on disk, without the GIL.

numba is a core dependency, and each hot loop has one compiled implementation. Set
``NUMBA_DISABLE_JIT=1`` to run the kernels as plain Python (to step through one in a
debugger); the numbers are the same up to floating-point contraction, slowly.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numba


def compiled(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` compiled by numba: no GIL (the localizer pool's threads run it in parallel),
    cached on disk next to its module so that only the first run on an install compiles."""
    return numba.njit(cache=True, nogil=True)(fn)


def jitable(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` itself, made callable from compiled kernels too (numba's ``register_jitable``):
    small helpers that several kernels share."""
    return numba.extending.register_jitable(fn)
