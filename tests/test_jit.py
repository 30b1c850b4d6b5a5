"""The project's one kernel decorator: numba's compiled function, with plain Python's result."""

import numpy as np

from dynmap_sim.jit import compiled, jitable


@jitable
def _twice(x: float) -> float:
    return 2.0 * x


def _sum_twice(a: np.ndarray) -> float:
    s = 0.0
    for v in a:
        s += _twice(v)
    return s


def test_a_compiled_kernel_gives_the_plain_functions_result() -> None:
    kernel = compiled(_sum_twice)
    a = np.arange(10, dtype=np.float64)
    assert kernel(a) == _sum_twice(a) == 90.0
    assert hasattr(kernel, "py_func") and kernel.py_func is _sum_twice  # numba's dispatcher
