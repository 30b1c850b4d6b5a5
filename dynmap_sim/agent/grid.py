"""Occupancy grid and its likelihood field (distance to the nearest obstacle).

The grid follows ROS ``nav_msgs/OccupancyGrid`` conventions: cell ``[iy, ix]`` covers
``origin + ([ix, iy] .. [ix+1, iy+1]) * resolution_m``; values are ``-1`` unknown, ``0``
free, ``100`` occupied. The likelihood field of Thrun et al., *Probabilistic Robotics*
§6.4 (the table AMCL precomputes) is the Euclidean distance from each cell centre to the
nearest occupied cell centre (the exact transform of Felzenszwalb & Huttenlocher 2012,
:func:`_squared_distances`), clipped at ``max_dist_m``.

Grids are built either by rasterizing known wall segments (a scenario's prior) or by
tracing laser beams from known poses (free cells along each beam, an occupied cell at each
end point, combined as log-odds, Thrun et al. §9.2).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from dynmap_sim import se2
from dynmap_sim.jit import compiled
from dynmap_sim.types import LaserSpec

FloatArray = NDArray[np.float64]

UNKNOWN = -1
FREE = 0
OCCUPIED = 100

#: Stands for "no occupied cell in this column" (far beyond any grid's squared distances).
_FAR = 1e20


@compiled
def _squared_distances(occ, col, f, v, z, out):  # type: ignore[no-untyped-def]
    """``out[y, x]``: squared distance [cells²] from cell ``(y, x)`` to the nearest True cell
    of ``occ`` (at least one), by Felzenszwalb & Huttenlocher's (2012) exact transform: along
    the columns, then the lower envelope of parabolas along each row. ``col`` ``(H, W)``,
    ``f, v`` ``(W,)``, ``z`` ``(W + 1,)``: scratch."""
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


def squared_distances(occupied: NDArray[np.bool_]) -> NDArray[np.float64]:
    """``(H, W)`` squared distances [cells²] from each cell to the nearest of ``occupied``
    (at least one True): exact integers in float64."""
    h, w = occupied.shape
    out = np.empty((h, w), dtype=np.float64)
    _squared_distances(np.ascontiguousarray(occupied), np.empty((h, w)), np.empty(w),
                       np.empty(w, np.intp), np.empty(w + 1), out)  # fmt: skip
    return out


def _sample_counts(clear: FloatArray, step: float) -> NDArray[np.int64]:
    """How many samples ``i * step`` [m] (``i >= 0``) fall short of each beam's clear length
    ``clear`` [m]: ``#{i : i * step < clear}``, exactly (the float ceil may be off by one)."""
    n_b = np.maximum(np.ceil(clear / step), 0.0).astype(np.int64)
    n_b -= (n_b > 0) & ((n_b - 1) * step >= clear)
    n_b += n_b * step < clear
    return n_b


def _beam_passes(
    lp: FloatArray,
    cos_b: FloatArray,
    sin_b: FloatArray,
    n_b: NDArray[np.int64],
    step: float,
    origin: FloatArray,
    resolution_m: float,
    shape: tuple[int, int],
) -> FloatArray:
    """How many beams pass each cell of a grid of ``shape`` ``(H, W)`` at ``origin`` [m]
    (flat, ``(H * W,)``): beam ``b`` of laser pose ``lp`` ``(K, 3)`` with direction
    ``cos_b, sin_b`` ``(K, n_beams)`` is sampled every ``step`` [m] ``n_b[b]`` times, and a
    cell it passes counts once for it. Along a ray the cell indices change monotonically,
    so a beam's repeated cells are consecutive samples; the samples go in batches."""
    h, w = shape
    n_beams = cos_b.shape[1]
    lx = np.repeat(lp[:, 0], n_beams)
    ly = np.repeat(lp[:, 1], n_beams)
    cb, sb = cos_b.ravel(), sin_b.ravel()
    passes = np.zeros(h * w, dtype=np.float64)
    ends = np.cumsum(n_b)
    chunk = 1 << 17  # samples per vectorized batch
    lo = 0
    while lo < len(n_b):
        start = int(ends[lo - 1]) if lo else 0
        hi = max(int(np.searchsorted(ends, start + chunk, side="right")), lo + 1)
        cnt = n_b[lo:hi]
        beam = np.repeat(np.arange(lo, hi), cnt)
        first = np.cumsum(cnt) - cnt
        t = (np.arange(len(beam)) - np.repeat(first, cnt)) * step
        ix = np.floor((lx[beam] + cb[beam] * t - origin[0]) / resolution_m).astype(np.intp)
        iy = np.floor((ly[beam] + sb[beam] * t - origin[1]) / resolution_m).astype(np.intp)
        key = iy * w + ix
        new = t == 0.0
        new[1:] |= key[1:] != key[:-1]
        passes += np.bincount(key[new], minlength=h * w)
        lo = hi
    return passes


def _cells_of_counts(
    hits: FloatArray, passes: FloatArray, l_hit: float, l_pass: float
) -> NDArray[np.int8]:
    """Cell values (flat) from the beams ending in each cell (``hits``) and passing it
    (``passes``), combined as log-odds ``l_hit * hits + l_pass * passes``: negative free,
    else occupied where a beam ended, free where none did; unseen unknown."""
    logodds = l_hit * hits + l_pass * passes
    grid = np.full(len(hits), UNKNOWN, dtype=np.int8)
    seen = (hits + passes) > 0
    grid[seen & (logodds < 0)] = FREE
    grid[seen & (logodds >= 0) & (hits > 0)] = OCCUPIED
    grid[seen & (logodds >= 0) & (hits == 0)] = FREE
    return grid


def points_on_segments(segments: ArrayLike, spacing_m: float) -> FloatArray:
    """Points ``(M, 2)`` [m] every ``spacing_m`` or closer along the segments ``(N, 4)``
    (``x0, y0, x1, y1``), both ends included: a wall plan as points (rasterizing, ICP)."""
    return sample_segments(segments, spacing_m)[0]


def sample_segments(segments: ArrayLike, spacing_m: float) -> tuple[FloatArray, NDArray[np.intp]]:
    """:func:`points_on_segments` and, for each point, the index of its segment ``(M,)``."""
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
    if len(seg) == 0:
        return np.zeros((0, 2)), np.zeros(0, dtype=np.intp)
    length = np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1])
    n = np.maximum(np.ceil(length / spacing_m).astype(np.intp), 1) + 1
    t = np.concatenate([np.linspace(0.0, 1.0, k) for k in n])
    of = np.repeat(np.arange(len(seg)), n)
    s = seg[of]
    pts = np.column_stack([s[:, 0] + t * (s[:, 2] - s[:, 0]), s[:, 1] + t * (s[:, 3] - s[:, 1])])
    return pts, of


class OccupancyGrid:
    """A 2-D occupancy grid with a cached likelihood field.

    ``occupancy`` is ``(H, W)`` int8 (``-1``/``0``/``100``); ``origin_xy_m`` the map-frame
    corner of cell ``[0, 0]``; ``dist_m`` ``(H, W)`` float32 the distance [m] from each
    cell centre to the nearest occupied cell centre, clipped at ``max_dist_m``.
    """

    def __init__(
        self,
        occupancy: ArrayLike,
        origin_xy_m: ArrayLike,
        resolution_m: float = 0.05,
        max_dist_m: float = 2.0,
    ) -> None:
        occ = np.asarray(occupancy, dtype=np.int8)
        if occ.ndim != 2 or occ.size == 0:
            raise ValueError(f"occupancy must be a non-empty 2-D array, got shape {occ.shape}")
        if resolution_m <= 0:
            raise ValueError(f"resolution_m must be > 0, got {resolution_m}")
        self.occupancy = occ
        self.origin_xy_m = np.asarray(origin_xy_m, dtype=np.float64).reshape(2)
        self.resolution_m = float(resolution_m)
        self.max_dist_m = float(max_dist_m)
        self.dist_m = self._distance_field(self.max_dist_m)

    # -- geometry ------------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        return self.occupancy.shape  # type: ignore[return-value]

    @property
    def extent_m(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` of the grid [m]."""
        h, w = self.shape
        x0, y0 = self.origin_xy_m
        return (x0, y0, x0 + w * self.resolution_m, y0 + h * self.resolution_m)

    def cell_of(self, xy: ArrayLike) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
        """Cell indices ``(ix, iy)`` of points ``(..., 2)`` (may be out of the grid)."""
        p = np.asarray(xy, dtype=np.float64)
        ix = np.floor((p[..., 0] - self.origin_xy_m[0]) / self.resolution_m).astype(np.intp)
        iy = np.floor((p[..., 1] - self.origin_xy_m[1]) / self.resolution_m).astype(np.intp)
        return ix, iy

    def cell_centers(self, ix: ArrayLike, iy: ArrayLike) -> FloatArray:
        """Map-frame centres ``(N, 2)`` of cells ``(ix, iy)``."""
        ix = np.asarray(ix, dtype=np.float64)
        iy = np.asarray(iy, dtype=np.float64)
        return np.stack(
            [
                self.origin_xy_m[0] + (ix + 0.5) * self.resolution_m,
                self.origin_xy_m[1] + (iy + 0.5) * self.resolution_m,
            ],
            axis=-1,
        )

    def _distance_field(self, max_dist_m: float) -> NDArray[np.float32]:
        """Distance [m] from each cell centre to the nearest occupied one, clipped at
        ``max_dist_m`` (everywhere ``max_dist_m`` without an occupied cell)."""
        occ = self.occupancy == OCCUPIED
        if not occ.any():
            return np.full(self.shape, max_dist_m, dtype=np.float32)
        d = np.sqrt(squared_distances(occ)) * self.resolution_m
        return np.minimum(d, max_dist_m).astype(np.float32)

    def distance_at(self, x_m: ArrayLike, y_m: ArrayLike) -> NDArray[np.float32]:
        """Likelihood-field distance [m] at map points; ``max_dist_m`` outside the grid."""
        x = np.asarray(x_m, dtype=np.float64)
        y = np.asarray(y_m, dtype=np.float64)
        ix = np.floor((x - self.origin_xy_m[0]) / self.resolution_m).astype(np.intp)
        iy = np.floor((y - self.origin_xy_m[1]) / self.resolution_m).astype(np.intp)
        h, w = self.shape
        inside = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
        out = np.full(x.shape, self.max_dist_m, dtype=np.float32)
        out[inside] = self.dist_m[iy[inside], ix[inside]]
        return out

    def occupied_points(self) -> FloatArray:
        """Centres ``(N, 2)`` of the occupied cells [m]."""
        iy, ix = np.nonzero(self.occupancy == OCCUPIED)
        return self.cell_centers(ix, iy)

    def free_points(self) -> FloatArray:
        """Centres ``(N, 2)`` of the free cells [m] (AMCL draws random poses from these)."""
        iy, ix = np.nonzero(self.occupancy == FREE)
        return self.cell_centers(ix, iy)

    # -- construction --------------------------------------------------------------------
    @classmethod
    def _empty(
        cls, bounds: tuple[float, float, float, float], resolution_m: float, margin_m: float
    ) -> tuple[FloatArray, int, int]:
        xmin, ymin, xmax, ymax = bounds
        origin = np.array(
            [
                np.floor((xmin - margin_m) / resolution_m) * resolution_m,
                np.floor((ymin - margin_m) / resolution_m) * resolution_m,
            ]
        )
        w = int(np.ceil((xmax + margin_m - origin[0]) / resolution_m))
        h = int(np.ceil((ymax + margin_m - origin[1]) / resolution_m))
        return origin, max(h, 1), max(w, 1)

    @classmethod
    def from_segments(
        cls,
        segments: ArrayLike,
        resolution_m: float = 0.05,
        margin_m: float = 1.0,
        free_seed_xy_m: ArrayLike | None = None,
        max_dist_m: float = 2.0,
    ) -> OccupancyGrid:
        """Rasterize wall segments ``(N, 4)`` (``x0, y0, x1, y1`` [m]) into a grid.

        Cells the segments pass through are occupied. Given ``free_seed_xy_m`` (e.g. the
        robot's start), the non-occupied cells 4-connected to it are free and the rest
        unknown (the inside of the building, not the outside); otherwise every other cell
        is free.
        """
        segs = np.asarray(segments, dtype=np.float64).reshape(-1, 4)
        if len(segs) == 0:
            raise ValueError("from_segments needs at least one segment")
        pts_all = np.concatenate([segs[:, :2], segs[:, 2:]])
        bounds = (*pts_all.min(axis=0), *pts_all.max(axis=0))
        origin, h, w = cls._empty(bounds, resolution_m, margin_m)
        xy = points_on_segments(segs, 0.25 * resolution_m)
        ix = np.floor((xy[:, 0] - origin[0]) / resolution_m).astype(np.intp)
        iy = np.floor((xy[:, 1] - origin[1]) / resolution_m).astype(np.intp)
        occ = np.zeros((h, w), dtype=bool)
        occ[iy, ix] = True
        grid = np.full((h, w), FREE, dtype=np.int8)
        if free_seed_xy_m is not None:
            seed = np.asarray(free_seed_xy_m, dtype=np.float64)
            sx = int(np.floor((seed[0] - origin[0]) / resolution_m))
            sy = int(np.floor((seed[1] - origin[1]) / resolution_m))
            labels, _ = ndimage.label(~occ)
            if 0 <= sx < w and 0 <= sy < h and labels[sy, sx] > 0:
                grid[:] = UNKNOWN
                grid[labels == labels[sy, sx]] = FREE
        grid[occ] = OCCUPIED
        return cls(grid, origin, resolution_m, max_dist_m)

    @classmethod
    def from_scans(
        cls,
        poses: ArrayLike,
        ranges_m: ArrayLike,
        laser: LaserSpec,
        resolution_m: float = 0.05,
        margin_m: float = 1.0,
        no_return_free_m: float = 4.0,
        l_hit: float = 0.9,
        l_pass: float = -0.4,
        max_dist_m: float = 2.0,
        max_hit_range_m: float | None = None,
    ) -> OccupancyGrid:
        """Trace scans ``ranges_m`` ``(K, n_beams)`` taken at robot ``poses`` ``(K, 3)``.

        Each finite reading marks its end cell with log-odds ``l_hit`` and the cells before
        it with ``l_pass`` (each cell counted once per beam); a ``+inf`` (no return) clears
        ``no_return_free_m`` of free space.
        Cells with positive total log-odds are occupied, negative free, unseen unknown.
        Readings beyond ``max_hit_range_m`` (default: the sensor's range) only clear free
        space up to that range: far readings are noisy (URG-04LX: 1 % of the range).
        """
        hit_max = laser.range_max_m if max_hit_range_m is None else float(max_hit_range_m)
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
        rng_all = np.asarray(ranges_m, dtype=np.float64).reshape(len(poses), -1)
        angles = laser.angles()
        mount = np.asarray(laser.mount_pose, dtype=np.float64)
        lp = se2.compose(poses, np.broadcast_to(mount, poses.shape))  # laser poses (K, 3)
        th = lp[:, 2:3] + angles[None, :]  # (K, n_beams) beam directions
        cos_b, sin_b = np.cos(th), np.sin(th)
        with np.errstate(invalid="ignore"):
            valid = np.isfinite(rng_all) & (rng_all >= laser.range_min_m)
            valid &= rng_all < laser.range_max_m
            hit = valid & (rng_all < hit_max)
        ex = (lp[:, 0:1] + cos_b * rng_all)[hit]  # end points of the hits
        ey = (lp[:, 1:2] + sin_b * rng_all)[hit]
        reach = max(no_return_free_m, 0.0)
        far = valid & ~hit
        # the grid holds every cell a beam clears: a far reading clears up to the hit range
        extent = max(reach, hit_max) if np.any(far) else reach
        bounds = (
            min(lp[:, 0].min(), ex.min(initial=np.inf)) - extent,
            min(lp[:, 1].min(), ey.min(initial=np.inf)) - extent,
            max(lp[:, 0].max(), ex.max(initial=-np.inf)) + extent,
            max(lp[:, 1].max(), ey.max(initial=-np.inf)) + extent,
        )
        origin, h, w = cls._empty(bounds, resolution_m, margin_m)
        # each beam clears free space up to its hit (less a cell), to the hit range for a far
        # reading, or ``reach`` for no return
        clear = np.where(
            hit,
            rng_all - resolution_m,
            np.where(far, hit_max, np.where(rng_all == np.inf, reach, 0.0)),
        ).ravel()
        step = 0.5 * resolution_m
        n_b = _sample_counts(clear, step)
        passes = _beam_passes(lp, cos_b, sin_b, n_b, step, origin, resolution_m, (h, w))
        ix = np.floor((ex - origin[0]) / resolution_m).astype(np.intp)
        iy = np.floor((ey - origin[1]) / resolution_m).astype(np.intp)
        hits = np.bincount(iy * w + ix, minlength=h * w).astype(np.float64)
        grid = _cells_of_counts(hits, passes, l_hit, l_pass)
        return cls(grid.reshape(h, w), origin, resolution_m, max_dist_m)
