"""Draw world states with matplotlib (Agg): walls, objects coloured by kind, people, route."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.backend_bases import FigureCanvasBase  # noqa: E402
from matplotlib.patches import Circle, Patch, Polygon  # noqa: E402

from dynmap_sim.world.schedule import Snapshot  # noqa: E402
from dynmap_sim.world.spec import WorldSpec  # noqa: E402
from dynmap_sim.world.world import World  # noqa: E402

KIND_COLOURS: dict[str, str] = {
    "wall": "#333333",
    "furniture": "#8c6d46",
    "exhibit": "#d62728",
    "door": "#2ca02c",
    "robot": "#1f77b4",
    "person": "#ff7f0e",
}


def draw_snapshot(ax: Axes, spec: WorldSpec, snap: Snapshot, title: str | None = None) -> None:
    """Draw one snapshot on ``ax``."""
    for o in snap.objects:
        colour = KIND_COLOURS.get(o.kind, "#777777")
        edge = "black" if o.blocks_route else colour
        if o.circle is not None:
            x, y, r = o.circle
            ax.add_patch(Circle((x, y), r, facecolor=colour, edgecolor=edge, lw=0.6))
        else:
            ax.add_patch(Polygon(o.polygon, closed=True, facecolor=colour, edgecolor=edge, lw=0.6))
    route = spec.robot.route
    ax.plot(route[:, 0], route[:, 1], "-", color="#9467bd", lw=0.9, alpha=0.8)
    sx, sy, sth = spec.robot.start
    ax.plot([sx], [sy], "o", color="#9467bd", ms=4)
    ax.arrow(sx, sy, 0.5 * np.cos(sth), 0.5 * np.sin(sth), width=0.04, color="#9467bd")
    for px, py, _ in snap.people:
        ax.add_patch(Circle((px, py), 0.22, facecolor=KIND_COLOURS["person"], alpha=0.8))
    x0, y0, x1, y1 = spec.bounds
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.tick_params(labelsize=6)
    ax.set_xlabel("x [m]", fontsize=7)
    ax.set_ylabel("y [m]", fontsize=7)
    if title:
        ax.set_title(title, fontsize=8)


def _title(world: World, day: int, run: int) -> str:
    slot = world.calendar.slot(day, run)
    h, m = divmod(int(slot.start_s) // 60, 60)
    return f"day {day} run {run}  {slot.date.isoformat()} {h:02d}:{m:02d}"


#: Most runs a sheet examines for changes (each costs a snapshot, ~15 ms): a longer calendar
#: is sampled evenly, and the sheet says so.
MAX_SHEET_SCAN = 240


def image_formats() -> list[str]:
    """The image file types figures can be saved as (``png``, ``pdf``, ``svg``, ...)."""
    return sorted(FigureCanvasBase.get_supported_filetypes())


def image_path(out_path: str | Path) -> Path:
    """The file a figure for ``out_path`` is written to: ``.png`` appended to a name without
    a suffix (as matplotlib does); ValueError for a suffix that is no image format."""
    out = Path(out_path)
    fmt = out.suffix[1:].lower()
    if not fmt:
        return out.with_name(out.name + ".png")
    if fmt not in image_formats():
        raise ValueError(
            f"unsupported image format {fmt!r}; supported: {', '.join(image_formats())}"
        )
    return out


def _legend(fig) -> None:
    handles = [Patch(facecolor=c, label=k) for k, c in KIND_COLOURS.items()]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles), fontsize=7, frameon=False)


def render_snapshot(
    spec: WorldSpec, seed: int = 0, day: int = 1, run: int = 1, out_path: str | Path = "world.png"
) -> Path:
    """Draw the state at the start of ``(day, run)`` to ``out_path`` (PNG/PDF/SVG; see
    :func:`image_path`); returns the file written."""
    out = image_path(out_path)
    world = World(spec, seed=seed)
    snap = world.snapshot(day, run)
    x0, y0, x1, y1 = spec.bounds
    w = 8.0
    fig, ax = plt.subplots(figsize=(w, w * (y1 - y0) / (x1 - x0) + 0.8))
    draw_snapshot(ax, spec, snap, f"{spec.name}: {_title(world, day, run)}")
    _legend(fig)
    fig.savefig(out, dpi=120, bbox_inches="tight")
    plt.close(fig)
    return out


def sheet_slots(world: World, n_panels: int = 12) -> list[tuple[int, int]]:
    """Runs to show on a sheet: the first run and the runs where something changes.

    Groups shuffled more often than once a day are ignored when looking for changes (they
    change every run); with more change points than panels they are subsampled evenly, with
    fewer the sheet is filled with evenly spaced runs. A calendar of more than
    :data:`MAX_SHEET_SCAN` runs is sampled evenly first (the changes are looked for at those).
    """
    slots = world.calendar.slots
    if len(slots) <= n_panels:
        return [(s.day, s.run) for s in slots]
    if len(slots) > MAX_SHEET_SCAN:
        keep = np.linspace(0, len(slots) - 1, MAX_SHEET_SCAN).round().astype(int)
        slots = tuple(slots[i] for i in sorted(set(keep.tolist())))
    rpd = world.calendar.runs_per_day
    frequent = {
        ev.group
        for ev in world.spec.schedule
        if ev.action == "shuffle" and ev.every_runs < rpd  # type: ignore[union-attr]
    }
    picks, prev = [], None
    for s in slots:
        objs = world.snapshot(s.day, s.run).objects
        sig = tuple((o.id, o.pose) for o in objs if o.group not in frequent or o.group is None)
        if sig != prev:
            picks.append((s.day, s.run))
        prev = sig
    if len(picks) > n_panels:
        idx = np.linspace(0, len(picks) - 1, n_panels).round().astype(int)
        return [picks[i] for i in sorted(set(idx.tolist()))]
    extra = [(s.day, s.run) for s in slots if (s.day, s.run) not in picks]
    idx = np.linspace(0, len(extra) - 1, n_panels - len(picks)).round().astype(int)
    return sorted(set(picks) | {extra[i] for i in idx})


def render_sheet(spec: WorldSpec, seed: int = 0, out_path: str | Path = "sheet.png") -> Path:
    """Draw a grid of snapshots spread over the whole calendar to ``out_path`` (see
    :func:`image_path`); returns the file written."""
    out = image_path(out_path)
    world = World(spec, seed=seed)
    picks = sheet_slots(world)
    ncol = 4
    nrow = int(np.ceil(len(picks) / ncol))
    x0, y0, x1, y1 = spec.bounds
    pw = 4.0
    ph = pw * (y1 - y0) / (x1 - x0) + 0.4
    fig, axes = plt.subplots(nrow, ncol, figsize=(pw * ncol, ph * nrow + 0.6), squeeze=False)
    for ax in axes.flat:
        ax.set_axis_off()
    for ax, (day, run) in zip(axes.flat, picks, strict=False):
        ax.set_axis_on()
        draw_snapshot(ax, spec, world.snapshot(day, run), _title(world, day, run))
    title = f"{spec.name} (seed {seed})"
    n = world.calendar.n_slots
    if n > MAX_SHEET_SCAN:
        title += f": {len(picks)} runs picked from {MAX_SHEET_SCAN} evenly spaced of {n}"
    fig.suptitle(title, fontsize=10)
    _legend(fig)
    fig.savefig(out, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return out


def render_worlds(
    specs: list[WorldSpec], seed: int = 0, out_path: str | Path = "worlds.png"
) -> Path:
    """Draw several worlds side by side, each at the start of day 1, to ``out_path`` (see
    :func:`image_path`); returns the file written."""
    out = image_path(out_path)
    ncol = min(4, len(specs))
    nrow = int(np.ceil(len(specs) / ncol))
    aspect = max((s.bounds[3] - s.bounds[1]) / (s.bounds[2] - s.bounds[0]) for s in specs)
    pw = 4.5
    fig, axes = plt.subplots(
        nrow, ncol, figsize=(pw * ncol, (pw * aspect + 0.5) * nrow + 0.6), squeeze=False
    )
    for ax in axes.flat:
        ax.set_axis_off()
    for ax, spec in zip(axes.flat, specs, strict=False):
        ax.set_axis_on()
        world = World(spec, seed=seed)
        draw_snapshot(ax, spec, world.snapshot(1, 1), f"{spec.name}: {_title(world, 1, 1)}")
    _legend(fig)
    fig.savefig(out, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return out
