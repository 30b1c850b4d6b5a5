"""Compiled kernel of :mod:`.particle_filter` (which is too long to hold it): the particle
clusters of ``AMCLFilter.estimate`` (nav2's ``pf_cluster_stats``) by union-find over the
occupied KLD bins."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled


@compiled
def _bin_clusters(ukeys, ny, n_th, parent, label):  # type: ignore[no-untyped-def]
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
                    v = np.searchsorted(ukeys, nk)  # the first key >= nk
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


def bin_clusters(ukeys: NDArray[np.int64], ny: int, n_th: int) -> NDArray[np.intp]:
    """Cluster label of each occupied bin: ``ukeys`` sorted unique bin keys ``(bx * ny + by)
    * n_th + bt`` (``bx, by >= 0``, ``by < ny - 1``), a cluster the bins connected through
    their 26 neighbours (theta wraps around), numbered in the order of their first bin."""
    parent = np.empty(len(ukeys), dtype=np.intp)
    label = np.empty(len(ukeys), dtype=np.intp)
    _bin_clusters(ukeys, int(ny), int(n_th), parent, label)
    return label
