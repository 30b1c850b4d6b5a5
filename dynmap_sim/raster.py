"""A tiny numpy rasterizer for top-down views of a world (no matplotlib state, ~ms per frame).

Shared by the env's ``render()`` and the run videos of :mod:`dynmap_sim.analysis.video`, so
it depends on numpy only: a :class:`Canvas` maps world coordinates [m] inside ``bounds`` to
the pixels of an RGB image and draws points, line segments and filled discs on it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

#: Colours of the beam / segment classes, indexed by :class:`~dynmap_sim.types.BeamClass`.
CLASS_RGB = np.array(
    [
        [120, 120, 120],  # none
        [20, 20, 20],  # wall
        [150, 90, 40],  # furniture
        [230, 140, 0],  # exhibit
        [40, 150, 60],  # door
        [210, 30, 30],  # person
        [60, 60, 200],  # robot
    ],
    dtype=np.uint8,
)


class Canvas:
    """A white RGB image of the world rectangle ``bounds = (xmin, ymin, xmax, ymax)`` [m]
    whose longer side is ``size_px`` pixels (``img``: ``(h, w, 3)`` uint8, row 0 at ``ymax``).

    Colours are a ``(3,)`` uint8 array, or one row per drawn item."""

    def __init__(self, bounds: Sequence[float], size_px: int) -> None:
        xmin, ymin, xmax, ymax = (float(b) for b in bounds)
        self.xmin, self.ymax = xmin, ymax
        self.scale = size_px / max(xmax - xmin, ymax - ymin)
        self.w = max(1, int(math.ceil((xmax - xmin) * self.scale)))
        self.h = max(1, int(math.ceil((ymax - ymin) * self.scale)))
        self.img = np.full((self.h, self.w, 3), 255, dtype=np.uint8)

    def px(self, xy: NDArray[np.float64]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Rows and columns of the pixels of points ``xy`` ``(..., 2)`` [m]."""
        c = np.floor((xy[..., 0] - self.xmin) * self.scale).astype(np.int64)
        r = np.floor((self.ymax - xy[..., 1]) * self.scale).astype(np.int64)
        return r, c

    def put(self, r: NDArray[np.int64], c: NDArray[np.int64], rgb: NDArray[np.uint8]) -> None:
        """Colour the pixels ``(r, c)`` that lie inside the image."""
        ok = (r >= 0) & (r < self.h) & (c >= 0) & (c < self.w)
        self.img[r[ok], c[ok]] = rgb if rgb.ndim == 1 else rgb[ok]

    def points(self, xy: NDArray[np.float64], rgb: NDArray[np.uint8]) -> None:
        """One pixel per point of ``xy`` ``(N, 2)`` [m]."""
        self.put(*self.px(xy), rgb)

    def lines(self, seg: NDArray[np.float64], rgb: NDArray[np.uint8]) -> None:
        """Segments ``(N, 4)`` = ``x0, y0, x1, y1`` [m], one pixel wide."""
        if seg.shape[0] == 0:
            return
        n = np.ceil(np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]) * self.scale)
        n = n.astype(int) + 2
        k = np.repeat(np.arange(seg.shape[0]), n)
        t = (np.arange(k.shape[0]) - np.repeat(np.cumsum(n) - n, n)) / np.repeat(n - 1, n)
        xy = seg[k, :2] + t[:, None] * (seg[k, 2:] - seg[k, :2])
        self.put(*self.px(xy), rgb if rgb.ndim == 1 else rgb[k])

    def discs(self, circ: NDArray[np.float64], rgb: NDArray[np.uint8]) -> None:
        """Filled discs ``(N, 3)`` = ``x, y, radius`` [m] (at least one pixel)."""
        for i in range(circ.shape[0]):
            x, y, rad = circ[i]
            rr = max(rad * self.scale, 1.0)
            r0, c0 = self.px(np.array([x, y]))
            ys, xs = np.mgrid[-int(rr) : int(rr) + 1, -int(rr) : int(rr) + 1]
            m = ys * ys + xs * xs <= rr * rr
            self.put(r0 + ys[m], c0 + xs[m], rgb if rgb.ndim == 1 else rgb[i])


def polyline(xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """The segments ``(N - 1, 4)`` joining consecutive points of ``xy`` ``(N, 2)``."""
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    return np.hstack([xy[:-1], xy[1:]])
