"""Optional numba kernels of the MCL core (extra ``fast``).

* :func:`endpoint_values`: the particles x beams part of
  :func:`.likelihood_field.endpoint_values` (*Probabilistic Robotics* Table 6.3, line 5: each
  beam's end point in the map, and the likelihood table's value there) one end point at a
  time: the numpy code builds four float32 and three integer ``(P, B)`` arrays for it, then
  gathers. The arithmetic is the numpy code's, operation for operation (float32 products and
  sums in the same order, ``floor`` in float32, the same bounds), so the values are
  identical; the per-particle and per-beam terms (``cos``, ``sin``, the float64 laser
  origins) stay in numpy, whose results the kernel takes.
* :func:`first_occupied`: the ray casting of the expected ranges (Fox et al.'s distance
  filter, H&W §6.1's map selection), beam by beam up to its first occupied sample, where the
  numpy code samples every beam to the end;
* :func:`wall_depths`: the walks of :mod:`.see_through` (sphere tracing on the distance
  field), beam by beam, where the numpy code moves all beams in lockstep;
* :func:`bin_clusters`: the particle clusters of ``AMCLFilter.estimate`` (``pf_cluster_stats``)
  by union-find over the occupied bins, numbered as scipy's ``connected_components`` numbers
  them.

The tests check the plain-Python kernels (what numba compiles) and the compiled ones against
the numpy code.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, pick_kernel
from dynmap_sim.jit import numba_available as numba_available  # re-exported

Float32Array = NDArray[np.float32]


def _endpoint_values_py(lx, ly, c, s, bx, by, values, h, w, out):  # type: ignore[no-untyped-def]
    """``out[i, j]``: ``values[iy * w + ix]`` at the cell of particle ``i``'s beam ``j``, whose
    end point is ``(c_i bx_j - s_i by_j + lx_i, s_i bx_j + c_i by_j + ly_i)`` [cells] (all
    float32), or ``values[h * w]`` outside the grid."""
    outside = values[h * w]
    for i in range(lx.shape[0]):
        ci, si, lxi, lyi = c[i], s[i], lx[i], ly[i]
        for j in range(bx.shape[0]):
            fx = np.floor(ci * bx[j] - si * by[j] + lxi)
            fy = np.floor(si * bx[j] + ci * by[j] + lyi)
            if 0 <= fx < w and 0 <= fy < h:
                out[i, j] = values[int(fy) * w + int(fx)]
            else:
                out[i, j] = outside


_endpoint_values = compiled(_endpoint_values_py)


def endpoint_values(
    values: NDArray[np.generic],
    terms: tuple[Float32Array, ...],
    shape: tuple[int, int],
    python: bool = False,
) -> NDArray[np.generic]:
    """:func:`_endpoint_values_py` compiled (needs numba; ``python``: the plain kernel) on a
    grid of ``shape`` ``(H, W)``, ``terms`` ``(lx, ly, c, s, bx, by)``: the ``(P, B)`` values
    (``values``' dtype)."""
    kernel = pick_kernel(_endpoint_values_py, _endpoint_values, python, "likelihood field")
    h, w = shape
    out = np.empty((len(terms[0]), len(terms[4])), dtype=values.dtype)
    kernel(*terms, values, int(h), int(w), out)
    return out


def _bin_clusters_py(ukeys, ny, n_th, parent, label):  # type: ignore[no-untyped-def]
    """``label[u]``: the cluster of occupied bin ``u`` (``ukeys`` sorted, key ``(bx * ny + by)
    * n_th + bt``), bins joined with their 26 neighbours (theta wraps around), clusters
    numbered in the order of their first bin; ``parent``: scratch of ``len(ukeys)``."""
    n = ukeys.shape[0]
    for u in range(n):
        parent[u] = u
    for u in range(n):
        bx, rem = divmod(ukeys[u], ny * n_th)
        by, bt = divmod(rem, n_th)
        for dx in range(-1, 2):
            for dy in range(-1, 2):
                if bx + dx < 0 or by + dy < 0:
                    continue
                for dt in range(-1, 2):
                    if dx == 0 and dy == 0 and dt == 0:
                        continue
                    nk = ((bx + dx) * ny + (by + dy)) * n_th + (bt + dt) % n_th
                    lo, hi = 0, n  # binary search: the first key >= nk
                    while lo < hi:
                        mid = (lo + hi) // 2
                        if ukeys[mid] < nk:
                            lo = mid + 1
                        else:
                            hi = mid
                    v = lo
                    if v < n and ukeys[v] == nk:
                        ru, rv = u, v  # union under the smaller root, path halving
                        while parent[ru] != ru:
                            parent[ru] = parent[parent[ru]]
                            ru = parent[ru]
                        while parent[rv] != rv:
                            parent[rv] = parent[parent[rv]]
                            rv = parent[rv]
                        if ru < rv:
                            parent[rv] = ru
                        elif rv < ru:
                            parent[ru] = rv
    n_labels = 0
    for u in range(n):  # a parent is never after its child: its label is known
        if parent[u] == u:
            label[u] = n_labels
            n_labels += 1
        else:
            label[u] = label[parent[u]]


_bin_clusters = compiled(_bin_clusters_py)


def bin_clusters(
    ukeys: NDArray[np.int64], ny: int, n_th: int, python: bool = False
) -> NDArray[np.intp]:
    """:func:`_bin_clusters_py` compiled (needs numba; ``python``: the plain kernel): the
    cluster label of each occupied bin."""
    kernel = pick_kernel(_bin_clusters_py, _bin_clusters, python, "particle clusters")
    parent = np.empty(len(ukeys), dtype=np.intp)
    label = np.empty(len(ukeys), dtype=np.intp)
    kernel(ukeys, int(ny), int(n_th), parent, label)
    return label


def _first_occupied_py(occupied, x0, y0, ca, sa, t, ox, oy, res, out):  # type: ignore[no-untyped-def]
    """``out[i]``: the first ``k`` whose sample ``(x0 + ca_i t_k, y0 + sa_i t_k)`` falls in an
    occupied cell (``occupied[iy, ix]``, cells ``floor((x - ox) / res)``), -1 for none."""
    h, w = occupied.shape
    for i in range(ca.shape[0]):
        out[i] = -1
        for k in range(t.shape[0]):
            fx = np.floor((x0 + ca[i] * t[k] - ox) / res)
            fy = np.floor((y0 + sa[i] * t[k] - oy) / res)
            if 0 <= fx < w and 0 <= fy < h and occupied[int(fy), int(fx)]:
                out[i] = k
                break


_first_occupied = compiled(_first_occupied_py)


def first_occupied(
    occupied: NDArray[np.bool_],
    origin_xy: NDArray[np.float64],
    res: float,
    laser_xy: NDArray[np.float64],
    cos_sin: tuple[NDArray[np.float64], NDArray[np.float64]],
    t: NDArray[np.float64],
    python: bool = False,
) -> NDArray[np.intp]:
    """:func:`_first_occupied_py` compiled (needs numba; ``python``: the plain kernel): per
    beam (direction ``cos_sin``), the index into ``t`` of its first occupied sample, -1 for
    none."""
    kernel = pick_kernel(_first_occupied_py, _first_occupied, python, "ray casting")
    out = np.empty(len(cos_sin[0]), dtype=np.intp)
    kernel(occupied, float(laser_xy[0]), float(laser_xy[1]), cos_sin[0], cos_sin[1], t,
           float(origin_xy[0]), float(origin_xy[1]), float(res), out)  # fmt: skip
    return out


def _wall_depths_py(dist, ox, oy, res, lx, ly, c, s, cb, sb, length, out):  # type: ignore[no-untyped-def]
    """``out[i, j]``: the first sample ``t < length_j`` [m] at which the walk from particle
    ``i``'s laser ``(lx_i, ly_i)`` (heading ``c_i, s_i``) along beam ``j`` (``cb_j, sb_j`` in
    the robot frame) is in an occupied cell, ``inf`` for none; samples from ``res / 2`` on,
    each step ``max(dist - 1.5 res, res / 2)`` with ``dist`` [m] the distance field at the
    sample's cell; a sample off the grid ends the walk (:mod:`.see_through`). A cell is
    occupied where ``dist`` is 0."""
    h, w = dist.shape
    inv_res = 1.0 / res
    for i in range(c.shape[0]):
        for j in range(cb.shape[0]):
            out[i, j] = np.inf
            ca = c[i] * cb[j] - s[i] * sb[j]
            sa = s[i] * cb[j] + c[i] * sb[j]
            t = 0.5 * res
            while t < length[j]:
                fx = np.floor((lx[i] + ca * t - ox) * inv_res)
                fy = np.floor((ly[i] + sa * t - oy) * inv_res)
                if not (0 <= fx < w and 0 <= fy < h):
                    break
                d = float(dist[int(fy), int(fx)])
                if d == 0.0:  # an occupied cell: its distance to the nearest is 0
                    out[i, j] = t
                    break
                t = t + max(d - 1.5 * res, 0.5 * res)


_wall_depths = compiled(_wall_depths_py)


def wall_depths(
    dist: Float32Array,
    grid_frame: tuple[float, float, float],
    terms: tuple[NDArray[np.float64], ...],
    python: bool = False,
) -> NDArray[np.float64]:
    """:func:`_wall_depths_py` compiled (needs numba; ``python``: the plain kernel) on the
    distance field ``dist`` of a grid ``(ox, oy, res)``, ``terms`` ``(lx, ly, c, s, cb, sb,
    length)``: the ``(P, B)`` wall depths of :func:`.see_through.wall_depths`."""
    kernel = pick_kernel(_wall_depths_py, _wall_depths, python, "see-through test")
    out = np.empty((len(terms[2]), len(terms[4])), dtype=np.float64)
    kernel(dist, *(float(v) for v in grid_frame), *terms, out)
    return out
