"""Broad phase: a uniform grid listing, per cell, the segments a person there may feel.

A person is repelled by the closest point of every segment within ``REACH_M`` (Helbing &
Molnár 1995, eq. 5). Rather than testing all segments, each step gathers, per person, the
segments listed in the grid cell (``CELL_M``) the person stands in: every segment that comes
within ``REACH_M`` of the cell. Rows are padded with a far-away dummy segment so that the
candidates of ``P`` people form one dense ``(P, K)`` block.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled
from dynmap_sim.world.people.params import CELL_M, REACH_M
from dynmap_sim.world.polygons import FloatArray

#: Cells per metre.
_INV_CELL = 1.0 / CELL_M


class SegmentGrid:
    """Uniform grid (cell ``CELL_M``) over ``segments`` ``(N, 4)``, listing per cell the
    segments within ``REACH_M`` of it, and the segments as complex rows for the narrow phase.
    """

    def __init__(self, segments: FloatArray) -> None:
        s = segments
        far = np.array([[1e6, 1e6, 1e6 + 1.0, 1e6]])
        ext = np.concatenate([s, far])
        d = ext[:, 2:4] - ext[:, 0:2]
        inv = 1.0 / np.maximum(np.sum(d * d, axis=1), 1e-18)
        #: per segment (and the far dummy last), complex: p0, conj(d), 1 / |d|^2
        self.segrows = np.column_stack(
            [ext[:, 0] + 1j * ext[:, 1], d[:, 0] - 1j * d[:, 1], inv + 0j]
        )
        if len(s) == 0:
            self.origin = np.zeros(2)
            self.origin_c = 0j
            self.shape = (1, 1)
            self.cells = np.zeros((1, 1), dtype=np.int64)
            return
        lo = np.minimum(s[:, :2], s[:, 2:]).min(axis=0) - REACH_M
        hi = np.maximum(s[:, :2], s[:, 2:]).max(axis=0) + REACH_M
        nx, ny = (np.ceil((hi - lo) / CELL_M).astype(int) + 1).tolist()
        self.origin, self.shape = lo, (nx, ny)
        self.origin_c = complex(lo[0], lo[1])
        #: ``(nx * ny, K)``: the segments near each cell, padded with the far dummy
        self.cells = _cell_lists(s, lo, nx, ny)

    def all_rows(self, n: int) -> NDArray[np.complex128]:
        """Every segment (and the far dummy) as candidate rows ``(n, N + 1, 3)`` (no grid)."""
        return np.ascontiguousarray(np.broadcast_to(self.segrows, (n, *self.segrows.shape)))

    def rows(self, z: NDArray[np.complex128]) -> NDArray[np.complex128]:
        """Candidate segments near each point ``z`` as ``(P, K, 3)`` complex rows."""
        rows = np.empty((len(z), self.cells.shape[1], 3), dtype=np.complex128)
        nx, ny = self.shape
        _rows(np.ascontiguousarray(z), self.origin_c, nx, ny, self.cells, self.segrows, rows)
        return rows


@compiled
def _rows(z, origin, nx, ny, cells, segrows, rows):  # type: ignore[no-untyped-def]
    """The rows of the segments listed in each point's cell (its cell index truncated and
    clipped to the grid) into ``rows``."""
    for i in range(z.shape[0]):
        ci = min(max(int((z[i].real - origin.real) * _INV_CELL), 0), nx - 1)
        cj = min(max(int((z[i].imag - origin.imag) * _INV_CELL), 0), ny - 1)
        cell = ci * ny + cj
        for j in range(cells.shape[1]):
            seg = cells[cell, j]
            for c in range(3):
                rows[i, j, c] = segrows[seg, c]


def _cell_lists(s: FloatArray, lo: FloatArray, nx: int, ny: int) -> NDArray[np.int64]:
    """Per cell of the ``nx`` x ``ny`` grid at ``lo``, the segments whose ``REACH_M``-grown
    bounding box overlaps it, padded with the index ``len(s)`` (the far dummy)."""
    smin = np.minimum(s[:, :2], s[:, 2:]) - REACH_M - lo
    smax = np.maximum(s[:, :2], s[:, 2:]) + REACH_M - lo
    i0 = np.clip(np.floor(smin / CELL_M).astype(np.int64), 0, [nx - 1, ny - 1])
    i1 = np.clip(np.floor(smax / CELL_M).astype(np.int64), 0, [nx - 1, ny - 1])
    ncx = i1[:, 0] - i0[:, 0] + 1
    ncy = i1[:, 1] - i0[:, 1] + 1
    npairs = ncx * ncy
    seg = np.repeat(np.arange(len(s)), npairs)
    j = np.arange(int(npairs.sum())) - np.repeat(np.cumsum(npairs) - npairs, npairs)
    cell = (i0[seg, 0] + j // ncy[seg]) * ny + (i0[seg, 1] + j % ncy[seg])
    order = np.argsort(cell, kind="stable")
    cell_sorted = cell[order]
    counts = np.bincount(cell, minlength=nx * ny)
    first = np.cumsum(counts) - counts
    rank = np.arange(len(cell)) - first[cell_sorted]
    cells = np.full((nx * ny, max(1, int(counts.max()))), len(s), dtype=np.int64)
    cells[cell_sorted, rank] = seg[order]
    return cells
