"""H&W §4.2 (eqs. 8-11): objects in the short-term memory, tracked and classified by speed.

Each scan is segmented into spatially related points, each segment becomes an oriented
bounding box ``o = (x, y, φ, l, w, v, d)`` (eq. 8; set ``O`` per scan, eq. 9), the boxes are
tracked with a constant-velocity Kalman filter (H&W: "a common Kalman filter as in [7]",
Wang et al.'s DATMO) with nearest-neighbour association, the robot's own motion removed by
tracking in the odometry frame, and classified by speed (eq. 10): dynamic if ``v >= v_thres``,
static if ``v < v_thres``, unknown if not associated. A point takes its box's class (eq. 11);
a point in no box (a segment of fewer than ``min_points``) is unknown.

The paper does not say how to segment; we use the adaptive breakpoint detector of Borges &
Aldon (2004): consecutive returns belong together when their distance is below
``r·sin(Δα)/sin(λ-Δα) + 3σ_r`` (``breakpoint_lambda_deg``).

**The sliding-wall trap.** The visible part of a long wall (or of anything cut by the field of
view or by a nearer object) changes as the robot moves, so its box's centre slides along it
and the filter sees motion where there is none. Such boxes are never dynamic: boxes longer
than ``max_dynamic_length_m`` (a person or a moving robot is well under 1.2 m), boxes that
reach the first or last beam of the scan (cut by the field of view) and, with
``occlusion_never_dynamic``, boxes whose end is hidden behind a nearer return (cut by
occlusion). "Reach" and "next to" allow the ``max_gap_beams`` missing beams a segment
bridges; beyond them lie beams without a return (open space beyond the range, or readings
the sensor dropped), which show no nearer object: with the URG-04LX limited to 4 m (H&W
§7.1) a person seen against an open room has no return on either side, and the nearest
return farther along the scan says nothing about its ends.
Their points are still static when associated.

The segmentation, the tracking and the per-point bookkeeping are compiled kernels
(:func:`_segment`, :func:`_track`, :func:`_scan_points`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled, jitable

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
Int8Array = NDArray[np.int8]

#: Point-class codes (``dynmap_sim.metrics.point_classes.POINT_CLASSES``; the agent may not
#: import metrics, so they are repeated here).
UNKNOWN, DYNAMIC, SEMISTATIC, STATIC = 0, 1, 2, 3


class TrackerParams(NamedTuple):
    """Tracker parameters (set from ``AdaptiveMemoryConfig``; see its field docs); a
    NamedTuple, so the kernels take it as one argument."""

    v_thres: float = 0.3
    breakpoint_lambda_deg: float = 10.0
    sigma_r_m: float = 0.01
    min_points: int = 3
    max_gap_beams: int = 2
    max_dynamic_length_m: float = 1.2
    occlusion_never_dynamic: bool = True
    sigma_accel: float = 1.0
    sigma_meas_m: float = 0.05
    sigma_v0: float = 1.0
    gate_m: float = 0.5
    confirm_steps: int = 2
    max_misses: int = 2
    leg_pair_m: float = 0.0
    leg_max_m: float = 0.25

    def typed(self) -> TrackerParams:
        """The same values with the field types the kernels are compiled for."""
        return TrackerParams(
            float(self.v_thres), float(self.breakpoint_lambda_deg), float(self.sigma_r_m),
            int(self.min_points), int(self.max_gap_beams), float(self.max_dynamic_length_m),
            bool(self.occlusion_never_dynamic), float(self.sigma_accel),
            float(self.sigma_meas_m), float(self.sigma_v0), float(self.gate_m),
            int(self.confirm_steps), int(self.max_misses), float(self.leg_pair_m),
            float(self.leg_max_m),
        )  # fmt: skip


@dataclass
class Boxes:
    """The boxes of one scan (eq. 9), all arrays of length ``n`` except ``labels``."""

    center_robot: FloatArray  # (n, 2) box centre in the robot frame (eq. 8: x, y)
    phi: FloatArray  # (n,) orientation in the robot frame
    length: FloatArray  # (n,) along phi
    width: FloatArray  # (n,)
    never_dynamic: NDArray[np.bool_]  # (n,) the sliding-wall trap (module doc)
    labels: IntArray  # (n_beams,) box index of each beam, -1 none


def beam_trig(angles_rad: FloatArray, mount: FloatArray) -> FloatArray:
    """The cosines and sines ``(2, n_beams)`` of every beam's angle in the robot frame
    (``angles_rad`` plus the mount's yaw), for :func:`segment_scan`."""
    a = np.asarray(angles_rad, dtype=np.float64) + mount[2]
    return np.stack([np.cos(a), np.sin(a)])


def segment_scan(
    ranges_m: NDArray[np.floating],
    angles_rad: FloatArray,
    mount: FloatArray,
    range_max_m: float,
    params: TrackerParams,
    beam_trig_: FloatArray | None = None,
) -> Boxes:
    """Segment one scan into oriented boxes (eqs. 8-9). ``beam_trig_``: :func:`beam_trig`
    of ``angles_rad`` and ``mount``, if at hand."""
    angles = np.ascontiguousarray(angles_rad, dtype=np.float64)
    trig = beam_trig(angles, mount) if beam_trig_ is None else beam_trig_
    mount = np.asarray(mount, dtype=np.float64)
    return Boxes(*_segment(np.asarray(ranges_m, dtype=np.float64), angles, trig, mount,
                           float(range_max_m), params.typed()))  # fmt: skip


def point_classes_of(boxes: Boxes, box_class: Int8Array) -> Int8Array:
    """Eq. 11: each beam takes its box's class; beams in no box are unknown."""
    out = np.full(len(boxes.labels), UNKNOWN, dtype=np.int8)
    inside = boxes.labels >= 0
    out[inside] = box_class[boxes.labels[inside]]
    return out


def scan_points(
    ranges: FloatArray, range_max_m: float, boxes: Boxes, box_cls: Int8Array,
    sigma_r_min_m: float, sigma_r_rel: float,
) -> tuple[IntArray, FloatArray, FloatArray, Int8Array, IntArray, IntArray]:  # fmt: skip
    """The valid returns of a scan (finite, ``0 < r < range_max_m``): beam indices ``vi``,
    ranges, range noise ``max(sigma_r_min_m, sigma_r_rel·r)`` (§4.1), classes (eq. 11) and
    boxes, and the positions among them of the static ones (§4.3's candidates)."""
    r = np.asarray(ranges, dtype=np.float64)
    return _scan_points(r, float(range_max_m), boxes.labels, box_cls, float(sigma_r_min_m),
                        float(sigma_r_rel))  # fmt: skip


class ObjectTracker:
    """Constant-velocity Kalman filters on box centres in the odometry frame (§4.2), all tracks
    as arrays: state ``x`` ``(N, 4)`` = ``(x, y, vx, vy)``.

    The model is separable: position and velocity along x and along y with the same white
    acceleration, measurement noise and initial covariance (and ``H = [I 0]``), so the two
    axes never correlate and share one covariance ``[[p, c], [c, v]]`` (position, velocity)
    per track: ``P`` ``(N, 3)`` holds ``(p, c, v)``, the 4 x 4 covariance being
    ``blockdiag`` of it per axis. ``counts`` ``(N, 4)``: each track's hits, misses and
    consecutive fast and slow updates."""

    def __init__(self, params: TrackerParams) -> None:
        self.params = params.typed()
        self.reset()

    def reset(self) -> None:
        self.x = np.zeros((0, 4))
        self.P = np.zeros((0, 3))
        self.counts = np.zeros((0, 4), np.int32)
        self.dynamic = np.zeros(0, bool)
        self.t_last: float | None = None

    @property
    def n_tracks(self) -> int:
        return len(self.x)

    def update(
        self, boxes: Boxes, odom_pose: FloatArray, t_s: float
    ) -> tuple[Int8Array, FloatArray]:
        """Track one scan's boxes (their centres taken to the odometry frame by
        ``odom_pose``) at time ``t_s`` [s]; returns each box's class (eq. 10) and speed
        [m/s]."""
        dt = 0.0 if self.t_last is None or t_s < self.t_last else t_s - self.t_last
        self.t_last = t_s
        cls, speed, self.x, self.P, self.counts, self.dynamic = _track(
            self.x, self.P, self.counts, self.dynamic,
            np.ascontiguousarray(boxes.center_robot, dtype=np.float64), boxes.never_dynamic,
            np.asarray(odom_pose, dtype=np.float64), float(dt), self.params,
        )  # fmt: skip
        return cls, speed


# -- kernels ------------------------------------------------------------------------------
@jitable
def _breakpoints(r, idx, angles, xy, p):  # type: ignore[no-untyped-def]
    """Each valid return's segment (Borges & Aldon's breakpoints, or more than
    ``max_gap_beams`` beams missing) and the segments' first returns: ``(seg, starts)``."""
    n = r.shape[0]
    lam = math.radians(p.breakpoint_lambda_deg)
    seg = np.zeros(n, dtype=np.intp)
    starts = np.zeros(n, dtype=np.intp)
    m = 1
    for j in range(n - 1):
        da = abs(angles[idx[j + 1]] - angles[idx[j]])
        d_max = r[j] * math.sin(da) / max(math.sin(lam - da), 1e-6)
        d_max += 3.0 * max(p.sigma_r_m, 0.01 * r[j])
        dist = math.hypot(xy[j + 1, 0] - xy[j, 0], xy[j + 1, 1] - xy[j, 1])
        if dist > d_max or idx[j + 1] - idx[j] > 1 + p.max_gap_beams:
            starts[m] = j + 1
            m += 1
        seg[j + 1] = m - 1
    return seg, starts[:m]


@jitable
def _box(xy, lo, hi):  # type: ignore[no-untyped-def]
    """The oriented box of points ``xy[lo:hi]``: its axis by PCA, centre ``(x, y)``,
    orientation, length along it and width."""
    n = hi - lo
    mx = my = 0.0
    for j in range(lo, hi):
        mx += xy[j, 0]
        my += xy[j, 1]
    mx, my = mx / n, my / n
    cxx = cxy = cyy = 0.0
    for j in range(lo, hi):
        dx, dy = xy[j, 0] - mx, xy[j, 1] - my
        cxx += dx * dx
        cxy += dx * dy
        cyy += dy * dy
    phi = 0.5 * math.atan2(2.0 * cxy, cxx - cyy)
    c, s = math.cos(phi), math.sin(phi)
    umin = vmin = math.inf
    umax = vmax = -math.inf
    for j in range(lo, hi):
        dx, dy = xy[j, 0] - mx, xy[j, 1] - my
        u, v = dx * c + dy * s, -dx * s + dy * c
        umin, umax, vmin, vmax = min(umin, u), max(umax, u), min(vmin, v), max(vmax, v)
    uc, vc = 0.5 * (umin + umax), 0.5 * (vmin + vmax)
    return mx + uc * c - vc * s, my + uc * s + vc * c, phi, umax - umin, vmax - vmin


@jitable
def _pair_legs(xy, starts, ends, p):  # type: ignore[no-untyped-def]
    """Each segment's partner leg (its own index: none): segments no longer than
    ``leg_max_m`` from first to last return are legs, and two legs whose centroids are
    mutual nearest within ``leg_pair_m`` are one person's (the ROS ``leg_detector``'s
    pairing); ``leg_pair_m = 0`` pairs nothing."""
    m = starts.shape[0]
    mate = np.arange(m)
    if p.leg_pair_m <= 0.0 or m < 2:
        return mate
    cx, cy = np.zeros(m), np.zeros(m)
    leg = np.zeros(m, dtype=np.bool_)
    for k in range(m):
        lo, hi = starts[k], ends[k]
        ext = math.hypot(xy[hi - 1, 0] - xy[lo, 0], xy[hi - 1, 1] - xy[lo, 1])
        leg[k] = ext <= p.leg_max_m
        for j in range(lo, hi):
            cx[k] += xy[j, 0]
            cy[k] += xy[j, 1]
        cx[k] /= hi - lo
        cy[k] /= hi - lo
    nearest = np.full(m, -1, dtype=np.intp)
    for k in range(m):
        if not leg[k]:
            continue
        best = p.leg_pair_m
        for j in range(m):
            if j != k and leg[j]:
                d = math.hypot(cx[j] - cx[k], cy[j] - cy[k])
                if d < best:
                    best, nearest[k] = d, j
    for k in range(m):
        j = nearest[k]
        if j >= 0 and nearest[j] == k:
            mate[k] = j
    return mate


@compiled
def _segment(r_all, angles, trig, mount, range_max_m, p):  # type: ignore[no-untyped-def]
    """:func:`segment_scan`: the valid returns' points, their segments, the boxes of those
    of at least ``min_points`` returns and the sliding-wall trap; ``(center, phi, length,
    width, never, labels)``."""
    n_beams = r_all.shape[0]
    labels = np.full(n_beams, -1, dtype=np.intp)
    idx = np.empty(n_beams, dtype=np.intp)
    n = 0
    for i in range(n_beams):
        v = r_all[i]
        if math.isfinite(v) and 0.0 < v < range_max_m:
            idx[n] = i
            n += 1
    if n < p.min_points:
        return (np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0),
                np.zeros(0, dtype=np.bool_), labels)  # fmt: skip
    idx = idx[:n]
    r = np.empty(n)
    xy = np.empty((n, 2))
    for j in range(n):
        r[j] = r_all[idx[j]]
        xy[j, 0] = mount[0] + r[j] * trig[0, idx[j]]
        xy[j, 1] = mount[1] + r[j] * trig[1, idx[j]]
    seg, starts = _breakpoints(r, idx, angles, xy, p)
    m = starts.shape[0]
    ends = np.empty(m, dtype=np.intp)
    for k in range(m):
        ends[k] = starts[k + 1] if k + 1 < m else n
    mate = _pair_legs(xy, starts, ends, p)
    n_box = 0
    for k in range(m):
        if mate[k] < k:
            continue  # the second leg of a pair, boxed with the first
        size = ends[k] - starts[k] + (ends[mate[k]] - starts[mate[k]] if mate[k] > k else 0)
        if size >= p.min_points:
            n_box += 1
    center = np.empty((n_box, 2))
    phi, length, width = np.empty(n_box), np.empty(n_box), np.empty(n_box)
    never = np.empty(n_box, dtype=np.bool_)
    b = 0
    near = 1 + p.max_gap_beams
    for k in range(m):
        if mate[k] < k:
            continue
        k2 = mate[k] if mate[k] > k else k  # the segment of the box's last return
        lo, hi = starts[k], ends[k]
        lo2, hi2 = starts[k2], ends[k2]
        if (hi - lo) + (hi2 - lo2 if k2 > k else 0) < p.min_points:
            continue
        if k2 > k:
            pts = np.concatenate((xy[lo:hi], xy[lo2:hi2]))
            center[b, 0], center[b, 1], phi[b], length[b], width[b] = _box(pts, 0, len(pts))
        else:
            center[b, 0], center[b, 1], phi[b], length[b], width[b] = _box(xy, lo, hi)
        # an end is cut only by what lies next to it: the field of view's edge or a nearer
        # return at most 1 + max_gap_beams beams away (beams without a return between a box
        # and the next return are open space beyond the range, which hides nothing); a
        # pair's ends are its first leg's first return and its second leg's last one
        cut_lo = idx[lo] < near if k == 0 else idx[lo] - idx[lo - 1] <= near
        cut_hi = (idx[hi2 - 1] >= n_beams - near if k2 == m - 1
                  else idx[hi2] - idx[hi2 - 1] <= near)  # fmt: skip
        nv = length[b] > p.max_dynamic_length_m or (k == 0 and cut_lo)
        nv = nv or (k2 == m - 1 and cut_hi)
        if p.occlusion_never_dynamic:  # an end hidden behind the neighbour's nearer return
            nv = nv or (k > 0 and cut_lo and r[lo - 1] < r[lo])
            nv = nv or (k2 + 1 < m and cut_hi and r[hi2] < r[hi2 - 1])
        never[b] = nv
        for j in range(lo, hi):
            labels[idx[j]] = b
        if k2 > k:
            for j in range(lo2, hi2):
                labels[idx[j]] = b
        b += 1
    return center, phi, length, width, never, labels


@jitable
def _associate(x, z, gate_m):  # type: ignore[no-untyped-def]
    """Each box's track (-1: none): the mutual nearest neighbours closer than ``gate_m``
    (the first of equal distances)."""
    nt, nb = x.shape[0], z.shape[0]
    match_box = np.full(nb, -1, dtype=np.intp)
    if nt == 0 or nb == 0:
        return match_box
    dist = np.empty((nt, nb))
    for t in range(nt):
        for b in range(nb):
            dist[t, b] = math.hypot(x[t, 0] - z[b, 0], x[t, 1] - z[b, 1])
    for t in range(nt):
        nn = np.argmin(dist[t])
        if np.argmin(dist[:, nn]) == t and dist[t, nn] < gate_m:
            match_box[nn] = t
    return match_box


@compiled
def _track(x, P, counts, dynamic, centers, never, odom, dt, p):  # type: ignore[no-untyped-def]
    """One scan of :meth:`ObjectTracker.update`: the boxes into the odometry frame, the
    prediction by ``dt`` (white acceleration ``sigma_accel``), the association, the update
    (measurement std ``sigma_meas_m``), each matched box's class with ``confirm_steps``
    hysteresis and its speed; then the lost tracks (``misses > max_misses``) dropped and a
    new one at rest started at each unmatched box. Returns ``(cls, speed, x, P, counts,
    dynamic)`` (the tracks as new arrays)."""
    nt, nb = x.shape[0], centers.shape[0]
    c0, s0 = math.cos(odom[2]), math.sin(odom[2])
    z = np.empty((nb, 2))
    for b in range(nb):
        z[b, 0] = odom[0] + c0 * centers[b, 0] - s0 * centers[b, 1]
        z[b, 1] = odom[1] + s0 * centers[b, 0] + c0 * centers[b, 1]
    if dt > 0:
        q = p.sigma_accel * p.sigma_accel
        g0, g1 = 0.5 * dt * dt, dt
        for t in range(nt):
            x[t, 0] += dt * x[t, 2]
            x[t, 1] += dt * x[t, 3]
            pp, pc, pv = P[t, 0], P[t, 1], P[t, 2]
            P[t, 0] = pp + 2.0 * dt * pc + dt * dt * pv + q * g0 * g0
            P[t, 1] = pc + dt * pv + q * g0 * g1
            P[t, 2] = pv + q * g1 * g1
    match_box = _associate(x, z, p.gate_m)
    cls = np.zeros(nb, dtype=np.int8)  # UNKNOWN
    speed = np.zeros(nb)
    for t in range(nt):
        counts[t, 1] += 1  # misses, undone for the matched ones below
    r2 = p.sigma_meas_m * p.sigma_meas_m
    for b in range(nb):
        t = match_box[b]
        if t < 0:
            continue
        pp, pc, pv = P[t, 0], P[t, 1], P[t, 2]
        kp, kv = pp / (pp + r2), pc / (pp + r2)
        ix, iy = z[b, 0] - x[t, 0], z[b, 1] - x[t, 1]
        x[t, 0] += kp * ix
        x[t, 1] += kp * iy
        x[t, 2] += kv * ix
        x[t, 3] += kv * iy
        P[t, 0], P[t, 1], P[t, 2] = pp - kp * pp, pc - kp * pc, pv - kv * pc
        counts[t, 0] += 1
        counts[t, 1] = 0
        sp = math.hypot(x[t, 2], x[t, 3])
        if sp >= p.v_thres and not never[b] and counts[t, 0] >= 2:
            counts[t, 2] += 1
            counts[t, 3] = 0
        else:
            counts[t, 2] = 0
            counts[t, 3] += 1
        if counts[t, 2] >= p.confirm_steps:
            dynamic[t] = True
        if counts[t, 3] >= p.confirm_steps or never[b]:
            dynamic[t] = False
        speed[b] = sp
        cls[b] = DYNAMIC if dynamic[t] else STATIC
    keep = np.nonzero(counts[:, 1] <= p.max_misses)[0]
    new = np.nonzero(match_box < 0)[0]
    n_keep, n = keep.shape[0], keep.shape[0] + new.shape[0]
    x2, P2 = np.zeros((n, 4)), np.empty((n, 3))
    counts2 = np.zeros((n, 4), dtype=np.int32)
    dyn2 = np.zeros(n, dtype=np.bool_)
    for i in range(n_keep):
        x2[i] = x[keep[i]]
        P2[i] = P[keep[i]]
        counts2[i] = counts[keep[i]]
        dyn2[i] = dynamic[keep[i]]
    for i in range(new.shape[0]):
        k = n_keep + i
        x2[k, 0], x2[k, 1] = z[new[i], 0], z[new[i], 1]
        P2[k, 0], P2[k, 1], P2[k, 2] = r2, 0.0, p.sigma_v0 * p.sigma_v0
        counts2[k, 0] = 1  # seen once
    return cls, speed, x2, P2, counts2, dyn2


@compiled
def _scan_points(ranges, range_max_m, labels, box_cls, sigma_r_min_m, sigma_r_rel):  # type: ignore[no-untyped-def]
    """:func:`scan_points`: ``(vi, rv, sig_r, cls_v, lab_v, stat)``."""
    n_beams = ranges.shape[0]
    vi = np.empty(n_beams, dtype=np.intp)
    lab_v = np.empty(n_beams, dtype=np.intp)
    stat = np.empty(n_beams, dtype=np.intp)
    rv, sig_r = np.empty(n_beams), np.empty(n_beams)
    cls_v = np.empty(n_beams, dtype=np.int8)
    n = n_stat = 0
    for i in range(n_beams):
        r = ranges[i]
        if not (math.isfinite(r) and 0.0 < r < range_max_m):
            continue
        vi[n], rv[n], sig_r[n] = i, r, max(sigma_r_min_m, sigma_r_rel * r)
        b = labels[i]
        lab_v[n] = b
        cls_v[n] = box_cls[b] if b >= 0 else UNKNOWN
        if cls_v[n] == STATIC:
            stat[n_stat] = n
            n_stat += 1
        n += 1
    return vi[:n], rv[:n], sig_r[:n], cls_v[:n], lab_v[:n], stat[:n_stat]
