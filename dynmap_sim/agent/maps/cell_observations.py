"""Observations of many cells, as the temporal cell models take them.

One observation is a cell index, a time [s] and a state (0 free, 1 occupied, or a
probability); :mod:`.fremen` and :mod:`.markov_grid` learn from flat arrays of them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray


def observation_arrays(
    times_s: ArrayLike, cells: ArrayLike, states: ArrayLike, n_cells: int
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.float64]]:
    """``(times_s, cells, states)`` as contiguous 1-D float64 / int64 / float64 arrays of one
    length, every cell in ``[0, n_cells)`` (ValueError / IndexError otherwise)."""
    t = np.ascontiguousarray(times_s, np.float64).ravel()
    c = np.ascontiguousarray(cells, np.int64).ravel()
    s = np.ascontiguousarray(states, np.float64).ravel()
    if not t.size == c.size == s.size:
        raise ValueError("times_s, cells and states must have the same length")
    if c.size and (c.min() < 0 or c.max() >= n_cells):
        raise IndexError("cell index out of range")
    return t, c, s


def cell_indices(cells: ArrayLike | None, n_cells: int) -> NDArray[np.int64]:
    """The flat indices ``cells`` as int64, or all ``n_cells`` cells for None."""
    if cells is None:
        return np.arange(n_cells)
    return np.asarray(cells, np.int64).reshape(-1)
