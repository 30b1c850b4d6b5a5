"""Planar rigid-body transforms (SE(2)) on ``(x_m, y_m, theta_rad)`` arrays.

All functions broadcast over leading dimensions: a pose may be ``(3,)`` or ``(..., 3)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def wrap_angle(theta_rad: ArrayLike) -> FloatArray:
    """Wrap angles to ``[-pi, pi)``."""
    return (np.asarray(theta_rad, dtype=np.float64) + np.pi) % (2.0 * np.pi) - np.pi


def compose(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """``a ⊕ b``: pose ``b`` expressed in frame ``a``, returned in ``a``'s parent frame."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.shape == b.shape == (3,):
        return _compose_one(a, b)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    return np.stack([x, y, wrap_angle(a[..., 2] + b[..., 2])], axis=-1)


def _compose_one(a: FloatArray, b: FloatArray) -> FloatArray:
    """:func:`compose` of two single poses on numpy float64 scalars: the same operations in
    the same order (so the same numbers), without the array machinery (several times faster
    for one pose, as the localizers compose them every scan)."""
    a0, a1, a2 = a
    b0, b1, b2 = b
    c, s = np.cos(a2), np.sin(a2)
    return np.array([a0 + c * b0 - s * b1, a1 + s * b0 + c * b1, wrap_one(a2 + b2)])


def wrap_one(theta_rad: float) -> float:
    """:func:`wrap_angle` of one angle, a float or a numpy float64 scalar (the same
    operations; Python's float ``%`` is numpy's, fmod with the divisor's sign)."""
    return (theta_rad + np.pi) % (2.0 * np.pi) - np.pi


def inverse(a: ArrayLike) -> FloatArray:
    """``⊖ a``: the inverse transform."""
    a = np.asarray(a, dtype=np.float64)
    if a.shape == (3,):
        a0, a1, a2 = a  # one pose on numpy scalars, as _compose_one
        c, s = np.cos(a2), np.sin(a2)
        return np.array([-c * a0 - s * a1, s * a0 - c * a1, wrap_one(-a2)])
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -c * a[..., 0] - s * a[..., 1]
    y = s * a[..., 0] - c * a[..., 1]
    return np.stack([x, y, wrap_angle(-a[..., 2])], axis=-1)


def apply_increment(a: FloatArray, b: FloatArray, c: FloatArray) -> FloatArray:
    """``compose(a, between(b, c))`` of single poses (the odometry increment from ``b`` to
    ``c`` applied to ``a``): :func:`inverse`'s and :func:`compose`'s operations in their
    order on Python floats (the same IEEE results; ``cos``, ``sin`` still numpy's), without
    the array machinery: a few microseconds instead of some twenty, for localizers that do
    it every scan."""
    a0, a1, a2 = float(a[0]), float(a[1]), float(a[2])
    b0, b1, b2 = float(b[0]), float(b[1]), float(b[2])
    c0, c1, c2 = float(c[0]), float(c[1]), float(c[2])
    cb, sb = float(np.cos(b2)), float(np.sin(b2))  # inverse(b)
    i0, i1, i2 = -cb * b0 - sb * b1, sb * b0 - cb * b1, wrap_one(-b2)
    ci, si = float(np.cos(i2)), float(np.sin(i2))  # compose(inverse(b), c)
    d0, d1, d2 = i0 + ci * c0 - si * c1, i1 + si * c0 + ci * c1, wrap_one(i2 + c2)
    ca, sa = float(np.cos(a2)), float(np.sin(a2))  # compose(a, ...)
    return np.array([a0 + ca * d0 - sa * d1, a1 + sa * d0 + ca * d1, wrap_one(a2 + d2)])


def between(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """``⊖ a ⊕ b``: pose ``b`` expressed in the frame of pose ``a``."""
    return compose(inverse(a), b)


def transform_points(pose: ArrayLike, points: ArrayLike) -> FloatArray:
    """Map points ``(N, 2)`` from the frame of ``pose`` into its parent frame."""
    pose = np.asarray(pose, dtype=np.float64)
    pts = np.asarray(points, dtype=np.float64)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    out = np.empty_like(pts)
    out[:, 0] = pose[0] + c * pts[:, 0] - s * pts[:, 1]
    out[:, 1] = pose[1] + s * pts[:, 0] + c * pts[:, 1]
    return out


def scan_to_points(
    ranges_m: ArrayLike, angles_rad: ArrayLike, pose: ArrayLike | None = None
) -> FloatArray:
    """Finite readings of a scan as 2-D points, in the sensor frame or, given ``pose``, its parent.

    Non-finite readings (REP-117 ``±inf``, ``NaN``) are dropped.
    """
    r = np.asarray(ranges_m, dtype=np.float64)
    a = np.asarray(angles_rad, dtype=np.float64)
    ok = np.isfinite(r)
    pts = np.stack([r[ok] * np.cos(a[ok]), r[ok] * np.sin(a[ok])], axis=-1)
    return pts if pose is None else transform_points(pose, pts)
