"""The batched ray caster is exact: it agrees with pymunk's segment_query_first per beam."""

import numpy as np
import pymunk
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dynmap_sim.sensors.raycast import SegmentCache, beam_directions, cast_scan, cast_scans

URG_INC = 2.0 * np.pi / 1024.0


def cast(origin, heading, amin, inc, n, r_max, segs, circ):
    """Our caster; also returns the world-frame beam directions for the pymunk reference."""
    cl, sl = beam_directions(amin, inc, n)
    r, hit = cast_scan(
        (origin[0], origin[1], heading), amin, inc, cl, sl, r_max, SegmentCache.build(segs), circ
    )
    a = heading + amin + inc * np.arange(n)
    return r, hit, np.cos(a), np.sin(a)


def random_geometry(rng, n_seg=150, n_circ=30):
    p = rng.uniform(-8.0, 8.0, (n_seg, 2))
    ang = rng.uniform(0.0, 2.0 * np.pi, n_seg)
    length = rng.uniform(0.1, 3.0, n_seg)
    d = length[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])
    segs = np.column_stack([p, p + d])
    circ = np.column_stack([rng.uniform(-6.0, 6.0, (n_circ, 2)), rng.uniform(0.05, 0.25, n_circ)])
    return segs, circ


def pymunk_space(segs, circ):
    space = pymunk.Space()
    for s in segs:
        space.add(pymunk.Segment(space.static_body, (s[0], s[1]), (s[2], s[3]), 0.0))
    for c in circ:
        space.add(pymunk.Circle(space.static_body, c[2], (c[0], c[1])))
    # a sensor shape must not be hit: filtered out by category
    sensor = pymunk.Circle(space.static_body, 50.0, (0.0, 0.0))
    sensor.sensor = True
    sensor.filter = pymunk.ShapeFilter(categories=0b10)
    space.add(sensor)
    return space


def pymunk_ranges(space, origin, cos_b, sin_b, r_max):
    flt = pymunk.ShapeFilter(mask=pymunk.ShapeFilter.ALL_MASKS() ^ 0b10)
    out = np.full(cos_b.shape[0], np.inf)
    for i in range(cos_b.shape[0]):
        end = (origin[0] + r_max * cos_b[i], origin[1] + r_max * sin_b[i])
        q = space.segment_query_first((origin[0], origin[1]), end, 0.0, flt)
        if q is not None:
            out[i] = q.alpha * r_max
    return out


def test_matches_pymunk_on_random_geometry():
    rng = np.random.default_rng(3)
    segs, circ = random_geometry(rng)
    space = pymunk_space(segs, circ)
    n_hits = 0
    for _ in range(6):
        origin = rng.uniform(-3.0, 3.0, 2)
        heading = rng.uniform(-np.pi, np.pi)
        ours, hit, cb, sb = cast(origin, heading, -2.0862, URG_INC, 683, 5.6, segs, circ)
        ref = pymunk_ranges(space, origin, cb, sb, 5.6)
        np.testing.assert_array_equal(np.isinf(ours), np.isinf(ref))
        fin = np.isfinite(ref)
        assert np.max(np.abs(ours[fin] - ref[fin]), initial=0.0) < 1e-6
        assert np.all((hit >= 0) == fin)
        n_hits += int(fin.sum())
    assert n_hits > 1000


def test_full_circle_scanner_wraps():
    """A 360 deg scanner: segments straddling the first/last beam are found on both sides."""
    rng = np.random.default_rng(5)
    segs, circ = random_geometry(rng, 80, 10)
    space = pymunk_space(segs, circ)
    ours, _, cb, sb = cast((0.1, -0.2), 0.7, -np.pi, 2 * np.pi / 720, 720, 8.0, segs, circ)
    ref = pymunk_ranges(space, (0.1, -0.2), cb, sb, 8.0)
    np.testing.assert_array_equal(np.isinf(ours), np.isinf(ref))
    fin = np.isfinite(ref)
    assert np.max(np.abs(ours[fin] - ref[fin])) < 1e-6


@settings(max_examples=40, deadline=None)
@given(
    x0=st.floats(-4, 4),
    y0=st.floats(-4, 4),
    x1=st.floats(-4, 4),
    y1=st.floats(-4, 4),
    heading=st.floats(-np.pi, np.pi),
)
def test_single_segment_matches_pymunk(x0, y0, x1, y1, heading):
    segs = np.array([[x0, y0, x1, y1]])
    length = np.hypot(x1 - x0, y1 - y0)
    if length < 1e-3:
        return
    # a sensor on the segment's supporting line is degenerate: beams run along a zero-width
    # wall (edge-on); shipped worlds are closed polygons, whose adjacent face is hit instead
    if abs(x0 * (y1 - y0) - y0 * (x1 - x0)) / length < 1e-3:
        return
    space = pymunk_space(segs, np.empty((0, 3)))
    ours, _, cb, sb = cast((0.0, 0.0), heading, -np.pi / 2, np.pi / 180, 181, 10.0, segs, None)
    ref = pymunk_ranges(space, (0.0, 0.0), cb, sb, 10.0)
    # beams grazing an endpoint may legitimately differ by a rounding error: compare hits
    both = np.isfinite(ours) & np.isfinite(ref)
    assert np.all(np.abs(ours[both] - ref[both]) < 1e-6)
    assert np.sum(np.isfinite(ours) != np.isfinite(ref)) <= 2


def test_wall_three_metres_ahead():
    segs = np.array([[3.0, -5.0, 3.0, 5.0]])
    r, hit, _, _ = cast((0.0, 0.0), 0.0, -0.1, 0.1, 3, 5.6, segs, None)
    np.testing.assert_allclose(r, 3.0 / np.cos([-0.1, 0.0, 0.1]), rtol=1e-12)
    assert list(hit) == [0, 0, 0]


def test_out_of_range_and_empty():
    segs = np.array([[10.0, -5.0, 10.0, 5.0]])
    r, hit, _, _ = cast((0.0, 0.0), 0.0, -0.5, 0.01, 101, 5.6, segs, None)
    assert np.all(np.isinf(r)) and np.all(hit == -1)
    r, hit, _, _ = cast((0.0, 0.0), 0.0, -0.5, 0.01, 101, 5.6, np.empty((0, 4)), None)
    assert np.all(np.isinf(r))


@pytest.mark.parametrize("inside", [False, True])
def test_circle_hit_distance(inside):
    circ = np.array([[2.0, 0.0, 0.5]]) if not inside else np.array([[0.0, 0.0, 0.5]])
    r, hit, _, _ = cast((0.0, 0.0), 0.0, 0.0, 0.01, 2, 5.6, np.empty((0, 4)), circ)
    expected = 0.0 if inside else 1.5
    assert r[0] == pytest.approx(expected, abs=1e-12)
    assert hit[0] == 0  # circle 0 after N = 0 segments


@settings(max_examples=30, deadline=None)
@given(
    tx=st.floats(-20, 20),
    ty=st.floats(-20, 20),
    rot=st.floats(-np.pi, np.pi),
    seed=st.integers(0, 1000),
)
def test_ranges_invariant_under_rigid_motion_of_world_and_sensor(tx, ty, rot, seed):
    """Moving the whole scene (geometry and sensor) rigidly leaves every range unchanged."""
    rng = np.random.default_rng(seed)
    segs, circ = random_geometry(rng, 60, 10)
    origin = rng.uniform(-2.0, 2.0, 2)
    heading = rng.uniform(-np.pi, np.pi)
    c, s = np.cos(rot), np.sin(rot)

    def move(xy):
        return np.stack(
            [c * xy[..., 0] - s * xy[..., 1] + tx, s * xy[..., 0] + c * xy[..., 1] + ty], -1
        )

    segs2 = np.concatenate([move(segs[:, :2]), move(segs[:, 2:])], axis=1)
    circ2 = np.column_stack([move(circ[:, :2]), circ[:, 2]])
    r1, h1, _, _ = cast(origin, heading, -2.0862, URG_INC, 683, 5.6, segs, circ)
    r2, h2, _, _ = cast(move(origin), heading + rot, -2.0862, URG_INC, 683, 5.6, segs2, circ2)
    fin = np.isfinite(r1) & np.isfinite(r2)
    assert np.mean(np.isfinite(r1) == np.isfinite(r2)) > 0.995  # grazing beams may flip
    assert np.max(np.abs(r1[fin] - r2[fin]), initial=0.0) < 1e-6


@settings(max_examples=60, deadline=None)
@given(
    x=st.floats(-10.0, 10.0, allow_nan=False),
    y=st.floats(-10.0, 10.0, allow_nan=False),
    r_max=st.floats(0.5, 8.0),
)
def test_near_cells_hold_every_segment_in_range(x, y, r_max):
    """The per-cell candidate list is a superset of the segments within r_max of the sensor."""
    segs, _ = random_geometry(np.random.default_rng(11), 120, 0)
    cache = SegmentCache.build(segs)
    cache.near(x + 0.3, y - 0.2, r_max)  # fill another cell first: the memo is per cell
    idx, p0, d = cache.near(x, y, r_max)
    a, b = segs[:, :2], segs[:, 2:]
    t = np.clip(
        np.sum((np.array([x, y]) - a) * (b - a), axis=1) / np.sum((b - a) ** 2, axis=1), 0, 1
    )
    dist = np.hypot(*(a + t[:, None] * (b - a) - np.array([x, y])).T)
    assert set(np.flatnonzero(dist <= r_max)) <= set(idx.tolist())
    np.testing.assert_array_equal(p0, cache.p0[idx])
    np.testing.assert_array_equal(d, cache.d[idx])


def test_cast_scans_gives_each_scan_the_numbers_of_cast_scan():
    """Scans cast together (each among its own shapes, some without circles or in range of
    nothing) are bit for bit those cast one at a time."""
    rng = np.random.default_rng(11)
    cl, sl = beam_directions(-2.0862, URG_INC, 683)
    poses, caches, circles = [], [], []
    for k in range(5):
        segs, circ = random_geometry(rng, n_seg=60 + 20 * k, n_circ=10)
        poses.append((*rng.uniform(-4.0, 4.0, 2), rng.uniform(-np.pi, np.pi)))
        caches.append(SegmentCache.build(segs))
        circles.append(None if k == 1 else circ)
    poses.append((100.0, 100.0, 0.0))  # nothing within range
    caches.append(caches[0])
    circles.append(circles[0])
    ranges, hits = cast_scans(poses, -2.0862, URG_INC, cl, sl, 5.6, caches, circles)
    assert ranges.shape == hits.shape == (len(poses), 683)
    for i, pose in enumerate(poses):
        r, h = cast_scan(pose, -2.0862, URG_INC, cl, sl, 5.6, caches[i], circles[i])
        assert np.array_equal(ranges[i], r)
        assert np.array_equal(hits[i], h)
    assert np.isinf(ranges[-1]).all() and (hits[-1] == -1).all()


def test_cast_scans_of_many_scans_bit_for_bit():
    """Enough scans that the pair arrays pass numpy's 256 KB threshold for reusing a
    temporary in place (which would swap a product's operands, and a complex product's last
    bits depend on their order): still each scan's numbers, bit for bit."""
    rng = np.random.default_rng(13)
    cl, sl = beam_directions(-2.0862, URG_INC, 683)
    segs, circ = random_geometry(rng, n_seg=300, n_circ=60)
    cache = SegmentCache.build(segs)
    poses = [(*rng.uniform(-3.0, 3.0, 2), rng.uniform(-np.pi, np.pi)) for _ in range(24)]
    ranges, hits = cast_scans(poses, -2.0862, URG_INC, cl, sl, 5.6, [cache] * 24, [circ] * 24)
    for i, pose in enumerate(poses):
        r, h = cast_scan(pose, -2.0862, URG_INC, cl, sl, 5.6, cache, circ)
        assert ranges[i].tobytes() == r.tobytes()
        assert np.array_equal(hits[i], h)


def test_cast_scans_without_circles_in_range():
    """No circle anywhere, or circles only out of every scan's range: the same numbers as
    one scan at a time."""
    rng = np.random.default_rng(12)
    cl, sl = beam_directions(-2.0862, URG_INC, 683)
    segs, circ = random_geometry(rng, n_seg=80, n_circ=6)
    far = circ.copy()
    far[:, :2] += 1000.0
    cache = SegmentCache.build(segs)
    poses = [(*rng.uniform(-4.0, 4.0, 2), rng.uniform(-np.pi, np.pi)) for _ in range(3)]
    for circles in ([None, None, None], [far, np.zeros((0, 3)), None]):
        ranges, hits = cast_scans(poses, -2.0862, URG_INC, cl, sl, 5.6, [cache] * 3, circles)
        for i, pose in enumerate(poses):
            r, h = cast_scan(pose, -2.0862, URG_INC, cl, sl, 5.6, cache, circles[i])
            assert np.array_equal(ranges[i], r)
            assert np.array_equal(hits[i], h)
