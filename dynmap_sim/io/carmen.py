"""Read CARMEN log files (plain or gzip) into the simulator's scan and odometry stream.

Supported lines (CARMEN ``logger`` format, one message per line, ``#`` comments):

* ``ODOM x y theta tv rv accel timestamp host logger_timestamp``
* ``FLASER n r_1..r_n x y theta odom_x odom_y odom_theta timestamp host logger_timestamp``
  (``RLASER`` the same for the rear laser) — the old format; ``x y theta`` is the laser's
  pose (the *corrected* pose in the "-corrected" Radish logs), ``odom_*`` the robot's
  odometry. The field of view is guessed from ``n`` as CARMEN does (181/361 beams: 180°,
  180: 179°, 360: 179.5°, 401: 100°, otherwise 180°), centred on the laser's x axis;
* ``ROBOTLASER1 type start_angle fov resolution max_range accuracy remission_mode n r_1..r_n
  n_rem rem_1..rem_m laser_x laser_y laser_theta robot_x robot_y robot_theta tv rv
  forward_safety side_safety turn_axis timestamp host logger_timestamp`` (``ROBOTLASER2``
  the rear one); the laser's mount pose is the robot pose expressed in the laser pose;
* ``RAWLASER1..4 type start_angle fov resolution max_range accuracy remission_mode n
  r_1..r_n n_rem rem_1..rem_m timestamp host logger_timestamp`` (no poses).

Old ``FLASER`` lines state no maximum range: it is the reading the scanner repeats for "no
return" (:func:`saturation_range`; 80 m when none repeats). Time stamps that go back are an
error, equal consecutive ones a warning. Ranges at or beyond the maximum range become
``+inf`` (no return), non-positive ones
``NaN`` (REP-117). When laser lines carry poses, the robot poses they imply are the
**reference**.

Odometry (:data:`ODOMETRY_SOURCES`, ``read_carmen(odometry=...)``, ``--odometry``). CARMEN's
logger writes ``ODOM`` (the base's odometry: ``x y theta tv rv accel``) and, on each laser
line, the laser's and the robot's pose (``carmen_robot_laser_message``: ``laser_pose``
"position of the center of the laser", ``robot_pose`` "of the center of the robot"; the old
``FLASER`` line prints them as ``x y theta odom_x odom_y odom_theta``; CARMEN logger and
playback, https://carmen.sourceforge.net/logger_playback.html; robot messages,
https://carmen.sourceforge.net/doc/structcarmen__robot__laser__message.html). In a raw log
both come from the base's odometry at the scan's time, so the two records are one stream:
the ``ODOM`` lines interpolated to a scan's time stamp give its laser line's odometry (FR079
and CSAIL raw: to 1e-6 m), and the laser pose is that odometry plus the fixed laser mount.
A log rewritten by a SLAM (Radish "-corrected") puts its poses on the laser lines, in the
pose and often also in the odometry fields, and its ``ODOM`` lines are whatever the writer
left (FR079 corrected: 2.7 cm median from the scans' poses, every other one repeating a
scan's pose with time stamp 0). ``"auto"`` (:func:`choose_odometry`) therefore takes the
``ODOM`` lines, interpolated (heading unwrapped) to the scan times, only where they are shown to be
the laser lines' odometry (:data:`ODOM_AGREEMENT_SHARE` of the scans within
:data:`ODOM_AGREEMENT_M` and :data:`ODOM_AGREEMENT_RAD`), and otherwise the laser lines' own
odometry fields, warning (:class:`CarmenOdometryWarning`) with the measured disagreement and
whether the laser lines carry one trajectory in both fields (a corrected log: its odometry
is not raw wheel odometry). A log with only one of the two takes that one.

Reversing (``read_carmen(reversals=...)``, ``--odometry-reversals``). An ``ODOM`` line also
carries the base's signed translational velocity ``tv``. Where the lines' poses move
*forward* along the heading while ``tv`` says the robot reverses, the poses were integrated
without the sign (FR079 raw, written by ``bag2carmen``: 400 of its 8,950 increments, ~50 s of
reversing at 0.5 m/s; no increment of its poses moves backward, and the scans and the
corrected log agree with ``tv``: the robot backs away). ``"repair"`` (the default) negates
the translation of those increments in the robot frame and integrates the poses again
(heading increments as logged), warning (:class:`CarmenOdometryWarning`) with the count;
``"keep"`` takes the poses as logged, also warning. A log whose increments agree with its
``tv`` (CSAIL raw, any log reversing correctly) is not touched and gives no warning.
"""

from __future__ import annotations

import gzip
import io
import math
import re
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from dynmap_sim import se2
from dynmap_sim.errors import FileError
from dynmap_sim.io.beam_grid import beam_grid
from dynmap_sim.types import LaserSpec, Odometry, Scan

FloatArray = NDArray[np.float64]

#: Laser message types per laser id, in order of preference.
LASER_TYPES: dict[int, tuple[str, ...]] = {
    1: ("ROBOTLASER1", "FLASER", "RAWLASER1"),
    2: ("ROBOTLASER2", "RLASER", "RAWLASER2"),
    3: ("RAWLASER3",),
    4: ("RAWLASER4",),
}


#: Where a log's odometry comes from (``read_carmen(odometry=...)``): ``"auto"`` the ``ODOM``
#: lines where they agree with the laser lines' odometry fields, else those fields (warned);
#: ``"odom-lines"`` the ``ODOM`` lines interpolated to the scan times; ``"laser-lines"`` the
#: laser lines' odometry fields (``odom_*`` of ``FLASER``, ``robot_*`` of ``ROBOTLASER``).
ODOMETRY_SOURCES = ("auto", "odom-lines", "laser-lines")

#: Largest translation [m] and rotation [rad] between the interpolated ``ODOM`` lines and a
#: laser line's odometry for the two to count as one stream at that scan: the print precision
#: of a raw log (1e-6) plus interpolation against extrapolation between odometry samples
#: (1 m/s over 10 ms). FR079 corrected: 0.027 m median apart.
ODOM_AGREEMENT_M = 0.01
ODOM_AGREEMENT_RAD = 0.01

#: Share of the scans (within the ``ODOM`` lines' time span) that must agree for ``"auto"``
#: to take the ``ODOM`` lines as the raw odometry.
ODOM_AGREEMENT_SHARE = 0.95

#: Where an ``ODOM`` increment's poses contradict its line's velocity (module docstring):
#: ``"repair"`` negates the increment's translation, ``"keep"`` takes it as logged.
REVERSAL_MODES = ("repair", "keep")

#: An ``ODOM`` increment counts as moving forward against a reversing base when its
#: translation along the heading is over this [m] (the print precision of a raw log and a
#: standing robot's jitter are far below) and its line's ``tv`` below minus this [m/s].
REVERSAL_MIN_STEP_M = 1e-3
REVERSAL_MIN_SPEED_MPS = 0.01

#: Largest spread [m, rad] of the laser pose seen from the laser line's odometry for the
#: two fields to be one trajectory (a fixed mount, zero in FR079 and CSAIL).
ONE_TRAJECTORY_TOL = 1e-3

#: Longest line read [characters]: a laser line of 10,000 beams with remissions is ~150 kB.
MAX_LINE_CHARS = 1 << 20
#: A file none of whose first this many non-comment lines is a CARMEN message is refused.
SNIFF_LINES = 20
#: What the first field of a CARMEN message looks like (``ODOM``, ``ROBOTLASER1``, ``PARAM``).
_MESSAGE_NAME = re.compile(r"[A-Z][A-Z0-9_]*\Z")


class CarmenLogError(FileError):
    """A CARMEN log that cannot be read; names the file and ``line N.field``."""


class CarmenOdometryWarning(UserWarning):
    """A log whose odometry is not shown to be raw: what was used and why."""


@dataclass
class CarmenLog:
    """One laser's scans with odometry at the scan times, and the reference poses if any.

    ``ranges_m`` ``(T, n_beams)`` float32 (REP-117); ``stamps_s`` ``(T,)``; ``odometry``
    ``(T, 3)`` in the odom frame; ``reference`` ``(T, 3)`` robot poses from the laser lines
    (corrected in "-corrected" logs) or ``None``; ``message`` the laser line type used;
    ``odometry_source`` ``"odom-lines"`` or ``"laser-lines"`` (:func:`choose_odometry`);
    ``n_reversals`` the ``ODOM`` increments found moving forward while the base reverses and
    ``reversals`` what was done with them (:data:`REVERSAL_MODES`; module docstring).
    """

    path: Path
    laser: LaserSpec
    stamps_s: FloatArray
    ranges_m: NDArray[np.float32]
    odometry: FloatArray
    reference: FloatArray | None
    message: str
    odometry_source: str
    n_reversals: int = 0
    reversals: str = "repair"

    def __len__(self) -> int:
        return len(self.stamps_s)

    def stream(self) -> list[tuple[Odometry, Scan]]:
        """The ``(Odometry, Scan)`` pairs a localizer consumes, in time order."""
        return [
            (Odometry(self.odometry[k].copy(), float(t)), Scan(self.ranges_m[k], float(t)))
            for k, t in enumerate(self.stamps_s)
        ]


def guess_fov_rad(n: int) -> float:
    """CARMEN's field-of-view guess for old-style ``FLASER`` lines with ``n`` readings."""
    table = {181: math.pi, 361: math.pi, 180: math.radians(179.0), 360: math.radians(179.5)}
    table[401] = math.radians(100.0)
    return table.get(n, math.pi)


def _lines(path: Path) -> Iterator[tuple[int, str]]:
    """``(line number, line)`` of a plain or gzip text file, read one line at a time; a line
    over :data:`MAX_LINE_CHARS` or a file whose first :data:`SNIFF_LINES` non-comment lines
    hold no CARMEN message is refused."""
    try:
        with open(path, "rb") as fh:
            magic = fh.read(2)
        raw = gzip.open(path, "rb") if magic == b"\x1f\x8b" else open(path, "rb")  # noqa: SIM115
    except FileNotFoundError:
        raise CarmenLogError(path, [("", "file not found")]) from None
    except OSError as exc:
        raise CarmenLogError(path, [("", f"cannot read file: {exc}")]) from None
    seen = carmen_like = 0
    ln = 0
    with io.TextIOWrapper(raw, encoding="utf-8", errors="replace") as fh:
        while True:
            try:
                line = fh.readline(MAX_LINE_CHARS)
            except (OSError, EOFError) as exc:
                raise CarmenLogError(
                    path, [("", f"cannot read file at line {ln + 1}: {exc}")]
                ) from None
            if not line:
                break
            ln += 1
            if len(line) >= MAX_LINE_CHARS and not line.endswith("\n"):
                raise CarmenLogError(
                    path,
                    [(f"line {ln}", f"longer than {MAX_LINE_CHARS} characters: not a CARMEN log")],
                )
            tok = line.split(maxsplit=1)
            if tok and not tok[0].startswith("#") and seen < SNIFF_LINES:
                seen += 1
                carmen_like += bool(_MESSAGE_NAME.match(tok[0]))
                if seen == SNIFF_LINES and not carmen_like:
                    raise CarmenLogError(path, [(f"lines 1-{ln}", _not_carmen(line))])
            yield ln, line
    if seen and not carmen_like:
        raise CarmenLogError(
            path, [(f"lines 1-{ln}", "no line is a CARMEN message: not a CARMEN log")]
        )


def _not_carmen(line: str) -> str:
    """The message for a file whose first lines are no CARMEN messages."""
    head = line.strip()[:40]
    return (
        f"none of the first {SNIFF_LINES} lines is a CARMEN message (the last begins "
        f"{head!r}): not a CARMEN log"
    )


@dataclass
class _LaserMsg:
    line: int
    stamp: float
    ranges: NDArray[np.float32]
    start: float
    fov: float
    res: float
    max_range: float
    laser_pose: FloatArray | None
    robot_pose: FloatArray | None
    odom_pose: FloatArray | None


def _floats(tok: list[str], a: int, b: int, where: str, errs: list[tuple[str, str]]) -> FloatArray:
    """Fields ``a..b-1`` as numbers; a missing, non-numeric or non-finite field is an error."""
    try:
        v = np.array([float(t) for t in tok[a:b]], dtype=np.float64)
    except ValueError:
        errs.append((where, f"expected numbers in fields {a}..{b - 1}"))
        return np.zeros(max(b - a, 0))
    if len(v) < b - a:
        errs.append((where, f"expected {b - a} numbers in fields {a}..{b - 1}, found {len(v)}"))
        return np.zeros(b - a)
    bad = np.flatnonzero(~np.isfinite(v))
    if len(bad):
        errs.append((where, f"field {a + int(bad[0])} is {tok[a + int(bad[0])]!r}, not finite"))
    return v


def _number(tok: list[str], i: int, where: str, errs: list[tuple[str, str]]) -> float:
    """Field ``i`` as a finite number (an error otherwise)."""
    return float(_floats(tok, i, i + 1, where, errs)[0])


def _parse_laser(tok: list[str], ln: int, errs: list[tuple[str, str]]) -> _LaserMsg | None:
    """The laser message of a ``FLASER``/``RLASER``/``ROBOTLASERk``/``RAWLASERk`` line."""
    kind = tok[0]
    where = f"line {ln}"
    n_err = len(errs)
    try:
        if kind in ("FLASER", "RLASER"):
            n = int(tok[1])
            if len(tok) < 2 + n + 6 + 1:
                errs.append((where, f"{kind} with {n} readings needs {n + 9} fields"))
                return None
            r = _floats(tok, 2, 2 + n, f"{where}.ranges", errs)
            p = _floats(tok, 2 + n, 2 + n + 6, f"{where}.pose", errs)
            stamp = _number(tok, 2 + n + 6, f"{where}.timestamp", errs)
            fov = guess_fov_rad(n)
            if len(errs) > n_err:
                return None
            return _LaserMsg(
                ln, stamp, r.astype(np.float32), -fov / 2, fov, fov / max(n - 1, 1), 0.0,
                p[:3], None, p[3:6],
            )  # fmt: skip
        # ROBOTLASERk / RAWLASERk
        hdr = _floats(tok, 1, 7, f"{where}.header", errs)
        n = int(tok[8])
        r = _floats(tok, 9, 9 + n, f"{where}.ranges", errs)
        n_rem = int(tok[9 + n])
        i = 10 + n + n_rem
        laser_pose = robot_pose = None
        if kind.startswith("ROBOTLASER"):
            poses = _floats(tok, i, i + 6, f"{where}.pose", errs)
            laser_pose, robot_pose = poses[:3], poses[3:6]
            i += 11
        stamp = _number(tok, i, f"{where}.timestamp", errs)
        if len(errs) > n_err:
            return None
        max_range = hdr[4] if hdr[4] > 0 else 80.0
        r = np.where(r >= max_range, np.inf, r)  # no return (the line states the maximum)
        return _LaserMsg(
            ln, stamp, r.astype(np.float32), hdr[1], hdr[2], hdr[3], max_range, laser_pose,
            robot_pose, robot_pose,
        )  # fmt: skip
    except (ValueError, IndexError):
        errs.append((where, f"malformed {kind} line"))
        return None


def saturation_range(ranges: FloatArray, min_share: float = 1e-3) -> float | None:
    """The maximum range of an old ``FLASER`` log, which does not state it: the largest
    reading when at least ``min_share`` of all readings equal it (a scanner prints "no
    return" as its maximum, e.g. 50.00 or 81.91 m, over and over); ``None`` otherwise."""
    finite = ranges[np.isfinite(ranges)]
    if finite.size == 0:
        return None
    top = float(finite.max())
    if top < 4.0 or np.mean(finite >= top - 1e-6) < min_share:
        return None
    return top


def interpolate_poses(t_src: FloatArray, poses: FloatArray, t: FloatArray) -> FloatArray:
    """Poses ``(N, 3)`` at times ``t`` by linear interpolation (heading unwrapped), clamped."""
    order = np.argsort(t_src, kind="stable")
    ts, ps = t_src[order], poses[order]
    th = np.unwrap(ps[:, 2])
    out = np.column_stack(
        [np.interp(t, ts, ps[:, 0]), np.interp(t, ts, ps[:, 1]), np.interp(t, ts, th)]
    )
    out[:, 2] = se2.wrap_angle(out[:, 2])
    return out


@dataclass(frozen=True)
class OdometryAgreement:
    """How the ``ODOM`` lines, interpolated to the scan times, compare with the laser lines'
    odometry over the ``n_compared`` scans within the ``ODOM`` lines' time span: ``share``
    within :data:`ODOM_AGREEMENT_M` and :data:`ODOM_AGREEMENT_RAD`, translation median and
    max [m], rotation median and max [rad]; ``n_back`` ``ODOM`` time stamps that go back."""

    n_compared: int
    share: float
    median_m: float
    max_m: float
    median_rad: float
    max_rad: float
    n_back: int

    @property
    def agrees(self) -> bool:
        """The ``ODOM`` lines are the laser lines' odometry stream."""
        return self.n_compared > 0 and self.share >= ODOM_AGREEMENT_SHARE

    def describe(self) -> str:
        """The figures, for a message."""
        if self.n_compared == 0:
            return "no scan lies within the ODOM lines' time span"
        text = (
            f"they differ by {self.median_m:.3g} m median, {self.max_m:.3g} m max "
            f"({self.median_rad:.3g} / {self.max_rad:.3g} rad); "
            f"{100 * self.share:.0f} % of {self.n_compared} scans agree to "
            f"{ODOM_AGREEMENT_M:g} m and {ODOM_AGREEMENT_RAD:g} rad"
        )
        return text + (f"; {self.n_back} ODOM time stamps go back" if self.n_back else "")


def odometry_agreement(
    odom_t: FloatArray, odom_p: FloatArray, stamps: FloatArray, laser_odo: FloatArray
) -> OdometryAgreement:
    """Compare the ``ODOM`` lines ``(odom_t, odom_p)`` with the laser lines' odometry
    ``laser_odo`` ``(T, 3)`` at the scan ``stamps`` (see :class:`OdometryAgreement`)."""
    inside = (stamps >= odom_t.min()) & (stamps <= odom_t.max())
    n_back = int(np.sum(np.diff(odom_t) < 0))
    if not inside.any():
        return OdometryAgreement(0, 0.0, math.nan, math.nan, math.nan, math.nan, n_back)
    d = interpolate_poses(odom_t, odom_p, stamps[inside]) - laser_odo[inside]
    trans = np.hypot(d[:, 0], d[:, 1])
    rot = np.abs(se2.wrap_angle(d[:, 2]))
    ok = (trans <= ODOM_AGREEMENT_M) & (rot <= ODOM_AGREEMENT_RAD)
    return OdometryAgreement(
        int(inside.sum()),
        float(ok.mean()),
        float(np.median(trans)),
        float(trans.max()),
        float(np.median(rot)),
        float(rot.max()),
        n_back,
    )


def unsigned_reversals(odom_p: FloatArray, odom_tv: FloatArray) -> NDArray[np.bool_]:
    """``(N - 1,)``: which ``ODOM`` increments ``odom_p[k] -> odom_p[k + 1]`` move forward along
    the heading by over :data:`REVERSAL_MIN_STEP_M` while the later line's velocity
    ``odom_tv[k + 1]`` is below ``-REVERSAL_MIN_SPEED_MPS`` (a reversing base whose poses were
    integrated without the sign; module docstring)."""
    if len(odom_p) < 2:
        return np.zeros(0, dtype=bool)
    inc = se2.between(odom_p[:-1], odom_p[1:])
    return (inc[:, 0] > REVERSAL_MIN_STEP_M) & (odom_tv[1:] < -REVERSAL_MIN_SPEED_MPS)


def repair_reversals(odom_p: FloatArray, flagged: NDArray[np.bool_]) -> FloatArray:
    """The ``ODOM`` poses integrated again from their increments, with the translation of the
    ``flagged`` increments (:func:`unsigned_reversals`) negated in the robot frame."""
    if len(odom_p) < 2:
        return odom_p.copy()
    inc = se2.between(odom_p[:-1], odom_p[1:])
    inc[flagged, :2] *= -1.0
    out = np.empty_like(odom_p)
    out[0] = odom_p[0]
    for k in range(len(inc)):
        out[k + 1] = se2.compose(out[k], inc[k])
    return out


def one_trajectory(laser_pose: FloatArray, laser_odo: FloatArray) -> bool:
    """Whether the laser lines' pose is their odometry plus a fixed mount (a raw log, or a
    corrected one that wrote its poses into both fields), to :data:`ONE_TRAJECTORY_TOL`."""
    rel = se2.between(laser_odo, laser_pose)
    d = rel - rel[0]
    d[:, 2] = se2.wrap_angle(d[:, 2])
    return bool(np.abs(d).max() <= ONE_TRAJECTORY_TOL)


def choose_odometry(
    path: Path,
    kind: str,
    mode: str,
    odom_t: FloatArray,
    odom_p: FloatArray,
    stamps: FloatArray,
    laser_odo: FloatArray | None,
    laser_pose: FloatArray | None,
    odom_out: FloatArray | None = None,
) -> tuple[FloatArray, str, str | None]:
    """The odometry at the scan ``stamps``, its source and, when ``mode`` is ``"auto"`` and
    the ``ODOM`` lines are not shown to be raw, the warning to give (module docstring).

    ``odom_t``/``odom_p`` the ``ODOM`` lines (may be empty), ``laser_odo``/``laser_pose`` the
    ``kind`` lines' odometry and pose fields (``None``: the lines carry none); ``odom_out``
    the ``ODOM`` poses to interpolate when those lines are taken (default ``odom_p``; e.g.
    with reversals repaired, :func:`repair_reversals`: ``odom_p`` as logged is what is
    compared with the laser lines).
    """
    if odom_out is None:
        odom_out = odom_p
    have_odom = len(odom_t) > 0
    if mode == "odom-lines" or (mode == "auto" and laser_odo is None and have_odom):
        if not have_odom:
            raise CarmenLogError(path, [("odometry", "odom-lines: the log has no ODOM lines")])
        return interpolate_poses(odom_t, odom_out, stamps), "odom-lines", None
    if laser_odo is None:
        why = "no ODOM lines and " if mode == "auto" else "laser-lines: "
        raise CarmenLogError(path, [("odometry", f"{why}{kind} lines carry no odometry")])
    if mode == "laser-lines" or not have_odom:
        return laser_odo, "laser-lines", None
    agreement = odometry_agreement(odom_t, odom_p, stamps, laser_odo)
    if agreement.agrees:  # one raw stream: the ODOM lines, as CARMEN's logger wrote them
        return interpolate_poses(odom_t, odom_out, stamps), "odom-lines", None
    note = (
        f"{path}: odometry from the {kind} lines' odometry fields, not the ODOM lines: "
        f"interpolated to the scan times, the ODOM lines are not the laser lines' odometry "
        f"({agreement.describe()}), so they are not the raw odometry the scans were logged with."
    )
    if laser_pose is not None and one_trajectory(laser_pose, laser_odo):
        note += (
            f" The {kind} lines' pose and odometry fields are identical (up to a fixed mount): "
            "this looks like a corrected log; its odometry is not raw wheel odometry (it "
            "follows the log's own poses)."
        )
    note += " odometry='odom-lines' (--odometry odom-lines) takes the ODOM lines instead."
    return laser_odo, "laser-lines", note


def read_carmen(
    path: str | Path,
    laser_id: int = 1,
    max_errors: int = 20,
    odometry: str = "auto",
    reversals: str = "repair",
) -> CarmenLog:
    """Read one laser (``laser_id`` 1 = front, 2 = rear, 3/4 raw) of a CARMEN log, its
    odometry from ``odometry`` (one of :data:`ODOMETRY_SOURCES`, :func:`choose_odometry`),
    ``ODOM`` increments that move forward while the base reverses repaired or kept as
    ``reversals`` says (:data:`REVERSAL_MODES`, module docstring)."""
    p = Path(path)
    if laser_id not in LASER_TYPES:
        raise CarmenLogError(p, [("laser_id", f"must be one of {sorted(LASER_TYPES)}")])
    if odometry not in ODOMETRY_SOURCES:
        raise CarmenLogError(
            p, [("odometry", f"must be one of {', '.join(ODOMETRY_SOURCES)}, not {odometry!r}")]
        )
    if reversals not in REVERSAL_MODES:
        raise CarmenLogError(
            p, [("reversals", f"must be one of {', '.join(REVERSAL_MODES)}, not {reversals!r}")]
        )
    msgs, kind, odom_t, odom_arr, odom_tv = _scan_file(p, laser_id, max_errors)
    laser, ranges = _laser_and_ranges(p, kind, msgs)
    stamps = np.array([m.stamp for m in msgs])
    steps = np.diff(stamps)
    if np.any(steps < 0):
        k = int(np.argmax(steps < 0)) + 1
        raise CarmenLogError(
            p,
            [
                (
                    f"line {msgs[k].line}",
                    f"time stamps go back at scan {k} ({stamps[k - 1]:.6f} -> {stamps[k]:.6f})",
                )
            ],
        )
    if np.any(steps == 0):
        warnings.warn(
            f"{p}: {int(np.sum(steps == 0))} of {len(stamps)} scans have the time stamp of the "
            "scan before (too few digits?): they cannot be told apart by time",
            stacklevel=2,
        )
    mount = np.asarray(laser.mount_pose, dtype=np.float64)
    laser_odo = np.array([m.odom_pose for m in msgs]) if msgs[0].odom_pose is not None else None
    lp = np.array([m.laser_pose for m in msgs]) if msgs[0].laser_pose is not None else None
    flagged = unsigned_reversals(odom_arr, odom_tv)
    repair = reversals == "repair" and bool(flagged.any())
    odom_out = repair_reversals(odom_arr, flagged) if repair else odom_arr
    odo, source, note = choose_odometry(
        p, kind, odometry, odom_t, odom_arr, stamps, laser_odo, lp, odom_out
    )
    if note is not None:
        warnings.warn(note, CarmenOdometryWarning, stacklevel=2)
    if flagged.any():
        n_flag = int(flagged.sum())
        text = (
            f"{p}: {n_flag} of {len(flagged)} ODOM increments move forward along the heading "
            "while their line's velocity tv is negative (the base reversing): the poses were "
            "integrated without the sign. "
        )
        if source != "odom-lines":
            text += f"The odometry comes from the {kind} lines, which are kept as logged."
        elif reversals == "repair":
            text += (
                "Their translation is negated (reversals='repair'); "
                "--odometry-reversals keep takes them as logged."
            )
        else:
            text += "They are kept as logged (reversals='keep')."
        warnings.warn(text, CarmenOdometryWarning, stacklevel=2)
    reference = None
    if lp is not None:
        reference = se2.compose(lp, np.broadcast_to(se2.inverse(mount), lp.shape))
    return CarmenLog(
        p, laser, stamps, ranges, odo, reference, kind, source, int(flagged.sum()), reversals
    )


def _scan_file(p: Path, laser_id: int, max_errors: int) -> tuple:
    """One pass over the log's lines: ``(laser messages, their type, ODOM stamps, poses
    (N, 3), velocities)``, the laser messages of the first of :data:`LASER_TYPES` present."""
    errs: list[tuple[str, str]] = []
    odom_t: list[float] = []
    odom_p: list[FloatArray] = []
    odom_tv: list[float] = []
    by_kind: dict[str, list[_LaserMsg]] = {k: [] for k in LASER_TYPES[laser_id]}
    for ln, line in _lines(p):
        tok = line.split()
        if not tok or tok[0].startswith("#"):
            continue
        if tok[0] == "ODOM":
            if len(tok) < 8:
                errs.append((f"line {ln}", "ODOM needs x y theta tv rv accel timestamp"))
                continue
            v = _floats(tok, 1, 8, f"line {ln}", errs)
            odom_p.append(v[:3])
            odom_tv.append(float(v[3]))
            odom_t.append(float(v[6]))
        elif tok[0] in by_kind:
            msg = _parse_laser(tok, ln, errs)
            if msg is not None:
                by_kind[tok[0]].append(msg)
        if len(errs) >= max_errors:
            break
    if errs:
        raise CarmenLogError(p, errs)
    kind = next((k for k in LASER_TYPES[laser_id] if by_kind[k]), None)
    if kind is None:
        raise CarmenLogError(
            p, [("", f"no laser lines of types {', '.join(LASER_TYPES[laser_id])}")]
        )
    odom = np.array(odom_p).reshape(-1, 3)
    return by_kind[kind], kind, np.array(odom_t), odom, np.array(odom_tv)


def _laser_and_ranges(
    p: Path, kind: str, msgs: list[_LaserMsg]
) -> tuple[LaserSpec, NDArray[np.float32]]:
    """The laser of the messages and their ranges ``(T, n_beams)`` (REP-117). Scans with
    their own start angle or beam count (an interlaced scanner) are placed on one common
    beam grid (:mod:`.beam_grid`)."""
    m0 = msgs[0]
    mount = (0.0, 0.0, 0.0)
    if m0.laser_pose is not None and m0.robot_pose is not None:
        off = se2.between(m0.robot_pose, m0.laser_pose)
        mount = (float(off[0]), float(off[1]), float(off[2]))
    if kind in ("FLASER", "RLASER"):  # no maximum range on the line: find the saturation
        n = len(m0.ranges)
        bad = [m.line for m in msgs if len(m.ranges) != n]
        if bad:
            raise CarmenLogError(
                p, [(f"line {bad[0]}", f"{len(bad)} lines have a beam count other than {n}")]
            )
        ranges = np.array([m.ranges for m in msgs], dtype=np.float32)
        sat = saturation_range(ranges)
        max_range = sat if sat is not None else 80.0
        ranges[ranges >= max_range] = np.inf
    else:
        max_range = float(m0.max_range)
        counts = np.array([len(m.ranges) for m in msgs])
        incs = np.array([m.res if m.res > 0 else m.fov / max(len(m.ranges) - 1, 1) for m in msgs])
        grid = beam_grid(np.array([m.start for m in msgs]), incs, counts)
        if isinstance(grid, str):
            raise CarmenLogError(p, [(kind, f"the scans share no beam layout: {grid}")])
        ranges = grid.place([m.ranges for m in msgs])
    ranges[ranges <= 0.0] = np.nan
    laser = LaserSpec(
        name=f"carmen-{kind.lower()}",
        n_beams=ranges.shape[1],
        angle_min_rad=float(msgs[0].start) if kind in ("FLASER", "RLASER") else grid.angle_min_rad,
        angle_increment_rad=float(m0.res) if kind in ("FLASER", "RLASER") else grid.increment_rad,
        range_min_m=0.0,
        range_max_m=max_range,
        scan_period_s=0.0,
        time_increment_s=0.0,
        mount_pose=mount,
    )
    return laser, ranges
