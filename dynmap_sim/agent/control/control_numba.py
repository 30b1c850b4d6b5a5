"""Optional numba kernels of the controllers' per-scan work (extra ``fast``).

* :func:`probe_offsets`: :class:`~.corridor_follower.CorridorFollower`'s lateral-offset probe
  (H&W §6.3): every candidate offset's shifted path ahead and its way to the shifted carrot
  looked up in the clearance grid, the free ones scored; one loop instead of ~40 small numpy
  operations on ``(offsets x samples)`` arrays.
* :func:`monitor_action`: :class:`~.collision_monitor.CollisionMonitor`'s zone check of one
  scan.

The arithmetic is the numpy code's, operation for operation (the same adds, products,
``rint`` and clips; the beams' trigonometry stays numpy's), so the results are identical.
Each kernel is plain Python (what the tests run against the numpy code), compiled with
:func:`dynmap_sim.jit.compiled` when numba is installed.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled
from dynmap_sim.jit import numba_available as numba_available  # re-exported

FloatArray = NDArray[np.float64]

#: :func:`monitor_action`'s codes, least to most restrictive (the monitor's action names)
PASS_CODE, SLOWDOWN_CODE, STOP_CODE, FOOTPRINT_STOP_CODE = 0, 1, 2, 3


def _probe_offsets_py(  # type: ignore[no-untyped-def]
    path,
    cum,
    tangent,
    normal,
    seg_hw,
    seg,
    s_robot,
    steps_m,
    unit_offsets,
    carrot_x,
    carrot_y,
    s_carrot,
    x_m,
    y_m,
    way_fractions,
    clear,
    origin_x_m,
    origin_y_m,
    res_m,
    min_clearance_m,
    speed_probe_m,
    clearance_enough_m,
    offset_cost_per_m,
    switch_cost_per_m,
    offset_m,
    offsets_out,
    clear_near_out,
):
    """The follower's offset choice (:meth:`.CorridorFollower._choose_offset`): fills the
    candidate offsets and their clearance within ``speed_probe_m``; returns the best free
    offset's index (-1: none free) and the clearance at the robot."""
    n_off = unit_offsets.shape[0]
    n_s = steps_m.shape[0]
    n_seg = seg_hw.shape[0]
    end_m = cum[cum.shape[0] - 1]
    hw_seg = seg_hw[seg]
    for o in range(n_off):
        offsets_out[o] = unit_offsets[o] * hw_seg
    h, w = clear.shape
    # clearance_at (nearest cell, clipped to the grid) of the robot's position
    row = min(max(np.int64(np.rint((y_m - origin_y_m) / res_m)), 0), h - 1)
    col = min(max(np.int64(np.rint((x_m - origin_x_m) / res_m)), 0), w - 1)
    here = clear[row, col]
    need_way = min(min_clearance_m, here)
    min_all = np.full(n_off, math.inf)
    free = np.ones(n_off, np.bool_)
    for o in range(n_off):
        clear_near_out[o] = math.inf
    # the shifted path ahead
    idx = 0  # searchsorted(cum, s, "right"), s non-decreasing
    for m in range(n_s):
        s = min(s_robot + steps_m[m], end_m)
        while idx < cum.shape[0] and cum[idx] <= s:
            idx += 1
        k = min(max(idx - 1, 0), n_seg - 1)
        u = s - cum[k]
        bx = path[k, 0] + u * tangent[k, 0]
        by = path[k, 1] + u * tangent[k, 1]
        nx, ny = normal[k, 0], normal[k, 1]
        hw = min(seg_hw[k], max(end_m - s, 0.0))
        near = s - s_robot <= speed_probe_m
        for o in range(n_off):
            d = min(max(offsets_out[o], -hw), hw)
            row = min(max(np.int64(np.rint((by + d * ny - origin_y_m) / res_m)), 0), h - 1)
            col = min(max(np.int64(np.rint((bx + d * nx - origin_x_m) / res_m)), 0), w - 1)
            c = clear[row, col]
            if c < min_all[o]:
                min_all[o] = c
            if not c >= min_clearance_m:
                free[o] = False
            if near and c < clear_near_out[o]:
                clear_near_out[o] = c
    # the way there: robot -> shifted carrot
    hw_c = min(seg_hw[seg], max(end_m - s_carrot, 0.0))
    nx, ny = normal[seg, 0], normal[seg, 1]
    for o in range(n_off):
        d = min(max(offsets_out[o], -hw_c), hw_c)
        tx = carrot_x + d * nx
        ty = carrot_y + d * ny
        min_way = math.inf
        for t in range(way_fractions.shape[0]):
            f = way_fractions[t]
            py = y_m + f * (ty - y_m)
            px = x_m + f * (tx - x_m)
            row = min(max(np.int64(np.rint((py - origin_y_m) / res_m)), 0), h - 1)
            col = min(max(np.int64(np.rint((px - origin_x_m) / res_m)), 0), w - 1)
            c = clear[row, col]
            if c < min_way:
                min_way = c
            if not c >= need_way:
                free[o] = False
        if here >= min_clearance_m and min_way < clear_near_out[o]:
            clear_near_out[o] = min_way
    best = -1
    best_score = -math.inf
    for o in range(n_off):
        if not free[o]:
            continue
        score = (
            min(min_all[o], clearance_enough_m)
            - offset_cost_per_m * abs(offsets_out[o])
            - switch_cost_per_m * abs(offsets_out[o] - offset_m)
        )
        if best < 0 or score > best_score:
            best, best_score = o, score
    return best, here


def _monitor_action_py(  # type: ignore[no-untyped-def]
    ranges_m,
    cos_a,
    sin_a,
    mount_x_m,
    mount_y_m,
    range_min_m,
    v_mps,
    footprint_r_m,
    stop_x_max_m,
    stop_half_width_m,
    slow_x_max_m,
    slow_half_width_m,
    min_points,
):
    """:meth:`.CollisionMonitor.check` on the scan's ranges: the action's code."""
    sign = math.copysign(1.0, v_mps)
    n_foot = 0
    n_stop = 0
    n_slow = 0
    for b in range(ranges_m.shape[0]):
        r = ranges_m[b]
        if r == -math.inf:
            r = range_min_m
        if not math.isfinite(r):
            continue
        x = mount_x_m + r * cos_a[b]
        y = mount_y_m + r * sin_a[b]
        if np.hypot(x, y) <= footprint_r_m:
            n_foot += 1
        ax = x * sign
        ay = abs(y)
        if ax >= 0.0 and ax <= stop_x_max_m and ay <= stop_half_width_m:
            n_stop += 1
        if ax >= 0.0 and ax <= slow_x_max_m and ay <= slow_half_width_m:
            n_slow += 1
    if n_foot >= min_points:
        return FOOTPRINT_STOP_CODE
    if v_mps == 0.0:
        return PASS_CODE
    if n_stop >= min_points:
        return STOP_CODE
    if n_slow >= min_points:
        return SLOWDOWN_CODE
    return PASS_CODE


_probe_offsets_nb = compiled(_probe_offsets_py)
_monitor_action_nb = compiled(_monitor_action_py)


def probe_offsets(*args: object, python: bool = False) -> tuple[int, float]:
    """:func:`_probe_offsets_py` compiled (its arguments; ``python``: the uncompiled one)."""
    fn = _probe_offsets_py if python or _probe_offsets_nb is None else _probe_offsets_nb
    best, here = fn(*args)
    return int(best), float(here)


def monitor_action(*args: object, python: bool = False) -> int:
    """:func:`_monitor_action_py` compiled (its arguments; ``python``: the uncompiled one)."""
    fn = _monitor_action_py if python or _monitor_action_nb is None else _monitor_action_nb
    return int(fn(*args))
