"""Watching a run: a video of one stored run (``dynmap-sim video``, extra ``video``).

One frame per stored scan, drawn from the results store alone (the simulator is not run
again) with the numpy rasterizer the env renders with (:mod:`dynmap_sim.raster`):

* the world's obstacles as stored for the run (its static segments, coloured by class:
  walls, furniture, doors, exhibits);
* the route and, when the driver stored one, its last planned path (``planned_path.f8``);
* the long-term map (highest timescale, e.g. λ5) of a ``dynamic-map`` localizer: its last
  daily snapshot before the run's day, the map it localized on (when stored);
* the true pose (blue disc, heading, trail) and each chosen localizer's estimate (its colour,
  heading, trail); a header with the day, run, date and clock, the time in the run, each
  localizer's position error, the bumper and the latest event (kidnapping, detour, ...);
* the scan's returns from the true pose and the people (red discs of their body radius), when
  the experiment kept them (``run --keep-scans``).

Not drawn: the scan and the people of an experiment run without ``--keep-scans``; watch
those live with the env's ``render()``.

MP4 is encoded by the ffmpeg that ships with the ``imageio-ffmpeg`` wheel (H.264, yuv420p),
GIF by Pillow (for short runs: its frames are held in memory); either is written to a
temporary file that replaces the output only when complete.
"""

from __future__ import annotations

import datetime as dt
import math
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from dynmap_sim.errors import InputError
from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.raster import CLASS_RGB, Canvas, polyline
from dynmap_sim.types import BeamClass

#: Output formats by suffix.
SUFFIXES = (".mp4", ".gif")
#: What a video cannot show, and why (the CLI's help and note say it too).
NO_SCANS = "the experiment kept no laser ranges (run it with --keep-scans), so no scan is drawn"
NO_PEOPLE = "the experiment kept no people (run it with --keep-scans), so none is drawn"
#: Seconds an event stays in the header.
EVENT_HOLD_S = 3.0

_TRUTH = np.array([60, 60, 200], np.uint8)
_ROUTE = np.array([200, 200, 235], np.uint8)
_PLANNED = np.array([20, 170, 190], np.uint8)
_MAP = np.array([175, 175, 175], np.uint8)
_SCAN = np.array([230, 40, 160], np.uint8)
_TEXT = np.array([30, 30, 30], np.uint8)
_ALERT = np.array([210, 30, 30], np.uint8)
#: Localizer colours (matplotlib's tab10 without its blue, which is the truth's).
_PALETTE = np.array(
    [
        [255, 127, 14],
        [44, 160, 44],
        [214, 39, 40],
        [148, 103, 189],
        [140, 86, 75],
        [227, 119, 194],
        [188, 189, 34],
        [127, 127, 127],
    ],
    dtype=np.uint8,
)
_MARKER_M = 0.18  # radius of the true pose's disc [m]
_HEADING_M = 0.4


@dataclass
class VideoResult:
    """What :func:`write_video` wrote."""

    path: Path
    n_frames: int
    fps: int
    size_px: tuple[int, int]  # (width, height)
    encode_s: float
    notes: list[str] = field(default_factory=list)

    @property
    def duration_s(self) -> float:
        return self.n_frames / self.fps


@dataclass
class _Run:
    """One run's stored data, as the frames need it."""

    title: str
    date: str
    t_s: NDArray[np.float64]
    truth: NDArray[np.float64]
    collision: NDArray[np.bool_]
    labels: list[str]
    estimates: list[NDArray[np.float64]]  # per label (T, 3), NaN where not stored
    errors: list[NDArray[np.float64]]  # per label (T,)
    segments: NDArray[np.float64]
    segment_class: NDArray[np.int8]
    route: NDArray[np.float64]
    planned: NDArray[np.float64] | None
    map_points: NDArray[np.float64] | None
    map_note: str
    #: returns of each scan in the map frame from the true pose ``(T, n_beams, 2)``, NaN
    #: where a beam has none; None when the ranges were not kept
    scan_xy: NDArray[np.float64] | None
    #: the people at each scan ``(T, n, 3)`` ``x, y, radius`` [m] (NaN: not on the floor);
    #: None when they were not kept
    people: NDArray[np.float64] | None
    events: list[tuple[float, str]]  # (t_s, text)
    bounds: tuple[float, float, float, float]
    fps: int


def _ranges(values: Sequence[int]) -> str:
    """``1-3, 5`` for ``[1, 2, 3, 5]``."""
    out: list[str] = []
    vals = sorted(set(values))
    i = 0
    while i < len(vals):
        j = i
        while j + 1 < len(vals) and vals[j + 1] == vals[j] + 1:
            j += 1
        out.append(str(vals[i]) if i == j else f"{vals[i]}-{vals[j]}")
        i = j + 1
    return ", ".join(out)


def _plural(what: str, values: Sequence[int]) -> str:
    """``day 1`` or ``days 1-3, 5``."""
    return f"{what}{'s' if len(set(values)) > 1 else ''} {_ranges(values)}"


def check_output(path: str | Path, force: bool) -> Path:
    """The output file: suffix ``.mp4`` or ``.gif``; an existing file only with ``force``."""
    p = Path(path)
    if p.suffix.lower() not in SUFFIXES:
        raise InputError(f"-o {path}: a video is .mp4 or .gif, not {p.suffix or 'no suffix'!r}")
    if p.exists() and not force:
        raise InputError(f"-o {path}: the file exists; pass --force to replace it")
    return p


def check_run(db: ResultsDB, day: int, run: int) -> None:
    """InputError unless ``db`` holds a finished run ``day``/``run`` (naming what it holds)."""
    runs = [(int(d), int(r)) for d, r in db.query("SELECT day, run FROM runs ORDER BY day, run")]
    where = db.path.parent
    if not runs:
        raise InputError(f"{where}: no finished run to show")
    days = sorted({d for d, _ in runs})
    if day not in days:
        raise InputError(f"--day {day}: {where} holds {_plural('day', days)}")
    in_day = [r for d, r in runs if d == day]
    if run not in in_day:
        raise InputError(f"--run {run}: day {day} of {where} holds {_plural('run', in_day)}")


def check_labels(db: ResultsDB, chosen: Sequence[str] | None) -> list[str]:
    """The localizer labels to draw (all when ``chosen`` is empty), in store order."""
    labels = db.labels()
    if not chosen:
        return labels
    unknown = [c for c in chosen if c not in labels]
    if unknown:
        raise InputError(
            f"--localizer {unknown[0]}: not in this results folder; its localizers: "
            + ", ".join(labels)
        )
    return [label for label in labels if label in chosen]


def _fps(meta: dict[str, Any], t_s: NDArray[np.float64]) -> int:
    """Real time: the laser's scan rate (else the median step of the stamps; else 10)."""
    period = (meta.get("laser") or {}).get("scan_period_s")
    if not (isinstance(period, int | float) and period > 0) and len(t_s) > 1:
        period = float(np.median(np.diff(t_s)))
    if not (isinstance(period, int | float) and math.isfinite(period) and period > 0):
        return 10
    return max(1, round(1.0 / period))


def _dynamic_map(db: ResultsDB, day: int, labels: list[str]) -> tuple[NDArray | None, str]:
    """The points of the highest timescale of the first ``dynamic-map``'s last snapshot
    before ``day`` (the map it localized on), and a legend text; ``(None, "")`` without."""
    from dynmap_sim.studies.biber_duckett.map_structure import dynamic_map_snapshots

    rows = db.query("SELECT idx, label, name FROM localizers ORDER BY idx")
    dyn = [label for _, label, name in rows if name == "dynamic-map"]
    if not dyn or dyn[0] not in labels:
        return None, ""
    before = [(d, s) for d, s in dynamic_map_snapshots(db) if d < day]
    if not before:
        return None, ""
    snap_day, snap = before[-1]
    for level in sorted(snap.levels, reverse=True):
        pts = [snap.points(i, level) for i in range(len(snap.centres))]
        xy = np.concatenate(pts, axis=0) if pts else np.zeros((0, 2))
        if len(xy):
            return xy, f"{dyn[0]} map λ{level} (day {snap_day})"
    return None, ""


def load_run(db: ResultsDB, day: int, run: int, labels: list[str], fps: int | None = None) -> _Run:
    """Everything one run's frames draw, read from the store."""
    meta = db.meta()
    steps = db.query(
        "SELECT step, t_s, x, y, theta, collision FROM scans WHERE day=? AND run=? ORDER BY step",
        (day, run),
    )
    a = np.array(steps, dtype=np.float64).reshape(-1, 6)
    step_index = {int(s): i for i, s in enumerate(a[:, 0])}
    all_labels = db.labels()
    estimates, errors = [], []
    for label in labels:
        d = db.per_scan(all_labels.index(label), day, run)
        est = np.full((len(a), 3), np.nan)
        err = np.full(len(a), np.nan)
        idx = np.array([step_index.get(int(s), -1) for s in d["step"]], dtype=int)
        ok = idx >= 0
        est[idx[ok]] = d["estimate"][ok]
        err[idx[ok]] = d["err_m"][ok]
        estimates.append(est)
        errors.append(err)
    geo = db.geometry(day, run)
    seg, cls = geo if geo is not None else (np.zeros((0, 4)), np.zeros(0, np.int8))
    route = np.asarray(meta.get("route") or np.zeros((0, 2)), float).reshape(-1, 2)
    planned = next(
        (
            np.frombuffer(b, dtype="<f8").reshape(-1, 2)
            for d, r, b in db.driver_artifacts("planned_path.f8")
            if (d, r) == (day, run)
        ),
        None,
    )
    map_points, map_note = _dynamic_map(db, day, labels)
    ranges = db.scan_ranges(day, run)
    laser = meta.get("laser")
    scan_xy = None
    if ranges is not None and laser is not None and len(ranges) == len(a):
        scan_xy = _returns_xy(a[:, 2:5], ranges, laser)
    track = db.scan_people(day, run)
    people = None
    if track is not None and len(track.xy) == len(a):
        radius = np.broadcast_to(track.radius_m, track.xy.shape[:2])[..., None]
        people = np.concatenate([track.xy, radius], axis=2)
    events = [
        (float(t), f"{kind}: {detail}" if detail else str(kind))
        for t, kind, detail in db.query(
            "SELECT t_s, kind, detail FROM events WHERE day=? AND run=? ORDER BY step",
            (day, run),
        )
        if t is not None
    ]
    date = db.query("SELECT date FROM runs WHERE day=? AND run=?", (day, run))[0][0] or ""
    name = meta.get("scenario_name") or meta.get("world") or db.path.parent.name
    bounds = meta.get("bounds")
    if not (isinstance(bounds, list) and len(bounds) == 4):
        bounds = _extent([a[:, 2:4], seg[:, :2], seg[:, 2:], *(e[:, :2] for e in estimates)])
    return _Run(
        title=f"{name}  day {day} run {run}",
        date=str(date),
        t_s=a[:, 1],
        truth=a[:, 2:5],
        collision=a[:, 5] > 0,
        labels=labels,
        estimates=estimates,
        errors=errors,
        segments=seg,
        segment_class=cls,
        route=route,
        planned=planned,
        map_points=map_points,
        map_note=map_note,
        scan_xy=scan_xy,
        people=people,
        events=events,
        bounds=tuple(float(b) for b in bounds),  # type: ignore[arg-type]
        fps=fps if fps is not None else _fps(meta, a[:, 1]),
    )


def _returns_xy(
    pose: NDArray[np.float64], ranges: NDArray[np.float32], laser: dict[str, Any]
) -> NDArray[np.float64]:
    """Scan returns ``(T, n_beams, 2)`` in the map frame: each beam's end from the laser's
    pose (``pose`` ∘ mount); NaN for no return (REP-117 ±inf) and invalid readings."""
    mx, my, mth = (float(v) for v in laser.get("mount_pose", (0.0, 0.0, 0.0)))
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    lx = pose[:, 0] + c * mx - s * my
    ly = pose[:, 1] + s * mx + c * my
    n = ranges.shape[1]
    angles = float(laser["angle_min_rad"]) + np.arange(n) * float(laser["angle_increment_rad"])
    th = (pose[:, 2] + mth)[:, None] + angles[None, :]
    r = np.where(np.isfinite(ranges), ranges, np.nan).astype(np.float64)
    return np.stack([lx[:, None] + r * np.cos(th), ly[:, None] + r * np.sin(th)], axis=-1)


def _extent(parts: list[NDArray[np.float64]], margin_m: float = 0.5) -> list[float]:
    """The bounding box of the finite points of ``parts`` with a margin (a folder without
    stored bounds, e.g. a replay)."""
    xy = np.concatenate([p.reshape(-1, 2) for p in parts], axis=0)
    xy = xy[np.isfinite(xy).all(axis=1)]
    if not len(xy):
        return [-1.0, -1.0, 1.0, 1.0]
    lo, hi = xy.min(axis=0) - margin_m, xy.max(axis=0) + margin_m
    return [float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])]


class _Font:
    """Monospaced text drawn into numpy images (matplotlib's FreeType font, no figure)."""

    def __init__(self, size_pt: float = 10.0, dpi: int = 100) -> None:
        from matplotlib import font_manager, ft2font

        path = font_manager.findfont(font_manager.FontProperties(family="DejaVu Sans Mono"))
        self.font = ft2font.FT2Font(path)
        self.size = (size_pt, dpi)
        self.font.set_size(*self.size)
        self.font.set_text("M" * 10)
        self.advance = self.font.get_width_height()[0] / 64 / 10
        self.line_px = int(math.ceil(size_pt * dpi / 72 * 1.5))

    def draw(self, img: NDArray[np.uint8], x: float, y: int, text: str, rgb: NDArray) -> float:
        """Draw ``text`` with its baseline at row ``y`` from column ``x``; the column after it."""
        if not text:
            return x
        self.font.set_size(*self.size)
        self.font.set_text(text)
        self.font.draw_glyphs_to_bitmap(antialiased=True)
        alpha = np.asarray(self.font.get_image(), dtype=np.float32) / 255.0
        top = y - int(round((self.font.get_width_height()[1] - self.font.get_descent()) / 64))
        left = int(round(x))
        h, w = alpha.shape
        r0, c0 = max(top, 0), max(left, 0)
        r1, c1 = min(top + h, img.shape[0]), min(left + w, img.shape[1])
        if r1 > r0 and c1 > c0:
            a = alpha[r0 - top : r1 - top, c0 - left : c1 - left, None]
            region = img[r0:r1, c0:c1].astype(np.float32)
            img[r0:r1, c0:c1] = (region * (1.0 - a) + rgb.astype(np.float32) * a).astype(np.uint8)
        return x + len(text) * self.advance


def _heading(pose: NDArray[np.float64], length_m: float) -> NDArray[np.float64]:
    x, y, th = pose
    return np.array([[x, y, x + length_m * math.cos(th), y + length_m * math.sin(th)]])


def _lighter(rgb: NDArray[np.uint8], f: float = 0.5) -> NDArray[np.uint8]:
    return (255 - (255 - rgb.astype(np.float64)) * f).astype(np.uint8)


class _Frames:
    """The frames of one run: a static layer (obstacles, route, map, planned path), trails
    drawn into a second layer scan by scan, the current poses and the header on top."""

    def __init__(self, run: _Run, size_px: int) -> None:
        self.run = run
        self.font = _Font()
        lh = self.font.line_px
        canvas = Canvas(run.bounds, size_px)
        self.canvas = canvas
        canvas.lines(polyline(run.route), _ROUTE)
        if run.map_points is not None:
            canvas.points(run.map_points, _MAP)
        canvas.lines(run.segments, CLASS_RGB[run.segment_class])
        if run.planned is not None and len(run.planned) > 1:
            canvas.lines(polyline(run.planned), _PLANNED)
        self.colors = [_PALETTE[k % len(_PALETTE)] for k in range(len(run.labels))]
        self.header_px = 3 * lh + lh // 2
        self.footer_px = lh + lh // 2
        self.start = run.t_s[0] if len(run.t_s) else 0.0
        self.total = run.t_s[-1] - self.start if len(run.t_s) else 0.0
        self.legend = [("route", _ROUTE)]
        if run.planned is not None:
            self.legend.append(("planned path", _PLANNED))
        if run.map_note:
            self.legend.append((run.map_note, _MAP))
        self.legend += [
            ("walls", CLASS_RGB[1]),
            ("furniture", CLASS_RGB[2]),
            ("doors", CLASS_RGB[4]),
        ]
        if run.scan_xy is not None:
            self.legend.append(("scan", _SCAN))
        if run.people is not None:
            self.legend.append(("people", CLASS_RGB[BeamClass.PERSON]))
        missing = [w for w, x in (("scans", run.scan_xy), ("people", run.people)) if x is None]
        if missing:
            self.legend.append((f"(no {' or '.join(missing)} stored)", _MAP))
        chars = [  # the longest text of each line (monospaced: width = chars x advance)
            len(self._title(self.start + 86399.0)),
            sum(len(label) + 9 for label in ["truth", *run.labels]),
            sum(len(text) + 2 for text, _ in self.legend),
        ]
        width = max(canvas.w, 480, int(math.ceil(max(chars) * self.font.advance)) + 12)
        self.width = -(-width // 16) * 16  # H.264 wants multiples of the macroblock
        self.height = -(-(self.header_px + canvas.h + self.footer_px) // 16) * 16
        self.map_left = (self.width - canvas.w) // 2
        self.footer = self._footer()

    def _footer(self) -> NDArray[np.uint8]:
        lh = self.font.line_px
        img = np.full((self.footer_px, self.width, 3), 255, np.uint8)
        x = 6.0
        for text, rgb in self.legend:
            x = self.font.draw(img, x, lh, text, np.minimum(rgb, 200).astype(np.uint8)) + 12
        return img

    def _title(self, t: float) -> str:
        clock = str(dt.timedelta(seconds=int(t))) if math.isfinite(t) else "?"
        run = self.run
        return f"{run.title}  {run.date} {clock}  t {t - self.start:.1f}/{self.total:.1f} s"

    def __len__(self) -> int:
        return len(self.run.t_s)

    def __iter__(self) -> Iterator[NDArray[np.uint8]]:
        run, canvas, lh = self.run, self.canvas, self.font.line_px
        trail = canvas.img  # trails accumulate on the static layer
        frame = np.full((self.height, self.width, 3), 255, np.uint8)
        top, left = self.header_px, self.map_left
        frame[top + canvas.h : top + canvas.h + self.footer_px] = self.footer
        for i in range(len(run.t_s)):
            if i > 0:
                canvas.img = trail
                canvas.lines(polyline(run.truth[i - 1 : i + 1, :2]), _lighter(_TRUTH))
                for est, rgb in zip(run.estimates, self.colors, strict=True):
                    seg = polyline(est[i - 1 : i + 1, :2])
                    if np.isfinite(seg).all():
                        canvas.lines(seg, _lighter(rgb))
            canvas.img = trail.copy()
            if run.people is not None:
                here = run.people[i]
                canvas.discs(here[np.isfinite(here[:, 0])], CLASS_RGB[BeamClass.PERSON])
            if run.scan_xy is not None:
                hits = run.scan_xy[i]
                canvas.points(hits[np.isfinite(hits[:, 0])], _SCAN)
            pose = run.truth[i]
            canvas.discs(np.array([[pose[0], pose[1], _MARKER_M]]), _TRUTH)
            canvas.lines(_heading(pose, _HEADING_M), np.array([255, 220, 0], np.uint8))
            for est, rgb in zip(run.estimates, self.colors, strict=True):
                if np.isfinite(est[i]).all():
                    canvas.discs(np.array([[est[i, 0], est[i, 1], _MARKER_M / 2]]), rgb)
                    canvas.lines(_heading(est[i], _HEADING_M), rgb)
            frame[top : top + canvas.h, left : left + canvas.w] = canvas.img
            frame[:top] = 255
            self._header(frame, i, lh)
            yield frame
        canvas.img = trail

    def _header(self, frame: NDArray[np.uint8], i: int, lh: int) -> None:
        run, font = self.run, self.font
        t = float(run.t_s[i])
        font.draw(frame, 6, lh, self._title(t), _TEXT)
        x = font.draw(frame, 6, 2 * lh, "truth", _TRUTH) + 14
        for label, rgb, err in zip(run.labels, self.colors, run.errors, strict=True):
            e = err[i]
            text = f"{label} {e:.2f} m" if math.isfinite(e) else f"{label} -"
            x = font.draw(frame, x, 2 * lh, text, rgb) + 14
        x = 6.0
        if run.collision[i]:
            x = font.draw(frame, x, 3 * lh, "BUMPER", _ALERT) + 14
        recent = [text for te, text in run.events if t - EVENT_HOLD_S <= te <= t]
        if recent:
            font.draw(frame, x, 3 * lh, recent[-1], _ALERT)


class _Writer:
    """Frames into ``path``: .mp4 streamed to imageio-ffmpeg's ffmpeg (H.264); .gif by
    Pillow (matplotlib's own dependency) on one palette made from the first frame, the
    frames kept in memory until :meth:`close` (about 0.4 MB each: for short runs)."""

    def __init__(self, path: Path, size: tuple[int, int], fps: int) -> None:
        self.path, self.fps = path, fps
        self.gif = path.suffix.lower() == ".gif"
        self.images: list[Any] = []
        if not self.gif:
            import imageio_ffmpeg

            self.gen = imageio_ffmpeg.write_frames(
                str(path),
                size,
                fps=fps,
                codec="libx264",
                quality=7,
                macro_block_size=16,
                ffmpeg_log_level="error",
            )
            self.gen.send(None)

    def write(self, frame: NDArray[np.uint8]) -> None:
        if not self.gif:
            self.gen.send(np.ascontiguousarray(frame))
            return
        from PIL import Image

        im = Image.fromarray(frame)
        if not self.images:
            self.palette = im.quantize(colors=256, method=Image.Quantize.MEDIANCUT)
        self.images.append(im.quantize(palette=self.palette, dither=Image.Dither.NONE))

    def close(self, ok: bool = True) -> None:
        if not self.gif:
            self.gen.close()
        elif ok and self.images:
            first, *rest = self.images
            duration = round(1000 / self.fps)
            first.save(self.path, save_all=True, append_images=rest, duration=duration, loop=0)
        self.images = []


def _require_extra(gif: bool) -> None:
    if gif:
        return  # Pillow comes with matplotlib
    try:
        import imageio_ffmpeg  # noqa: F401
    except ImportError:
        raise InputError(
            "videos need the 'video' extra: python -m pip install 'dynmap-sim[video]'"
        ) from None


def write_video(
    results_dir: str | Path,
    day: int,
    run: int,
    out_path: str | Path,
    *,
    fps: int | None = None,
    localizers: Sequence[str] | None = None,
    size_px: int = 640,
    force: bool = False,
    progress: bool = True,
) -> VideoResult:
    """Write a video of run ``day``/``run`` of a results folder to ``out_path`` (.mp4 or
    .gif); one frame per stored scan at ``fps`` (default: the scan rate, i.e. real time),
    the map's longer side ``size_px`` pixels. ``localizers``: labels to draw (default all)."""
    out = check_output(out_path, force)
    if fps is not None and (isinstance(fps, bool) or not isinstance(fps, int) or fps < 1):
        raise InputError(f"--fps must be an integer >= 1, not {fps!r}")
    if isinstance(size_px, bool) or not isinstance(size_px, int) or not 64 <= size_px <= 4096:
        raise InputError(f"--size must be an integer in 64..4096, not {size_px!r}")
    _require_extra(out.suffix.lower() == ".gif")
    with ResultsDB.open(results_dir) as db:
        check_run(db, day, run)
        labels = check_labels(db, localizers)
        data = load_run(db, day, run, labels, fps)
    if not len(data.t_s):
        raise InputError(f"day {day} run {run}: no scans stored, nothing to show")
    frames = _Frames(data, size_px)
    notes = ([] if data.scan_xy is not None else [NO_SCANS]) + (
        [] if data.people is not None else [NO_PEOPLE]
    )
    if data.planned is None:
        notes.append("the driver stored no planned path for this run")
    if len(data.segments) == 0:
        notes.append("the store holds no obstacles for this run")
    tmp = out.with_name(f".{out.stem}.partial{out.suffix}")
    t0 = time.perf_counter()
    from tqdm import tqdm

    try:
        writer = _Writer(tmp, (frames.width, frames.height), data.fps)
        ok = False
        try:
            bar = tqdm(frames, total=len(frames), unit="frame", disable=not progress, leave=False)
            for frame in bar:
                writer.write(frame)
            ok = True
        finally:
            writer.close(ok)
        tmp.replace(out)
    finally:
        tmp.unlink(missing_ok=True)
    return VideoResult(
        path=out,
        n_frames=len(frames),
        fps=data.fps,
        size_px=(frames.width, frames.height),
        encode_s=time.perf_counter() - t0,
        notes=notes,
    )
