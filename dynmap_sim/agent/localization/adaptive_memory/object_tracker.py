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
touch the first or last return of the scan (cut by the field of view) and, with
``occlusion_never_dynamic``, boxes whose end is hidden behind a nearer return (cut by
occlusion). Their points are still static when associated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from dynmap_sim import se2
from dynmap_sim.agent.localization.adaptive_memory import tracker_numba
from dynmap_sim.jit import kernel_backend

FloatArray = NDArray[np.float64]

#: Point-class codes (``dynmap_sim.metrics.point_classes.POINT_CLASSES``; the agent may not
#: import metrics, so they are repeated here).
UNKNOWN, DYNAMIC, SEMISTATIC, STATIC = 0, 1, 2, 3


@dataclass(frozen=True)
class TrackerParams:
    """Tracker parameters (set from ``AdaptiveMemoryConfig``; see its field docs)."""

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


@dataclass
class Boxes:
    """The boxes of one scan (eq. 9), all arrays of length ``n`` except ``labels``."""

    center_robot: FloatArray  # (n, 2) box centre in the robot frame (eq. 8: x, y)
    phi: FloatArray  # (n,) orientation in the robot frame
    length: FloatArray  # (n,) along phi
    width: FloatArray  # (n,)
    never_dynamic: NDArray[np.bool_]  # (n,) the sliding-wall trap (module doc)
    labels: NDArray[np.intp]  # (n_beams,) box index of each beam, -1 none


def segment_scan(
    ranges_m: NDArray[np.floating],
    angles_rad: FloatArray,
    mount: FloatArray,
    range_max_m: float,
    params: TrackerParams,
    backend: str = "auto",
    beam_trig: tuple[FloatArray, FloatArray] | None = None,
) -> Boxes:
    """Segment one scan into oriented boxes (eqs. 8-9), vectorized (no per-point loop).
    ``backend`` (:data:`dynmap_sim.jit.KERNEL_BACKENDS`): the arithmetic in
    :func:`.tracker_numba.segment`'s kernels (the same numbers) or in numpy.
    ``beam_trig``: :func:`beam_trig` of ``angles_rad`` and ``mount``, if at hand (the
    kernels take it instead of computing the returns' cosines and sines)."""
    kernel = kernel_backend(backend)
    r_all = np.asarray(ranges_m, dtype=np.float64)
    n_beams = len(r_all)
    empty = np.zeros(0)
    if kernel:
        got = tracker_numba.segment(
            r_all, np.asarray(angles_rad, dtype=np.float64), mount, range_max_m,
            float(np.deg2rad(params.breakpoint_lambda_deg)), params.sigma_r_m, params.min_points,
            params.max_gap_beams, params.max_dynamic_length_m, params.occlusion_never_dynamic,
            beam_trig, python=kernel == "python",
        )  # fmt: skip
        if got is None:
            labels = np.full(n_beams, -1, dtype=np.intp)
            return Boxes(np.zeros((0, 2)), empty, empty, empty, np.zeros(0, bool), labels)
        return Boxes(*got)
    labels = np.full(n_beams, -1, dtype=np.intp)
    valid = np.isfinite(r_all) & (r_all > 0) & (r_all < range_max_m)
    idx = np.nonzero(valid)[0]
    if len(idx) < params.min_points:
        return Boxes(np.zeros((0, 2)), empty, empty, empty, np.zeros(0, bool), labels)
    r = r_all[idx]
    a = angles_rad[idx] + mount[2]
    xy = np.column_stack([mount[0] + r * np.cos(a), mount[1] + r * np.sin(a)])
    step = np.diff(xy, axis=0)
    dist = np.hypot(step[:, 0], step[:, 1])
    dalpha = np.abs(np.diff(angles_rad[idx]))
    lam = np.deg2rad(params.breakpoint_lambda_deg)
    d_max = r[:-1] * np.sin(dalpha) / np.maximum(np.sin(lam - dalpha), 1e-6)
    d_max += 3.0 * np.maximum(params.sigma_r_m, 0.01 * r[:-1])
    brk = (dist > d_max) | (np.diff(idx) > 1 + params.max_gap_beams)
    seg = np.concatenate([[0], np.cumsum(brk)])
    starts = np.concatenate([[0], np.nonzero(brk)[0] + 1])
    counts = np.diff(np.concatenate([starts, [len(idx)]]))
    keep = counts >= params.min_points
    # Per-segment PCA (sums by reduceat over the contiguous segments).
    sx = np.add.reduceat(xy[:, 0], starts)
    sy = np.add.reduceat(xy[:, 1], starts)
    mx, my = sx / counts, sy / counts
    dx, dy = xy[:, 0] - mx[seg], xy[:, 1] - my[seg]
    cxx = np.add.reduceat(dx * dx, starts)
    cxy = np.add.reduceat(dx * dy, starts)
    cyy = np.add.reduceat(dy * dy, starts)
    phi = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)
    c, s = np.cos(phi)[seg], np.sin(phi)[seg]
    u = dx * c + dy * s
    v = -dx * s + dy * c
    umin, umax = np.minimum.reduceat(u, starts), np.maximum.reduceat(u, starts)
    vmin, vmax = np.minimum.reduceat(v, starts), np.maximum.reduceat(v, starts)
    uc, vc = 0.5 * (umin + umax), 0.5 * (vmin + vmax)
    cphi, sphi = np.cos(phi), np.sin(phi)
    center = np.column_stack([mx + uc * cphi - vc * sphi, my + uc * sphi + vc * cphi])
    length, width = umax - umin, vmax - vmin
    # The sliding-wall trap: long, cut by the field of view, or cut by occlusion.
    ends = np.concatenate([starts[1:] - 1, [len(idx) - 1]])
    never = length > params.max_dynamic_length_m
    never[0] = True  # touches the first return of the scan
    never[-1] = True  # touches the last one
    if params.occlusion_never_dynamic and len(starts) > 1:
        # A segment's end is hidden when the neighbouring segment's adjacent return is nearer.
        r_first, r_last = r[starts], r[ends]
        occl_left = np.zeros(len(starts), bool)
        occl_right = np.zeros(len(starts), bool)
        occl_left[1:] = r_last[:-1] < r_first[1:]
        occl_right[:-1] = r_first[1:] < r_last[:-1]
        never |= occl_left | occl_right
    box_of_seg = np.full(len(starts), -1, dtype=np.intp)
    box_of_seg[keep] = np.arange(int(keep.sum()))
    labels[idx] = box_of_seg[seg]
    return Boxes(center[keep], phi[keep], length[keep], width[keep], never[keep], labels)


def beam_trig(angles_rad: FloatArray, mount: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The cosines and sines of every beam's angle in the robot frame (``angles_rad`` plus
    the mount's yaw), for :func:`segment_scan`."""
    a = np.asarray(angles_rad, dtype=np.float64) + mount[2]
    return np.cos(a), np.sin(a)


class ObjectTracker:
    """Constant-velocity Kalman filters on box centres in the odometry frame (§4.2), all tracks
    as arrays: state ``x`` ``(N, 4)`` = ``(x, y, vx, vy)``.

    The model is separable: position and velocity along x and along y with the same white
    acceleration, measurement noise and initial covariance (and ``H = [I 0]``), so the two
    axes never correlate and share one covariance ``[[p, c], [c, v]]`` (position, velocity)
    per track: ``P`` ``(N, 3)`` holds ``(p, c, v)``, the 4 x 4 covariance being
    ``blockdiag`` of it per axis. Prediction and update are written out in closed form, IEEE
    operations on the arrays of tracks (no BLAS), so a compiled kernel can repeat them."""

    def __init__(self, params: TrackerParams) -> None:
        self.params = params
        self.reset()

    def reset(self) -> None:
        params = self.params
        #: A new track's covariance ``(p, c, v)`` (each axis).
        self.P0 = np.array([params.sigma_meas_m**2, 0.0, params.sigma_v0**2])
        self.x = np.zeros((0, 4))
        self.P = np.zeros((0, 3))
        self.hits = np.zeros(0, np.int32)
        self.misses = np.zeros(0, np.int32)
        self.fast = np.zeros(0, np.int32)
        self.slow = np.zeros(0, np.int32)
        self.dynamic = np.zeros(0, bool)
        self.t_last: float | None = None

    @property
    def n_tracks(self) -> int:
        return len(self.x)

    def _predict(self, dt: float) -> None:
        """``x' = F x``, ``P' = F P Fᵀ + Q`` with ``F = [[1, dt], [0, 1]]`` and
        ``Q = σ_a² g gᵀ``, ``g = (dt²/2, dt)`` per axis (white acceleration)."""
        if self.n_tracks == 0 or dt <= 0:
            return
        q = self.params.sigma_accel**2
        g0, g1 = 0.5 * dt * dt, dt
        x, P = self.x, self.P
        x[:, 0] += dt * x[:, 2]
        x[:, 1] += dt * x[:, 3]
        p, c, v = P[:, 0], P[:, 1], P[:, 2]
        cv = c + dt * v  # (F P)[0, 1] = (F P Fᵀ)[0, 1] before Q
        P[:, 0] = ((p + dt * c) + dt * cv) + q * (g0 * g0)
        P[:, 1] = cv + q * (g0 * g1)
        P[:, 2] = v + q * (g1 * g1)

    def update(
        self, boxes: Boxes, odom_pose: FloatArray, t_s: float, backend: str = "auto"
    ) -> tuple[NDArray[np.int8], NDArray[np.float64]]:
        """Track one scan's boxes; returns each box's class (eq. 10) and speed [m/s].
        ``backend`` (:data:`dynmap_sim.jit.KERNEL_BACKENDS`): the prediction, association,
        update, classification and the tracks' renewal in :func:`.tracker_numba.track`
        (the same numbers) or in numpy."""
        kernel = kernel_backend(backend)
        p = self.params
        dt = 0.0 if self.t_last is None or t_s < self.t_last else t_s - self.t_last
        self.t_last = t_s
        if kernel:
            counters = (self.hits, self.misses, self.fast, self.slow)
            cls, speed, state = tracker_numba.track(
                self.x, self.P, counters, self.dynamic, odom_pose, boxes.center_robot,
                boxes.never_dynamic, dt, p.sigma_accel**2, p.sigma_meas_m**2, p.gate_m,
                p.v_thres, p.confirm_steps, p.max_misses, self.P0, python=kernel == "python",
            )  # fmt: skip
            self.x, self.P, self.hits, self.misses, self.fast, self.slow, self.dynamic = state
            return cls, speed
        nb = len(boxes.center_robot)
        z = se2.transform_points(odom_pose, boxes.center_robot) if nb else np.zeros((0, 2))
        matched, cls, speed = self._update_numpy(boxes, z, dt)
        # Drop lost tracks, start new ones for unmatched boxes (unknown until associated).
        alive = self.misses <= p.max_misses
        new = ~matched
        n_new = int(new.sum())
        self.x = np.concatenate([self.x[alive], np.column_stack([z[new], np.zeros((n_new, 2))])])
        self.P = np.concatenate([self.P[alive], np.broadcast_to(self.P0, (n_new, 3))])
        for name in ("hits", "misses", "fast", "slow"):
            start = 1 if name == "hits" else 0  # a new track has been seen once
            old = getattr(self, name)[alive]
            setattr(self, name, np.concatenate([old, np.full(n_new, start, np.int32)]))
        self.dynamic = np.concatenate([self.dynamic[alive], np.zeros(n_new, bool)])
        return cls, speed

    def _update_numpy(
        self, boxes: Boxes, z: FloatArray, dt: float
    ) -> tuple[NDArray[np.bool_], NDArray[np.int8], FloatArray]:
        """:meth:`update`'s filter steps in numpy: which boxes matched a track, their
        classes and speeds."""
        p = self.params
        self._predict(dt)
        nb = len(z)
        match_box = np.full(nb, -1, dtype=np.intp)  # track index of each box
        nt = self.n_tracks
        if nt and nb:
            d = np.hypot(self.x[:, None, 0] - z[None, :, 0], self.x[:, None, 1] - z[None, :, 1])
            nn_box = np.argmin(d, axis=1)
            nn_trk = np.argmin(d, axis=0)
            ti = np.arange(nt)
            mutual = (nn_trk[nn_box] == ti) & (d[ti, nn_box] < p.gate_m)
            match_box[nn_box[mutual]] = ti[mutual]
        matched = match_box >= 0
        tr = match_box[matched]
        if len(tr):  # Kalman update, H = [1 0] per axis: gain (p, c) / (p + σ_m²)
            P = self.P[tr]
            s = P[:, 0] + p.sigma_meas_m**2
            kp, kv = P[:, 0] / s, P[:, 1] / s
            ix = z[matched, 0] - self.x[tr, 0]
            iy = z[matched, 1] - self.x[tr, 1]
            self.x[tr, 0] += kp * ix
            self.x[tr, 1] += kp * iy
            self.x[tr, 2] += kv * ix
            self.x[tr, 3] += kv * iy
            self.P[tr] = np.column_stack(
                [P[:, 0] - kp * P[:, 0], P[:, 1] - kp * P[:, 1], P[:, 2] - kv * P[:, 1]]
            )
            self.hits[tr] += 1
            self.misses[tr] = 0
        unmatched_tracks = np.ones(nt, bool)
        unmatched_tracks[tr] = False
        self.misses[unmatched_tracks] += 1
        speed = np.zeros(nb)
        cls = np.full(nb, UNKNOWN, dtype=np.int8)
        if len(tr):
            v = np.hypot(self.x[tr, 2], self.x[tr, 3])
            fast = (v >= p.v_thres) & ~boxes.never_dynamic[matched] & (self.hits[tr] >= 2)
            self.fast[tr] = np.where(fast, self.fast[tr] + 1, 0)
            self.slow[tr] = np.where(fast, 0, self.slow[tr] + 1)
            dyn = self.dynamic[tr]
            dyn = np.where(self.fast[tr] >= p.confirm_steps, True, dyn)
            dyn = np.where(self.slow[tr] >= p.confirm_steps, False, dyn)
            dyn &= ~boxes.never_dynamic[matched]
            self.dynamic[tr] = dyn
            speed[matched] = v
            cls[matched] = np.where(dyn, DYNAMIC, STATIC)
        return matched, cls, speed


def point_classes_of(boxes: Boxes, box_class: NDArray[np.int8]) -> NDArray[np.int8]:
    """Eq. 11: each beam takes its box's class; beams in no box are unknown."""
    out = np.full(len(boxes.labels), UNKNOWN, dtype=np.int8)
    inside = boxes.labels >= 0
    out[inside] = box_class[boxes.labels[inside]]
    return out
