"""Export runs of a results folder as a ROS 2 bag for Foxglove, RViz and ``ros2 bag play``.

The bag is a folder with ``metadata.yaml`` (rosbag2 metadata version 8) and one ``.mcap``
file: MCAP profile ``ros2``, CDR messages typed as in ROS 2 Jazzy, schemas ``ros2msg``, and
zstd-compressed chunks (the chunk compression Foxglove reads; rosbag2's FILE or MESSAGE
compression would make the file unreadable there). It is written with ``rosbags`` (extra
``ros``).

Topics, from what the results store holds:

* ``/odom`` ``nav_msgs/msg/Odometry`` (``odom`` -> ``base_link``): the dead-reckoning
  localizer's pose (class ``odometry``) and its covariance diagonal; the twist is its pose
  difference between scans, in ``base_link``. Absent when no such localizer was run.
* ``/tf`` ``tf2_msgs/msg/TFMessage``: ``map`` -> ``odom`` (chosen localizer's estimate ⊖
  odometry; identity without odometry) and ``odom`` -> ``base_link`` (odometry; without it
  the chosen localizer's estimate), one message per scan.
* ``/tf_static``: ``base_link`` -> ``laser`` from the laser's mount pose, once per run,
  offered with transient-local durability.
* ``/truth/pose`` and ``/<label>/pose`` (each localizer; its label made a ROS name)
  ``geometry_msgs/msg/PoseStamped`` in ``map``.
* ``/world/obstacles`` ``visualization_msgs/msg/MarkerArray``: the run's static segments as
  one ``LINE_LIST`` per class (walls, furniture, ...), after a ``DELETEALL``; transient local.
* ``/world/people`` ``visualization_msgs/msg/MarkerArray``: the people at each scan, one
  ``CYLINDER`` per person (ns ``people``, id: the person's index in the run's crowd, which is
  fixed for a run; diameter its body's, :data:`PERSON_HEIGHT_M` tall) living one scan period,
  so one who leaves the floor fades; when the experiment kept them (``run --keep-scans``).
* ``/<label>/map`` ``nav_msgs/msg/OccupancyGrid`` in ``map``, for each localizer that hands
  over its map as a grid (named arrays ``logodds`` ``(H, W)`` rows along y, ``origin_m``
  lower-left corner, ``resolution_m``; e.g. ``adaptive-memory``'s long-term map ``ltm``):
  per run, the grid it handed over after the run's day (else the latest earlier day), as
  the H&W figures show it, stamped at the run's first scan; transient local. Occupancy is
  ``round(100 p)`` of the log-odds' probability, -1 where the log-odds are 0 (never
  observed, or evenly).
* ``/plan`` ``nav_msgs/msg/Path``: the driver's last planned path of a run, stamped at the
  run's last scan, where the driver stored one; transient local.
* ``/scan`` ``sensor_msgs/msg/LaserScan`` in ``laser`` (REP-117 ranges: +inf no return,
  -inf too close), one per scan, when the experiment kept its ranges (``run --keep-scans``).

Not exported, because the store does not hold it: ``/scan`` and ``/world/people`` of an
experiment run without ``--keep-scans`` (or, for the people, written before they were
kept), and a map of a localizer that stores none as a grid (the dynamic map's
``map_snapshot`` holds per-local-map range medians). :attr:`McapExport.notes` says so.

Stamps are nanoseconds since the Unix epoch of the run's calendar date plus its clock time:
the TUM export's timestamp plus the first date's epoch seconds. A ``replay`` folder uses the
log's own clock (as its TUM export does) and exports the localization pass (day 2) unless
days are chosen.
"""

from __future__ import annotations

import datetime as dt
import os
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dynmap_sim import se2
from dynmap_sim.errors import InputError
from dynmap_sim.experiments.results import ResultsDB
from dynmap_sim.types import BeamClass

#: How to install what this module needs.
ROS_EXTRA = 'pip install "dynmap-sim[ros]"'
#: The class name of the dead-reckoning localizer (the source of ``odom``).
ODOMETRY_CLASS = "odometry"
#: rosbag2 metadata version written (ROS 2 Humble to Jazzy read it).
BAG_VERSION = 8
#: The people's cylinders' height [m] (the simulation's people are discs: a display height).
PERSON_HEIGHT_M = 1.7
#: The people's colour (RGBA, 0-1).
_PERSON_RGBA = (0.85, 0.1, 0.1, 0.8)

_EPOCH = dt.date(1970, 1, 1)
_NS = 1_000_000_000
#: Line colours of the obstacle markers per segment class (RGB, 0-1).
_MARKER_RGB = {
    BeamClass.NONE: (0.5, 0.5, 0.5),
    BeamClass.WALL: (0.15, 0.15, 0.15),
    BeamClass.FURNITURE: (0.6, 0.35, 0.15),
    BeamClass.EXHIBIT: (0.9, 0.55, 0.0),
    BeamClass.DOOR: (0.15, 0.6, 0.25),
    BeamClass.PERSON: (0.8, 0.1, 0.1),
    BeamClass.ROBOT: (0.25, 0.25, 0.8),
}


@dataclass
class McapExport:
    """What :func:`export_mcap` wrote: the bag folder, the ``.mcap`` file, messages per
    topic, and notes on what could not be exported (and why)."""

    path: Path
    mcap_file: Path
    counts: dict[str, int] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)


def ros_name(label: str) -> str:
    """A localizer label as one token of a ROS topic name (letters, digits, ``_``; not
    starting with a digit)."""
    name = re.sub(r"[^A-Za-z0-9_]+", "_", label).strip("_")
    name = re.sub(r"_+", "_", name)
    if not name or name[0].isdigit():
        name = f"loc_{name}"
    return name


def pose_topics(labels: list[str]) -> list[str]:
    """The pose topic of each localizer, ``/<ros_name(label)>/pose``, unique and never
    ``/truth/pose`` (a clash gets ``_<index>``)."""
    out: list[str] = []
    for k, label in enumerate(labels):
        name = ros_name(label)
        topic = f"/{name}/pose"
        if name == "truth" or topic in out:
            topic = f"/{name}_{k}/pose"
        out.append(topic)
    return out


def stamp_ns(date: str, t_s: np.ndarray) -> np.ndarray:
    """Nanoseconds since the epoch of ``date`` (ISO) at clock times ``t_s`` [s]."""
    days = (dt.date.fromisoformat(date) - _EPOCH).days
    return days * 86_400 * _NS + np.rint(np.asarray(t_s, dtype=np.float64) * _NS).astype(np.int64)


def _import_rosbags() -> Any:
    try:
        import rosbags.rosbag2 as rosbag2
    except ImportError:
        raise InputError(
            f"--mcap needs the optional packages of the 'ros' extra: {ROS_EXTRA}"
        ) from None
    return rosbag2


class _Msgs:
    """Message builders over a rosbags typestore (ROS 2 Jazzy types)."""

    def __init__(self) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.store = get_typestore(Stores.ROS2_JAZZY)
        self.t = self.store.types

    def time(self, ns: int) -> Any:
        return self.t["builtin_interfaces/msg/Time"](sec=int(ns // _NS), nanosec=int(ns % _NS))

    def header(self, ns: int, frame: str) -> Any:
        return self.t["std_msgs/msg/Header"](stamp=self.time(ns), frame_id=frame)

    def pose(self, p: np.ndarray) -> Any:
        point = self.t["geometry_msgs/msg/Point"](x=float(p[0]), y=float(p[1]), z=0.0)
        return self.t["geometry_msgs/msg/Pose"](position=point, orientation=self.quat(p[2]))

    def quat(self, yaw: float) -> Any:
        h = 0.5 * float(yaw)
        return self.t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=np.sin(h), w=np.cos(h))

    def pose_stamped(self, ns: int, frame: str, p: np.ndarray) -> Any:
        return self.t["geometry_msgs/msg/PoseStamped"](
            header=self.header(ns, frame), pose=self.pose(p)
        )

    def transform(self, ns: int, parent: str, child: str, p: np.ndarray) -> Any:
        t = self.t
        tf = t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](x=float(p[0]), y=float(p[1]), z=0.0),
            rotation=self.quat(p[2]),
        )
        return t["geometry_msgs/msg/TransformStamped"](
            header=self.header(ns, parent), child_frame_id=child, transform=tf
        )

    def laser_scan(self, ns: int, laser: dict[str, Any], ranges: np.ndarray) -> Any:
        n = int(laser["n_beams"])
        inc = float(laser["angle_increment_rad"])
        return self.t["sensor_msgs/msg/LaserScan"](
            header=self.header(ns, "laser"),
            angle_min=float(laser["angle_min_rad"]),
            angle_max=float(laser["angle_min_rad"]) + (n - 1) * inc,
            angle_increment=inc,
            time_increment=float(laser["time_increment_s"]),
            scan_time=float(laser["scan_period_s"]),
            range_min=float(laser["range_min_m"]),
            range_max=float(laser["range_max_m"]),
            ranges=np.asarray(ranges, dtype=np.float32),
            intensities=np.zeros(0, dtype=np.float32),
        )

    def tf(self, transforms: list[Any]) -> Any:
        return self.t["tf2_msgs/msg/TFMessage"](transforms=transforms)

    def odometry(self, ns: int, p: np.ndarray, var: np.ndarray, twist: np.ndarray) -> Any:
        t = self.t
        cov = np.zeros(36)
        cov[[0, 7, 35]] = np.nan_to_num(var, nan=0.0)
        vec = t["geometry_msgs/msg/Vector3"]
        tw = t["geometry_msgs/msg/Twist"](
            linear=vec(x=float(twist[0]), y=float(twist[1]), z=0.0),
            angular=vec(x=0.0, y=0.0, z=float(twist[2])),
        )
        return t["nav_msgs/msg/Odometry"](
            header=self.header(ns, "odom"),
            child_frame_id="base_link",
            pose=t["geometry_msgs/msg/PoseWithCovariance"](pose=self.pose(p), covariance=cov),
            twist=t["geometry_msgs/msg/TwistWithCovariance"](twist=tw, covariance=np.zeros(36)),
        )

    def marker(
        self,
        ns: int,
        name: str,
        ident: int,
        kind: int,
        shape: int | None = None,
        lifetime_ns: int = 0,
        **kw: Any,
    ) -> Any:
        t = self.t
        u8 = np.zeros(0, dtype=np.uint8)
        fields: dict[str, Any] = {
            "pose": self.pose(np.zeros(3)),
            "scale": t["geometry_msgs/msg/Vector3"](x=0.03, y=0.0, z=0.0),
            "color": t["std_msgs/msg/ColorRGBA"](r=0.0, g=0.0, b=0.0, a=1.0),
            "points": [],
        } | kw
        return t["visualization_msgs/msg/Marker"](
            header=self.header(ns, "map"),
            ns=name,
            id=ident,
            type=t["visualization_msgs/msg/Marker"].LINE_LIST if shape is None else shape,
            action=kind,
            lifetime=t["builtin_interfaces/msg/Duration"](
                sec=int(lifetime_ns // _NS), nanosec=int(lifetime_ns % _NS)
            ),
            frame_locked=False,
            colors=[],
            texture_resource="",
            texture=t["sensor_msgs/msg/CompressedImage"](
                header=self.header(0, ""), format="", data=u8
            ),
            uv_coordinates=[],
            text="",
            mesh_resource="",
            mesh_file=t["visualization_msgs/msg/MeshFile"](filename="", data=u8),
            mesh_use_embedded_materials=False,
            **fields,
        )

    def obstacles(self, ns: int, segments: np.ndarray, classes: np.ndarray) -> Any:
        t = self.t
        marker_t = t["visualization_msgs/msg/Marker"]
        point = t["geometry_msgs/msg/Point"]
        markers = [self.marker(ns, "", 0, marker_t.DELETEALL)]
        for c in np.unique(classes):
            seg = segments[classes == c]
            ends = seg.reshape(-1, 2)  # (x1, y1), (x2, y2) per segment: a LINE_LIST
            r, g, b = _MARKER_RGB.get(BeamClass(int(c)), (0.0, 0.0, 0.0))
            markers.append(
                self.marker(
                    ns,
                    BeamClass(int(c)).name.lower(),
                    int(c),
                    marker_t.ADD,
                    points=[point(x=float(x), y=float(y), z=0.0) for x, y in ends],
                    color=t["std_msgs/msg/ColorRGBA"](r=r, g=g, b=b, a=1.0),
                )
            )
        return t["visualization_msgs/msg/MarkerArray"](markers=markers)

    def people(self, ns: int, xy: np.ndarray, radius: np.ndarray, lifetime_ns: int) -> Any:
        """One ``CYLINDER`` per person on the floor (finite position), id its index."""
        t = self.t
        marker_t = t["visualization_msgs/msg/Marker"]
        r, g, b, a = _PERSON_RGBA
        markers = [
            self.marker(
                ns,
                "people",
                j,
                marker_t.ADD,
                shape=marker_t.CYLINDER,
                lifetime_ns=lifetime_ns,
                pose=t["geometry_msgs/msg/Pose"](
                    position=t["geometry_msgs/msg/Point"](
                        x=float(xy[j, 0]), y=float(xy[j, 1]), z=0.5 * PERSON_HEIGHT_M
                    ),
                    orientation=self.quat(0.0),
                ),
                scale=t["geometry_msgs/msg/Vector3"](
                    x=2.0 * float(radius[j]), y=2.0 * float(radius[j]), z=PERSON_HEIGHT_M
                ),
                color=t["std_msgs/msg/ColorRGBA"](r=r, g=g, b=b, a=a),
            )
            for j in range(len(xy))
            if np.isfinite(xy[j]).all()
        ]
        return t["visualization_msgs/msg/MarkerArray"](markers=markers)

    def occupancy_grid(self, ns: int, grid: _Grid) -> Any:
        t = self.t
        h, w = grid.data.shape
        info = t["nav_msgs/msg/MapMetaData"](
            map_load_time=self.time(ns),
            resolution=float(grid.resolution_m),
            width=w,
            height=h,
            origin=self.pose(np.array([grid.origin_m[0], grid.origin_m[1], 0.0])),
        )
        return t["nav_msgs/msg/OccupancyGrid"](
            header=self.header(ns, "map"), info=info, data=grid.data.ravel()
        )

    def path(self, ns: int, xy: np.ndarray) -> Any:
        heading = np.zeros(len(xy))
        if len(xy) > 1:  # each pose faces the next point
            d = np.diff(xy, axis=0)
            heading[:-1] = np.arctan2(d[:, 1], d[:, 0])
            heading[-1] = heading[-2]
        poses = [
            self.pose_stamped(ns, "map", np.array([x, y, h]))
            for (x, y), h in zip(xy, heading, strict=True)
        ]
        return self.t["nav_msgs/msg/Path"](header=self.header(ns, "map"), poses=poses)


@dataclass(frozen=True)
class _Grid:
    """A localizer's map as ROS cells: ``data`` ``(H, W)`` int8 (0-100, -1 unknown), row 0
    at ``origin_m`` (the lower-left corner [m]), ``resolution_m`` [m/cell]."""

    data: np.ndarray
    origin_m: tuple[float, float]
    resolution_m: float


def occupancy_from_logodds(logodds: np.ndarray) -> np.ndarray:
    """ROS occupancy of log-odds cells: ``round(100 p)`` (int8), -1 where they are 0 (no
    evidence) or not finite."""
    lo = np.asarray(logodds, dtype=np.float64)
    p = 1.0 / (1.0 + np.exp(-np.clip(np.nan_to_num(lo), -50.0, 50.0)))
    out = np.rint(100.0 * p).astype(np.int8)
    out[(lo == 0.0) | ~np.isfinite(lo)] = -1
    return out


def _grid_of(arrays: Any) -> _Grid | None:
    """The grid among a day artifact's named arrays (``logodds`` with ``origin_m`` and
    ``resolution_m``), or None."""
    if not isinstance(arrays, dict) or not {"logodds", "origin_m", "resolution_m"} <= set(arrays):
        return None
    lo = np.asarray(arrays["logodds"])
    origin = np.asarray(arrays["origin_m"], dtype=np.float64).ravel()
    res = float(np.asarray(arrays["resolution_m"], dtype=np.float64).ravel()[0])
    if lo.ndim != 2 or lo.dtype.kind not in "fiu" or origin.size < 2 or not res > 0:
        return None
    return _Grid(occupancy_from_logodds(lo), (float(origin[0]), float(origin[1])), res)


def stored_grids(db: ResultsDB, loc: int) -> list[tuple[int, _Grid]]:
    """``(day, grid)`` of every map localizer ``loc`` handed over as a grid, by day (of
    one artifact name: the first that holds grids)."""
    if not db.query("SELECT count(*) FROM sqlite_master WHERE type='table' AND name='artifacts'")[
        0
    ][0]:
        return []
    names = [
        str(n)
        for (n,) in db.query(
            "SELECT DISTINCT name FROM artifacts WHERE loc=? ORDER BY name", (loc,)
        )
    ]
    for name in names:
        grids = [(d, g) for d, a in db.artifacts(loc, name) if (g := _grid_of(a)) is not None]
        if grids:
            return grids
    return []


def _grid_for_day(grids: list[tuple[int, _Grid]], day: int) -> _Grid | None:
    """The grid handed over after ``day``, else after the latest day before it."""
    before = [g for d, g in grids if d <= day]
    return before[-1] if before else None


def _qos(transient_local: bool) -> list[Any]:
    """The offered QoS of a topic: reliable, keep last 1 (transient local) or 10."""
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )

    zero = QosTime(0, 0)  # the RMW default: no deadline, lifespan or lease
    return [
        Qos(
            QosHistory.KEEP_LAST,
            1 if transient_local else 10,
            QosReliability.RELIABLE,
            QosDurability.TRANSIENT_LOCAL if transient_local else QosDurability.VOLATILE,
            zero,
            zero,
            QosLiveliness.AUTOMATIC,
            zero,
            False,
        )
    ]


def _selected_runs(
    db: ResultsDB, replay: bool, days: tuple[int, int] | None, run: int | None
) -> list[tuple[int, int, str]]:
    """``(day, run, date)`` of the chosen finished runs, in order."""
    rows = [
        (int(d), int(r), str(date))
        for d, r, date in db.query("SELECT day, run, date FROM runs ORDER BY day, run")
    ]
    if not rows:
        raise InputError(f"{db.path.parent}: no finished run to export")
    if days is None and replay:
        days = (2, 2)  # the two passes share the log's clock: the localization pass
    chosen = [
        x
        for x in rows
        if (days is None or days[0] <= x[0] <= days[1]) and (run is None or x[1] == run)
    ]
    if not chosen:
        have = ", ".join(f"day {d} run {r}" for d, r, _ in rows[:8])
        more = " ..." if len(rows) > 8 else ""
        raise InputError(
            f"{db.path.parent}: no finished run matches the chosen day/run; it has {have}{more}"
        )
    return chosen


def _poses(db: ResultsDB, loc: int, day: int, run: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Estimates ``(n, 3)`` and covariance diagonals ``(n, 3)`` of localizer ``loc``."""
    rows = db.query(
        "SELECT x, y, theta, var_x, var_y, var_theta FROM estimates "
        "WHERE loc=? AND day=? AND run=? ORDER BY step",
        (loc, day, run),
    )
    a = np.array(rows, dtype=np.float64).reshape(-1, 6)
    if len(a) != n:
        raise InputError(
            f"{db.path}: day {day} run {run}: localizer {loc} has {len(a)} estimates for {n} scans"
        )
    return a[:, :3], a[:, 3:]


def _body_twist(poses: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """``(n, 3)`` velocities (vx, vy, wz) in the body frame from consecutive poses (the
    first scan: at rest)."""
    out = np.zeros_like(poses)
    if len(poses) > 1:
        dt_s = np.diff(t_s)
        step = se2.between(poses[:-1], poses[1:])
        ok = dt_s > 0
        out[1:][ok] = step[ok] / dt_s[ok, None]
    return out


def _refuse_or_clear(out: Path, force: bool) -> None:
    """Refuse an existing ``out`` unless ``force``; with it, remove a bag folder (only
    ``metadata.yaml`` and ``.mcap`` files) but nothing else."""
    if not out.exists() and not out.is_symlink():
        return
    if not force:
        raise InputError(
            f"--mcap {out}: already exists; pass --force to replace it or choose another name"
        )
    if not out.is_dir() or out.is_symlink():
        raise InputError(f"--mcap {out}: is not a bag folder; remove it yourself")
    names = [p.name for p in out.iterdir()]
    if any(not (n == "metadata.yaml" or n.endswith(".mcap")) for n in names):
        raise InputError(
            f"--mcap {out}: holds files that are not part of a bag; not replaced (remove it "
            "yourself or choose another name)"
        )


def _prepare_destination(dst: Path, out: str | Path, force: bool) -> None:
    """Refuse or clear an existing bag at ``dst`` (:func:`_refuse_or_clear`) and make the
    folders above it, as ``--parquet``'s and ``--tum``'s are made."""
    _refuse_or_clear(dst, force)
    try:
        dst.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(
            f"--mcap {out}: cannot create folder {dst.parent}: {exc.strerror}"
        ) from None


@dataclass(frozen=True)
class _Source:
    """What a bag is made of, read once from the results: the chosen runs ``(day, run,
    date)``, the localizers' labels, the index of the one that gives ``map`` -> ``odom``
    and of the dead-reckoning one (None: none ran), the laser's mount pose ``(x, y, θ)``
    [m, rad], the driver's planned paths per ``(day, run)``, the run metadata of a replay
    (None: an experiment), the laser's parameters and each localizer's stored grids."""

    db: ResultsDB
    runs: list[tuple[int, int, str]]
    labels: list[str]
    chosen: int
    odo_loc: int | None
    mount: np.ndarray
    plans: dict[tuple[int, int], bytes]
    replay_meta: dict[str, Any] | None
    laser: dict[str, Any] | None
    grids: dict[int, list[tuple[int, _Grid]]]
    keep_scans: bool


def _chosen_localizer(labels: list[str], localizer: str | None, results_dir: str | Path) -> int:
    """The index of the label ``localizer`` (None: the first) among ``labels``."""
    if not labels:
        raise InputError(f"{results_dir}: no localizers in the results")
    if localizer is None:
        return 0
    if localizer in labels:
        return labels.index(localizer)
    raise InputError(
        f"--localizer {localizer!r}: not in the results; they have {', '.join(labels)}"
    )


def _read_source(
    db: ResultsDB,
    results_dir: str | Path,
    localizer: str | None,
    days: tuple[int, int] | None,
    run: int | None,
) -> _Source:
    """The :class:`_Source` of the runs of ``db`` that :func:`export_mcap` chose."""
    meta = db.meta()
    labels = db.labels()
    classes = [str(r[0]) for r in db.query("SELECT name FROM localizers ORDER BY idx")]
    chosen = _chosen_localizer(labels, localizer, results_dir)
    replay = "log_path" in meta
    runs = _selected_runs(db, replay, days, run)
    return _Source(
        db=db,
        runs=runs,
        labels=labels,
        chosen=chosen,
        odo_loc=classes.index(ODOMETRY_CLASS) if ODOMETRY_CLASS in classes else None,
        mount=np.asarray((meta.get("laser") or {}).get("mount_pose", [0.0, 0.0, 0.0]), float),
        plans={(d, r): blob for d, r, blob in db.driver_artifacts("planned_path.f8")},
        replay_meta=meta if replay else None,
        laser=meta.get("laser"),
        grids={k: g for k in range(len(labels)) if (g := stored_grids(db, k))},
        keep_scans=bool(meta.get("keep_scans")),
    )


def _missing_notes(src: _Source) -> list[str]:
    """Why ``/scan``, ``/odom`` or the occupancy grids are not in the bag, for those that
    are not."""
    notes = []
    if not src.keep_scans:
        notes.append(
            "/scan not exported: the experiment kept no laser ranges (run it with "
            "--keep-scans to store them)"
        )
    if src.odo_loc is None:
        notes.append(
            "/odom not exported: no dead-reckoning localizer ('odometry') in the results; "
            f"/tf has map->odom identity and odom->base_link from {src.labels[src.chosen]!r}"
        )
    if not src.grids:
        notes.append(
            "no OccupancyGrid: no localizer's map is stored as a grid in the results (the "
            "artifacts hold at most the dynamic map's range medians per local map)"
        )
    return notes


def _people_note(src: _Source) -> str:
    """Why ``/world/people`` is not in the bag: nobody on the floor, or no tracks kept."""
    kept = any(src.db.scan_people(d, r) is not None for d, r, _ in src.runs)
    return (
        "/world/people not exported: no people on the floor in the exported runs"
        if kept
        else "/world/people not exported: the results hold no people's tracks "
        "(run the experiment with --keep-scans to store them)"
    )


def export_mcap(
    results_dir: str | Path,
    out: str | Path,
    *,
    localizer: str | None = None,
    days: tuple[int, int] | None = None,
    run: int | None = None,
    force: bool = False,
) -> McapExport:
    """Write the chosen runs of ``results_dir`` as a ROS 2 bag folder ``out`` (see the
    module doc). ``localizer``: the label whose estimate gives ``map`` -> ``odom``
    (default: the first); ``days`` ``(first, last)`` and ``run``: which runs (default:
    all). An existing ``out`` is refused unless ``force``; missing folders above it are
    created. The bag is written next to
    ``out`` and moved there when complete, so a failure leaves no half bag."""
    rosbag2 = _import_rosbags()
    dst = Path(out)
    _prepare_destination(dst, out, force)
    msgs = _Msgs()
    with ResultsDB.open(results_dir) as db:
        src = _read_source(db, results_dir, localizer, days, run)
        result = McapExport(dst, dst / f"{dst.name}.mcap")
        result.notes.extend(_missing_notes(src))
        staging = dst.parent / f".{dst.name}.partial-{os.getpid()}"
        shutil.rmtree(staging, ignore_errors=True)
        staging.mkdir()
        try:
            bag = staging / dst.name
            writer = rosbag2.Writer(
                bag, version=BAG_VERSION, storage_plugin=rosbag2.StoragePlugin.MCAP
            )
            # STORAGE: zstd-compressed MCAP chunks (FILE/MESSAGE would hide them from Foxglove)
            writer.set_compression(rosbag2.CompressionMode.STORAGE, rosbag2.CompressionFormat.ZSTD)
            with writer:
                _write_runs(src, _Topics(writer, msgs, result, src.labels, src.grids))
            if "/world/people" not in result.counts:
                result.notes.append(_people_note(src))
            if dst.exists():
                shutil.rmtree(dst)
            os.replace(bag, dst)
        finally:
            shutil.rmtree(staging, ignore_errors=True)
    return result


class _Topics:
    """The bag's topics: their message types and offered QoS, each localizer's pose topic
    and, for those that stored grids, map topic; a topic's connection is added when its
    first message is written, and :attr:`McapExport.counts` counts the messages."""

    def __init__(
        self,
        writer: Any,
        msgs: _Msgs,
        result: McapExport,
        labels: list[str],
        grids: dict[int, list[tuple[int, _Grid]]],
    ) -> None:
        self.writer, self.msgs, self.result = writer, msgs, result
        self.conns: dict[str, Any] = {}
        self.types = {
            "/tf_static": "tf2_msgs/msg/TFMessage",
            "/world/obstacles": "visualization_msgs/msg/MarkerArray",
            "/tf": "tf2_msgs/msg/TFMessage",
            "/odom": "nav_msgs/msg/Odometry",
            "/truth/pose": "geometry_msgs/msg/PoseStamped",
            "/plan": "nav_msgs/msg/Path",
            "/scan": "sensor_msgs/msg/LaserScan",
            "/world/people": "visualization_msgs/msg/MarkerArray",
        }
        self.latched = {"/tf_static", "/world/obstacles", "/plan"}
        self.poses = pose_topics(labels)
        for topic in self.poses:
            self.types[topic] = "geometry_msgs/msg/PoseStamped"
        self.maps = {k: self.poses[k].removesuffix("/pose") + "/map" for k in grids}
        for topic in self.maps.values():
            self.types[topic] = "nav_msgs/msg/OccupancyGrid"
            self.latched.add(topic)

    def put(self, topic: str, ns: int, msg: Any) -> None:
        """Write ``msg`` on ``topic`` stamped ``ns`` [ns since the epoch]."""
        if topic not in self.conns:
            self.conns[topic] = self.writer.add_connection(
                topic,
                self.types[topic],
                typestore=self.msgs.store,
                offered_qos_profiles=_qos(topic in self.latched),
            )
            self.result.counts[topic] = 0
        ser = self.msgs.store.serialize_cdr(msg, self.types[topic])
        self.writer.write(self.conns[topic], int(ns), ser)
        self.result.counts[topic] += 1


@dataclass(frozen=True)
class _Run:
    """One run's contents, per scan: stamps [ns since the epoch], true poses, every
    localizer's estimates and covariance diagonals, the ``odom`` -> ``base_link`` pose, its
    covariance diagonal and body twist (None: no odometry), ``map`` -> ``odom``, the laser
    ranges and people (None: not kept), and how long a person's marker lives [ns]."""

    ns: np.ndarray
    truth: np.ndarray
    est: list[tuple[np.ndarray, np.ndarray]]
    odom: np.ndarray
    odom_var: np.ndarray
    twist: np.ndarray | None
    map_odom: np.ndarray
    ranges: np.ndarray | None
    people: Any
    life_ns: int


def _run_stamps(date: str, t_s: np.ndarray, replay_meta: dict[str, Any] | None) -> np.ndarray:
    """Nanoseconds since the epoch of a run's scans at clock times ``t_s`` [s]: the run's
    calendar date, or a replay's log's own clock (as the TUM export)."""
    if replay_meta is None:
        return stamp_ns(date, t_s)
    t0 = float(replay_meta.get("log_start_s") or 0.0)
    return np.rint((t0 + t_s) * _NS).astype(np.int64)


def _run_people(db: ResultsDB, day: int, run_: int, n: int) -> Any:
    """The people kept at each of a run's ``n`` scans (None: not kept, or nobody on the
    floor this run)."""
    people = db.scan_people(day, run_)
    if people is not None and not people.ids:
        return None
    if people is not None and len(people.xy) != n:
        raise InputError(
            f"{db.path}: day {day} run {run_}: {len(people.xy)} people's rows for {n} scans"
        )
    return people


def _read_run(src: _Source, day: int, run_: int, date: str) -> _Run | None:
    """The :class:`_Run` of ``(day, run_)`` (None: it has no scans)."""
    db = src.db
    rows = db.query(
        "SELECT t_s, x, y, theta FROM scans WHERE day=? AND run=? ORDER BY step", (day, run_)
    )
    scans = np.array(rows, dtype=np.float64).reshape(-1, 4)
    n = len(scans)
    if n == 0:
        return None
    t_s, truth = scans[:, 0], scans[:, 1:]
    est = [_poses(db, k, day, run_, n) for k in range(len(src.labels))]
    if src.odo_loc is not None:
        odom, odom_var = est[src.odo_loc]
        map_odom = se2.compose(est[src.chosen][0], se2.inverse(odom))
        twist = _body_twist(odom, t_s)
    else:
        odom, odom_var, twist = est[src.chosen][0], est[src.chosen][1], None
        map_odom = np.zeros((n, 3))
    period_s = float((src.laser or {}).get("scan_period_s") or 0.0)
    life_s = period_s if period_s > 0 else float(np.median(np.diff(t_s))) if n > 1 else 0.0
    return _Run(
        ns=_run_stamps(date, t_s, src.replay_meta),
        truth=truth,
        est=est,
        odom=odom,
        odom_var=odom_var,
        twist=twist,
        map_odom=map_odom,
        ranges=db.scan_ranges(day, run_) if src.laser is not None else None,
        people=_run_people(db, day, run_, n),
        life_ns=int(round(life_s * _NS)),  # 0: forever (ids are stable: the next replaces)
    )


def _write_scan(topics: _Topics, run: _Run, i: int, laser: dict[str, Any] | None) -> None:
    """The messages of a run's scan ``i``: frames, odometry, poses, ranges and people."""
    msgs, s = topics.msgs, int(run.ns[i])
    tf = [
        msgs.transform(s, "map", "odom", run.map_odom[i]),
        msgs.transform(s, "odom", "base_link", run.odom[i]),
    ]
    topics.put("/tf", s, msgs.tf(tf))
    if run.twist is not None:
        topics.put("/odom", s, msgs.odometry(s, run.odom[i], run.odom_var[i], run.twist[i]))
    if np.isfinite(run.truth[i]).all():  # a replay's scans without reference: none
        topics.put("/truth/pose", s, msgs.pose_stamped(s, "map", run.truth[i]))
    if run.ranges is not None:
        topics.put("/scan", s, msgs.laser_scan(s, laser, run.ranges[i]))
    if run.people is not None:
        people = msgs.people(s, run.people.xy[i], run.people.radius_m, run.life_ns)
        topics.put("/world/people", s, people)
    for topic, (poses, _) in zip(topics.poses, run.est, strict=True):
        topics.put(topic, s, msgs.pose_stamped(s, "map", poses[i]))


def _write_runs(src: _Source, topics: _Topics) -> None:
    """Every message of the chosen runs, in time order per run: at a run's first scan the
    laser mount, the obstacles and the maps, then each scan's, then the planned path at
    its last."""
    msgs = topics.msgs
    for day, run_, date in src.runs:
        run = _read_run(src, day, run_, date)
        if run is None:
            continue
        t0_ns = int(run.ns[0])
        topics.put(
            "/tf_static", t0_ns, msgs.tf([msgs.transform(t0_ns, "base_link", "laser", src.mount)])
        )
        geom = src.db.geometry(day, run_)
        if geom is not None:
            topics.put("/world/obstacles", t0_ns, msgs.obstacles(t0_ns, *geom))
        for k, topic in topics.maps.items():
            grid = _grid_for_day(src.grids[k], day)
            if grid is not None:
                topics.put(topic, t0_ns, msgs.occupancy_grid(t0_ns, grid))
        for i in range(len(run.ns)):
            _write_scan(topics, run, i, src.laser)
        blob = src.plans.get((day, run_))
        if blob is not None:
            s = int(run.ns[-1])
            topics.put("/plan", s, msgs.path(s, np.frombuffer(blob, dtype="<f8").reshape(-1, 2)))
