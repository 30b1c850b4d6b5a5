"""The code keeps a readable shape: no function of ``dynmap_sim`` runs over
:data:`MAX_FUNCTION_LINES` lines unless it is a compiled kernel (a hot loop numba compiles,
where one long body is the point), and no compiled kernel takes more than
:data:`MAX_KERNEL_PARAMS` parameters (pass a kernel a few arrays, not a bag of scalars).
Pure ``ast``: nothing is imported or compiled."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "dynmap_sim"
#: Longest function or method, counted from its ``def`` line to its last line.
MAX_FUNCTION_LINES = 100
#: Most parameters of a function decorated with :func:`dynmap_sim.jit.compiled`.
MAX_KERNEL_PARAMS = 12

Function = ast.FunctionDef | ast.AsyncFunctionDef


@functools.cache
def _functions() -> tuple[tuple[str, Function], ...]:
    """``(path:line name, node)`` of every function and method (nested ones too) of the
    package, parsed once for all the tests."""
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        rel = path.relative_to(ROOT).as_posix()
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                out.append((f"{rel}:{node.lineno} {node.name}", node))
    return tuple(out)


def _is_compiled(fn: Function) -> bool:
    """Whether ``fn`` is decorated with ``compiled`` (``@compiled`` or ``@jit.compiled``)."""
    for dec in fn.decorator_list:
        if isinstance(dec, ast.Name) and dec.id == "compiled":
            return True
        if isinstance(dec, ast.Attribute) and dec.attr == "compiled":
            return True
    return False


def _lines(fn: Function) -> int:
    """Lines from ``def`` to the function's end (decorators not counted)."""
    assert fn.end_lineno is not None
    return fn.end_lineno - fn.lineno + 1


def _n_params(fn: Function) -> int:
    """Every parameter: positional-only, positional, keyword-only, ``*args``, ``**kwargs``."""
    a = fn.args
    star = (a.vararg is not None) + (a.kwarg is not None)
    return len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + star


def test_the_package_has_functions_and_kernels_to_check() -> None:
    functions = _functions()
    assert len(functions) > 1000
    assert sum(_is_compiled(fn) for _, fn in functions) > 20


def test_no_function_is_longer_than_the_limit_but_compiled_kernels() -> None:
    long = [
        f"{where} ({_lines(fn)} lines)"
        for where, fn in _functions()
        if _lines(fn) > MAX_FUNCTION_LINES and not _is_compiled(fn)
    ]
    assert not long, (
        f"functions over {MAX_FUNCTION_LINES} lines (split them into helpers with one role "
        "each):\n" + "\n".join(long)
    )


def test_compiled_kernels_take_few_parameters() -> None:
    many = [
        f"{where} ({_n_params(fn)} parameters)"
        for where, fn in _functions()
        if _is_compiled(fn) and _n_params(fn) > MAX_KERNEL_PARAMS
    ]
    assert not many, (
        f"compiled kernels with over {MAX_KERNEL_PARAMS} parameters (group the inputs into a "
        "few arrays):\n" + "\n".join(many)
    )


def test_the_checks_see_length_decorators_and_parameters() -> None:
    src = (
        "@compiled\ndef k(a, b, /, c, *d, e, **f):\n    pass\n\n"
        "@jit.compiled\ndef j():\n    pass\n\n"
        "def long():\n" + "    x = 1\n" * 120
    )
    fns = {n.name: n for n in ast.walk(ast.parse(src)) if isinstance(n, ast.FunctionDef)}
    assert _is_compiled(fns["k"]) and _is_compiled(fns["j"]) and not _is_compiled(fns["long"])
    assert _n_params(fns["k"]) == 6 and _n_params(fns["j"]) == 0
    assert _lines(fns["k"]) == 2 and _lines(fns["long"]) == 121
