"""The segmentation and the tracker (:mod:`.object_tracker`) against references written from
their definitions: Borges & Aldon's breakpoints return by return, each box the PCA of its
points, the Kalman filter as 4 x 4 matrix products, the mutual nearest neighbours by brute
force, and the valid returns' bookkeeping beam by beam."""

from __future__ import annotations

import numpy as np
import pytest
from synthetic_scans import LASER, box, raycast, room_segments

from dynmap_sim import se2
from dynmap_sim.agent.localization.adaptive_memory.object_tracker import (
    STATIC,
    UNKNOWN,
    Boxes,
    ObjectTracker,
    TrackerParams,
    point_classes_of,
    scan_points,
    segment_scan,
)

MOUNT = np.array([0.1, -0.02, 0.05])


def random_scan(rng: np.random.Generator) -> np.ndarray:
    """A room with a cupboard or not, a few boxes (people, chairs) and dropped beams."""
    segs = [room_segments(cupboard=bool(rng.random() < 0.5))]
    for _ in range(int(rng.integers(0, 4))):
        x, y = rng.uniform(0.5, 4.5, 2)
        s = rng.uniform(0.1, 0.6)
        segs.append(box(x, y, x + s, y + s))
    pose = np.array([*rng.uniform(0.8, 2.0, 2), rng.uniform(-np.pi, np.pi)])
    r = raycast(pose, LASER.angles(), np.concatenate(segs), LASER.range_max_m)
    r = r + rng.normal(0, 0.01, r.shape)
    r[rng.random(len(r)) < rng.choice([0.0, 0.05, 0.3])] = np.inf
    return r


def segments_reference(r_all: np.ndarray, p: TrackerParams) -> list[list[int]]:
    """The valid returns grouped return by return: a new segment where two consecutive ones
    are farther apart than ``r sin Δα / sin(λ - Δα) + 3 max(σ_r, 1 % r)`` or more than
    ``max_gap_beams`` beams lie between them."""
    ang = LASER.angles()
    valid = [i for i in range(len(r_all)) if np.isfinite(r_all[i]) and 0 < r_all[i] < 5.6]
    lam = np.deg2rad(p.breakpoint_lambda_deg)
    segs: list[list[int]] = []
    for i in valid:
        if segs:
            j = segs[-1][-1]
            pi = r_all[i] * np.array([np.cos(ang[i] + MOUNT[2]), np.sin(ang[i] + MOUNT[2])])
            pj = r_all[j] * np.array([np.cos(ang[j] + MOUNT[2]), np.sin(ang[j] + MOUNT[2])])
            da = abs(ang[i] - ang[j])
            d_max = r_all[j] * np.sin(da) / max(np.sin(lam - da), 1e-6)
            d_max += 3 * max(p.sigma_r_m, 0.01 * r_all[j])
            if np.hypot(*(pi - pj)) <= d_max and i - j <= 1 + p.max_gap_beams:
                segs[-1].append(i)
                continue
        segs.append([i])
    return segs


def leg_pairs_reference(r: np.ndarray, segs: list[list[int]], p: TrackerParams) -> list[list[int]]:
    """The segments grouped into boxes: a leg is a segment whose first and last points are at
    most ``leg_max_m`` apart; two legs whose centroids are each other's nearest leg, closer
    than ``leg_pair_m``, are one group; every other segment is a group of its own. Groups are
    lists of segment indices, in the order of their first segment."""
    a = LASER.angles() + MOUNT[2]
    pts = [MOUNT[:2] + r[s, None] * np.column_stack([np.cos(a[s]), np.sin(a[s])]) for s in segs]
    legs = [k for k, q in enumerate(pts) if np.hypot(*(q[-1] - q[0])) <= p.leg_max_m]
    cen = {k: pts[k].mean(axis=0) for k in legs}
    nearest = {}
    for k in legs:
        d = {j: np.hypot(*(cen[j] - cen[k])) for j in legs if j != k}
        j = min(d, key=lambda j: (d[j], j)) if d else None
        if j is not None and d[j] < p.leg_pair_m:
            nearest[k] = j
    groups, done = [], set()
    for k in range(len(segs)):
        if k in done:
            continue
        j = nearest.get(k)
        if j is not None and nearest.get(j) == k:
            groups.append([k, j])
            done.add(j)
        else:
            groups.append([k])
    return groups


def never_dynamic_reference(
    r: np.ndarray, segs: list[list[int]], group: list[int], length: float, p: TrackerParams
) -> bool:
    """The sliding-wall trap of the box of the segments ``group``: longer than
    ``max_dynamic_length_m``, or an end (the first segment's first return, the last one's last)
    cut by the field of view's edge or (``occlusion_never_dynamic``) by a nearer return,
    where "cut" needs the edge or that return at most ``1 + max_gap_beams`` beams away."""
    near = 1 + p.max_gap_beams
    k, k2 = group[0], group[-1]
    s, s2 = segs[k], segs[k2]
    lo_cut = s[0] < near if k == 0 else s[0] - segs[k - 1][-1] <= near
    hi_cut = s2[-1] >= len(r) - near if k2 == len(segs) - 1 else segs[k2 + 1][0] - s2[-1] <= near
    if length > p.max_dynamic_length_m or (k == 0 and lo_cut) or (k2 == len(segs) - 1 and hi_cut):
        return True
    if not p.occlusion_never_dynamic:
        return False
    left = k > 0 and lo_cut and r[segs[k - 1][-1]] < r[s[0]]
    right = k2 + 1 < len(segs) and hi_cut and r[segs[k2 + 1][0]] < r[s2[-1]]
    return bool(left or right)


def test_an_end_next_to_beams_without_return_is_not_cut() -> None:
    """A box in open space (no return on either side for more than ``max_gap_beams`` beams)
    is not cut, though a nearer return lies farther along the scan; the same box with that
    return right next to it is."""
    p = TrackerParams(max_gap_beams=2, leg_pair_m=0.0)
    n = len(LASER.angles())
    r = np.full(n, np.inf)
    mid = n // 2
    r[mid - 40 : mid - 30] = 1.0  # a nearer object 10 beams before the box
    r[mid : mid + 8] = 2.0  # the box
    b = segment_scan(r, LASER.angles(), MOUNT, LASER.range_max_m, p)
    assert len(b.length) == 2 and not b.never_dynamic[1]
    r[mid - 40 : mid - 30] = np.inf
    r[mid - 10 : mid - 1] = 1.0  # now it ends one beam before the box
    b = segment_scan(r, LASER.angles(), MOUNT, LASER.range_max_m, p)
    assert len(b.length) == 2 and b.never_dynamic[1]
    r[mid - 10 : mid - 1] = np.inf
    r[:8], r[mid : mid + 8] = 1.0, np.inf  # a box at the field of view's first beam
    b = segment_scan(r, LASER.angles(), MOUNT, LASER.range_max_m, p)
    assert len(b.length) == 1 and b.never_dynamic[0]
    r[:8], r[10:18] = np.inf, 1.0  # 10 beams in: not cut by the field of view
    b = segment_scan(r, LASER.angles(), MOUNT, LASER.range_max_m, p)
    assert len(b.length) == 1 and not b.never_dynamic[0]


@pytest.mark.parametrize("leg_pair_m", [0.0, 0.5])
def test_segment_scan_groups_by_breakpoints_and_boxes_each_segments_points(
    leg_pair_m: float,
) -> None:
    """Each box holds the points of one segment, or of a pair of legs (``leg_pair_m`` > 0)."""
    rng = np.random.default_rng(21)
    n_boxes = n_pairs = 0
    for _ in range(60):
        r = random_scan(rng)
        p = TrackerParams(breakpoint_lambda_deg=float(rng.choice([5.0, 10.0, 20.0])),
                          min_points=int(rng.integers(1, 6)),
                          max_gap_beams=int(rng.integers(0, 4)),
                          max_dynamic_length_m=float(rng.choice([0.3, 1.2])),
                          occlusion_never_dynamic=bool(rng.random() < 0.5),
                          leg_pair_m=leg_pair_m)  # fmt: skip
        b = segment_scan(r, LASER.angles(), MOUNT, LASER.range_max_m, p)
        segs = segments_reference(r, p)
        groups = leg_pairs_reference(r, segs, p)
        groups = [g for g in groups if sum(len(segs[k]) for k in g) >= p.min_points]
        kept = [sum((segs[k] for k in g), []) for g in groups]
        n_pairs += sum(len(g) == 2 for g in groups)
        assert len(b.length) == len(kept)
        labels = np.full(len(r), -1)
        for k, s in enumerate(kept):
            labels[s] = k
        np.testing.assert_array_equal(b.labels, labels)
        for k, s in enumerate(kept):
            a = LASER.angles()[s] + MOUNT[2]
            xy = MOUNT[:2] + r[s, None] * np.column_stack([np.cos(a), np.sin(a)])
            axis = np.linalg.eigh(np.cov(xy.T, bias=True))[1][:, -1] if len(s) > 1 else [1, 0]
            u = np.array([np.cos(b.phi[k]), np.sin(b.phi[k])])
            if len(s) > 2 and abs(np.diff(np.linalg.eigvalsh(np.cov(xy.T)))[0]) > 1e-9:
                assert abs(abs(u @ axis) - 1) < 1e-6  # the principal axis
            loc = (xy - b.center_robot[k]) @ np.column_stack([u, [-u[1], u[0]]])
            np.testing.assert_allclose(
                np.abs(loc).max(axis=0), [b.length[k] / 2, b.width[k] / 2], atol=1e-9
            )  # the box is the points' tight extent
            assert b.never_dynamic[k] == never_dynamic_reference(r, segs, groups[k],
                                                                 b.length[k], p)  # fmt: skip
        n_boxes += len(kept)
    assert n_boxes > 300
    assert (n_pairs > 20) == (leg_pair_m > 0)


def kalman_reference(zs: np.ndarray, dts: list[float], p: TrackerParams) -> tuple:
    """Constant velocity in 4-D, ``x = (x, y, vx, vy)``, with matrices."""
    x = np.array([*zs[0], 0.0, 0.0])
    P = np.diag([p.sigma_meas_m**2] * 2 + [p.sigma_v0**2] * 2)
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    R = np.eye(2) * p.sigma_meas_m**2
    for z, dt in zip(zs[1:], dts, strict=True):
        F = np.eye(4)
        F[0, 2] = F[1, 3] = dt
        G = np.vstack([np.eye(2) * dt**2 / 2, np.eye(2) * dt])
        x, P = F @ x, F @ P @ F.T + p.sigma_accel**2 * G @ G.T
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
        x, P = x + K @ (z - H @ x), (np.eye(4) - K @ H) @ P
    return x, P


def one_box(c: np.ndarray, never: bool = False) -> Boxes:
    return Boxes(c[None, :], np.zeros(1), np.full(1, 0.3), np.full(1, 0.2),
                 np.array([never]), np.full(5, -1, dtype=np.intp))  # fmt: skip


@pytest.mark.parametrize("speed", [0.0, 0.2, 0.8])
def test_one_track_is_the_constant_velocity_kalman_filter(speed: float) -> None:
    rng = np.random.default_rng(int(speed * 10))
    p = TrackerParams()
    tr = ObjectTracker(p)
    odom = np.array([0.3, -0.2, 0.4])  # boxes seen in the robot frame of this odometry pose
    zs, dts, t = [], [], 0.0
    for k in range(25):
        dt = float(rng.choice([0.1, 0.2]))
        t += dt
        z = np.array([1.0 + speed * t, 2.0]) + rng.normal(0, 0.01, 2)
        zs.append(z)
        dts.append(dt)
        cls, sp = tr.update(one_box(se2.transform_points(se2.inverse(odom), z[None])[0]), odom, t)
        x_ref, P_ref = kalman_reference(np.array(zs), dts[1:], p)
        assert tr.n_tracks == 1
        np.testing.assert_allclose(tr.x[0], x_ref, atol=1e-9)
        cov = tr.P[0]
        np.testing.assert_allclose(P_ref[0, [0, 2]], [cov[0], cov[1]], atol=1e-12)
        np.testing.assert_allclose(P_ref[2, 2], cov[2], atol=1e-12)
        np.testing.assert_allclose(P_ref[0, 1], 0.0, atol=1e-15)  # the axes never correlate
        assert sp[0] == pytest.approx(np.hypot(*x_ref[2:]), abs=1e-9) or k == 0
    assert cls[0] == (1 if speed >= p.v_thres else STATIC)


def test_association_is_the_mutual_nearest_neighbour_within_the_gate() -> None:
    rng = np.random.default_rng(5)
    p = TrackerParams(gate_m=0.6)
    for _ in range(200):
        tr = ObjectTracker(p)
        a = rng.uniform(-2, 2, (int(rng.integers(1, 6)), 2))
        n = len(a)
        tr.update(Boxes(a, *(np.zeros(n),) * 3, np.zeros(n, bool), np.zeros(0, np.intp)),
                  np.zeros(3), 0.0)  # fmt: skip
        b = rng.uniform(-2, 2, (int(rng.integers(1, 6)), 2))
        m = len(b)
        cls, _ = tr.update(Boxes(b, *(np.zeros(m),) * 3, np.zeros(m, bool),
                                 np.zeros(0, np.intp)), np.zeros(3), 0.0)  # fmt: skip
        d = np.hypot(*(a[:, None, :] - b[None, :, :]).transpose(2, 0, 1))
        for j in range(m):
            t = int(np.argmin(d[:, j]))
            mutual = int(np.argmin(d[t])) == j and d[t, j] < p.gate_m
            assert (cls[j] != UNKNOWN) == mutual
        assert tr.n_tracks == n + int(np.sum(cls == UNKNOWN))  # a new track per unmatched box


def test_scan_points_are_the_valid_returns_with_their_boxes_classes() -> None:
    rng = np.random.default_rng(32)
    for _ in range(100):
        n = int(rng.integers(0, 200))
        r = rng.uniform(0.01, 6.0, n)
        bad = rng.random(n) < 0.2
        r[bad] = rng.choice([np.inf, -np.inf, np.nan, 0.0, -1.0, 7.0], int(bad.sum()))
        nb = int(rng.integers(1, 6))
        labels = rng.integers(-1, nb, n).astype(np.intp)
        box_cls = rng.choice(np.array([0, 1, 3], np.int8), nb)
        boxes = Boxes(np.zeros((nb, 2)), *(np.zeros(nb),) * 3, np.zeros(nb, bool), labels)
        vi, rv, sig, cls_v, lab_v, stat = scan_points(r, 5.6, boxes, box_cls, 0.01, 0.01)
        valid = [i for i in range(n) if np.isfinite(r[i]) and 0 < r[i] < 5.6]
        np.testing.assert_array_equal(vi, valid)
        np.testing.assert_array_equal(rv, r[valid])
        np.testing.assert_array_equal(sig, [max(0.01, 0.01 * v) for v in r[valid]])
        np.testing.assert_array_equal(cls_v, point_classes_of(boxes, box_cls)[valid])
        np.testing.assert_array_equal(lab_v, labels[valid])
        np.testing.assert_array_equal(stat, np.nonzero(cls_v == STATIC)[0])
