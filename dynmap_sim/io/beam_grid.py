"""Scans whose beam angles differ from scan to scan, on one common beam grid.

A log's scans may each carry their own start angle and resolution: a SICK LMS run
interlaced (the Freiburg hospital log) sends 181 beams at 1° from -90°, or 180 beams offset
by ¼°, ½° or ¾°. The agent's :class:`~dynmap_sim.types.LaserSpec` holds one beam layout, so
every scan is placed, reading for reading, on the finest grid that holds all of them (here
¼°, 721 beams); beams a scan does not have are NaN (no reading, REP-117). No reading is
moved or interpolated: a reading's angle on the grid is its own to within
:data:`ANGLE_TOL_STEPS` of a grid step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

#: Most sub-steps a resolution is split into to find a common grid (¼° of 1°: 4).
MAX_SUBDIVISION = 8
#: Largest distance of a scan's start angle from the grid, as a share of a grid step.
ANGLE_TOL_STEPS = 0.02
#: Largest relative difference between the scans' resolutions taken as one resolution.
RESOLUTION_RTOL = 1e-5


@dataclass(frozen=True)
class BeamGrid:
    """The common grid: ``angle_min_rad``, ``increment_rad`` and ``n_beams``; ``offsets``
    ``(T,)`` the grid index of each scan's first beam and ``stride`` the grid steps between
    a scan's consecutive beams."""

    angle_min_rad: float
    increment_rad: float
    n_beams: int
    offsets: NDArray[np.int64]
    stride: int

    def place(self, ranges: list[NDArray[np.float32]]) -> NDArray[np.float32]:
        """The scans' ranges ``(T, n_beams)`` on the grid, NaN where a scan has no beam."""
        out = np.full((len(ranges), self.n_beams), np.nan, dtype=np.float32)
        for k, r in enumerate(ranges):
            o = int(self.offsets[k])
            out[k, o : o + self.stride * len(r) : self.stride] = r
        return out


def beam_grid(starts: NDArray, increments: NDArray, counts: NDArray) -> BeamGrid | str:
    """The common grid of scans with first-beam angles ``starts`` [rad], resolutions
    ``increments`` [rad] and beam counts ``counts`` (each ``(T,)``), or why there is none."""
    starts = np.asarray(starts, dtype=np.float64)
    inc = float(np.median(increments))
    if not inc > 0.0:
        return f"the beam increment is {inc:g} rad, not positive"
    if np.any(np.abs(np.asarray(increments) - inc) > RESOLUTION_RTOL * inc):
        lo, hi = float(np.min(increments)), float(np.max(increments))
        return f"the scans' resolutions differ ({lo:.6g} to {hi:.6g} rad)"
    a0 = float(starts.min())
    rel = (starts - a0) / inc  # in beams
    for m in range(1, MAX_SUBDIVISION + 1):
        steps = rel * m
        if np.all(np.abs(steps - np.rint(steps)) <= ANGLE_TOL_STEPS):
            offsets = np.rint(steps).astype(np.int64)
            n = int(np.max(offsets + m * (np.asarray(counts, dtype=np.int64) - 1))) + 1
            return BeamGrid(a0, inc / m, n, offsets, m)
    spread = math.degrees(float(starts.max() - a0))
    return (
        f"the scans' start angles (spread over {spread:.4g} deg) lie on no grid of up to "
        f"1/{MAX_SUBDIVISION} of the {math.degrees(inc):.4g} deg resolution"
    )
