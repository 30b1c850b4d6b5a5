"""Optional numba (the ``fast`` extra): the one import guard of every compiled backend.

Each ``*_numba`` module keeps a pure-Python kernel that the numpy code's tests check, and
compiles it with :func:`compiled` when numba is installed.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from fractions import Fraction
from typing import Any

import numba


def fma(a: float, b: float, c: float) -> float:
    """``a * b + c`` rounded once (IEEE 754 fusedMultiplyAdd), as numpy's SIMD loops compute
    where they fuse; in kernels compiled by numba, the CPU's instruction (``llvm.fma.f64``).
    Plain Python computes it exactly with fractions (slow: for the kernels' tests)."""
    if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(c)):
        return a * b + c
    return float(Fraction(a) * Fraction(b) + Fraction(c))


def jitable(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` itself, made callable from compiled kernels too when numba is installed (its
    ``register_jitable``): helpers shared by a kernel's plain and compiled runs."""
    return numba.extending.register_jitable(fn) if numba is not None else fn


def _register_fma() -> None:  # pragma: no cover - depends on the optional extra
    """Let compiled kernels call :func:`fma` as the LLVM intrinsic (one instruction on CPUs
    with FMA, a correctly rounded library call elsewhere)."""
    from llvmlite import ir
    from numba.core import cgutils
    from numba.extending import intrinsic, overload

    @intrinsic
    def _fma_ir(typingctx: Any, a: Any, b: Any, c: Any) -> Any:
        sig = numba.float64(numba.float64, numba.float64, numba.float64)

        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            fnty = ir.FunctionType(ir.DoubleType(), [ir.DoubleType()] * 3)
            return builder.call(
                cgutils.get_or_insert_function(builder.module, fnty, "llvm.fma.f64"), args
            )

        return sig, codegen

    @overload(fma)
    def _fma_overload(a, b, c):  # type: ignore[no-untyped-def]  (numba compares the names)
        def impl(a, b, c):  # type: ignore[no-untyped-def]  (numba: the overload's names)
            return _fma_ir(float(a), float(b), float(c))

        return impl


if numba is not None:  # pragma: no cover - depends on the optional extra
    _register_fma()


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
