"""Raw laser scans made ready for scan matching: points, mixed pixels, moving obstacles.

The first run's SLAM (:mod:`.keyframe_slam`, :mod:`.loop_closure`), the dynamic-map localizer
(B&D §4.3: "scan matching ... as described in [4]") and the benchmarks turn a scan's ranges
into points in the robot frame (:func:`scan_points_base`), leave out readings that lie on no
surface (:func:`range_discontinuities`: mixed pixels at depth edges) or in space an earlier
scan saw free (:func:`free_space_violations`: walking people), weight points by the range
noise (:func:`range_weights`) and thin them to one per cell (:func:`voxel_downsample`).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim import se2
from dynmap_sim.jit import compiled
from dynmap_sim.types import LaserSpec

FloatArray = NDArray[np.float64]


class BeamDirections:
    """Cosines and sines of a laser's beam angles, computed once for many scans."""

    def __init__(self, laser: LaserSpec) -> None:
        angles = laser.angles()
        self.laser = laser
        self.cos = np.cos(angles)
        self.sin = np.sin(angles)

    def mount(self) -> FloatArray:
        """``(x, y, cos, sin)`` of the laser's mount pose, as :func:`se2.transform_points`
        computes them (cached; rebuilt for pickles made before the cache)."""
        m = self.__dict__.get("_mount")
        if m is None:
            pose = np.asarray(self.laser.mount_pose, dtype=np.float64)
            m = self._mount = np.array([pose[0], pose[1], np.cos(pose[2]), np.sin(pose[2])])
        return m


@compiled
def _scan_points(
    ranges_m: FloatArray,
    cos: FloatArray,
    sin: FloatArray,
    range_min_m: float,
    range_max_m: float,
    mount: FloatArray,
    out: FloatArray,
) -> int:
    """Points ``out[:k]`` (robot frame) of the ``k`` valid readings (finite, in
    ``[range_min_m, range_max_m)``), in beam order; ``mount`` is ``(x, y, cos, sin)`` of
    the laser's mount pose. Returns ``k``."""
    mx, my, mc, ms = mount[0], mount[1], mount[2], mount[3]
    k = 0
    for i in range(ranges_m.shape[0]):
        r = ranges_m[i]
        if math.isfinite(r) and r >= range_min_m and r < range_max_m:
            x = r * cos[i]
            y = r * sin[i]
            out[k, 0] = mx + mc * x - ms * y
            out[k, 1] = my + ms * x + mc * y
            k += 1
    return k


def scan_points_base(
    laser: LaserSpec, ranges_m: ArrayLike, beams: BeamDirections | None = None
) -> FloatArray:
    """Valid readings of a scan as points ``(N, 2)`` in the robot (``base_link``) frame.

    ``beams`` (the laser's :class:`BeamDirections`, optional) saves recomputing the beam
    directions for every scan; the points are the same.
    """
    r = np.ascontiguousarray(ranges_m, dtype=np.float64)
    if beams is None or not (beams.laser is laser or beams.laser == laser):
        beams = BeamDirections(laser)
    out = np.empty((len(r), 2))
    k = _scan_points(r, beams.cos, beams.sin, float(laser.range_min_m), float(laser.range_max_m),
                     beams.mount(), out)  # fmt: skip
    return out[:k]


def range_discontinuities(
    ranges_m: ArrayLike, jump_m: float = 0.1, jump_rel: float = 0.03, isolated_only: bool = False
) -> NDArray[np.bool_]:
    """Beams whose range jumps from a neighbour's by more than ``jump_m + jump_rel * r``.

    At a depth edge the laser spot straddles two surfaces and may read a range in between
    (a *mixed pixel*, cf. the lidar model's ``p_mixed``); such points lie on no surface and
    pull ICP. Dropping every beam next to a jump removes them (and the edge beams proper,
    a small loss); ``isolated_only`` drops only beams that jump from *both* neighbours
    (isolated points: most mixed pixels and spurious short returns). Non-finite readings
    count as jumps. Returns ``(n_beams,)``.
    """
    r = np.asarray(ranges_m, dtype=np.float64)
    fin = np.where(np.isfinite(r), r, 1e9)
    gap = np.abs(np.diff(fin)) > jump_m + jump_rel * np.minimum(fin[1:], fin[:-1])
    left = np.concatenate([[False], gap])  # a jump to the previous beam
    right = np.concatenate([gap, [False]])
    return (left & right) if isolated_only else (left | right)


def free_space_violations(
    laser: LaserSpec,
    ranges_m: NDArray[np.float32],
    pose: FloatArray,
    ref_ranges_m: NDArray[np.float32],
    ref_pose: FloatArray,
    gate_m: float = 0.15,
    gate_rel: float = 0.05,
) -> NDArray[np.bool_]:
    """Readings of a scan that lie in space an earlier scan saw free: moving obstacles.

    The end point of each valid reading (scan at robot ``pose``) is projected into the
    earlier scan (at ``ref_pose``); if the earlier beams around that direction (the beam and
    its two neighbours, to be safe at edges) all reached farther than the point by more than
    ``gate_m + gate_rel * range``, or returned nothing, the point sits in space that was
    free a moment ago -- a person's legs, not the static world (the free-space consistency
    test behind dynamic-object filtering, e.g. Hähnel et al. 2003). Returns ``(n_beams,)``.
    """
    r = np.asarray(ranges_m, dtype=np.float64)
    ok = np.isfinite(r) & (r >= laser.range_min_m) & (r < laser.range_max_m)
    out = np.zeros(len(r), dtype=bool)
    if not ok.any():
        return out
    mount = np.asarray(laser.mount_pose, dtype=np.float64)
    lp = se2.compose(pose, mount)
    ref_lp = se2.compose(ref_pose, mount)
    ang = laser.angles()
    th = lp[2] + ang[ok]
    pts = lp[:2] + r[ok, None] * np.stack([np.cos(th), np.sin(th)], axis=1)
    rel = se2.transform_points(se2.inverse(ref_lp), pts)
    rho = np.hypot(rel[:, 0], rel[:, 1])
    b = np.rint(
        (np.arctan2(rel[:, 1], rel[:, 0]) - laser.angle_min_rad) / laser.angle_increment_rad
    )
    b = b.astype(np.intp)
    inside = (b >= 1) & (b < laser.n_beams - 1)
    ref = np.asarray(ref_ranges_m, dtype=np.float64)
    ref = np.where(np.isnan(ref) | (ref < laser.range_min_m), 0.0, ref)  # unknown: not free
    ref = np.where(ref >= laser.range_max_m, np.inf, ref)
    bc = np.clip(b, 1, laser.n_beams - 2)
    reach = np.minimum(np.minimum(ref[bc - 1], ref[bc]), ref[bc + 1])
    free = inside & (reach > rho + gate_m + gate_rel * rho) & (rho < laser.range_max_m - 0.5)
    out[np.nonzero(ok)[0][free]] = True
    return out


def range_weights(points_base: FloatArray, rel_noise: float = 0.01, min_sigma_m: float = 0.01):
    """Relative inverse variances ``(sigma_min / sigma(r))^2`` of points for ICP, with the
    range noise ``sigma(r) = max(min_sigma_m, rel_noise * r)`` (URG-04LX datasheet)."""
    r = np.hypot(points_base[:, 0], points_base[:, 1])
    return (min_sigma_m / np.maximum(min_sigma_m, rel_noise * r)) ** 2


#: Most cells of the bounding box for which :func:`_first_per_cell` marks the seen cells in
#: a dense table (beyond: ``4 * N`` more), instead of sorting the keys.
_DENSE_CELLS = 1 << 18
#: Cell indices up to this size keep ``kx * 1,000,003 + ky`` clear of int64 overflow.
_SAFE_INDEX = 1 << 40
#: The key's multiplier: cells whose y indices differ by less than this have distinct keys.
_KEY_STRIDE = 1_000_003


@compiled
def _first_per_cell(px: FloatArray, py: FloatArray, cell_m: float, keep: NDArray[np.bool_]):
    """``keep[i]``: point ``i`` is the first (lowest index) of its cell key ``kx * 1,000,003
    + ky`` (``keep`` all False on entry). A small bounding box of cells is marked in a dense
    table, a large one by a stable sort of the keys."""
    m = px.shape[0]
    kxs = np.empty(m, dtype=np.int64)
    kys = np.empty(m, dtype=np.int64)
    for i in range(m):
        kxs[i] = np.int64(math.floor(px[i] / cell_m))
        kys[i] = np.int64(math.floor(py[i] / cell_m))
    x0, x1, y0, y1 = kxs.min(), kxs.max(), kys.min(), kys.max()
    small = max(-x0, x1, -y0, y1) < _SAFE_INDEX
    if small and y1 - y0 < _KEY_STRIDE and (x1 - x0 + 1) * (y1 - y0 + 1) <= 4 * m + _DENSE_CELLS:
        ny = y1 - y0 + 1
        seen = np.zeros((x1 - x0 + 1) * ny, dtype=np.bool_)
        for i in range(m):
            c = (kxs[i] - x0) * ny + (kys[i] - y0)
            if not seen[c]:
                seen[c] = True
                keep[i] = True
        return
    key = kxs * _KEY_STRIDE + kys
    order = np.argsort(key, kind="mergesort")
    for j in range(m):
        if j == 0 or key[order[j]] != key[order[j - 1]]:
            keep[order[j]] = True


def first_per_cell(points: FloatArray, cell_m: float) -> NDArray[np.intp]:
    """Increasing indices of the first point of each ``cell_m`` square cell of ``points``
    ``(N, 2)`` (finite)."""
    keep = np.zeros(len(points), dtype=bool)
    if len(points):
        _first_per_cell(
            np.ascontiguousarray(points[:, 0], dtype=np.float64),
            np.ascontiguousarray(points[:, 1], dtype=np.float64),
            float(cell_m),
            keep,
        )
    return np.flatnonzero(keep)


def voxel_downsample(points: FloatArray, voxel_m: float, mean: bool = False) -> FloatArray:
    """One point per ``voxel_m`` square cell: the first one (:func:`first_per_cell`), or
    (``mean``) the centroid."""
    if len(points) == 0:
        return points
    if not mean:
        return points[first_per_cell(points, voxel_m)]
    key = np.floor(points / voxel_m).astype(np.int64)
    _, inv = np.unique(key[:, 0] * _KEY_STRIDE + key[:, 1], return_inverse=True)
    inv = inv.reshape(-1)
    cnt = np.bincount(inv)
    cx = np.bincount(inv, weights=points[:, 0]) / cnt
    cy = np.bincount(inv, weights=points[:, 1]) / cnt
    return np.column_stack([cx, cy])
