"""The kernel choice every ``*_numba`` wrapper makes (:func:`dynmap_sim.jit.pick_kernel`)."""

import pytest

from dynmap_sim import jit
from dynmap_sim.jit import pick_kernel


def plain() -> str:
    return "plain"


def jitted() -> str:
    return "jitted"


def test_the_plain_kernel_when_asked_for_else_the_compiled_one() -> None:
    assert pick_kernel(plain, jitted, True, "x") is plain
    assert pick_kernel(plain, None, True, "x") is plain  # no numba needed for the plain one
    assert pick_kernel(plain, jitted, False, "x") is jitted


def test_no_compiled_kernel_is_a_clear_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(jit, "numba", None)  # as without the `fast` extra
    with pytest.raises(
        RuntimeError, match=r'the numba ray casting needs numba: pip install "dynmap-sim\[fast\]"'
    ):
        pick_kernel(plain, None, False, "ray casting")
