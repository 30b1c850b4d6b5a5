"""Optional numba backend of :func:`.correlative_matcher.correlative_match` (extra ``fast``).

The two sums of the branch and bound -- the upper bound of every (rotation, block) from the
coarse table, and the fine score of every translation of an expanded block -- and the loop
over the blocks, best bound first, in compiled loops. Each score is the sum over the scan's
points as numpy's ``sum`` over the points' axis adds them: in point order while other axes
of more than one value are inside it, numpy's pairwise summation when the points' axis is
the only one left (a single block or translation); lookups clipped to the table as
``_lookup`` clips them, the first best translation of a block as ``argmax`` finds it: the
results are the numpy code's, bit for bit. The order of the blocks is numpy's ``argsort``
(the caller's).
:func:`numba_available` says whether it can be used.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, kernel_backend, require_numba
from dynmap_sim.jit import numba_available as numba_available  # re-exported

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: numpy's pairwise summation: up to this many values in one block of 8 accumulators.
PW_BLOCKSIZE = 128


def _pairwise_py(a: FloatArray, n: int) -> float:
    """``a[:n]`` summed as numpy's ``pairwise_sum`` (``loops_utils.h``) adds them, without
    recursion (a compiled recursive kernel does not cache): the halves of a range of more
    than :data:`PW_BLOCKSIZE` values (the first a multiple of 8) are summed first, then
    added; a range up to that in 8 interleaved partial sums and the rest in order; fewer
    than 8 values in order."""
    lo_s = np.empty(128, dtype=np.int64)  # ranges to sum (lo, n) or, n < 0, an addition
    n_s = np.empty(128, dtype=np.int64)
    vals = np.empty(128)
    lo_s[0], n_s[0] = 0, n
    top, nv = 1, 0
    while top > 0:
        top -= 1
        lo, m = lo_s[top], n_s[top]
        if m < 0:  # both halves are summed: add them
            nv -= 1
            vals[nv - 1] = vals[nv - 1] + vals[nv]
        elif m > PW_BLOCKSIZE:
            m2 = m // 2
            m2 -= m2 % 8
            lo_s[top], n_s[top] = 0, -1
            lo_s[top + 1], n_s[top + 1] = lo + m2, m - m2
            lo_s[top + 2], n_s[top + 2] = lo, m2
            top += 3
        else:
            vals[nv] = _block_sum(a, lo, m)
            nv += 1
    return vals[0]


def _block_sum_py(a: FloatArray, lo: int, n: int) -> float:
    """``a[lo:lo + n]`` (``n`` at most :data:`PW_BLOCKSIZE`) as ``pairwise_sum`` adds it."""
    if n < 8:
        res = -0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    r = np.empty(8)
    for j in range(8):
        r[j] = a[lo + j]
    i = 8
    while i < n - n % 8:
        for j in range(8):
            r[j] += a[lo + i + j]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


def _bounds_py(coarse: FloatArray, ix0: IntArray, iy0: IntArray, boff: IntArray) -> FloatArray:
    """``out[t, by, bx]``: the sum over points ``i`` of ``coarse`` at ``(iy0[t, i] +
    boff[by], ix0[t, i] + boff[bx])``, clipped to the table."""
    h, w = coarse.shape
    n_t, n_p = ix0.shape
    nb = boff.shape[0]
    out = np.zeros((n_t, nb, nb))
    if nb == 1:  # one block: numpy sums each rotation's points pairwise
        vals = np.empty(n_p)
        for t in range(n_t):
            for i in range(n_p):
                vals[i] = coarse[min(max(iy0[t, i], 0), h - 1), min(max(ix0[t, i], 0), w - 1)]
            out[t, 0, 0] = -0.0 + _pairwise(vals, n_p)
        return out
    for t in range(n_t):
        for i in range(n_p):
            for by in range(nb):
                y = min(max(iy0[t, i] + boff[by], 0), h - 1)
                for bx in range(nb):
                    x = min(max(ix0[t, i] + boff[bx], 0), w - 1)
                    out[t, by, bx] += coarse[y, x]
    return out


def _search_py(
    order: IntArray,
    bounds: FloatArray,
    fine: FloatArray,
    ix0: IntArray,
    iy0: IntArray,
    boff: IntArray,
    block: int,
    last: int,
    max_blocks: int,
) -> tuple[float, int, int, int, int]:
    """The blocks in ``order`` (flat indices of ``bounds``), at most ``max_blocks``, until a
    bound is no better than the best fine score: ``(best score, rotation, y offset, x
    offset, fine translations scored)``; translation offsets beyond ``last`` are left out."""
    h, w = fine.shape
    n_p = ix0.shape[1]
    nb = bounds.shape[1]
    vals = np.empty((block, block))
    one = np.empty(n_p)  # a block of one translation: numpy sums its points pairwise
    best_score = -1.0
    best_t = best_y = best_x = 0
    n_eval = 0
    for j in range(min(max_blocks, order.shape[0])):
        flat = order[j]
        t = flat // (nb * nb)
        by = (flat // nb) % nb
        bx = flat % nb
        if bounds[t, by, bx] <= best_score:
            break
        oy0 = boff[by]
        ox0 = boff[bx]
        ny = min(block, last - oy0 + 1)
        nx = min(block, last - ox0 + 1)
        vals[:ny, :nx] = 0.0
        if ny == 1 and nx == 1:
            for i in range(n_p):
                y = min(max(iy0[t, i] + oy0, 0), h - 1)
                one[i] = fine[y, min(max(ix0[t, i] + ox0, 0), w - 1)]
            vals[0, 0] = -0.0 + _pairwise(one, n_p)
        for i in range(n_p if ny > 1 or nx > 1 else 0):
            for a in range(ny):
                y = min(max(iy0[t, i] + oy0 + a, 0), h - 1)
                for b in range(nx):
                    x = min(max(ix0[t, i] + ox0 + b, 0), w - 1)
                    vals[a, b] += fine[y, x]
        n_eval += ny * nx
        ka = kb = 0
        for a in range(ny):  # argmax: the first maximum in row-major order
            for b in range(nx):
                if vals[a, b] > vals[ka, kb]:
                    ka, kb = a, b
        if vals[ka, kb] > best_score:
            best_score = vals[ka, kb]
            best_t, best_y, best_x = t, oy0 + ka, ox0 + kb
    return best_score, best_t, best_y, best_x, n_eval


_block_sum = compiled(_block_sum_py) or _block_sum_py
_pairwise = compiled(_pairwise_py) or _pairwise_py
_bounds = compiled(_bounds_py)
_search = compiled(_search_py)


def kernels(backend: str) -> tuple | None:
    """``(bounds, search)`` compiled (``"numba"``) or not (``"python"``) for a ``backend``
    argument (:data:`dynmap_sim.jit.KERNEL_BACKENDS`); None for the numpy code."""
    kind = kernel_backend(backend)
    if kind == "numba":
        require_numba("correlative matcher backend")
        return _bounds, _search
    if kind == "python":
        return _bounds_py, _search_py
    return None
