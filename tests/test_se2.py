"""SE(2) helpers: closed-form cases and algebraic invariants on random poses."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from dynmap_sim import se2

coord = st.floats(-50, 50, allow_nan=False)
angle = st.floats(-10, 10, allow_nan=False)
pose = st.tuples(coord, coord, angle).map(np.array)


def test_wrap_angle_range():
    a = se2.wrap_angle(np.array([np.pi, -np.pi, 3 * np.pi, 0.5, -7.0]))
    assert np.all(a >= -np.pi) and np.all(a < np.pi)
    np.testing.assert_allclose(a[[0, 1, 2, 3]], [-np.pi, -np.pi, -np.pi, 0.5])


def test_compose_closed_form():
    a = np.array([1.0, 2.0, np.pi / 2])
    b = np.array([1.0, 0.0, 0.0])
    np.testing.assert_allclose(se2.compose(a, b), [1.0, 3.0, np.pi / 2], atol=1e-12)


@given(pose, pose)
def test_between_inverts_compose(a, b):
    c = se2.compose(a, se2.between(a, b))
    np.testing.assert_allclose(c[:2], b[:2], atol=1e-9)
    assert abs(se2.wrap_angle(c[2] - b[2])) < 1e-9


@given(pose)
def test_inverse_is_identity(a):
    e = se2.compose(a, se2.inverse(a))
    np.testing.assert_allclose(e, [0.0, 0.0, 0.0], atol=1e-9)


def test_scan_to_points_drops_non_finite():
    r = np.array([1.0, np.inf, -np.inf, np.nan, 2.0])
    a = np.array([0.0, 0.1, 0.2, 0.3, np.pi / 2])
    pts = se2.scan_to_points(r, a, pose=np.array([1.0, 1.0, 0.0]))
    np.testing.assert_allclose(pts, [[2.0, 1.0], [1.0, 3.0]], atol=1e-12)


def test_one_pose_gives_the_numbers_of_a_batch_of_one():
    """compose and inverse of single poses (a scalar fast path) equal the batched code bit
    for bit, also where theta wraps at +-pi."""
    rng = np.random.default_rng(5)
    a = rng.normal(0, 5, (4000, 3))
    b = rng.normal(0, 5, (4000, 3))
    a[::7, 2] = np.pi * rng.integers(-3, 4, len(a[::7]))
    b[::5, 2] = -a[::5, 2] + rng.choice([np.pi, -np.pi, 0.0, 2 * np.pi], len(b[::5]))
    for i in range(len(a)):
        one = se2.compose(a[i], b[i])
        assert one.tobytes() == se2.compose(a[i : i + 1], b[i : i + 1])[0].tobytes()
        assert se2.inverse(a[i]).tobytes() == se2.inverse(a[i : i + 1])[0].tobytes()
