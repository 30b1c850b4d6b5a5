"""Wheel odometry with UMBmark systematic errors and random encoder noise (docs/architecture.md §4).

Odometry is a sensor, not noisy truth. The robot's motor controller turns a commanded twist
``(v, omega)`` into wheel rotation rates using the *nominal* wheel diameter ``D`` and
wheelbase ``b`` (:func:`wheel_rates_for_twist`). The real wheels differ from nominal by
Borenstein & Feng's two dominant systematic errors (UMBmark, "Measurement and Correction of
Systematic Odometry Errors in Mobile Robots", IEEE T-RA 12(6), 1996, §2):

* ``E_d = D_R / D_L``, the ratio of the actual wheel diameters, with the average diameter equal
  to the nominal one: ``D_R = 2 E_d / (E_d + 1) D`` and ``D_L = 2 / (E_d + 1) D``;
* ``E_b = b_actual / b_nominal``, the uncertainty of the effective wheelbase.

The wheels' true rotation moves the body with the *actual* geometry
(:func:`body_twist_from_wheels`), while :class:`WheelOdometry` counts the same rotation with
its encoders (optional tick quantization plus a random error whose variance grows with the
distance rolled) and integrates it with the *nominal* geometry. The difference between the
two is the odometry drift. Each step is integrated as an exact circular arc, so a motion made
of constant-rate segments is integrated without discretisation error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


#: Sensible ranges of the wheel geometry: (name, smallest, largest); UMBmark's ``E_d`` and
#: ``E_b`` are ratios near 1 (a few per cent off on a real robot).
_WHEEL_RANGES = (
    ("wheel_diameter_m", 1e-3, 2.0),
    ("wheelbase_m", 1e-2, 5.0),
    ("e_d", 0.5, 2.0),
    ("e_b", 0.5, 2.0),
)


@dataclass(frozen=True)
class WheelGeometry:
    """Nominal wheel diameter and wheelbase [m] and the systematic errors ``E_d``, ``E_b``."""

    wheel_diameter_m: float = 0.15
    wheelbase_m: float = 0.33
    e_d: float = 1.0
    e_b: float = 1.0

    def __post_init__(self) -> None:
        for name, low, high in _WHEEL_RANGES:
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0.0):
                raise ValueError(f"WheelGeometry.{name} must be finite and > 0, got {v!r}")
            if not low <= v <= high:
                raise ValueError(f"WheelGeometry.{name} must be in {low:g}..{high:g}, got {v!r}")

    @property
    def diameter_right_m(self) -> float:
        """Actual right wheel diameter ``D_R = 2 E_d / (E_d + 1) D`` [m]."""
        return 2.0 * self.e_d / (self.e_d + 1.0) * self.wheel_diameter_m

    @property
    def diameter_left_m(self) -> float:
        """Actual left wheel diameter ``D_L = 2 / (E_d + 1) D`` [m]."""
        return 2.0 / (self.e_d + 1.0) * self.wheel_diameter_m

    @property
    def wheelbase_actual_m(self) -> float:
        """Actual (effective) wheelbase ``E_b b`` [m]."""
        return self.e_b * self.wheelbase_m


def wheel_rates_for_twist(
    geom: WheelGeometry, v_mps: float, omega_radps: float
) -> tuple[float, float]:
    """Motor controller: wheel rotation rates ``(left, right)`` [rad/s] for a twist, nominally."""
    r = 0.5 * geom.wheel_diameter_m
    half_b = 0.5 * geom.wheelbase_m
    return (v_mps - omega_radps * half_b) / r, (v_mps + omega_radps * half_b) / r


def body_twist_from_wheels(
    geom: WheelGeometry, rate_left_radps: float, rate_right_radps: float
) -> tuple[float, float]:
    """True body twist ``(v, omega)`` produced by wheel rates with the *actual* geometry."""
    vl = rate_left_radps * 0.5 * geom.diameter_left_m
    vr = rate_right_radps * 0.5 * geom.diameter_right_m
    return 0.5 * (vl + vr), (vr - vl) / geom.wheelbase_actual_m


def integrate_arc(pose: FloatArray, ds_m: float, dtheta_rad: float) -> FloatArray:
    """Move ``pose`` along a circular arc of length ``ds_m`` turning by ``dtheta_rad``."""
    x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
    half = 0.5 * dtheta_rad
    chord = ds_m * (math.sin(half) / half if abs(half) > 1e-9 else 1.0 - half * half / 6.0)
    mid = th + half
    th2 = math.remainder(th + dtheta_rad, 2.0 * math.pi)
    return np.array([x + chord * math.cos(mid), y + chord * math.sin(mid), th2])


@dataclass(frozen=True)
class EncoderNoise:
    """Encoder imperfections: ``ticks_per_rev`` quantization (0: none) and a random error.

    The random error of each wheel's rolled distance over a step is Gaussian with standard
    deviation ``sigma_sqrt_m * sqrt(|distance| / 1 m)`` (variance proportional to distance,
    as in the usual odometry motion models), independently per wheel.
    """

    ticks_per_rev: int = 2048
    sigma_sqrt_m: float = 0.002

    def __post_init__(self) -> None:
        tpr = self.ticks_per_rev
        if not (isinstance(tpr, int) and not isinstance(tpr, bool) and 0 <= tpr <= 2**31):
            raise ValueError(f"ticks_per_rev must be an integer in 0..2**31, got {tpr!r}")
        if not (math.isfinite(self.sigma_sqrt_m) and 0.0 <= self.sigma_sqrt_m <= 1.0):
            raise ValueError(f"sigma_sqrt_m must be in 0..1, got {self.sigma_sqrt_m}")


class WheelOdometry:
    """Dead reckoning from wheel encoders into the ``odom`` frame (starts at ``(0, 0, 0)``)."""

    def __init__(self, geom: WheelGeometry, noise: EncoderNoise | None = None) -> None:
        self.geom = geom
        self.noise = noise if noise is not None else EncoderNoise()
        self.reset()

    def reset(self, pose: FloatArray | None = None) -> None:
        """Restart at ``pose`` (default the odom origin) with the encoder counters at zero."""
        self._pose = np.zeros(3) if pose is None else np.asarray(pose, dtype=np.float64).copy()
        self._phi_true = [0.0, 0.0]  # accumulated true wheel angles [rad]
        self._ticks = [0, 0]
        self.distance_m = 0.0

    @property
    def pose(self) -> FloatArray:
        """Current odometry pose ``(x_m, y_m, theta_rad)`` in the odom frame (a copy)."""
        return self._pose.copy()

    def _measure(self, wheel: int, dphi_rad: float) -> float:
        """Encoder reading of one wheel's rotation increment [rad] (quantized)."""
        tpr = self.noise.ticks_per_rev
        if tpr == 0:
            return dphi_rad
        self._phi_true[wheel] += dphi_rad
        ticks = math.floor(self._phi_true[wheel] * tpr / (2.0 * math.pi))
        d = ticks - self._ticks[wheel]
        self._ticks[wheel] = ticks
        return d * 2.0 * math.pi / tpr

    def update(
        self, dphi_left_rad: float, dphi_right_rad: float, rng: np.random.Generator | None
    ) -> tuple[float, float]:
        """Count one step's true wheel rotations; return the estimated ``(ds_m, dtheta_rad)``."""
        g = self.geom
        r = 0.5 * g.wheel_diameter_m
        dl = self._measure(0, dphi_left_rad) * r
        dr = self._measure(1, dphi_right_rad) * r
        k = self.noise.sigma_sqrt_m
        if k > 0.0 and rng is not None:
            n = rng.standard_normal(2)
            dl += k * math.sqrt(abs(dl)) * float(n[0])
            dr += k * math.sqrt(abs(dr)) * float(n[1])
        ds = 0.5 * (dl + dr)
        dth = (dr - dl) / g.wheelbase_m
        self._pose = integrate_arc(self._pose, ds, dth)
        self.distance_m += abs(ds)
        return ds, dth
