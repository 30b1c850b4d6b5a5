"""Planar geometry helpers: closed-form cases and Hypothesis invariants."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dynmap_sim.world.polygons import (
    box_vertices,
    ccw,
    is_convex,
    point_segment_distance,
    points_in_convex,
    polyline_clearance,
    sat_separation,
    segment_pair_distances,
    thick_segment,
    transform,
)


def test_sat_gap_between_boxes_is_exact():
    a = box_vertices(1.0, 1.0)
    for gap in (0.3, 0.0, -0.2):
        b = transform(box_vertices(1.0, 1.0), (1.0 + gap, 0.0, 0.0))
        assert sat_separation(a, b) == pytest.approx(gap)


def test_thick_segment_is_capped():
    r = thick_segment((0.0, 0.0), (2.0, 0.0), 0.2)
    assert r[:, 0].min() == pytest.approx(-0.1) and r[:, 0].max() == pytest.approx(2.1)
    assert r[:, 1].min() == pytest.approx(-0.1) and r[:, 1].max() == pytest.approx(0.1)


def test_point_segment_distance_closed_form():
    seg = np.array([[0.0, 0.0, 2.0, 0.0]])
    pts = np.array([[1.0, 3.0], [-3.0, 4.0], [2.0, 0.0]])
    np.testing.assert_allclose(point_segment_distance(pts, seg)[:, 0], [3.0, 5.0, 0.0])


def test_route_clearance_of_a_box():
    box = transform(box_vertices(1.0, 1.0), (0.0, 2.0, 0.0))
    route = np.array([[-3.0, 0.0], [3.0, 0.0]])
    assert polyline_clearance(route, [box])[0] == pytest.approx(1.5)
    inside = np.array([[-0.1, 2.0], [0.1, 2.0]])
    assert polyline_clearance(inside, [box])[0] == 0.0


def test_is_convex():
    assert is_convex(box_vertices(1, 2))
    assert not is_convex(np.array([[0, 0], [1, 0], [0.2, 0.2], [0, 1]], dtype=float))


coord = st.floats(-5, 5, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(st.tuples(coord, coord, st.floats(-np.pi, np.pi)), st.floats(0.1, 2), st.floats(0.1, 2))
def test_sat_sign_matches_overlap(pose, w, h):
    """Convex shapes overlap iff their edges touch or one holds a vertex of the other; SAT
    says so by a negative gap, and a positive gap is a lower bound on their distance."""
    a = box_vertices(1.0, 0.6)
    b = transform(box_vertices(w, h), pose)
    gap = sat_separation(a, b)
    edges_a = np.concatenate([a, np.roll(a, -1, axis=0)], axis=1)
    edges_b = np.concatenate([b, np.roll(b, -1, axis=0)], axis=1)
    dist = segment_pair_distances(edges_a, edges_b).min()
    contains = points_in_convex(b, a).any() or points_in_convex(a, ccw(b)).any()
    overlap = dist < 1e-9 or contains
    if gap > 1e-9:
        assert not overlap and dist >= gap - 1e-9
    elif gap < -1e-9:
        assert overlap
    if not overlap:
        assert gap >= -1e-9


@settings(max_examples=200, deadline=None)
@given(st.lists(coord, min_size=4, max_size=4), st.lists(coord, min_size=4, max_size=4))
def test_segment_distance_matches_dense_sampling(s1, s2):
    a = np.array([s1])
    b = np.array([s2])
    d = segment_pair_distances(a, b)[0, 0]
    t = np.linspace(0, 1, 201)[:, None]
    pa = a[0, :2] + t * (a[0, 2:] - a[0, :2])
    pb = b[0, :2] + t * (b[0, 2:] - b[0, :2])
    dense = np.min(np.hypot(*(pa[:, None] - pb[None]).transpose(2, 0, 1)))
    assert d <= dense + 1e-9
    assert dense - d <= 0.05 * (np.hypot(*(a[0, 2:] - a[0, :2])) + np.hypot(*(b[0, 2:] - b[0, :2])))
