"""Optional numba kernels of :func:`.object_tracker.segment_scan` (extra ``fast``).

The segmentation's arithmetic after the points are in the laser frame, one point and one
segment at a time instead of some thirty numpy calls on arrays of a few hundred points:

* :func:`segment_sums`: Borges & Aldon's breakpoints, the segments, their centroids and
  second moments (the sums that ``np.add.reduceat`` makes, in its order: a segment's first
  value plus numpy's pairwise sum of the rest, :func:`_pairwise_sum_py`);
* :func:`segment_boxes`: each point's coordinates along and across its segment's principal
  axis, the segments' extents, oriented boxes and the sliding-wall trap.

* :func:`track`: one scan of :class:`.object_tracker.ObjectTracker` (the Kalman prediction,
  the mutual nearest-neighbour association, the update and the speed classification) over
  the tracks in place, instead of some forty numpy calls on arrays of a few dozen tracks.

The arithmetic is the numpy code's, operation for operation, so the results are identical
(``np.hypot`` is the C library's in numba as in numpy; Python's ``math.hypot`` is not);
the transcendental functions (``cos``, ``sin``, ``hypot``, ``arctan2``) stay in numpy, whose
results the kernels take. The tests check the plain-Python kernels (what numba compiles) and
the compiled ones against the numpy code.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, pick_kernel
from dynmap_sim.jit import numba_available as numba_available  # re-exported

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

#: numpy's pairwise summation: up to this many values in one block of 8 accumulators.
PW_BLOCKSIZE = 128


def _pairwise_sum_py(a, lo, n):  # type: ignore[no-untyped-def]
    """``a[lo:lo + n]`` summed as numpy's ``pairwise_sum`` does (``loops_utils.h``): fewer
    than 8 values in order, up to :data:`PW_BLOCKSIZE` in 8 interleaved partial sums, more
    split in two halves (a multiple of 8 first)."""
    if n < 8:
        res = -0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    if n <= PW_BLOCKSIZE:
        r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
        r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
        i = 8
        top = n - n % 8
        while i < top:
            r0 += a[lo + i]
            r1 += a[lo + i + 1]
            r2 += a[lo + i + 2]
            r3 += a[lo + i + 3]
            r4 += a[lo + i + 4]
            r5 += a[lo + i + 5]
            r6 += a[lo + i + 6]
            r7 += a[lo + i + 7]
            i += 8
        res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
        while i < n:
            res += a[lo + i]
            i += 1
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return _pairwise_sum(a, lo, n2) + _pairwise_sum(a, lo + n2, n - n2)


def _reduceat_py(a, starts, n_total, out):  # type: ignore[no-untyped-def]
    """``out[k] = np.add.reduceat(a, starts)[k]``: the segment's first value plus the
    pairwise sum of the rest (``starts`` increasing, the last segment ends at ``n_total``)."""
    for k in range(starts.shape[0]):
        s = starts[k]
        e = starts[k + 1] if k + 1 < starts.shape[0] else n_total
        out[k] = a[s] if e - s == 1 else a[s] + _pairwise_sum(a, s + 1, e - s - 1)


def _segment_sums_py(  # type: ignore[no-untyped-def]
    x, y, dist, sin_da, sin_lam_da, r, idx, sigma_r_m, max_gap_beams, seg, starts, scratch
):
    """Breakpoints between points ``j`` and ``j + 1`` where ``dist[j]`` exceeds
    ``r[j] sin_da[j] / max(sin_lam_da[j], 1e-6) + 3 max(sigma_r_m, 0.01 r[j])`` or more than
    ``max_gap_beams`` beams are missing; fills ``seg`` (each point's segment) and ``starts``
    and returns the number of segments ``m``, the centroids ``mx, my`` and the sums
    ``cxx, cxy, cyy`` of the centred points' products (arrays of length ``m``), and the
    centred points ``dx, dy``. ``scratch``: ``len(x)`` floats."""
    n = x.shape[0]
    m = 1
    starts[0] = 0
    seg[0] = 0
    for j in range(n - 1):
        d_max = r[j] * sin_da[j] / max(sin_lam_da[j], 1e-6)
        d_max = d_max + 3.0 * max(sigma_r_m, 0.01 * r[j])
        if dist[j] > d_max or idx[j + 1] - idx[j] > 1 + max_gap_beams:
            starts[m] = j + 1
            m += 1
        seg[j + 1] = m - 1
    st = starts[:m]
    counts = np.empty(m, dtype=np.intp)
    for k in range(m):
        counts[k] = (st[k + 1] if k + 1 < m else n) - st[k]
    mx = np.empty(m)
    my = np.empty(m)
    _reduceat(x, st, n, mx)
    _reduceat(y, st, n, my)
    for k in range(m):
        mx[k] = mx[k] / counts[k]
        my[k] = my[k] / counts[k]
    dx = np.empty(n)
    dy = np.empty(n)
    for j in range(n):
        dx[j] = x[j] - mx[seg[j]]
        dy[j] = y[j] - my[seg[j]]
    cxx = np.empty(m)
    cxy = np.empty(m)
    cyy = np.empty(m)
    for j in range(n):
        scratch[j] = dx[j] * dx[j]
    _reduceat(scratch, st, n, cxx)
    for j in range(n):
        scratch[j] = dx[j] * dy[j]
    _reduceat(scratch, st, n, cxy)
    for j in range(n):
        scratch[j] = dy[j] * dy[j]
    _reduceat(scratch, st, n, cyy)
    return m, counts, mx, my, cxx, cxy, cyy, dx, dy


def _segment_boxes_py(  # type: ignore[no-untyped-def]
    dx, dy, seg, starts, counts, mx, my, cphi, sphi, r, min_points, max_dynamic_length_m,
    occlusion_never_dynamic, center, length, width, never, box_of_seg,
):  # fmt: skip
    """Each segment's extent along (``u``) and across (``v``) its axis ``(cphi, sphi)``, its
    box centre, length and width, ``never`` (the sliding-wall trap: long, at either end of
    the scan, or, with ``occlusion_never_dynamic``, an end hidden behind a nearer return of
    the neighbouring segment) and ``box_of_seg`` (the box index of a kept segment of at
    least ``min_points`` points, -1 otherwise); returns the number of boxes."""
    m = starts.shape[0]
    n = dx.shape[0]
    umin = np.full(m, np.inf)
    umax = np.full(m, -np.inf)
    vmin = np.full(m, np.inf)
    vmax = np.full(m, -np.inf)
    for j in range(n):
        k = seg[j]
        c = cphi[k]
        s = sphi[k]
        u = dx[j] * c + dy[j] * s
        v = -dx[j] * s + dy[j] * c
        # np.minimum's and np.maximum's choice (the new value unless the kept one is
        # strictly smaller / larger): the same zero's sign as numpy's
        umin[k] = umin[k] if umin[k] < u else u
        umax[k] = umax[k] if umax[k] > u else u
        vmin[k] = vmin[k] if vmin[k] < v else v
        vmax[k] = vmax[k] if vmax[k] > v else v
    n_box = 0
    for k in range(m):
        uc = 0.5 * (umin[k] + umax[k])
        vc = 0.5 * (vmin[k] + vmax[k])
        center[k, 0] = mx[k] + uc * cphi[k] - vc * sphi[k]
        center[k, 1] = my[k] + uc * sphi[k] + vc * cphi[k]
        length[k] = umax[k] - umin[k]
        width[k] = vmax[k] - vmin[k]
        never[k] = length[k] > max_dynamic_length_m or k == 0 or k == m - 1
        if occlusion_never_dynamic and m > 1:
            first = r[starts[k]]
            last = r[(starts[k + 1] if k + 1 < m else n) - 1]
            if k > 0 and r[starts[k] - 1] < first:  # the left neighbour's last return
                never[k] = True
            if k + 1 < m and r[starts[k + 1]] < last:  # the right neighbour's first return
                never[k] = True
        if counts[k] >= min_points:
            box_of_seg[k] = n_box
            n_box += 1
        else:
            box_of_seg[k] = -1
    return n_box


def _argmin_py(d, n):  # type: ignore[no-untyped-def]
    """``np.argmin`` of the first ``n`` values of ``d`` (the first minimum; the first NaN)."""
    k = 0
    m = d[0]
    for i in range(1, n):
        if m != m:  # NaN: numpy's argmin stops at the first one
            break
        if d[i] < m or d[i] != d[i]:
            m = d[i]
            k = i
    return k


def _track_py(  # type: ignore[no-untyped-def]
    x, P, hits, misses, fast, slow, dynamic, z, never, dt, q, r2, gate_m, v_thres,
    confirm_steps, match_box, cls, speed, dist, col,
):  # fmt: skip
    """One scan of :meth:`.object_tracker.ObjectTracker.update` on the tracks ``x`` ``(N, 4)``,
    ``P`` ``(N, 3)`` and their counters (in place), the boxes' centres ``z`` ``(M, 2)`` and
    ``never`` (the sliding-wall trap): the prediction by ``dt`` (``q`` = σ_a², skipped for
    ``dt <= 0``), each box's mutual nearest track within ``gate_m`` (``match_box``, -1 none),
    the update with measurement variance ``r2`` and each matched box's class and speed
    (``cls``, ``speed``; the others keep theirs). ``dist`` ``(N, M)`` and ``col`` ``(N,)`` are
    scratch space."""
    nt = x.shape[0]
    nb = z.shape[0]
    if nt > 0 and dt > 0:
        g0 = 0.5 * dt * dt
        g1 = dt
        q00 = q * (g0 * g0)
        q01 = q * (g0 * g1)
        q11 = q * (g1 * g1)
        for t in range(nt):
            x[t, 0] += dt * x[t, 2]
            x[t, 1] += dt * x[t, 3]
            p = P[t, 0]
            c = P[t, 1]
            v = P[t, 2]
            cv = c + dt * v
            P[t, 0] = ((p + dt * c) + dt * cv) + q00
            P[t, 1] = cv + q01
            P[t, 2] = v + q11
    for b in range(nb):
        match_box[b] = -1
    if nt > 0 and nb > 0:
        for t in range(nt):
            for b in range(nb):
                dist[t, b] = np.hypot(x[t, 0] - z[b, 0], x[t, 1] - z[b, 1])
        for t in range(nt):
            nn = _argmin(dist[t], nb)
            for u in range(nt):
                col[u] = dist[u, nn]
            if _argmin(col, nt) == t and dist[t, nn] < gate_m:
                match_box[nn] = t
    for t in range(nt):
        misses[t] += 1  # undone for the matched ones below
    for b in range(nb):
        t = match_box[b]
        if t < 0:
            continue
        p = P[t, 0]
        c = P[t, 1]
        v = P[t, 2]
        s = p + r2
        kp = p / s
        kv = c / s
        ix = z[b, 0] - x[t, 0]
        iy = z[b, 1] - x[t, 1]
        x[t, 0] += kp * ix
        x[t, 1] += kp * iy
        x[t, 2] += kv * ix
        x[t, 3] += kv * iy
        P[t, 0] = p - kp * p
        P[t, 1] = c - kp * c
        P[t, 2] = v - kv * c
        hits[t] += 1
        misses[t] = 0
        sp = np.hypot(x[t, 2], x[t, 3])
        is_fast = sp >= v_thres and not never[b] and hits[t] >= 2
        if is_fast:
            fast[t] += 1
            slow[t] = 0
        else:
            fast[t] = 0
            slow[t] += 1
        dyn = dynamic[t]
        if fast[t] >= confirm_steps:
            dyn = True
        if slow[t] >= confirm_steps:
            dyn = False
        dyn = dyn and not never[b]
        dynamic[t] = dyn
        speed[b] = sp
        cls[b] = 1 if dyn else 3  # DYNAMIC, STATIC (object_tracker's codes)


_argmin = compiled(_argmin_py) or _argmin_py
_track = compiled(_track_py)
_pairwise_sum = compiled(_pairwise_sum_py) or _pairwise_sum_py
_reduceat = compiled(_reduceat_py) or _reduceat_py
_segment_sums = compiled(_segment_sums_py)
_segment_boxes = compiled(_segment_boxes_py)


def segment_sums(
    x: FloatArray,
    y: FloatArray,
    dist: FloatArray,
    sin_da: FloatArray,
    sin_lam_da: FloatArray,
    r: FloatArray,
    idx: IntArray,
    sigma_r_m: float,
    max_gap_beams: int,
    python: bool = False,
) -> tuple[IntArray, IntArray, IntArray, FloatArray, FloatArray, FloatArray, FloatArray,
           FloatArray, FloatArray, FloatArray]:  # fmt: skip
    """:func:`_segment_sums_py` compiled (needs numba; ``python``: the plain kernel):
    ``seg, starts, counts, mx, my, cxx, cxy, cyy, dx, dy``."""
    kernel = pick_kernel(_segment_sums_py, _segment_sums, python, "scan segmentation")
    n = len(x)
    seg = np.empty(n, dtype=np.intp)
    starts = np.empty(n, dtype=np.intp)
    m, counts, mx, my, cxx, cxy, cyy, dx, dy = kernel(
        x, y, dist, sin_da, sin_lam_da, r, idx, float(sigma_r_m), int(max_gap_beams), seg,
        starts, np.empty(n),
    )  # fmt: skip
    return seg, starts[:m], counts, mx, my, cxx, cxy, cyy, dx, dy


def segment_boxes(
    dx: FloatArray,
    dy: FloatArray,
    seg: IntArray,
    starts: IntArray,
    counts: IntArray,
    mx: FloatArray,
    my: FloatArray,
    cphi: FloatArray,
    sphi: FloatArray,
    r: FloatArray,
    min_points: int,
    max_dynamic_length_m: float,
    occlusion_never_dynamic: bool,
    python: bool = False,
) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_], IntArray, NDArray[np.bool_]]:
    """:func:`_segment_boxes_py` compiled (needs numba; ``python``: the plain kernel):
    ``center (m, 2), length, width, never, box_of_seg`` of every segment and ``keep``."""
    kernel = pick_kernel(_segment_boxes_py, _segment_boxes, python, "scan segmentation")
    m = len(starts)
    center = np.empty((m, 2))
    length, width = np.empty(m), np.empty(m)
    never = np.empty(m, dtype=np.bool_)
    box_of_seg = np.empty(m, dtype=np.intp)
    kernel(dx, dy, seg, starts, counts, mx, my, cphi, sphi, r, int(min_points),
           float(max_dynamic_length_m), bool(occlusion_never_dynamic), center, length, width,
           never, box_of_seg)  # fmt: skip
    return center, length, width, never, box_of_seg, box_of_seg >= 0


def track(
    x: FloatArray,
    P: FloatArray,
    counters: tuple[NDArray[np.int32], NDArray[np.int32], NDArray[np.int32], NDArray[np.int32]],
    dynamic: NDArray[np.bool_],
    z: FloatArray,
    never: NDArray[np.bool_],
    dt: float,
    q: float,
    r2: float,
    gate_m: float,
    v_thres: float,
    confirm_steps: int,
    python: bool = False,
) -> tuple[IntArray, NDArray[np.int8], FloatArray]:
    """:func:`_track_py` compiled (needs numba; ``python``: the plain kernel), in place on the
    tracks (``counters``: hits, misses, fast, slow); each box's track (-1: none), class
    (``UNKNOWN`` when unmatched) and speed."""
    kernel = pick_kernel(_track_py, _track, python, "object tracker")
    nb = len(z)
    match_box = np.empty(nb, dtype=np.intp)
    cls = np.zeros(nb, dtype=np.int8)
    speed = np.zeros(nb)
    hits, misses, fast, slow = counters
    kernel(x, P, hits, misses, fast, slow, dynamic, np.ascontiguousarray(z, dtype=np.float64),
           never, float(dt), float(q), float(r2), float(gate_m), float(v_thres),
           int(confirm_steps), match_box, cls, speed, np.empty((len(x), nb)),
           np.empty(len(x)))  # fmt: skip
    return match_box, cls, speed
