"""Optional numba kernel of the occupancy grid's distance field (extra ``fast``).

:func:`squared_distances`: the exact Euclidean distance transform of Felzenszwalb &
Huttenlocher (2012), the squared distance [cells²] from each cell to the nearest occupied
one, in two passes (along columns, then the lower envelope of parabolas along rows). Its
values are exact integers (in float64), so ``sqrt`` of them is scipy's
``distance_transform_edt`` to the bit (scipy takes ``sqrt(dx² + dy²)`` of its nearest feature;
which of several equally near features it picks does not change the distance); the tests
check the plain-Python kernel (what numba compiles) and the compiled one against scipy.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, pick_kernel
from dynmap_sim.jit import numba_available as numba_available  # re-exported

#: Stands for "no occupied cell in this column" (far beyond any grid's squared distances).
_FAR = 1e20


def _squared_distances_py(occ, col, f, v, z, out):  # type: ignore[no-untyped-def]
    """``out[y, x]``: squared distance [cells²] from cell ``(y, x)`` to the nearest True cell
    of ``occ`` (at least one); ``col`` ``(H, W)``, ``f, v`` ``(W,)``, ``z`` ``(W + 1,)``:
    scratch."""
    h, w = occ.shape
    for y in range(h):  # 1. along the columns (row by row): the nearest occupied cell above
        for x in range(w):
            if occ[y, x]:
                col[y, x] = 0.0
            elif y > 0 and col[y - 1, x] < _FAR:
                col[y, x] = col[y - 1, x] + 1.0
            else:
                col[y, x] = _FAR
    for y in range(h - 2, -1, -1):  # ... or below
        for x in range(w):
            if col[y + 1, x] + 1.0 < col[y, x]:
                col[y, x] = col[y + 1, x] + 1.0
    for y in range(h):  # 2. along each row: min over q of (x - q)² + col[y, q]²
        for q in range(w):
            f[q] = col[y, q] * col[y, q] if col[y, q] < _FAR else _FAR
        k = 0
        v[0] = 0
        z[0] = -np.inf
        z[1] = np.inf
        for q in range(1, w):
            while True:  # where parabola q overtakes the envelope's last one
                p = v[k]
                s = ((f[q] + q * q) - (f[p] + p * p)) / (2.0 * q - 2.0 * p)
                if s > z[k]:
                    break
                k -= 1
            k += 1
            v[k] = q
            z[k] = s
            z[k + 1] = np.inf
        k = 0
        for q in range(w):
            while z[k + 1] < q:
                k += 1
            p = v[k]
            out[y, q] = (q - p) * (q - p) + f[p]


_squared_distances = compiled(_squared_distances_py)


def squared_distances(occupied: NDArray[np.bool_], python: bool = False) -> NDArray[np.float64]:
    """:func:`_squared_distances_py` compiled (needs numba; ``python``: the plain kernel):
    ``(H, W)`` squared distances [cells²] to the nearest of ``occupied`` (at least one)."""
    kernel = pick_kernel(_squared_distances_py, _squared_distances, python, "distance field")
    h, w = occupied.shape
    out = np.empty((h, w), dtype=np.float64)
    kernel(np.ascontiguousarray(occupied), np.empty((h, w)), np.empty(w), np.empty(w, np.intp),
           np.empty(w + 1), out)  # fmt: skip
    return out
