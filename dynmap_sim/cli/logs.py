"""The log commands: ``replay`` (mapping and localizers on a recorded log) and ``slam-eval``."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from dynmap_sim.cli.arguments import (
    _localizer_arg,
    _output_file,
    _positive_seconds,
    _reference_offset,
    _refuse_results,
    _seed,
    _wrote,
)

if TYPE_CHECKING:
    from dynmap_sim.cli.arguments import Subparsers


#: ``--odometry`` choices: :data:`dynmap_sim.io.carmen.ODOMETRY_SOURCES` (not imported here, so
#: the CLI starts without numpy; a test keeps the two equal).
ODOMETRY_CHOICES = ("auto", "odom-lines", "laser-lines")
#: ``--odometry-reversals`` choices: :data:`dynmap_sim.io.carmen.REVERSAL_MODES` (the same).
REVERSAL_CHOICES = ("repair", "keep")


def _odometry_option(s: argparse.ArgumentParser) -> None:
    """``--odometry`` for the subcommands that read a CARMEN log."""
    s.add_argument(
        "--odometry",
        choices=ODOMETRY_CHOICES,
        default="auto",
        help="the log's odometry: the ODOM lines where they agree with the laser lines' "
        "odometry fields, else those fields, with a warning (auto, default); or always the "
        "odom-lines or the laser-lines",
    )
    s.add_argument(
        "--odometry-reversals",
        choices=REVERSAL_CHOICES,
        default="repair",
        help="ODOM poses that move forward while the line's velocity tv says the base "
        "reverses (integrated without the sign, e.g. FR079 raw): negate their translation "
        "(repair, default) or take them as logged (keep); either way a warning counts them",
    )


def _bag_option(s: argparse.ArgumentParser) -> None:
    """``--scan-topic``, ``--odom-topic`` and ``--laser-mount`` for a ROS bag log."""
    s.add_argument("--scan-topic", help="a bag's sensor_msgs/LaserScan topic (default: the one)")
    s.add_argument(
        "--odom-topic",
        help="a bag's nav_msgs/Odometry topic, or /tf for odom -> base_link (default: the one "
        "Odometry topic, else /tf)",
    )
    s.add_argument(
        "--laser-mount",
        type=_laser_mount,
        metavar="X,Y,THETA",
        help="a bag's laser pose on the robot [m, m, rad] (default: from /tf_static)",
    )


def _laser_mount(text: str) -> tuple[float, float, float]:
    try:
        v = tuple(float(t) for t in text.split(","))
    except ValueError:
        v = ()
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise argparse.ArgumentTypeError(f"expected three finite numbers X,Y,THETA, got {text!r}")
    return v


def _bag(args: argparse.Namespace):  # -> BagOptions
    from dynmap_sim.io.logs import BagOptions

    return BagOptions(args.scan_topic, args.odom_topic, args.laser_mount)


def _log_file(path: str) -> None:
    """A log must be a regular file (a FIFO or a device would hang the reader) or a ROS 2
    bag's folder."""
    from dynmap_sim.errors import FileError, regular_file_size

    p = Path(path)
    if not (p.is_dir() and (p / "metadata.yaml").is_file()):
        regular_file_size(p, FileError)


def _cmd_replay(args: argparse.Namespace) -> int:
    from dynmap_sim.analysis.headline import results_headline
    from dynmap_sim.errors import FileError, InputError, regular_file_size
    from dynmap_sim.experiments.reference import REFERENCE_TOLERANCE_S
    from dynmap_sim.experiments.replay import replay_log

    _log_file(args.log)
    if args.reference is not None:
        regular_file_size(args.reference, FileError)
    elif args.reference_offset is not None or args.reference_tolerance is not None:
        raise InputError("--reference-offset and --reference-tolerance need --reference REF.log")
    _refuse_results(args.out, args.force, "replay")
    out = replay_log(
        Path(args.log),
        localizers=args.localizer,
        out_dir=Path(args.out),
        map_from_log_poses=args.map_from_log_poses,
        note=lambda text: print(text, file=sys.stderr),
        reference=Path(args.reference) if args.reference is not None else None,
        reference_offset_s=args.reference_offset,
        reference_tolerance_s=args.reference_tolerance or REFERENCE_TOLERANCE_S,
        odometry=args.odometry,
        reversals=args.odometry_reversals,
        seed=args.seed,
        bag=_bag(args),
        keep_scans=args.keep_scans,
    )
    print(f"results in {out}")
    for line in results_headline(out, timing=True):
        print(line)
    return 0


def _cmd_slam_eval(args: argparse.Namespace) -> int:
    from dynmap_sim.analysis.export import write_tum
    from dynmap_sim.errors import FileError, InputError, regular_file_size
    from dynmap_sim.experiments.slam_eval import slam_eval

    _log_file(args.log)
    regular_file_size(args.relations, FileError)
    outs = [(opt, _output_file(p)) for opt, p in (("--tum", args.tum), ("--json", args.json)) if p]
    for opt, p in outs:
        if p.exists() and not args.force:
            raise InputError(f"{opt} {p}: exists; pass --force to replace it or choose another")
    from dynmap_sim.agent.mapping.first_run import FirstRunConfig
    from dynmap_sim.experiments.replay import json_or_text

    params: dict = {}
    for item in args.mapper_param or []:
        key, sep, val = item.partition("=")
        if not sep or not key.strip():
            raise InputError(f"--mapper-param {item!r}: expected KEY=VALUE")
        params[key.strip()] = json_or_text(val)
    try:
        config = FirstRunConfig.from_params(**params)
    except (TypeError, ValueError) as exc:
        raise InputError(f"--mapper-param: {exc}") from None
    res = slam_eval(
        Path(args.log),
        Path(args.relations),
        config=config,
        progress=not args.quiet,
        note=lambda text: print(text, file=sys.stderr),
        odometry=args.odometry,
        reversals=args.odometry_reversals,
        bag=_bag(args),
    )
    for line in res.table():
        print(line)
    for opt, p in outs:
        existed = p.exists()
        if opt == "--tum":
            write_tum(p, res.stamps_s, res.trajectory)
        else:
            p.write_text(json.dumps(res.summary(), indent=2) + "\n", encoding="utf-8")
        print(_wrote(p, existed))
    return 0


def _add_replay(sub: Subparsers) -> None:
    """The ``replay`` command."""
    s = sub.add_parser("replay", help="run mapping and localizers on a CARMEN log or ROS bag")
    s.add_argument("log", help="CARMEN log file, or a ROS 1 .bag / ROS 2 bag (.db3, .mcap)")
    s.add_argument(
        "--localizer",
        action="append",
        required=True,
        type=_localizer_arg,
        metavar="NAME",
        help="a localizer to run, by registry name or package.module:Class, with optional "
        "parameters (static-mcl,config=nav2-default); repeat for several",
    )
    s.add_argument(
        "--map-from-log-poses",
        action="store_true",
        help="build the map from the log's scans at the reference poses (--reference; without "
        "it, at the poses on the log's laser lines, which on a raw log are its odometry) and "
        "give it to every localizer that accepts a map (static-mcl: as a grid; dynamic-map: "
        "its keyframe scans, and with --reference its odometry covariance acquired from the "
        "reference poses and the log's odometry); the others still map on day 1",
    )
    s.add_argument(
        "--reference",
        metavar="REF.log",
        help="ground truth: a CARMEN log (plain or gzip) whose laser lines carry the true "
        "poses, e.g. a Radish '-corrected' log, matched to the scans by time stamp; scans "
        "without a match get no error. Without it the log has no ground truth and no errors "
        "are stored (the log itself may be given to score against its own laser-line poses)",
    )
    s.add_argument(
        "--reference-offset",
        type=_reference_offset,
        default=None,
        metavar="SECONDS|auto",
        help="seconds added to the reference's time stamps to put them on the log's clock; "
        "default auto: the median difference over the scans both logs hold (0 without any)",
    )
    s.add_argument(
        "--reference-tolerance",
        type=_positive_seconds,
        default=None,
        metavar="SECONDS",
        help="largest time difference between a scan and the reference pose it takes "
        "(default: REFERENCE_TOLERANCE_S, 0.1 s)",
    )
    _odometry_option(s)
    _bag_option(s)
    s.add_argument(
        "--keep-scans",
        action="store_true",
        help="store every scan's ranges (export --mcap then writes /scan)",
    )
    s.add_argument(
        "--seed",
        type=_seed,
        default=0,
        help="root of the localizers' random generators, an integer >= 0 (default: 0); "
        "another seed is another draw of every particle filter on the same log",
    )
    s.add_argument("--out", required=True, help="results folder")
    s.add_argument(
        "--force", action="store_true", help="replace earlier results in --out (else refused)"
    )
    s.set_defaults(func=_cmd_replay)


def _add_slam_eval(sub: Subparsers) -> None:
    """The ``slam-eval`` command."""
    s = sub.add_parser(
        "slam-eval", help="map a CARMEN log and score it by Kümmerle's relation error"
    )
    s.add_argument("log", help="CARMEN log file or ROS bag (raw odometry)")
    s.add_argument("--relations", required=True, help="relations file (t1 t2 x y z r p yaw)")
    s.add_argument("--tum", help="write the loop-closed trajectory here (TUM, the log's stamps)")
    s.add_argument("--json", help="write the relation error and timings here (JSON)")
    s.add_argument(
        "--mapper-param",
        action="append",
        metavar="KEY=VALUE",
        help="a first-run mapper parameter (mapper_params), e.g. seed_window=[0,0]; repeat",
    )
    _odometry_option(s)
    _bag_option(s)
    s.add_argument("--force", action="store_true", help="replace existing --tum/--json files")
    s.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=_cmd_slam_eval)


def add_parsers(sub: Subparsers) -> None:
    """The log commands: replay, slam-eval."""
    for add in (_add_replay, _add_slam_eval):
        add(sub)
