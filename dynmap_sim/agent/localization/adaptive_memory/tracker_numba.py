"""Optional numba kernels of :func:`.object_tracker.segment_scan` (extra ``fast``).

The segmentation (H&W §4.2, eqs. 8-9) and the tracking one point, one segment and one
track at a time instead of some seventy numpy calls on arrays of a few hundred points and a
few dozen tracks:

* :func:`segment`: :func:`_valid_beams_py`, the valid returns; :func:`_segment_sums_py`,
  their points, Borges & Aldon's breakpoints, the segments, their centroids and second
  moments (the sums that ``np.add.reduceat`` makes, in its order: a segment's first value
  plus numpy's pairwise sum of the rest, :func:`_pairwise_sum_py`);
  :func:`_segment_boxes_py`, each point's coordinates along and across its segment's
  principal axis, the segments' extents, oriented boxes and the sliding-wall trap;
  :func:`_kept_boxes_py`, the boxes of the segments kept and each return's box.
* :func:`track`: one scan of :class:`.object_tracker.ObjectTracker`: the boxes into the
  odometry frame (:func:`_transform_py`), the Kalman prediction, the mutual
  nearest-neighbour association, the update and the speed classification over the tracks
  in place (:func:`_track_py`), the lost tracks dropped and new ones started
  (:func:`_renew_py`).

The arithmetic is the numpy code's, operation for operation, so the results are identical
(``np.hypot`` is the C library's in numba as in numpy; Python's ``math.hypot`` is not);
the other transcendental functions (``cos``, ``sin``, ``arctan2``) stay in numpy, whose
results the kernels take. The tests check the plain-Python kernels (what numba compiles) and
the compiled ones against the numpy code.
"""

from __future__ import annotations

import math
from typing import Any

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
    cos_a, sin_a, mount_x, mount_y, sin_da, sin_lam_da, r, idx, sigma_r_m, max_gap_beams, seg,
    starts, scratch,
):  # fmt: skip
    """The points ``x = mount_x + r cos_a``, ``y = mount_y + r sin_a``; breakpoints between
    points ``j`` and ``j + 1`` where their distance ``hypot(x[j+1] - x[j], y[j+1] - y[j])``
    exceeds ``r[j] sin_da[j] / max(sin_lam_da[j], 1e-6) + 3 max(sigma_r_m, 0.01 r[j])`` or
    more than ``max_gap_beams`` beams are missing; fills ``seg`` (each point's segment) and
    ``starts`` and returns the number of segments ``m``, the centroids ``mx, my``, the
    sums ``cxx, cxy, cyy`` of the centred points' products (arrays of length ``m``) and the
    centred points ``dx, dy``. ``scratch``: ``len(r)`` floats."""
    n = r.shape[0]
    x = np.empty(n)
    y = np.empty(n)
    for j in range(n):
        x[j] = mount_x + r[j] * cos_a[j]
        y[j] = mount_y + r[j] * sin_a[j]
    m = 1
    starts[0] = 0
    seg[0] = 0
    for j in range(n - 1):
        d_max = r[j] * sin_da[j] / max(sin_lam_da[j], 1e-6)
        d_max = d_max + 3.0 * max(sigma_r_m, 0.01 * r[j])
        dist = np.hypot(x[j + 1] - x[j], y[j + 1] - y[j])
        if dist > d_max or idx[j + 1] - idx[j] > 1 + max_gap_beams:
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


def _valid_beams_py(  # type: ignore[no-untyped-def]
    r_all, angles, mount_yaw, range_max_m, lam, idx, r, a, dalpha, lam_da
):
    """The valid returns of a scan (finite, ``0 < r < range_max_m``): their beam indices
    ``idx``, ranges ``r``, angles plus the mount's yaw ``a``, the angle steps to the next
    valid return ``dalpha = |Δangle|`` and ``lam - dalpha``; returns how many."""
    n = 0
    for i in range(r_all.shape[0]):
        v = r_all[i]
        if math.isfinite(v) and v > 0 and v < range_max_m:
            idx[n] = i
            r[n] = v
            a[n] = angles[i] + mount_yaw
            n += 1
    for j in range(n - 1):
        d = abs(angles[idx[j + 1]] - angles[idx[j]])
        dalpha[j] = d
        lam_da[j] = lam - d
    return n


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


def _kept_boxes_py(  # type: ignore[no-untyped-def]
    center, phi, length, width, never, box_of_seg, seg, idx, n_box, labels
):
    """The kept segments' boxes (``box_of_seg >= 0``, in order) as new arrays ``(center,
    phi, length, width, never)``, and each valid return's box in ``labels[idx]``."""
    c = np.empty((n_box, 2))
    ph = np.empty(n_box)
    ln = np.empty(n_box)
    wd = np.empty(n_box)
    nv = np.empty(n_box, dtype=np.bool_)
    for k in range(box_of_seg.shape[0]):
        b = box_of_seg[k]
        if b >= 0:
            c[b, 0] = center[k, 0]
            c[b, 1] = center[k, 1]
            ph[b] = phi[k]
            ln[b] = length[k]
            wd[b] = width[k]
            nv[b] = never[k]
    for j in range(idx.shape[0]):
        labels[idx[j]] = box_of_seg[seg[j]]
    return c, ph, ln, wd, nv


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


def _transform_py(x0, y0, c, s, pts, out):  # type: ignore[no-untyped-def]
    """:func:`dynmap_sim.se2.transform_points` of ``pts`` by the pose ``(x0, y0)`` whose
    heading has cosine ``c`` and sine ``s``, into ``out``."""
    for i in range(pts.shape[0]):
        px = pts[i, 0]
        py = pts[i, 1]
        out[i, 0] = x0 + c * px - s * py
        out[i, 1] = y0 + s * px + c * py


def _renew_py(  # type: ignore[no-untyped-def]
    x, P, hits, misses, fast, slow, dynamic, z, match_box, max_misses, p0, p1, p2
):
    """The tracks after a scan (:meth:`.object_tracker.ObjectTracker.update`): the lost
    ones (``misses > max_misses``) dropped, a new track at each unmatched box ``z`` (at
    rest, covariance ``(p0, p1, p2)``, seen once) appended; new arrays
    ``(x, P, hits, misses, fast, slow, dynamic)``."""
    nt = x.shape[0]
    nb = z.shape[0]
    n = 0
    for t in range(nt):
        if misses[t] <= max_misses:
            n += 1
    for b in range(nb):
        if match_box[b] < 0:
            n += 1
    x2 = np.empty((n, 4))
    P2 = np.empty((n, 3))
    h2 = np.empty(n, dtype=np.int32)
    m2 = np.empty(n, dtype=np.int32)
    f2 = np.empty(n, dtype=np.int32)
    s2 = np.empty(n, dtype=np.int32)
    d2 = np.empty(n, dtype=np.bool_)
    k = 0
    for t in range(nt):
        if misses[t] <= max_misses:
            for i in range(4):
                x2[k, i] = x[t, i]
            for i in range(3):
                P2[k, i] = P[t, i]
            h2[k] = hits[t]
            m2[k] = misses[t]
            f2[k] = fast[t]
            s2[k] = slow[t]
            d2[k] = dynamic[t]
            k += 1
    for b in range(nb):
        if match_box[b] < 0:
            x2[k, 0] = z[b, 0]
            x2[k, 1] = z[b, 1]
            x2[k, 2] = 0.0
            x2[k, 3] = 0.0
            P2[k, 0] = p0
            P2[k, 1] = p1
            P2[k, 2] = p2
            h2[k] = 1
            m2[k] = 0
            f2[k] = 0
            s2[k] = 0
            d2[k] = False
            k += 1
    return x2, P2, h2, m2, f2, s2, d2


_argmin = compiled(_argmin_py) or _argmin_py
_track = compiled(_track_py)
_pairwise_sum = compiled(_pairwise_sum_py) or _pairwise_sum_py
_reduceat = compiled(_reduceat_py) or _reduceat_py
_segment_sums = compiled(_segment_sums_py)
_segment_boxes = compiled(_segment_boxes_py)
_valid_beams = compiled(_valid_beams_py)
_kept_boxes = compiled(_kept_boxes_py)
_transform = compiled(_transform_py)
_renew = compiled(_renew_py)


def segment(
    r_all: FloatArray,
    angles: FloatArray,
    mount: FloatArray,
    range_max_m: float,
    lam: float,
    sigma_r_m: float,
    min_points: int,
    max_gap_beams: int,
    max_dynamic_length_m: float,
    occlusion_never_dynamic: bool,
    beam_trig: tuple[FloatArray, FloatArray] | None = None,
    python: bool = False,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, NDArray[np.bool_], IntArray] | None:
    """:func:`.object_tracker.segment_scan` of the scan ``r_all`` (float64) with the
    kernels (needs numba; ``python``: the plain kernels): ``center (n, 2), phi, length,
    width, never, labels``, or None when fewer than ``min_points`` returns are valid. The
    transcendental functions in numpy: ``cos``, ``sin`` of the returns' angles (``beam_trig``:
    those of every beam's, ``angles + mount[2]``, if at hand; numpy's are elementwise, the
    same numbers) and of the breakpoint detector's angles, ``arctan2`` of the segments'
    moments, ``cos``, ``sin`` of their axes."""
    valid_k = pick_kernel(_valid_beams_py, _valid_beams, python, "scan segmentation")
    sums_k = pick_kernel(_segment_sums_py, _segment_sums, python, "scan segmentation")
    boxes_k = pick_kernel(_segment_boxes_py, _segment_boxes, python, "scan segmentation")
    kept_k = pick_kernel(_kept_boxes_py, _kept_boxes, python, "scan segmentation")
    n_beams = len(r_all)
    idx = np.empty(n_beams, dtype=np.intp)
    r, a, da, lda = np.empty(n_beams), np.empty(n_beams), np.empty(n_beams), np.empty(n_beams)
    n = valid_k(r_all, angles, float(mount[2]), float(range_max_m), float(lam), idx, r, a, da,
                lda)  # fmt: skip
    labels = np.full(n_beams, -1, dtype=np.intp)
    if n < min_points:
        return None
    idx, r = idx[:n], r[:n]
    seg = np.empty(n, dtype=np.intp)
    starts = np.empty(n, dtype=np.intp)
    if beam_trig is None:
        cos_a, sin_a = np.cos(a[:n]), np.sin(a[:n])
    else:
        cos_a, sin_a = beam_trig[0][idx], beam_trig[1][idx]
    m, counts, mx, my, cxx, cxy, cyy, dx, dy = sums_k(
        cos_a, sin_a, float(mount[0]), float(mount[1]), np.sin(da[: n - 1]),
        np.sin(lda[: n - 1]), r, idx, float(sigma_r_m), int(max_gap_beams), seg, starts,
        np.empty(n),
    )  # fmt: skip
    starts = starts[:m]
    phi = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)
    center, length, width = np.empty((m, 2)), np.empty(m), np.empty(m)
    never = np.empty(m, dtype=np.bool_)
    box_of_seg = np.empty(m, dtype=np.intp)
    n_box = boxes_k(dx, dy, seg, starts, counts, mx, my, np.cos(phi), np.sin(phi), r,
                    int(min_points), float(max_dynamic_length_m), bool(occlusion_never_dynamic),
                    center, length, width, never, box_of_seg)  # fmt: skip
    c, ph, ln, wd, nv = kept_k(center, phi, length, width, never, box_of_seg, seg, idx, n_box,
                               labels)  # fmt: skip
    return c, ph, ln, wd, nv, labels


def track(
    x: FloatArray,
    P: FloatArray,
    counters: tuple[NDArray[np.int32], NDArray[np.int32], NDArray[np.int32], NDArray[np.int32]],
    dynamic: NDArray[np.bool_],
    odom_pose: FloatArray,
    centers_robot: FloatArray,
    never: NDArray[np.bool_],
    dt: float,
    q: float,
    r2: float,
    gate_m: float,
    v_thres: float,
    confirm_steps: int,
    max_misses: int,
    p_new: FloatArray,
    python: bool = False,
) -> tuple[NDArray[np.int8], FloatArray, tuple[Any, ...]]:
    """One scan of :class:`.object_tracker.ObjectTracker` with the kernels (needs numba;
    ``python``: the plain kernels): the boxes' centres ``centers_robot`` into the odometry
    frame (the heading's ``cos``, ``sin`` in numpy), :func:`_track_py` in place on the
    tracks (``counters``: hits, misses, fast, slow), then :func:`_renew_py` (lost tracks
    dropped, a new one per unmatched box, covariance ``p_new``). Returns each box's class
    (``UNKNOWN`` when unmatched) and speed, and the new track arrays ``(x, P, hits, misses,
    fast, slow, dynamic)``."""
    kernel = pick_kernel(_track_py, _track, python, "object tracker")
    transform = pick_kernel(_transform_py, _transform, python, "object tracker")
    renew = pick_kernel(_renew_py, _renew, python, "object tracker")
    nb = len(centers_robot)
    z = np.empty((nb, 2))
    if nb:
        pose = np.asarray(odom_pose, dtype=np.float64)
        transform(float(pose[0]), float(pose[1]), float(np.cos(pose[2])), float(np.sin(pose[2])),
                  np.ascontiguousarray(centers_robot, dtype=np.float64), z)  # fmt: skip
    match_box = np.empty(nb, dtype=np.intp)
    cls = np.zeros(nb, dtype=np.int8)
    speed = np.zeros(nb)
    hits, misses, fast, slow = counters
    kernel(x, P, hits, misses, fast, slow, dynamic, z, never, float(dt), float(q), float(r2),
           float(gate_m), float(v_thres), int(confirm_steps), match_box, cls, speed,
           np.empty((len(x), nb)), np.empty(len(x)))  # fmt: skip
    state = renew(x, P, hits, misses, fast, slow, dynamic, z, match_box, int(max_misses),
                  float(p_new[0]), float(p_new[1]), float(p_new[2]))  # fmt: skip
    return cls, speed, state
