"""What the laser sees of people: two legs whose fore-aft offset follows the gait phase."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.world.people.crowd import Crowd
from dynmap_sim.world.people.params import LEG_RADIUS_M, LEG_SPREAD_M, LEG_SWING_M
from dynmap_sim.world.polygons import FloatArray


def legs(crowd: Crowd) -> tuple[FloatArray, NDArray[np.int32]]:
    """Two leg circles per person ``(2P, 3)`` and the person index of each."""
    out = np.empty((2 * crowd.n, 3))
    legs_into(crowd, out)
    return out, np.repeat(np.arange(crowd.n, dtype=np.int32), 2)


def legs_into(crowd: Crowd, out: FloatArray) -> None:
    """Write the two leg circles of each person into rows of ``out`` ``(2P, 3)``.

    The legs stand ``LEG_SPREAD_M`` to either side of the heading of motion (``+x`` for
    a person standing still), offset fore and aft by ``LEG_SWING_M sin(phase)`` (scaled
    down below 0.5 m/s).
    """
    if crowd.n == 0:
        return
    leg_centres_into(crowd, out[:, :2].view(np.complex128)[:, 0])
    out[:, 2] = LEG_RADIUS_M


def leg_centres_into(
    crowd: Crowd, out: NDArray[np.complex128], kernel: Callable[..., None] | None = None
) -> None:
    """Write the centres ``x + iy`` of the two legs of each person into ``out`` ``(2P,)``
    (the legs of :func:`legs_into`, without their radii).

    ``kernel``: the compiled heading and swing of the numba backend
    (:func:`~dynmap_sim.world.people.dynamics_numba._legs_py`; the same numbers).
    """
    vel = np.ascontiguousarray(crowd.vel, dtype=np.float64)
    pos = np.ascontiguousarray(crowd.pos, dtype=np.float64)
    v = vel.view(np.complex128)[:, 0]
    z = pos.view(np.complex128)[:, 0]
    sp = np.abs(v)
    if kernel is None:
        h = np.where(sp > 1e-3, v / np.maximum(sp, 1e-9), 1.0)
        swing = np.sin(crowd.phase)
        swing *= np.minimum(sp * (LEG_SWING_M / 0.5), LEG_SWING_M)
        off = h * (swing + 1j * LEG_SPREAD_M)
    else:
        n = len(sp)
        h = np.empty(n, dtype=np.complex128)
        side = np.empty(n, dtype=np.complex128)
        kernel(sp, v / np.maximum(sp, 1e-9), np.sin(crowd.phase), *_SWING, h, side)
        off = h * side
    np.add(z, off, out=out[0::2])
    np.subtract(z, off, out=out[1::2])


#: The constants of the swing: gain, cap, and ``1j * LEG_SPREAD_M`` (real, imaginary part).
_SWING = (LEG_SWING_M / 0.5, LEG_SWING_M, (1j * LEG_SPREAD_M).real, (1j * LEG_SPREAD_M).imag)


def poses(crowd: Crowd) -> FloatArray:
    """People poses ``(P, 3)``: position and heading of motion [m, rad]."""
    th = np.arctan2(crowd.vel[:, 1], crowd.vel[:, 0])
    return np.column_stack([crowd.pos, th])
