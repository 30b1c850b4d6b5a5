"""What the laser sees of people: two legs whose fore-aft offset follows the gait phase."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.jit import compiled
from dynmap_sim.world.people.crowd import Crowd
from dynmap_sim.world.people.params import LEG_RADIUS_M, LEG_SPREAD_M, LEG_SWING_M
from dynmap_sim.world.polygons import FloatArray

#: The swing's gain [s]: the full ``LEG_SWING_M`` from 0.5 m/s up, less below.
_SWING_GAIN_S = LEG_SWING_M / 0.5


def legs(crowd: Crowd) -> tuple[FloatArray, NDArray[np.int32]]:
    """Two leg circles per person ``(2P, 3)`` and the person index of each."""
    out = np.empty((2 * crowd.n, 3))
    if crowd.n:
        leg_centres_into(crowd, out[:, :2].view(np.complex128)[:, 0])
        out[:, 2] = LEG_RADIUS_M
    return out, np.repeat(np.arange(crowd.n, dtype=np.int32), 2)


@compiled
def _legs(z, v, phase, out):  # type: ignore[no-untyped-def]
    """The two leg centres of each person into ``out[2 i]``, ``out[2 i + 1]``."""
    for i in range(z.shape[0]):
        sp = abs(v[i])
        h = v[i] / sp if sp > 1e-3 else 1.0 + 0.0j
        swing = math.sin(phase[i]) * min(sp * _SWING_GAIN_S, LEG_SWING_M)
        off = h * complex(swing, LEG_SPREAD_M)
        out[2 * i] = z[i] + off
        out[2 * i + 1] = z[i] - off


def leg_centres_into(crowd: Crowd, out: NDArray[np.complex128]) -> None:
    """Write the centres ``x + iy`` of the two legs of each person into ``out`` ``(2P,)``.

    The legs stand ``LEG_SPREAD_M`` to either side of the heading of motion (``+x`` for a
    person standing still), offset fore and aft by ``LEG_SWING_M sin(phase)`` (scaled down
    below 0.5 m/s).
    """
    vel = np.ascontiguousarray(crowd.vel, dtype=np.float64)
    pos = np.ascontiguousarray(crowd.pos, dtype=np.float64)
    phase = np.ascontiguousarray(crowd.phase, dtype=np.float64)
    _legs(pos.view(np.complex128)[:, 0], vel.view(np.complex128)[:, 0], phase, out)


def poses(crowd: Crowd) -> FloatArray:
    """People poses ``(P, 3)``: position and heading of motion [m, rad]."""
    th = np.arctan2(crowd.vel[:, 1], crowd.vel[:, 0])
    return np.column_stack([crowd.pos, th])
