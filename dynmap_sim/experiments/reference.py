"""Ground truth for a replayed log from an external reference log (``replay --reference``).

A raw robot log has no ground truth: the poses on its laser lines are its wheel odometry.
A *reference* is a second CARMEN log whose laser lines carry the robot's true (e.g.
SLAM-corrected, Radish "-corrected" logs) poses. Its poses are matched to the replayed
scans **by time stamp**: each scan takes the reference pose whose stamp, shifted by the
clock offset, is nearest to its own, if it is within :data:`REFERENCE_TOLERANCE_S`; a
scan without one gets no truth and no error (it is not scored, not counted as lost).

The two logs may have different clocks (FR079: the raw log starts at 1211.5 s, the
corrected one at 0.2 s). The offset is given in seconds or estimated (``"auto"``) from the
scans both logs hold: a reference log re-prints the same laser readings, so scans whose
ranges agree to the centimetre are the same scan, and the median of their stamp
differences is the offset (:func:`clock_offset`). Without such scans the offset is 0.
Passing the replayed log itself as its reference scores against its own laser-line poses
(e.g. a synthetic log written with true poses).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from dynmap_sim import se2
from dynmap_sim.errors import InputError
from dynmap_sim.io.carmen import CarmenLog, CarmenOdometryWarning, read_carmen

FloatArray = NDArray[np.float64]

#: Largest difference [s] between a scan's time stamp and the (offset) stamp of the reference
#: pose it takes. Half the scan period of a 5 Hz scanner (FR079 runs at ~4.5 Hz): the
#: nearest reference pose is then that scan's own, while the two logs' clocks may jitter
#: against each other by a few tens of ms (FR079: 95 % of the same scans within 0.065 s).
#: For a faster scanner give less (``--reference-tolerance``): at 10 Hz a scan the reference
#: lacks would take its neighbour's pose, 0.1 s of motion away.
REFERENCE_TOLERANCE_S = 0.1

#: Fewest scans found in both logs for ``"auto"`` to trust their median stamp difference as
#: the clock offset (fewer: the offset is 0).
MIN_SHARED_SCANS = 10


@dataclass(frozen=True)
class ReferenceMatch:
    """Reference poses matched to a log's scans.

    ``poses`` ``(T, 3)`` robot poses (NaN rows: no reference pose within the tolerance);
    ``offset_s`` the clock offset added to the reference's stamps; ``offset_source``
    ``"given"``, ``"shared scans"`` or ``"none found: 0"``; ``n_shared`` scans found in both
    logs (for ``"auto"``); ``tolerance_s`` the matching tolerance.
    """

    path: Path
    poses: FloatArray
    offset_s: float
    offset_source: str
    n_shared: int
    tolerance_s: float

    @property
    def n_matched(self) -> int:
        """Scans that have a reference pose."""
        return int(np.isfinite(self.poses).all(axis=1).sum())

    def describe(self) -> str:
        """One line for the user: file, coverage, offset."""
        n = len(self.poses)
        return (
            f"reference {self.path.name}: {self.n_matched} of {n} scans matched within "
            f"{self.tolerance_s:g} s (clock offset {self.offset_s:+.3f} s, {self.offset_source})"
        )


def _scan_keys(ranges: NDArray[np.float32]) -> list[bytes]:
    """Each scan's readings rounded to the centimetre (no return and invalid kept apart)."""
    r = np.asarray(ranges, dtype=np.float64)
    cm = np.where(np.isfinite(r), np.round(r * 100.0), np.where(np.isinf(r), -1.0, -2.0))
    return [row.tobytes() for row in cm.astype(np.int64)]


def clock_offset(log: CarmenLog, ref: CarmenLog) -> tuple[float, int]:
    """``(offset [s], n)``: the median of ``log`` stamp minus ``ref`` stamp over the ``n``
    scans both hold (readings equal to the centimetre, each unique in both logs); ``(0, n)``
    when ``n`` < :data:`MIN_SHARED_SCANS` or the beam counts differ."""
    if log.ranges_m.shape[1] != ref.ranges_m.shape[1]:
        return 0.0, 0
    mine: dict[bytes, int] = {}
    dup: set[bytes] = set()
    for i, k in enumerate(_scan_keys(log.ranges_m)):
        if k in mine:
            dup.add(k)
        mine[k] = i
    theirs: dict[bytes, int] = {}
    for j, k in enumerate(_scan_keys(ref.ranges_m)):
        if k in theirs:
            dup.add(k)
        theirs[k] = j
    pairs = [(i, theirs[k]) for k, i in mine.items() if k in theirs and k not in dup]
    if len(pairs) < MIN_SHARED_SCANS:
        return 0.0, len(pairs)
    p = np.array(pairs)
    diff = log.stamps_s[p[:, 0]] - ref.stamps_s[p[:, 1]]
    return float(np.median(diff)), len(pairs)


def match_by_stamp(
    stamps_s: FloatArray,
    ref_stamps_s: FloatArray,
    ref_poses: FloatArray,
    tolerance_s: float = REFERENCE_TOLERANCE_S,
) -> FloatArray:
    """``(T, 3)``: for each stamp the pose of the nearest reference stamp within
    ``tolerance_s`` (ties: the earlier), NaN where there is none."""
    t = np.asarray(stamps_s, dtype=np.float64)
    order = np.argsort(ref_stamps_s, kind="stable")
    rt, rp = np.asarray(ref_stamps_s)[order], np.asarray(ref_poses)[order]
    out = np.full((len(t), 3), np.nan)
    if len(rt) == 0:
        return out
    hi = np.clip(np.searchsorted(rt, t), 1, max(len(rt) - 1, 1))
    lo = hi - 1
    if len(rt) == 1:
        near = np.zeros(len(t), dtype=np.int64)
    else:
        near = np.where(np.abs(rt[lo] - t) <= np.abs(rt[hi] - t), lo, hi)
    ok = np.abs(rt[near] - t) <= tolerance_s
    out[ok] = rp[near[ok]]
    return out


def load_reference(
    path: str | Path,
    log: CarmenLog,
    offset_s: float | None = None,
    tolerance_s: float = REFERENCE_TOLERANCE_S,
) -> ReferenceMatch:
    """Read the reference log at ``path`` and match its poses to ``log``'s scans.

    ``offset_s`` is added to the reference's stamps (``None``: :func:`clock_offset`).
    :class:`InputError` (naming the file) when it carries no poses on its laser lines or no
    scan of ``log`` has a reference pose within ``tolerance_s``.
    """
    p = Path(path)
    if not tolerance_s > 0:
        raise InputError(f"--reference-tolerance must be > 0 s, not {tolerance_s}")
    if p.resolve() == Path(log.path).resolve():
        ref = log
    else:
        with warnings.catch_warnings():  # a reference's odometry is not used
            warnings.simplefilter("ignore", CarmenOdometryWarning)
            ref = read_carmen(p)
    if ref.reference is None:
        raise InputError(
            f"{p}: its {ref.message} lines carry no poses; a reference needs laser lines with "
            "the robot's poses (FLASER or ROBOTLASER1)"
        )
    n_shared = 0
    if offset_s is None:
        if ref is log:
            offset, source = 0.0, "the log itself"
        else:
            offset, n_shared = clock_offset(log, ref)
            source = "from shared scans" if n_shared >= MIN_SHARED_SCANS else "none found: 0"
    else:
        offset, source = float(offset_s), "given"
    poses = match_by_stamp(log.stamps_s, ref.stamps_s + offset, ref.reference, tolerance_s)
    match = ReferenceMatch(p, poses, offset, source, n_shared, float(tolerance_s))
    if match.n_matched == 0:
        a, b = float(log.stamps_s[0]), float(log.stamps_s[-1])
        c, d = float(ref.stamps_s[0] + offset), float(ref.stamps_s[-1] + offset)
        raise InputError(
            f"{p}: no time stamp within {tolerance_s:g} s of a scan of {Path(log.path).name} "
            f"(its scans {a:.3f}..{b:.3f} s, the reference's {c:.3f}..{d:.3f} s with clock "
            f"offset {offset:+.3f} s); give the offset with --reference-offset SECONDS"
        )
    return match


def start_pose(log: CarmenLog, truth: FloatArray) -> FloatArray:
    """The pose at the first scan in the frame of ``truth`` ``(T, 3)`` (NaN rows: none): the
    first truth pose carried back to scan 0 by the odometry between them."""
    ok = np.flatnonzero(np.isfinite(truth).all(axis=1))
    k = int(ok[0])
    back = se2.between(log.odometry[k], log.odometry[0])
    return np.asarray(se2.compose(truth[k], back), dtype=np.float64)
