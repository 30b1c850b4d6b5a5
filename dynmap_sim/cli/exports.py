"""The export commands: ``export`` (TUM, Parquet, a ROS 2 bag) and ``video``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from dynmap_sim.cli.arguments import _output_file, _positive, _wrote, day_range

if TYPE_CHECKING:
    from dynmap_sim.cli.arguments import Subparsers


def _export_parquet(args: argparse.Namespace) -> None:
    from dynmap_sim.errors import InputError

    try:
        from dynmap_sim.analysis.export_parquet import export_parquet, parquet_paths
    except ImportError as exc:  # the extra is not installed: say how to get it
        raise InputError(str(exc)) from None
    existed = {p for p in parquet_paths(args.parquet).values() if p.exists()}
    for f in export_parquet(Path(args.dir), Path(args.parquet), force=args.force):
        print(f"{_wrote(f.path, f.path in existed)}: {f.rows} rows, {f.bytes:,} bytes")


def _cmd_export(args: argparse.Namespace) -> int:
    from dynmap_sim.errors import InputError

    if args.tum is None and args.mcap is None and args.parquet is None:
        raise InputError("export: give --tum DIR, --mcap OUT, --parquet OUT or several")
    ros_only = [f"--{k}" for k in ("localizer", "day", "run") if getattr(args, k) is not None]
    if args.mcap is None and ros_only:
        raise InputError(f"{', '.join(ros_only)}: only with --mcap")
    if args.tum is not None:
        from dynmap_sim.analysis.export import export_tum

        out = Path(args.tum)
        existed = {p.name for p in out.iterdir()} if out.is_dir() else set()
        for path in export_tum(Path(args.dir), out, force=args.force):
            print(_wrote(path, path.name in existed))
    if args.mcap is not None:
        from dynmap_sim.analysis.export_mcap import export_mcap

        existed_bag = Path(args.mcap).exists()
        bag = export_mcap(
            Path(args.dir),
            Path(args.mcap),
            localizer=args.localizer,
            days=args.day,
            run=args.run,
            force=args.force,
        )
        counts = ", ".join(f"{t} {n}" for t, n in bag.counts.items())
        print(f"{_wrote(bag.path, existed_bag)} (ROS 2 bag, {bag.mcap_file.name}): {counts}")
        for note in bag.notes:
            print(f"note: {note}", file=sys.stderr)
    if args.parquet is not None:
        _export_parquet(args)
    return 0


def _cmd_video(args: argparse.Namespace) -> int:
    from dynmap_sim.analysis.video import write_video

    out = _output_file(args.output)
    existed = out.exists()
    opts = dict(fps=args.fps, localizers=args.localizer, size_px=args.size, force=args.force)
    res = write_video(Path(args.dir), args.day, args.run, out, progress=not args.quiet, **opts)
    w, h = res.size_px
    print(
        f"{_wrote(res.path, existed)}: {res.n_frames} frames, {w}x{h} px, "
        f"{res.duration_s:.1f} s at {res.fps} fps (encoded in {res.encode_s:.1f} s)"
    )
    for note in res.notes:
        print(f"note: {note}", file=sys.stderr)
    return 0


def _add_export(sub: Subparsers) -> None:
    """The ``export`` command."""
    s = sub.add_parser(
        "export",
        help="export trajectories (TUM), tables (Parquet) or runs as a ROS 2 bag (MCAP) of a "
        "results folder",
        description="Export a results folder: TUM trajectories (--tum), Parquet tables "
        "(--parquet, extra 'analysis') for pandas and polars, and/or a ROS 2 bag "
        "(--mcap, extra 'ros') for Foxglove, RViz and `ros2 bag play`. The bag holds /tf, "
        "/tf_static, /odom, /truth/pose, /<localizer>/pose, /world/obstacles, /plan, "
        "/<localizer>/map (OccupancyGrid) of a localizer that stores its map as a grid "
        "(adaptive-memory), and /scan and /world/people when the experiment was run with "
        "--keep-scans.",
    )
    s.add_argument("dir", help="a results folder (written by run, check or replay)")
    s.add_argument("--tum", help="output folder for TUM trajectory files")
    s.add_argument(
        "--mcap",
        metavar="OUT",
        help="write a ROS 2 bag folder OUT (metadata.yaml + OUT.mcap; zstd chunks, ros2 "
        'profile) of the chosen runs; needs pip install "dynmap-sim[ros]". /scan and '
        "/world/people only when the experiment was run with --keep-scans",
    )
    s.add_argument(
        "--parquet",
        metavar="OUT",
        help="write scans.parquet (per scan and localizer), runs.parquet, days.parquet and "
        "localizers.parquet into folder OUT, for pandas and polars; needs pip install "
        '"dynmap-sim[analysis]"',
    )
    s.add_argument(
        "--localizer",
        metavar="LABEL",
        help="with --mcap: the localizer whose estimate gives map->odom on /tf "
        "(default: the first)",
    )
    s.add_argument(
        "--day", type=day_range, help="with --mcap: day or day range, e.g. 2 or 1-3 (default: all)"
    )
    s.add_argument("--run", type=_positive, help="with --mcap: run of each day (default: all)")
    s.add_argument(
        "--force",
        action="store_true",
        help="replace existing TUM files (--tum), an existing bag OUT (--mcap) or Parquet "
        "files in OUT (--parquet); else refused",
    )
    s.set_defaults(func=_cmd_export)


def _add_video(sub: Subparsers) -> None:
    """The ``video`` command."""
    s = sub.add_parser(
        "video",
        help="a video of one stored run (extra 'video')",
        description="A video of one stored run, one frame per scan: the run's obstacles, the "
        "route, the planned path and a dynamic-map's long-term map when stored, the true pose "
        "and each localizer's estimate with trails, errors, bumper and events, and the scan "
        "and the people when the experiment was run with --keep-scans.",
    )
    s.add_argument("dir", help="a results folder (written by run, check or replay)")
    s.add_argument("--day", type=_positive, required=True, help="day of the run to show")
    s.add_argument("--run", type=_positive, required=True, help="run of that day")
    s.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="FILE",
        help="video file: .mp4 (H.264 by imageio-ffmpeg's ffmpeg) or .gif (short runs: its "
        "frames are held in memory); its folder must exist",
    )
    s.add_argument(
        "--fps",
        type=_positive,
        help="frames (scans) per second of video (default: the scan rate, i.e. real time; "
        "twice that plays at double speed)",
    )
    s.add_argument(
        "--localizer",
        action="append",
        metavar="LABEL",
        help="draw only this localizer, by label; repeat for several (default: all of the "
        "folder's)",
    )
    s.add_argument(
        "--size",
        type=_positive,
        default=640,
        metavar="PX",
        help="pixels along the map's longer side, 64..4096 (default: 640)",
    )
    s.add_argument("--force", action="store_true", help="replace an existing FILE (else refused)")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_video)


def add_parsers(sub: Subparsers) -> None:
    """The export commands: export, video."""
    for add in (_add_export, _add_video):
        add(sub)
