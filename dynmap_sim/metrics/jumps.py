"""Jumps of an estimate: scans where the estimate moves unlike the robot.

A localizer that re-localizes (a particle filter whose cloud moves to another mode, a scan
matcher that snaps to a wrong wall) shows a jump: between two consecutive scans of a run the
estimate's displacement differs from the true displacement by more than a threshold. Unlike
the error itself, a jump counts the event, so a localizer that is lost for a whole run counts
once (or not at all) while one that flickers between two places counts every flicker.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

#: A jump: the estimate's displacement between consecutive scans is this far [m] from the
#: truth's (the robot moves at most ~0.05 m a scan, so 0.5 m is no drift: the lost threshold).
JUMP_THRESHOLD_M = 0.5


def count_jumps(
    truth: ArrayLike, estimate: ArrayLike, runs: ArrayLike, threshold_m: float = JUMP_THRESHOLD_M
) -> int:
    """Consecutive scans of one run (``runs``: each scan's run key, ``(N,)`` or ``(N, k)``,
    scans of a run in time order) where ``|Δestimate - Δtruth| > threshold_m`` in position;
    pairs with a non-finite pose on either side are not counted."""
    t = np.asarray(truth, dtype=np.float64).reshape(-1, 3)[:, :2]
    e = np.asarray(estimate, dtype=np.float64).reshape(-1, 3)[:, :2]
    if len(t) != len(e):
        raise ValueError(f"{len(t)} true poses for {len(e)} estimates")
    keys = np.asarray(runs).reshape(len(t), -1)
    if len(t) < 2:
        return 0
    same_run = np.all(keys[1:] == keys[:-1], axis=1)
    step = np.hypot(*((e[1:] - e[:-1]) - (t[1:] - t[:-1])).T)
    ok = same_run & np.isfinite(step)
    return int(np.count_nonzero(step[ok] > threshold_m))
