"""Odometry motion model, AMCL's ``diff-corrected`` form (nav2 ``DifferentialMotionModel``).

Thrun, Burgard & Fox, *Probabilistic Robotics*, Table 5.6 (``sample_motion_model_odometry``):
the odometry increment is decomposed into a rotation ``rot1``, a translation ``trans`` and a
rotation ``rot2``, each perturbed by zero-mean Gaussian noise whose **standard deviation** is

    sd(rot1)  = sqrt(a1 rot1'^2 + a2 trans^2)
    sd(trans) = sqrt(a3 trans^2 + a4 rot1'^2 + a4 rot2'^2)
    sd(rot2)  = sqrt(a1 rot2'^2 + a2 trans^2)

(the "corrected" model; the old AMCL ``diff`` model used these as variances). Following
AMCL, ``rot1'``/``rot2'`` are the rotations folded to ``[0, pi/2]`` (min of the angle to 0 and
to pi), so that driving backwards is not treated as a half turn, and ``rot1`` is set to 0 for
translations below 1 cm (a turn in place).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from dynmap_sim.se2 import wrap_angle

FloatArray = NDArray[np.float64]


def decompose_odometry(odom_old: ArrayLike, odom_new: ArrayLike) -> tuple[float, float, float]:
    """``(rot1_rad, trans_m, rot2_rad)`` of the odometry increment (Table 5.6, lines 2-4)."""
    o0 = np.asarray(odom_old, dtype=np.float64)
    o1 = np.asarray(odom_new, dtype=np.float64)
    dx, dy = o1[0] - o0[0], o1[1] - o0[1]
    trans = float(np.hypot(dx, dy))
    dtheta = float(wrap_angle(o1[2] - o0[2]))
    rot1 = 0.0 if trans < 0.01 else float(wrap_angle(np.arctan2(dy, dx) - o0[2]))
    rot2 = float(wrap_angle(dtheta - rot1))
    return rot1, trans, rot2


def _fold(a: float) -> float:
    return min(abs(float(wrap_angle(a))), abs(float(wrap_angle(a - np.pi))))


def sample_odometry_motion(
    particles: FloatArray,
    odom_old: ArrayLike,
    odom_new: ArrayLike,
    alphas: tuple[float, float, float, float],
    rng: np.random.Generator,
) -> FloatArray:
    """Move ``particles`` ``(P, 3)`` by the odometry increment with sampled noise (new array)."""
    a1, a2, a3, a4 = (float(a) for a in alphas)
    rot1, trans, rot2 = decompose_odometry(odom_old, odom_new)
    r1n, r2n = _fold(rot1), _fold(rot2)
    n = len(particles)
    sd_r1 = np.sqrt(a1 * r1n**2 + a2 * trans**2)
    sd_t = np.sqrt(a3 * trans**2 + a4 * r1n**2 + a4 * r2n**2)
    sd_r2 = np.sqrt(a1 * r2n**2 + a2 * trans**2)
    noise = rng.standard_normal((3, n))
    rot1_hat = rot1 - sd_r1 * noise[0]
    trans_hat = trans - sd_t * noise[1]
    rot2_hat = rot2 - sd_r2 * noise[2]
    out = np.empty_like(particles)
    th = particles[:, 2] + rot1_hat
    out[:, 0] = particles[:, 0] + trans_hat * np.cos(th)
    out[:, 1] = particles[:, 1] + trans_hat * np.sin(th)
    out[:, 2] = wrap_angle(th + rot2_hat)
    return out
